"""``setdiff-bench weights export``: a finished training run's checkpoint (or the average of its last ones) and its
training manifest as a shipped-model folder (:mod:`~setdiff_bench.models.setdiff.packaged`): ``config.json``,
``model.safetensors`` and a ``manifest.json`` whose ``files`` table holds each file's SHA-256.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from setdiff_bench.errors import CheckpointError
from setdiff_bench.io.atomic import sha256_file, staged_folder, write_text_atomic
from setdiff_bench.models.setdiff.averaging import average_weights
from setdiff_bench.models.setdiff.checkpoint import read_config, resolve_checkpoint, write_weights
from setdiff_bench.models.setdiff.config import Config
from setdiff_bench.models.setdiff.distill import distillation_record
from setdiff_bench.models.setdiff.files import CONFIG_FILE, MANIFEST_FILE, WEIGHTS_FILE
from setdiff_bench.models.setdiff.packaged import file_table


def initialisation_record(config: Config) -> dict[str, Any] | None:
    """``{"model", "weights_sha256"}`` of the model a fine-tune started from (``[train] init_from``, as the
    config names it), ``None`` for a model trained from scratch."""
    if config.train.init_from is None:
        return None
    folder = resolve_checkpoint(config.train.init_from)
    return {"model": config.train.init_from, "weights_sha256": sha256_file(folder / WEIGHTS_FILE)}


def export_enhancer(
    checkpoint: Path,
    training_manifest: dict[str, Any],
    destination: Path,
    extra: dict[str, Any] | None = None,
    guidance_scale: float | None = None,
    average: Sequence[Path] = (),
) -> Path:
    """Copy a checkpoint's weights and config into ``destination`` (replaced atomically) with a manifest.

    The manifest of a guidance-distilled student also names its teacher (``distillation``:
    :func:`~setdiff_bench.models.setdiff.distill.distillation_record`), that of a fine-tune the model it
    started from (``initialised_from``: :func:`initialisation_record`).

    Args:
        checkpoint: a checkpoint folder (``config.json`` + ``model.safetensors``).
        training_manifest: the training run's manifest (commands, seed, steps, data, validation).
        destination: the new model folder, e.g. ``<package>/weights/tiny_setdiff``.
        extra: more manifest entries (e.g. the export command, evaluation metrics).
        guidance_scale: when given, the exported config's inference geometry-CFG scale (an inference
            knob, not part of the architecture: the weights are copied unchanged); ``None`` keeps the
            checkpoint's.
        average: when given, checkpoint folders of the same run whose weights' uniform mean is exported
            instead of ``checkpoint``'s (:mod:`~setdiff_bench.models.setdiff.averaging`); the config is
            ``checkpoint``'s.

    Raises:
        CheckpointError: the checkpoint lacks a file.
    """
    names = [CONFIG_FILE, WEIGHTS_FILE]
    for name in names:
        if not (checkpoint / name).is_file():
            raise CheckpointError(f"checkpoint has no {name}", checkpoint)
    saved = read_config(checkpoint)
    teacher = distillation_record(saved)
    origin = initialisation_record(saved)
    config = saved if guidance_scale is not None or average else None
    if config is not None and guidance_scale is not None:
        config = replace(config, model=replace(config.model, guidance_scale=float(guidance_scale)))
    averaged = average_weights(average) if average else None
    with staged_folder(destination) as staging:
        if config is not None and guidance_scale is not None:
            write_text_atomic(staging / CONFIG_FILE, config.to_json() + "\n")
        else:
            shutil.copyfile(checkpoint / CONFIG_FILE, staging / CONFIG_FILE)
        if config is not None and averaged is not None:
            write_weights(staging / WEIGHTS_FILE, averaged, config)
        else:
            shutil.copyfile(checkpoint / WEIGHTS_FILE, staging / WEIGHTS_FILE)
        manifest = {**training_manifest, **(extra or {}), "files": file_table(staging, names)}
        if teacher is not None:  # a guidance-distilled student (:mod:`.distill`)
            manifest["distillation"] = teacher
        if origin is not None:  # a fine-tune of another model
            manifest["initialised_from"] = origin
        write_text_atomic(staging / MANIFEST_FILE, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return destination
