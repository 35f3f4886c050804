"""Packet jobs: what one packet is made of (:class:`PacketJob`), the jobs of one (scene, group)
(:class:`GroupPlan`), and the **recipe**, the hash that says whether a stored packet is still current.

A :class:`PacketJob` is a small picklable description that a worker process turns into files
(:mod:`setdiff_bench.packets.worker`); nothing is rendered when it is made.

Recipe: SHA-256 over the packet's inputs: protocol settings that shape it, the fit PLY's SHA-256, frame
names, cameras, source image/mask paths and byte sizes, render backend, C-map precision (and the
trajectory or training-pair label when there is one).  Editing a capture in place without changing its
size is not detected; delete the packet folder to redo it.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from setdiff_bench.packets.working_view import ViewJob
from setdiff_bench.protocols import Protocol
from setdiff_bench.types import Frame, PacketKey, key_fields

PACKET_FORMAT = "setdiff-packets/1"


@dataclass(frozen=True)
class PacketJob(PacketKey):
    """Everything needed to write one packet: its key, then what to render and how."""

    fit_key: str
    fit_path: Path
    references: tuple[ViewJob, ...]
    targets: tuple[ViewJob, ...]
    resolution: tuple[int, int]
    cmap_bound: float | None
    cmap_center: tuple[float, float, float]
    cmap_half: bool = False
    recipe: str = ""
    trajectory: str | None = None
    pairs: str | None = None


@dataclass(frozen=True)
class GroupPlan:
    """The packets of one (scene, group) and the fit they need."""

    scene: str
    group: str
    fit_key: str
    fit_frames: tuple[Frame, ...]
    jobs: tuple[PacketJob, ...]


def with_recipe(job: PacketJob, protocol: Protocol, fit_sha: str, backend: str) -> PacketJob:
    """``job`` with its recipe: the SHA-256 of everything it is made from (module docstring)."""

    def view(v: ViewJob) -> dict[str, Any]:
        return {
            "frame": v.frame,
            "sensor": v.sensor,
            "traversal": v.traversal,
            "timestamp_us": v.timestamp_us,
            "image": None if v.image_path is None else v.image_path.name,
            "image_bytes": None if v.image_path is None else _size(v.image_path),
            "mask": None if v.mask_path is None else v.mask_path.name,
            "mask_bytes": None if v.mask_path is None else _size(v.mask_path),
            "invert_mask": v.invert_mask,
            "crop": [v.crop.left, v.crop.top, v.crop.width, v.crop.height],
            "K": _floats(v.camera.K),
            "w2c": _floats(v.camera.w2c),
            "score": v.overlap_score,
        }

    content = {
        "format": PACKET_FORMAT,
        **key_fields(job),
        "fit_key": job.fit_key,
        "fit_sha256": fit_sha,
        "resolution": list(job.resolution),
        "resize": protocol.images.resize,
        "masks": protocol.images.masks,
        "cmap_bound": job.cmap_bound,
        "cmap_center": list(job.cmap_center),
        "backend": backend,
        "cmap_precision": "half" if job.cmap_half else "float32",
        "references": [view(v) for v in job.references],
        "targets": [view(v) for v in job.targets],
    }
    if job.trajectory is not None:  # only then: the recipes of packets with ground truth stay as they were
        content["trajectory"] = job.trajectory
    if job.pairs is not None:  # likewise for training-pair recipes (packets.recipes)
        content["pairs"] = job.pairs
    # sorted keys: the hash does not depend on the order the fields are listed in
    digest = hashlib.sha256(
        json.dumps(content, sort_keys=True, separators=(",", ":")).encode("utf-8")
    ).hexdigest()
    return replace(job, recipe=digest)


def _floats(array: np.ndarray) -> list[str]:
    return [float(v).hex() for v in np.asarray(array, dtype=np.float64).reshape(-1)]


def _size(path: Path) -> int | None:
    try:
        return path.stat().st_size
    except OSError:
        return None


def flatten(plans: Sequence[GroupPlan]) -> list[PacketJob]:
    """Every job of ``plans``, in order."""
    return [job for plan in plans for job in plan.jobs]
