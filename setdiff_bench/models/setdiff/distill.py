"""Guidance distillation (issue 55; beyond the paper): a one-pass student of a geometry-CFG teacher.

The teacher (e.g. the shipped ``tiny_setdiff``, CFG scale 1.5) enhances with two UNet passes per set,
conditional and unconditional, combined as ``x̂0 = x̂0_u + s·(x̂0_c − x̂0_u)``.  The student has the
teacher's architecture, starts from its weights and is trained (``[train] distill_from``) to give the
guided result in *one* conditional pass: every loss term compares the student's conditional output with
the teacher's guided one instead of the ground truth — the latent loss ``‖x̂0_student − x̂0_teacher‖²``
and the L2 / SSIM / LPIPS terms on the decoded targets.  The student's config says ``guidance_scale = 1``
(inference runs no unconditional branch) and ``geometry_dropout = 0`` (it never learns the unguided
output).  ``weights export`` records the teacher in the exported manifest (:func:`distillation_record`).
"""

from __future__ import annotations

from typing import Any

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.models.setdiff.checkpoint import (
    SET_ATTENTION_KEYS,
    load_model,
    read_config,
    resolve_checkpoint,
)
from setdiff_bench.models.setdiff.config import Config
from setdiff_bench.models.setdiff.files import WEIGHTS_FILE
from setdiff_bench.models.setdiff.inputs import SetBatch
from setdiff_bench.models.setdiff.model import SetDiffModel, SetPrediction


def check_student_config(config: Config) -> None:
    """Refuse a distillation config whose student would not be a one-pass geometry model.

    Raises:
        UsageError: naming the ``[model]`` key to change.
    """
    model = config.model
    if model.method != "setdiff" or not model.use_geometry:
        raise UsageError(
            "distill_from distils geometry guidance: the student needs method 'setdiff' with use_geometry",
            "[model]",
        )
    if model.guidance_scale != 1.0:
        raise UsageError(
            f"a guidance-distilled student runs one pass: set guidance_scale = 1, got {model.guidance_scale}",
            "[model]",
        )
    if model.geometry_dropout != 0.0:
        raise UsageError(
            f"a guidance-distilled student always sees the geometry: set geometry_dropout = 0, got {model.geometry_dropout}",
            "[model]",
        )


def load_teacher(config: Config, device: str | torch.device = "cpu") -> tuple[SetDiffModel, float]:
    """The frozen teacher of ``config.train.distill_from`` (its architecture must be the student's) and the
    CFG scale of its targets (``distill_guidance_scale``, else the teacher config's).

    Raises:
        CheckpointError: the teacher is missing or of another architecture.
        UsageError: the teacher uses no guidance (scale 1): there is nothing to distil.
    """
    tc = config.train
    if tc.distill_from is None:
        raise UsageError("no teacher: set [train] distill_from", "[train]")
    teacher, saved = load_model(tc.distill_from, expected=config, ignore=SET_ATTENTION_KEYS, device=device)
    teacher.requires_grad_(False)
    scale = (
        saved.model.guidance_scale if tc.distill_guidance_scale is None else float(tc.distill_guidance_scale)
    )
    if scale == 1.0:
        raise UsageError(
            "the teacher's guidance scale is 1: nothing to distil (set distill_guidance_scale)", "[train]"
        )
    return teacher, scale


@torch.no_grad()
def distillation_targets(
    teacher: SetDiffModel, batch: SetBatch, guidance_scale: float, decode_index: torch.Tensor | None
) -> SetPrediction:
    """The teacher's guided output for a training set: target x̂0 ``(B, M, C, h, w)`` and, for the
    ``decode_index`` targets, the decoded images ``(B, K, 3, H, W)`` — what :meth:`SetDiffModel.enhance`
    gives at this scale, computed by the training forward pass."""
    return teacher(batch, decode_index=decode_index, guidance_scale=guidance_scale)


def distillation_record(config: Config) -> dict[str, Any] | None:
    """The teacher of a student's config for its manifest: ``{"teacher", "weights_sha256", "guidance_scale"}``
    (``None`` for a model that was not distilled).  The teacher as the config names it (a packaged name
    for the shipped students), its weights by hash: no machine path."""
    tc = config.train
    if tc.distill_from is None:
        return None
    folder = resolve_checkpoint(tc.distill_from)
    scale = tc.distill_guidance_scale
    if scale is None:
        scale = read_config(folder).model.guidance_scale
    return {
        "teacher": tc.distill_from,
        "weights_sha256": sha256_file(folder / WEIGHTS_FILE),
        "guidance_scale": float(scale),
    }
