"""Models shipped in the package: ``setdiff_bench/models/setdiff/weights/<name>/``.

Two kinds, each a folder with a ``manifest.json`` that says how it was made (command, seeds, steps,
wall time, data hash, validation metrics) and a ``files`` table of each file's SHA-256:

* an **autoencoder** (``tiny_autoencoder``): ``config.json`` + ``weights.safetensors``
  (:mod:`~setdiff_bench.models.setdiff.autoencoder`), named by a model config's ``autoencoder`` key;
* an **enhancer** (``tiny_setdiff``, ``tiny_difix``): a checkpoint folder (``config.json`` +
  ``model.safetensors``, :mod:`~setdiff_bench.models.setdiff.checkpoint`), named by ``--checkpoint``.

``setdiff-bench weights list`` shows them, ``weights verify`` recomputes every SHA-256, and
``weights export CKPT --name NAME`` turns a finished training run (its checkpoint and its training
manifest, :mod:`~setdiff_bench.models.setdiff.manifest`) into such a folder.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Sequence
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Any

from setdiff_bench.errors import CheckpointError, WeightsError
from setdiff_bench.io.atomic import sha256_file, staged_folder, write_text_atomic
from setdiff_bench.models.setdiff.manifest import MANIFEST_FILE

PACKAGED_FOLDER = "weights"
#: The file that tells the kinds apart: an enhancer checkpoint's weights, else an autoencoder's.
ENHANCER_WEIGHTS = "model.safetensors"
AUTOENCODER_WEIGHTS = "weights.safetensors"


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
        kind = (
            "enhancer"
            if (folder / ENHANCER_WEIGHTS).is_file()
            else "autoencoder"
            if (folder / AUTOENCODER_WEIGHTS).is_file()
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


def export_enhancer(
    checkpoint: Path,
    training_manifest: dict[str, Any],
    destination: Path,
    extra: dict[str, Any] | None = None,
    guidance_scale: float | None = None,
    average: Sequence[Path] = (),
) -> Path:
    """Copy a checkpoint's weights and config into ``destination`` (replaced atomically) with a manifest.

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
    # lazy: the checkpoint module imports this one
    from setdiff_bench.models.setdiff.averaging import average_weights
    from setdiff_bench.models.setdiff.checkpoint import CONFIG_FILE, WEIGHTS_FILE, read_config, write_weights

    names = [CONFIG_FILE, WEIGHTS_FILE]
    for name in names:
        if not (checkpoint / name).is_file():
            raise CheckpointError(f"checkpoint has no {name}", checkpoint)
    config = read_config(checkpoint) if guidance_scale is not None or average else None
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
        write_text_atomic(staging / MANIFEST_FILE, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return destination
