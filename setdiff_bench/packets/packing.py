"""Packing a scene into packets: which groups apply, the scene's extent, how targets are cut into packets
and which references each packet gets (the rules every plan of :mod:`setdiff_bench.packets.plan` shares).

* **Cutting targets into packets.**  A group's targets (scene order: consecutive in time per
  traversal and camera) are cut into ``⌈T / M⌉`` consecutive chunks whose sizes differ by at most
  one (``numpy.array_split``), where ``M = views − N`` and ``N = min(protocol N, fit frames)``: each
  target is in exactly one packet, and a group with few fit frames (DL3DV n = 3) takes more targets.
* **References.**  ``N`` fit frames chosen by Eq. 2 for the whole chunk
  (:func:`setdiff_bench.geometry.select_references`: mean score over the chunk's targets, ties by
  lower index, best first), with ``d_max`` = the largest pairwise camera-centre distance of the
  scene (every frame the loader returned).
* **C-map clipping.**  Gaussian centres clipped to ``mean camera centre ± cmap_clip · d_max``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import ProtocolError
from setdiff_bench.geometry import max_pairwise_distance, overlap_score_matrix, select_references
from setdiff_bench.packets.index import packet_id
from setdiff_bench.packets.jobs import PacketJob, with_recipe
from setdiff_bench.packets.working_view import ViewJob, view_job
from setdiff_bench.protocols import GroupSpec, Protocol
from setdiff_bench.types import Frame, Scene


def applicable_groups(protocol: Protocol, scene: Scene) -> list[GroupSpec]:
    """The protocol's groups whose ``scenes`` filter accepts ``scene``; ``ProtocolError`` if none does."""
    groups = [g for g in protocol.groups if g.applies_to(scene)]
    if not groups:
        wanted = "; ".join(f"{g.name}: {dict(g.scenes)}" for g in protocol.groups)
        found = {k: scene.metadata.get(k) for g in protocol.groups for k in g.scenes}
        raise ProtocolError(
            f"scene {scene.name!r} matches no group of protocol {protocol.name!r} (scene has "
            f"{found}; groups need {wanted})",
            protocol.path,
        )
    return groups


def scene_extent(
    protocol: Protocol, scene: Scene
) -> tuple[np.ndarray, float, tuple[float, ...], float | None]:
    """``(centres, d_max, centre, bound)`` of ``scene``: its frames' camera centres ``(F, 3)`` (world
    units), ``d_max`` (their largest pairwise distance), their mean, and the C-map clipping half-extent
    ``cmap_clip · d_max`` (``None``: no clipping)."""
    centers = np.stack([f.camera.center for f in scene.frames])
    d_max = max_pairwise_distance(centers)
    center = tuple(float(v) for v in centers.mean(axis=0))
    bound = protocol.cmap_clip * d_max if protocol.cmap_clip > 0 and d_max > 0 else None
    return centers, d_max, center, bound


def chunk_sizes(total: int, per_packet: int) -> list[int]:
    """Sizes of ``⌈total / per_packet⌉`` consecutive chunks differing by at most one."""
    if total <= 0:
        return []
    count = math.ceil(total / per_packet)
    return [len(c) for c in np.array_split(np.arange(total), count)]


def reference_views(
    protocol: Protocol,
    target_cameras: Sequence[Camera],
    fit: Sequence[Frame],
    n_ref: int,
    d_max: float,
    resolution: tuple[int, int],
) -> tuple[ViewJob, ...]:
    """The ``n_ref`` fit frames chosen by Eq. 2 for a chunk of targets (best first), each with its score
    aggregated over the chunk (the protocol's ``[references]`` alpha, beta and aggregate)."""
    refs_spec = protocol.references
    fit_cameras = [f.camera for f in fit]
    chosen = select_references(
        target_cameras,
        fit_cameras,
        n_ref,
        d_max=d_max,
        alpha=refs_spec.alpha,
        beta=refs_spec.beta,
        aggregate=refs_spec.aggregate,
    )
    scores = overlap_score_matrix(
        target_cameras, fit_cameras, d_max, alpha=refs_spec.alpha, beta=refs_spec.beta
    )
    aggregated = scores.mean(axis=0) if refs_spec.aggregate == "mean" else scores.max(axis=0)
    return tuple(
        view_job(protocol, fit[i], resolution, target=False, score=float(aggregated[i])) for i in chosen
    )


def group_jobs(
    protocol: Protocol,
    scene: Scene,
    *,
    group: str,
    split: str,
    fit_key: str,
    fit_file: tuple[Path, str],
    targets: Sequence[tuple[ViewJob, Camera]],
    candidates: Callable[[Sequence[tuple[ViewJob, Camera]]], Sequence[Frame]],
    n_ref: int,
    per_packet: int,
    resolution: tuple[int, int],
    extent: tuple[float, tuple[float, float, float], float | None],
    cmap_half: bool,
    backend: str,
    **extra: Any,
) -> tuple[PacketJob, ...]:
    """The packets of one group: ``targets`` cut into consecutive chunks of at most ``per_packet``
    (:func:`chunk_sizes`), each with its ``n_ref`` references chosen by Eq. 2 among ``candidates(chunk)``
    (:func:`reference_views`, from the targets' cameras at native resolution) and its recipe hash.

    Args:
        targets: ``(view job, native camera)`` of each target, in packet order.
        fit_file: ``(PLY path, its SHA-256)`` of the fit the group renders.
        extent: ``(d_max, C-map clip centre, C-map clip bound)`` of the scene (:func:`scene_extent`).
        extra: further :class:`PacketJob` fields (``trajectory``, ``pairs``).
    """
    d_max, center, bound = extent
    fit_path, fit_sha = fit_file
    jobs, start = [], 0
    for index, size in enumerate(chunk_sizes(len(targets), per_packet)):
        chunk = targets[start : start + size]
        start += size
        job = PacketJob(
            packet_id=packet_id(protocol.name, scene.name, group, index),
            dataset=scene.dataset,
            protocol=protocol.name,
            group=group,
            split=split,
            scene=scene.name,
            fit_key=fit_key,
            fit_path=fit_path,
            references=reference_views(
                protocol, [camera for _, camera in chunk], candidates(chunk), n_ref, d_max, resolution
            ),
            targets=tuple(view for view, _ in chunk),
            resolution=resolution,
            cmap_bound=bound,
            cmap_center=center,
            cmap_half=cmap_half,
            **extra,
        )
        jobs.append(with_recipe(job, protocol, fit_sha, backend))
    return tuple(jobs)
