"""Models shipped in the package: ``setdiff_bench/models/setdiff/weights/<name>/``.

Two kinds, each a folder with a ``manifest.json`` that says how it was made (command, seeds, steps,
wall time, data hash, validation metrics) and a ``files`` table of each file's SHA-256:

* an **autoencoder** (``tiny_autoencoder``): ``config.json`` + ``weights.safetensors``
  (:mod:`~setdiff_bench.models.setdiff.autoencoder`), named by a model config's ``autoencoder`` key;
* an **enhancer** (``tiny_setdiff``, ``tiny_difix``): a checkpoint folder (``config.json`` +
  ``model.safetensors``, :mod:`~setdiff_bench.models.setdiff.checkpoint`), named by ``--checkpoint``.

``setdiff-bench weights list`` shows them and ``weights verify`` recomputes every SHA-256.  This module is the
lookup table only (it imports no model code); ``weights export CKPT --name NAME``, which turns a finished
training run into such a folder, is :mod:`~setdiff_bench.models.setdiff.export`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from setdiff_bench.errors import WeightsError
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.models.setdiff.files import (
    AUTOENCODER_WEIGHTS_FILE,
    MANIFEST_FILE,
    PACKAGED_FOLDER,
    WEIGHTS_FILE,
)


@dataclass(frozen=True)
class PackagedModel:
    """One shipped model.

    Attributes:
        name: the folder name, used as ``--checkpoint NAME`` or ``autoencoder = "NAME"``.
        kind: ``"enhancer"`` or ``"autoencoder"``.
        folder: where it lies.
        manifest: its ``manifest.json``.
    """

    name: str
    kind: str
    folder: Path
    manifest: dict[str, Any]

    def size_bytes(self) -> int:
        return sum(p.stat().st_size for p in self.folder.iterdir() if p.is_file())


def packaged_root() -> Path:
    """The package's ``weights/`` folder."""
    return Path(str(resources.files("setdiff_bench.models.setdiff") / PACKAGED_FOLDER))


def packaged_models(root: Path | None = None) -> dict[str, PackagedModel]:
    """Every shipped model by name (folders with a manifest and a weights file), sorted by name."""
    root = packaged_root() if root is None else root
    models: dict[str, PackagedModel] = {}
    if not root.is_dir():
        return models
    for folder in sorted(p for p in root.iterdir() if p.is_dir()):
        # the weights file tells the kinds apart: an enhancer checkpoint's, else an autoencoder's
        kind = (
            "enhancer"
            if (folder / WEIGHTS_FILE).is_file()
            else "autoencoder"
            if (folder / AUTOENCODER_WEIGHTS_FILE).is_file()
            else None
        )
        if kind is None or not (folder / MANIFEST_FILE).is_file():
            continue
        models[folder.name] = PackagedModel(folder.name, kind, folder, read_json(folder / MANIFEST_FILE))
    return models


def packaged_folder(name: str, kind: str) -> Path | None:
    """The folder of the shipped model ``name`` of ``kind``, or ``None`` when there is none."""
    model = packaged_models().get(name)
    return model.folder if model is not None and model.kind == kind else None


def packaged_names(kind: str) -> list[str]:
    return [name for name, model in packaged_models().items() if model.kind == kind]


#: Speed presets of the shipped enhancers (``-o speed=NAME``, ``run --speed NAME``): ``paper`` runs the
#: checkpoint as it is (SetDiff: geometry CFG, two UNet branches); ``fast`` runs the shipped one-pass student
#: of a shipped SetDiff instead (one UNet pass; its quality against the teacher: docs/performance.md).  A
#: checkpoint that already runs one pass (a student, DiFix) is the same under both.
SPEEDS = ("paper", "fast")


def one_pass_student(teacher: str) -> str | None:
    """The name of the shipped guidance-distilled student of the shipped model ``teacher`` (the enhancer whose
    manifest's ``distillation.teacher`` is ``teacher``), or ``None`` when none ships."""
    for name, model in packaged_models().items():
        record = model.manifest.get("distillation")
        if model.kind == "enhancer" and isinstance(record, dict) and record.get("teacher") == teacher:
            return name
    return None


def read_json(path: Path) -> dict[str, Any]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise WeightsError(f"cannot read: {error}", path) from error
    if not isinstance(data, dict):
        raise WeightsError("not a JSON object", path)
    return data


def verify(model: PackagedModel) -> list[str]:
    """Recompute the SHA-256 of every file the manifest lists; one line per problem (empty = intact)."""
    files = model.manifest.get("files")
    if not isinstance(files, dict) or not files:
        return [f"{model.folder / MANIFEST_FILE}: no 'files' table of SHA-256s"]
    problems = []
    for name, expected in sorted(files.items()):
        path = model.folder / name
        if not path.is_file():
            problems.append(f"{path}: missing")
        elif sha256_file(path) != expected:
            problems.append(f"{path}: SHA-256 differs from the manifest")
    return problems


def file_table(folder: Path, names: list[str]) -> dict[str, str]:
    """``{file name: SHA-256}`` of ``names`` in ``folder``."""
    return {name: sha256_file(folder / name) for name in sorted(names)}
