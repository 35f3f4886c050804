"""``--method setdiff --checkpoint CKPT``: the SetDiff set model as an enhancer (thin adapter).

All references and targets of a packet are enhanced jointly in one set (see
:mod:`setdiff_bench.models.setdiff`), with geometry CFG at the checkpoint's guidance scale unless
``guidance_scale`` overrides it.  A packet of any size is enhanced: its views are reflect-padded to
the network's size multiple (the VAE's ``latent_factor``, 8) and the output cropped back
(:mod:`setdiff_bench.enhancers.padding`).  Heavy imports (diffusers, peft) happen when the enhancer is built.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.enhancers.base import enhancer_repr
from setdiff_bench.enhancers.padding import crop, pad_packet, padded_size
from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.models.setdiff import inference  # module attribute: looked up per call (tests replace it)
from setdiff_bench.models.setdiff.checkpoint import load_model, read_config, resolve_checkpoint
from setdiff_bench.models.setdiff.config import check_guidance_scale
from setdiff_bench.models.setdiff.domain import DataDomain, checkpoint_domain, domain_mismatch
from setdiff_bench.models.setdiff.files import CONFIG_FILE, MANIFEST_FILE, WEIGHTS_FILE
from setdiff_bench.models.setdiff.memory import inference_bytes
from setdiff_bench.models.setdiff.packaged import SPEEDS, one_pass_student
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.types import Packet

DTYPES = {"float32": torch.float32, "bfloat16": torch.bfloat16, "float16": torch.float16}


def speed_checkpoint(method: str, checkpoint: str | None, speed: str | None) -> str | None:
    """The checkpoint that ``speed`` runs for ``checkpoint`` (unchanged for ``paper`` or ``None``).

    Raises:
        UsageError: an unknown preset, or ``fast`` for a two-pass checkpoint that has no shipped student.
    """
    if speed is not None and speed not in SPEEDS:
        raise UsageError(f"speed must be one of {', '.join(SPEEDS)}, got {speed!r}", "--speed")
    if speed != "fast" or not checkpoint or method != "setdiff":
        return checkpoint
    if not read_config(resolve_checkpoint(checkpoint)).model.uses_cfg:
        return checkpoint  # one UNet pass already
    student = one_pass_student(checkpoint)
    if student is None:
        raise UsageError(
            f"--speed fast runs a shipped SetDiff's one-pass student, and none ships for {checkpoint!r}: "
            "train one with [train] distill_from (docs/model.md) and pass it as --checkpoint",
            "--speed",
        )
    return student


class ModelEnhancer:
    """A trained SetDiff/DiFix checkpoint behind the :class:`~setdiff_bench.enhancers.base.Enhancer` protocol.

    Attributes:
        name: the method name (``setdiff`` or ``difix``).
        checkpoint: the checkpoint folder actually loaded.
        config: its saved configuration (``Config``).
        options: the inference options in effect (for run manifests).
    """

    def __init__(
        self,
        name: str,
        model: Any,
        config: Any,
        checkpoint: Path,
        *,
        guidance_scale: float | None,
        sets_per_call: int | None,
        max_references: int | None = None,
        targets_per_set: int | None = None,
    ) -> None:
        self.name = name
        self.model = model
        self.config = config
        self.checkpoint = checkpoint
        self.guidance_scale = guidance_scale
        self.sets_per_call = sets_per_call
        self.max_references = max_references
        self.targets_per_set = targets_per_set
        parameter = next(model.parameters())
        self.options = {
            "checkpoint": str(checkpoint),
            "device": str(parameter.device),
            "dtype": str(parameter.dtype).removeprefix("torch."),
            "guidance_scale": config.model.guidance_scale if guidance_scale is None else guidance_scale,
            "sets_per_call": sets_per_call,
            "max_references": config.model.max_references if max_references is None else max_references,
            "targets_per_set": config.model.targets_per_set if targets_per_set is None else targets_per_set,
        }

    def __repr__(self) -> str:
        """The method, the checkpoint (:attr:`model_name`; its folder as ``path``), device and dtype."""
        return enhancer_repr(self, **self._repr_fields())

    def _repr_fields(self) -> dict[str, object]:
        return {
            "checkpoint": self.model_name,
            "path": str(self.checkpoint),
            "device": self.device,
            "dtype": self.options["dtype"],
        }

    @property
    def device(self) -> str:
        """The device the model computes on."""
        return self.options["device"]

    @property
    def model_name(self) -> str:
        """``tiny_setdiff`` for a shipped model, ``RUN/step_002250`` for a training checkpoint."""
        if (self.checkpoint / MANIFEST_FILE).is_file():
            return self.checkpoint.name
        return f"{self.checkpoint.parent.name}/{self.checkpoint.name}"

    @property
    def size_multiple(self) -> int:
        """Both image sides the network sees are multiples of this (the VAE's latent factor)."""
        return int(self.config.model.latent_factor)

    def memory_bytes(self, references: int, targets: int, height: int, width: int) -> int:
        """Estimated peak bytes above the loaded model to enhance one packet of ``height × width`` pixels
        (:func:`setdiff_bench.models.setdiff.memory.inference_bytes` with this enhancer's options, at
        the padded size the network sees)."""
        height, width = padded_size(height, width, self.size_multiple)
        return inference_bytes(
            self.config.model,
            references=references,
            targets=targets,
            height=height,
            width=width,
            max_references=self.max_references,
            targets_per_set=self.targets_per_set,
            sets_per_call=self.sets_per_call,
            guidance_scale=self.guidance_scale,
            dtype_bytes=next(self.model.parameters()).element_size(),
        )

    def out_of_distribution(
        self, datasets: Sequence[str], resolutions: Sequence[tuple[int, int]], what: str
    ) -> str | None:
        """The warning when the data differs from what the checkpoint's manifest records it was trained on
        (:func:`setdiff_bench.models.setdiff.domain.domain_mismatch`); ``None`` without such a record."""
        return domain_mismatch(
            self.model_name, checkpoint_domain(self.checkpoint), DataDomain.of(datasets, resolutions), what
        )

    def enhance(self, packet: Packet) -> torch.Tensor:
        """``(M, 3, H, W)`` float32 images in [0, 1], packet order, any H × W.

        Views are reflect-padded to :attr:`size_multiple` and the output cropped back
        (:func:`~setdiff_bench.enhancers.padding.pad_packet`); a packet already at a multiple is passed
        to the model as it is.
        """
        padded, padding = pad_packet(packet, self.size_multiple)
        output = inference.enhance_packet(
            self.model,
            padded,
            guidance_scale=self.guidance_scale,
            sets_per_call=self.sets_per_call,
            max_references=self.max_references,
            targets_per_set=self.targets_per_set,
        )
        return crop(output, padding)


def load_enhancer(
    method: str,
    checkpoint: str | None = None,
    *,
    device: str | None = None,
    dtype: str | None = None,
    guidance_scale: float | None = None,
    sets_per_call: int | None = None,
    max_references: int | None = None,
    targets_per_set: int | None = None,
    speed: str | None = None,
) -> ModelEnhancer:
    """Load ``checkpoint`` (a checkpoint folder or a training output folder) for ``method``.

    Args:
        speed: a preset of :data:`SPEEDS` (``fast``: the checkpoint's shipped one-pass student).
        device: ``cuda``/``cpu``/...; default CUDA when available.
        dtype: ``float32``, ``bfloat16`` or ``float16``; default bfloat16 on CUDA, float32 elsewhere.
        max_references, targets_per_set: inference set sizes (default: the checkpoint config's).

    Raises:
        UsageError: no checkpoint given, or an unknown dtype.
        CheckpointError: the checkpoint is missing, broken, or was trained as another method.
    """
    if not checkpoint:
        raise UsageError(
            f"method {method!r} needs a trained model: pass a checkpoint folder, a training output folder "
            "or a shipped model's name (train one with `setdiff-bench train`)",
            parameter="checkpoint",
        )
    device = resolve_device(None if device is None else str(device))
    dtype = dtype or ("bfloat16" if str(device).startswith("cuda") else "float32")
    for name, value in (("max_references", max_references), ("targets_per_set", targets_per_set)):
        if value is not None and (
            not isinstance(value, int) or value < (0 if name == "max_references" else 1)
        ):
            raise UsageError(
                f"{name} must be an integer >= {0 if name == 'max_references' else 1}, got {value!r}",
                f"-o {name}",
            )
    if guidance_scale is not None:
        guidance_scale = check_guidance_scale(guidance_scale, "-o guidance_scale")
    if dtype not in DTYPES:
        raise UsageError(f"dtype must be one of {', '.join(DTYPES)}, got {dtype!r}", "--dtype")
    folder = resolve_checkpoint(speed_checkpoint(method, checkpoint, speed))
    model, config = load_model(folder, method=method, device=device, dtype=DTYPES[dtype])
    return ModelEnhancer(
        method,
        model,
        config,
        folder,
        guidance_scale=guidance_scale,
        sets_per_call=sets_per_call,
        max_references=max_references,
        targets_per_set=targets_per_set,
    )


def fingerprint(checkpoint: str | None = None, speed: str | None = None, **_: Any) -> dict[str, str]:
    """``{file: SHA-256}`` of the weights and config that ``checkpoint`` resolves to (empty without one: the
    factory then refuses with its own message).  A training folder resolves to its newest checkpoint, so a
    run resumed after more training is refused, as its results would mix two models.

    Raises:
        CheckpointError: the checkpoint is missing or broken (the same line the factory would give).
    """
    if not checkpoint:
        return {}
    folder = resolve_checkpoint(speed_checkpoint("setdiff", checkpoint, speed))
    return {name: sha256_file(folder / name) for name in (WEIGHTS_FILE, CONFIG_FILE)}


#: Factory of ``--method setdiff``: :func:`load_enhancer` for the method (``-o max_references=N
#: -o targets_per_set=M`` set the set sizes); the registry reads its options from the signature.
create = functools.partial(load_enhancer, "setdiff")
