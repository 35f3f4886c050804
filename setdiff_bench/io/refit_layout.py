"""Where a refit puts its outputs, and what a refit's manifest says it cost.

``setdiff-bench refit --out OUT`` writes, per scene and fit, ``OUT/<scene>/<fit_key>.ply`` (where
``prepare --fits OUT`` finds it), the manifest ``OUT/<scene>/<fit_key>.refit.json`` beside it (written last,
atomically) and, while it runs, the resumable ``OUT/<scene>/<fit_key>.refit-checkpoint/``; with
``--snapshot-every N`` also ``OUT/snapshots/step-NNNNNN/<scene>/<fit_key>.ply``, the model after that many steps
(each snapshot folder is a fits folder ``prepare --fits`` reads).  Declared here, on
the I/O floor, for :mod:`setdiff_bench.refit` (which writes them) and ``run --refit OUT`` (which records the
refit's cost with the runs of its renders, so that ``leaderboard --cost`` shows it on the ``X 3D`` rows).
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from setdiff_bench.errors import UsageError

REFIT_FORMAT = "setdiff-refit/1"
MANIFEST_SUFFIX = ".refit.json"
CHECKPOINT_SUFFIX = ".refit-checkpoint"
SNAPSHOTS_FOLDER = "snapshots"


def refit_paths(out: str | os.PathLike[str], scene: str, fit_key: str) -> tuple[Path, Path, Path]:
    """``(PLY, manifest, checkpoint folder)`` of ``scene``'s refit of fit ``fit_key`` in ``out``."""
    base = Path(out) / scene
    return (
        base / f"{fit_key}.ply",
        base / f"{fit_key}{MANIFEST_SUFFIX}",
        base / f"{fit_key}{CHECKPOINT_SUFFIX}",
    )


def snapshot_folder(out: str | os.PathLike[str], step: int) -> Path:
    """The fits folder of the refit models of ``out`` after ``step`` steps (``prepare --fits`` it)."""
    return Path(out) / SNAPSHOTS_FOLDER / f"step-{step:06d}"


def refit_cost(out: str | os.PathLike[str], scene: str, fit_key: str) -> dict[str, Any]:
    """What the finished refit of ``scene``'s fit ``fit_key`` in ``out`` cost, from its manifest.

    Returns:
        ``wall_s`` (seconds, the whole refit: steps, updates, the enhancer inside them), ``s_per_step``,
        ``steps``, ``enhance_s`` (inside ``enhance()``), ``peak_memory_mb``, the enhancer's ``method``, the
        ``schedule`` name, the refit PLY's ``ply_sha256`` and the manifest's ``manifest_sha256``.

    Raises:
        UsageError: no manifest there (the refit is missing or unfinished), or a file that is not a refit
            manifest; the message names the file.
    """
    path = refit_paths(out, scene, fit_key)[1]
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise UsageError(
            f"no refit manifest for scene {scene!r}, fit {fit_key!r} (refit missing or unfinished)", path
        ) from None
    try:
        manifest = json.loads(raw)
        if manifest.get("format") != REFIT_FORMAT:
            raise ValueError(f"format {manifest.get('format')!r}")
        time_spent = manifest["time"]
        cost = {
            "wall_s": float(time_spent["wall_s"]),
            "s_per_step": float(time_spent["s_per_step"]),
            "steps": int(time_spent["steps_run"]),
            "enhance_s": float(time_spent["enhance_s"]),
            "peak_memory_mb": float(manifest["peak_memory_mb"]),
            "method": str(manifest["enhancer"]["method"]),
            "schedule": str(manifest["schedule"]["schedule"]),
            "ply_sha256": str(manifest["ply"]["sha256"]),
        }
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        reason = f"{type(error).__name__}: {error}" if not isinstance(error, KeyError) else f"no {error}"
        raise UsageError(f"not a refit manifest ({reason})", path) from None
    return {**cost, "manifest_sha256": hashlib.sha256(raw).hexdigest()}
