"""Provenance of a trained enhancer: the ``manifest.json`` that ``setdiff-bench train`` keeps beside its
checkpoints and that a shipped model carries (:mod:`setdiff_bench.models.setdiff.packaged`).

It says how to make the weights again and what they saw: the command of every training session (a
resumed run adds a session) with its code revision and torch thread count, the config's seed and step
count, the wall time, the training data
(scenes, packet and view counts, ``data_sha256`` = SHA-256 over the sorted SHA-256s of every file the
training split's rows name) and, for the synthetic benchmark, each training scene's generator seeds
``(seed, index)`` parsed from its name, so that a shipped model's training scenes can be checked to be
disjoint from the scenes it is evaluated on.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path
from typing import Any

from setdiff_bench.errors import CheckpointError
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.models.setdiff.files import MANIFEST_FILE
from setdiff_bench.packets.index import FILE_COLUMNS
from setdiff_bench.runtime.provenance import git_revision
from setdiff_bench.runtime.threads import threads_in_force

MANIFEST_FORMAT = "setdiff-enhancer-manifest/1"
#: Synthetic scene folder names (``setdiff_bench.synthetic.generate.scene_name``): seed and index.
SYNTHETIC_SCENE = re.compile(r"^scene_(\d{4,})_(\d{2,})$")


def synthetic_scene_seeds(scene: str) -> tuple[int, int] | None:
    """``(seed, index)`` of a synthetic scene name (``scene_0000_02`` → ``(0, 2)``); ``None`` for other names."""
    match = SYNTHETIC_SCENE.match(scene.rsplit("/", 1)[-1])
    return (int(match.group(1)), int(match.group(2))) if match else None


def training_data_record(store: Any, split: str) -> dict[str, Any]:
    """What a training run reads from a :class:`~setdiff_bench.packets.store.PacketStore`'s ``split``.

    Returns:
        ``{"split", "packets", "views", "scenes", "synthetic_seeds", "datasets", "resolutions",
        "data_sha256"}``; ``synthetic_seeds`` lists ``[seed, index]`` per synthetic scene (empty for other
        datasets); ``datasets`` the dataset names and ``resolutions`` the ``[height, width]`` image sizes
        (what :mod:`~setdiff_bench.models.setdiff.domain` compares a model's inputs with).
    """
    rows = store.index[store.index["split"] == split]
    hashes = sorted(
        {str(h) for column in FILE_COLUMNS for h in rows[f"{column}_sha256"] if isinstance(h, str) and h}
    )
    digest = hashlib.sha256("\n".join(hashes).encode("ascii")).hexdigest()
    scenes = sorted({str(s) for s in rows["scene"]})
    seeds = [list(pair) for pair in (synthetic_scene_seeds(s) for s in scenes) if pair is not None]
    return {
        "split": split,
        "packets": int(rows["packet_id"].nunique()),
        "views": len(rows),
        "scenes": scenes,
        "synthetic_seeds": seeds,
        "datasets": sorted({str(d) for d in rows["dataset"]}),
        "resolutions": sorted({(int(h), int(w)) for h, w in zip(rows["height"], rows["width"], strict=True)}),
        "data_sha256": digest,
    }


def read_manifest(folder: Path) -> dict[str, Any]:
    """The manifest in ``folder``.

    Raises:
        CheckpointError: missing or not a manifest.
    """
    path = folder / MANIFEST_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise CheckpointError(f"cannot read the manifest: {error}", path) from error
    if not isinstance(data, dict) or data.get("format") != MANIFEST_FORMAT:
        raise CheckpointError(f"not a {MANIFEST_FORMAT} manifest", path)
    return data


def record_training_session(
    out: Path,
    *,
    command: str,
    method: str,
    config_name: str,
    seed: int,
    steps: int,
    start_step: int,
    end_step: int,
    wall_seconds: float,
    data: dict[str, Any],
    validation: dict[str, float] | None,
) -> dict[str, Any]:
    """Add one training session to ``out/manifest.json`` (created on the first) and return the manifest.

    Args:
        command: the command line as typed (``setdiff-bench train ...``).
        config_name: the ``--config`` value (a packaged name or a TOML path).
        seed, steps: the config's seed and total step count.
        start_step, end_step: where this session started and stopped.
        wall_seconds: this session's wall time.
        data: :func:`training_data_record` of the training split; a resumed run must read the same data.
        validation: the last validation scores (``None`` when none ran).

    Raises:
        CheckpointError: the manifest there records other training data or another seed.
    """
    path = out / MANIFEST_FILE
    manifest: dict[str, Any]
    if path.is_file():
        manifest = read_manifest(out)
        if manifest["data"]["data_sha256"] != data["data_sha256"] or manifest["seed"] != seed:
            raise CheckpointError("this training run was started on other data or with another seed", path)
    else:
        manifest = {
            "format": MANIFEST_FORMAT,
            "method": method,
            "config": config_name,
            "seed": seed,
            "data": data,
            "sessions": [],
        }
    manifest["steps"] = steps
    manifest["sessions"].append(
        {
            "command": command,
            "start_step": start_step,
            "end_step": end_step,
            "wall_seconds": round(wall_seconds, 1),
            "code": git_revision(),
            "torch_threads": threads_in_force(),
        }
    )
    manifest["wall_seconds"] = round(sum(s["wall_seconds"] for s in manifest["sessions"]), 1)
    manifest["validation"] = validation
    write_text_atomic(path, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return manifest
