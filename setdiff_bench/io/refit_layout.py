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
import re
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


def snapshot_of(folder: str | os.PathLike[str]) -> tuple[Path, int] | None:
    """``(refit OUT, step)`` when ``folder`` is one of :func:`snapshot_folder`'s, else ``None``."""
    folder = Path(folder)
    match = re.fullmatch(r"step-(\d{6})", folder.name)
    if match is None or folder.parent.name != SNAPSHOTS_FOLDER:
        return None
    return folder.parent.parent, int(match.group(1))


def refit_cost(out: str | os.PathLike[str], scene: str, fit_key: str) -> dict[str, Any]:
    """What the finished refit of ``scene``'s fit ``fit_key`` in ``out`` cost, from its manifest.

    ``out`` may also be a snapshot folder of a refit (:func:`snapshot_folder`): the cost is then that of the
    refit's first ``step`` steps, which a refit of that many steps would have spent (its updates and steps are
    the same); ``wall_s`` and ``enhance_s`` are estimated from the refit's own times (steps pro rata, the
    updates done by then in full, the set-up once), and ``ply_sha256`` is the snapshot's.

    Returns:
        ``wall_s`` (seconds, the whole refit: steps, updates, the enhancer inside them), ``s_per_step``,
        ``steps`` (run by the invocation that finished it), ``refit_steps`` (the model's: every step since the
        fit), ``enhance_s`` (inside ``enhance()``), ``peak_memory_mb``, the enhancer's ``method``, the
        ``schedule`` name, the refit PLY's ``ply_sha256`` and the manifest's ``manifest_sha256``.

    Raises:
        UsageError: no manifest there (the refit is missing or unfinished), or a file that is not a refit
            manifest; the message names the file.
    """
    snapshot = snapshot_of(out)
    path = refit_paths(out if snapshot is None else snapshot[0], scene, fit_key)[1]
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
            "refit_steps": int(manifest["schedule"]["steps"]),
            "enhance_s": float(time_spent["enhance_s"]),
            "peak_memory_mb": float(manifest["peak_memory_mb"]),
            "method": str(manifest["enhancer"]["method"]),
            "schedule": str(manifest["schedule"]["schedule"]),
            "ply_sha256": str(manifest["ply"]["sha256"]),
        }
        if snapshot is not None:
            cost.update(_snapshot_cost(manifest, snapshot[1], path))
    except (ValueError, KeyError, TypeError, AttributeError) as error:
        reason = f"{type(error).__name__}: {error}" if not isinstance(error, KeyError) else f"no {error}"
        raise UsageError(f"not a refit manifest ({reason})", path) from None
    return {**cost, "manifest_sha256": hashlib.sha256(raw).hexdigest()}


def _snapshot_cost(manifest: dict[str, Any], step: int, path: Path) -> dict[str, Any]:
    """The cost fields of :func:`refit_cost` for the snapshot after ``step`` steps of ``manifest``'s refit."""
    listed = {int(entry["step"]): str(entry["sha256"]) for entry in manifest.get("snapshots", [])}
    if step not in listed:
        raise UsageError(
            f"the refit wrote no snapshot after {step} steps (snapshots: {sorted(listed)})", path
        )
    spent, schedule = manifest["time"], manifest["schedule"]
    total = int(schedule["steps"])
    every = int(schedule["update_every"])
    updates_by_step = 1 if every == 0 else len(range(0, step, every))
    share = updates_by_step / max(1, int(manifest["updates"]))
    steps_s, updates_s = float(spent["steps_s"]) * step / total, float(spent["updates_s"]) * share
    setup_s = float(spent["wall_s"]) - float(spent["steps_s"]) - float(spent["updates_s"])
    return {
        "wall_s": setup_s + steps_s + updates_s,
        "steps": step,
        "refit_steps": step,
        "enhance_s": float(spent["enhance_s"]) * share,
        "ply_sha256": listed[step],
    }
