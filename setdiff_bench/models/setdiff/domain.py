"""What data an enhancer was trained on, and the warning when it is run on data unlike it.

A model trained on the synthetic streets at 256×144 can damage an object capture at 576×1024 (the shipped
``tiny_difix`` lowered the render's PSNR by 1.3 to 4.6 dB on one), and nothing in its output says so.  A
training run records its data's datasets and image sizes in its manifest (``data.datasets``,
``data.resolutions``, from the packet store's index: :func:`~setdiff_bench.models.setdiff.manifest.training_data_record`);
:func:`domain_mismatch` compares them with the data a model is about to enhance and gives the one line
that ``run``, the stream session and ``serve`` warn with (:class:`setdiff_bench.errors.OutOfDistributionWarning`).
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from setdiff_bench.models.setdiff.files import MANIFEST_FILE


@dataclass(frozen=True)
class DataDomain:
    """Datasets and image sizes of some views (what a model was trained on, or what it is given).

    Attributes:
        datasets: dataset names (``synthetic``, ``dl3dv``, ...); empty = unknown.
        resolutions: ``(height, width)`` in pixels.
    """

    datasets: tuple[str, ...]
    resolutions: tuple[tuple[int, int], ...]

    @classmethod
    def of(cls, datasets: Iterable[str], resolutions: Iterable[tuple[int, int]]) -> DataDomain:
        """Sorted, without repeats."""
        return cls(
            tuple(sorted({str(d) for d in datasets})),
            tuple(sorted({(int(h), int(w)) for h, w in resolutions})),
        )

    def describe(self) -> str:
        """``synthetic at 256×144`` (sizes written width × height, as images are named)."""
        sizes = ", ".join(f"{w}×{h}" for h, w in self.resolutions)
        return f"{'/'.join(self.datasets)} at {sizes}" if self.datasets else f"images of {sizes}"


def domain_of_manifest(manifest: Mapping[str, Any]) -> DataDomain | None:
    """The training data recorded in a manifest, or ``None`` where it records none: an enhancer's
    ``data.datasets`` / ``data.resolutions``; an autoencoder's ``frame_size`` (its dataset unrecorded)."""
    data = manifest.get("data")
    frame_size = manifest.get("frame_size")
    if not isinstance(data, Mapping) and isinstance(frame_size, list) and len(frame_size) == 2:
        return DataDomain.of([], [(frame_size[0], frame_size[1])])
    if not isinstance(data, Mapping):
        return None
    datasets, resolutions = data.get("datasets"), data.get("resolutions")
    if not isinstance(datasets, list) or not isinstance(resolutions, list) or not resolutions:
        return None
    try:
        return DataDomain.of(datasets, [(size[0], size[1]) for size in resolutions])
    except (TypeError, ValueError, IndexError, KeyError):
        return None


def checkpoint_domain(folder: Path) -> DataDomain | None:
    """The training data of a checkpoint folder: the manifest beside its weights (a shipped model) or in
    the training run folder above it; ``None`` when neither records it."""
    for candidate in (folder / MANIFEST_FILE, folder.parent / MANIFEST_FILE):
        try:
            manifest = json.loads(candidate.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):
            continue
        if isinstance(manifest, dict):
            return domain_of_manifest(manifest)
    return None


def domain_mismatch(model: str, trained: DataDomain | None, given: DataDomain, what: str) -> str | None:
    """The warning line when ``given`` has a dataset or an image size that ``trained`` lacks, else ``None``.

    Args:
        model: the model's name (``tiny_difix``).
        what: what ``given`` describes (``this store``, ``this session``).
    """
    if trained is None:
        return None
    new_dataset = bool(given.datasets) and bool(set(given.datasets) - set(trained.datasets))
    new_size = bool(set(given.resolutions) - set(trained.resolutions))
    if not (new_dataset or new_size):
        return None
    return (
        f"{model} was trained on {trained.describe()}; {what} is {given.describe()}: its outputs may be worse "
        "than the input renders here (score them against the raw render, method identity)"
    )
