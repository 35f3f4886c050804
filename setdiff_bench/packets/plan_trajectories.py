"""Planning novel-trajectory packets (``prepare --trajectory``): the fit frames' cameras moved along a
trajectory are the targets (no ground truth), references are recorded fit frames chosen by Eq. 2."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import ProtocolError, UsageError
from setdiff_bench.packets.jobs import GroupPlan
from setdiff_bench.packets.packing import applicable_groups, group_jobs, scene_extent
from setdiff_bench.packets.trajectory import TrajectorySpec, check_within_bounds, novel_cameras, scene_bounds
from setdiff_bench.packets.working_view import ViewJob, crop_window, scene_resolution, working_camera
from setdiff_bench.protocols import Protocol
from setdiff_bench.types import Frame, Scene

#: The split of every novel-trajectory packet: its targets have no ground truth to train on.
TRAJECTORY_SPLIT = "test"


def trajectory_frame_name(frame: str, label: str) -> str:
    """``<stem>@<label><suffix>`` of a recorded frame name (``lane0_front_000.png`` → ``lane0_front_000@shift+3m.png``;
    a folder part is kept), so the run's ``<frame stem>.png`` stays distinct per trajectory."""
    head, _, tail = frame.replace("\\", "/").rpartition("/")
    stem, dot, suffix = tail.rpartition(".")
    named = f"{stem}@{label}.{suffix}" if dot and stem else f"{tail}@{label}"
    return f"{head}/{named}" if head else named


def trajectory_group_name(label: str, fit_key: str, fit_keys: Sequence[str]) -> str:
    """The group of a trajectory's packets: its label (``shift+3m``), or ``<label>@<fit key>`` when the
    scene's groups use several fits (each fit gives its own trajectory)."""
    return label if len(set(fit_keys)) <= 1 else f"{label}@{fit_key}"


def plan_trajectories(
    protocol: Protocol,
    scene: Scene,
    trajectories: Sequence[TrajectorySpec],
    fit_path_for: Any,
    gaussian_centres: Any,
    *,
    backend: str = "torch",
    cmap_half: bool = False,
) -> list[GroupPlan]:
    """Plan the novel-trajectory packets of ``scene``: one group per (fit key, trajectory).

    The recorded trajectory is the group's fit frames (what the 3DGS saw), moved as each spec says
    (:func:`setdiff_bench.packets.trajectory.novel_cameras`; a pose file's intrinsics and size are in the
    capture's pixels, before the protocol's crop and resize).  Targets are the moved cameras, in recorded
    order, named :func:`trajectory_frame_name`; they have no capture, so no ground truth and no mask.
    They are cut into packets as a test scene's targets are (``packets.test_views`` minus the references)
    and each chunk gets the protocol's ``N`` references chosen by Eq. 2 among the fit frames, with the
    scene's ``d_max``, exactly as protocol groups do.  Every packet's split is :data:`TRAJECTORY_SPLIT`.

    Args:
        protocol: the protocol (already restricted to the groups asked for).
        scene: the loaded scene.
        trajectories: parsed ``--trajectory`` specs (distinct labels).
        fit_path_for: ``callable(scene_name, fit_key) -> (Path, sha256)`` of the fit PLY.
        gaussian_centres: ``callable(scene_name, fit_key) -> (N, 3)`` float array of the fit's Gaussian
            centres in the world frame (the scene bounds a trajectory must stay in).
        backend, cmap_half: as :func:`plan_scene` (part of the recipe).

    Raises:
        UsageError: a camera of the trajectory leaves the scene bounds, or a pose of a pose file has
            another image size than the recorded frames.
        CameraError: a pose file's non-rigid pose or NaN.
        ProtocolError: as :func:`plan_scene`.
    """
    groups = applicable_groups(protocol, scene)
    resolution = scene_resolution(protocol, scene)
    centers, d_max, center, bound = scene_extent(protocol, scene)
    fit_keys = [g.fit_key for g in groups]
    plans = []
    for fit_key in dict.fromkeys(fit_keys):  # protocol order, each fit once
        group = next(g for g in groups if g.fit_key == fit_key)
        fit = group.select(scene).fit
        if not fit:
            raise ProtocolError(
                f"protocol {protocol.name!r} group {group.name!r} selects no fit frames in scene {scene.name!r}",
                protocol.path,
            )
        fit_path, fit_sha = fit_path_for(scene.name, fit_key)
        bounds = scene_bounds(gaussian_centres(scene.name, fit_key), centers)
        n_ref = min(protocol.references_for(TRAJECTORY_SPLIT), len(fit))
        per_packet = protocol.views_for(TRAJECTORY_SPLIT) - n_ref
        for spec in trajectories:
            targets = _trajectory_targets(protocol, spec, fit, resolution)
            what = f"--trajectory {spec.label} (scene {scene.name!r})"
            check_within_bounds([(v.frame, v.camera) for v, _ in targets], bounds, what)
            name = trajectory_group_name(spec.label, fit_key, fit_keys)
            jobs = group_jobs(
                protocol,
                scene,
                group=name,
                split=TRAJECTORY_SPLIT,
                fit_key=fit_key,
                fit_file=(fit_path, fit_sha),
                targets=targets,
                candidates=lambda chunk, fit=fit: fit,
                n_ref=n_ref,
                per_packet=per_packet,
                resolution=resolution,
                extent=(d_max, center, bound),
                cmap_half=cmap_half,
                backend=backend,
                trajectory=spec.label,
            )
            plans.append(GroupPlan(scene.name, name, fit_key, fit, jobs))
    return plans


def _trajectory_targets(
    protocol: Protocol, spec: TrajectorySpec, fit: Sequence[Frame], resolution: tuple[int, int]
) -> list[tuple[ViewJob, Camera]]:
    """``(target view at the working resolution, camera at the capture's size)`` of every novel camera."""
    novel = novel_cameras(spec, [(f.name, f.camera) for f in fit])
    out = []
    for i, (name, native) in enumerate(novel):
        base = None if spec.kind == "poses" else fit[i]  # a shift or yaw moves each fit frame, in order
        crop = crop_window(native.width, native.height, resolution, protocol.images.resize)
        camera = working_camera(native, crop, resolution)
        if (camera.height, camera.width) != tuple(resolution):
            raise UsageError(
                f"pose {i} ({name!r}) is {native.width}x{native.height}, which does not map to the packets' "
                f"{resolution[1]}x{resolution[0]}",
                spec.path or "--trajectory",
            )
        view = ViewJob(
            frame=trajectory_frame_name(base.name, spec.label) if base is not None else name,
            sensor=base.sensor if base is not None else "",
            traversal=base.traversal if base is not None else spec.label,
            timestamp_us=base.timestamp_us if base is not None else None,
            image_path=None,
            mask_path=None,
            invert_mask=False,
            crop=crop,
            camera=camera,
        )
        out.append((view, native))
    return out
