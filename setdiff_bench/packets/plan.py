"""Planning packets: protocol × scene → packet jobs (which frames, which cameras, which fit).

Nothing is rendered here; a :class:`~setdiff_bench.packets.jobs.PacketJob` is a small picklable description
that a worker process turns into files (:mod:`setdiff_bench.packets.worker`).

Rules (choices where the paper is silent, all deterministic), each in the module that applies it:

* **Working resolution**, crop and resize, masks: :mod:`setdiff_bench.packets.working_view`.
* **Cutting targets into packets**, **references** (Eq. 2), **C-map clipping**:
  :mod:`setdiff_bench.packets.packing`.
* **Recipe** (the hash that decides whether a stored packet is current): :mod:`setdiff_bench.packets.jobs`.

Plans: the protocol's groups (:func:`plan_scene`, here), novel trajectories
(:func:`~setdiff_bench.packets.plan_trajectories.plan_trajectories`) and training pairs
(:func:`~setdiff_bench.packets.plan_pairs.plan_recipe_pairs`).
"""

from __future__ import annotations

from typing import Any

from setdiff_bench.errors import ProtocolError
from setdiff_bench.packets.jobs import GroupPlan
from setdiff_bench.packets.packing import (
    applicable_groups,
    group_jobs,
    scene_extent,
)
from setdiff_bench.packets.working_view import (
    scene_resolution,
    view_job,
)
from setdiff_bench.protocols import GroupSpec, Protocol
from setdiff_bench.types import Scene

__all__ = ["plan_scene"]


def plan_scene(
    protocol: Protocol,
    scene: Scene,
    split: str,
    fit_path_for: Any,
    *,
    backend: str = "torch",
    cmap_half: bool = False,
) -> list[GroupPlan]:
    """Plan every packet of ``scene`` under ``protocol``.

    Args:
        protocol: the protocol.
        scene: the loaded scene.
        split: the scene's split (``"train"``/``"test"``), picking packet sizes.
        fit_path_for: ``callable(scene_name, fit_key) -> (Path, sha256)`` of the fit PLY.
        backend: render backend name (part of the recipe).
        cmap_half: store C-maps as half floats (part of the recipe).

    Raises:
        ProtocolError: no group applies to the scene, or a group selects no fit frames / targets, or
            targets that are also fit frames.
    """
    groups = applicable_groups(protocol, scene)
    # Distorted cameras stay distorted here: prepare resamples their captures to the pinhole camera
    # (setdiff_bench.undistort) before they enter a packet, as the renderer draws pinhole images.
    resolution = scene_resolution(protocol, scene)
    _, d_max, center, bound = scene_extent(protocol, scene)
    plans = []
    for group in groups:
        plans.append(
            _plan_group(
                protocol,
                scene,
                split,
                group,
                resolution,
                d_max,
                bound,
                center,
                fit_path_for,
                backend,
                cmap_half,
            )
        )
    return plans


def _plan_group(
    protocol: Protocol,
    scene: Scene,
    split: str,
    group: GroupSpec,
    resolution: tuple[int, int],
    d_max: float,
    bound: float | None,
    center: tuple[float, float, float],
    fit_path_for: Any,
    backend: str,
    cmap_half: bool,
) -> GroupPlan:
    frames = group.select(scene)
    where = f"protocol {protocol.name!r} group {group.name!r} ({group.rule}) in scene {scene.name!r}"
    if not frames.fit:
        raise ProtocolError(f"{where} selects no fit frames", protocol.path)
    if not frames.targets:
        raise ProtocolError(f"{where} selects no target frames", protocol.path)
    overlap = {f.name for f in frames.fit} & {f.name for f in frames.targets}
    if overlap:
        raise ProtocolError(
            f"{where}: frame {sorted(overlap)[0]!r} is both a fit frame and a target", protocol.path
        )
    n_ref = min(protocol.references_for(split), len(frames.fit))
    jobs = group_jobs(
        protocol,
        scene,
        group=group.name,
        split=split,
        fit_key=group.fit_key,
        fit_file=fit_path_for(scene.name, group.fit_key),
        targets=[(view_job(protocol, f, resolution, target=True), f.camera) for f in frames.targets],
        candidates=lambda chunk: frames.fit,
        n_ref=n_ref,
        per_packet=protocol.views_for(split) - n_ref,
        resolution=resolution,
        extent=(d_max, center, bound),
        cmap_half=cmap_half,
        backend=backend,
    )
    return GroupPlan(
        scene=scene.name, group=group.name, fit_key=group.fit_key, fit_frames=frames.fit, jobs=jobs
    )
