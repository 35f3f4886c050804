"""Planning packets: protocol × scene → packet jobs (which frames, which cameras, which fit).

Nothing is rendered here; a :class:`PacketJob` is a small picklable description that a worker
process turns into files (:mod:`setdiff_bench.packets.prepare`).

Rules (choices where the paper is silent, all deterministic):

* **Working resolution.**  A frame's camera and image are centre-cropped to the working aspect ratio
  (``resize = "crop"``; a no-op for 16:9 captures at 576×1024) and then resized; ``K`` follows
  through :meth:`Camera.cropped` and :meth:`Camera.resized`.  Images shrink with ``INTER_AREA``
  and grow with ``INTER_LINEAR``; masks use nearest neighbour (as the EUVS metric script).
* **Cutting targets into packets.**  A group's targets (scene order: consecutive in time per
  traversal and camera) are cut into ``⌈T / M⌉`` consecutive chunks whose sizes differ by at most
  one (``numpy.array_split``), where ``M = views − N`` and ``N = min(protocol N, fit frames)``: each
  target is in exactly one packet, and a group with few fit frames (DL3DV n = 3) takes more targets.
* **References.**  ``N`` fit frames chosen by Eq. 2 for the whole chunk
  (:func:`setdiff_bench.geometry.select_references`: mean score over the chunk's targets, ties by
  lower index, best first), with ``d_max`` = the largest pairwise camera-centre distance of the
  scene (every frame the loader returned).
* **C-map clipping.**  Gaussian centres clipped to ``mean camera centre ± cmap_clip · d_max``.
* **Recipe.**  SHA-256 over the packet's inputs: protocol settings that shape it, the fit PLY's
  SHA-256, frame names, cameras, source image/mask paths and byte sizes, render backend.  Editing a
  capture in place without changing its size is not detected; delete the packet folder to redo it.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import ProtocolError, UsageError
from setdiff_bench.geometry import max_pairwise_distance, overlap_score_matrix, select_references
from setdiff_bench.packets.index import packet_id
from setdiff_bench.packets.recipes import PairRecipe, RecipeFrames
from setdiff_bench.packets.trajectory import TrajectorySpec, check_within_bounds, novel_cameras, scene_bounds
from setdiff_bench.protocols import GroupSpec, Protocol
from setdiff_bench.types import Frame, PacketKey, Scene

PACKET_FORMAT = "setdiff-packets/1"


@dataclass(frozen=True)
class Crop:
    """Pixel window ``[left, left + width) × [top, top + height)`` of the source image."""

    left: int
    top: int
    width: int
    height: int


@dataclass(frozen=True)
class ViewJob:
    """One view of a packet, as the worker needs it.

    Attributes:
        frame, sensor, traversal, timestamp_us: from the loader's :class:`Frame`.
        image_path: the capture, or ``None`` for a view on a novel trajectory (rendered, no ground truth).
        mask_path: the mask file, or ``None`` (all pixels evaluated).
        invert_mask: the mask file marks what to ignore (Para-Lane foreground masks).
        crop: window of the source image kept before resizing.
        camera: world-frame camera at the working resolution.
        overlap_score: Eq. 2 score for a reference, ``None`` for a target.
    """

    frame: str
    sensor: str
    traversal: str
    timestamp_us: int | None
    image_path: Path | None
    mask_path: Path | None
    invert_mask: bool
    crop: Crop
    camera: Camera
    overlap_score: float | None = None


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


def crop_window(width: int, height: int, resolution: tuple[int, int], mode: str) -> Crop:
    """The centred window of a ``width × height`` image with the aspect ratio of ``resolution`` (H, W)."""
    if mode == "stretch":
        return Crop(0, 0, width, height)
    out_h, out_w = resolution
    if width * out_h > height * out_w:  # too wide: keep the full height
        crop_w = min(width, max(1, round(height * out_w / out_h)))
        return Crop((width - crop_w) // 2, 0, crop_w, height)
    crop_h = min(height, max(1, round(width * out_h / out_w)))
    return Crop(0, (height - crop_h) // 2, width, crop_h)


def working_camera(camera: Camera, crop: Crop, resolution: tuple[int, int]) -> Camera:
    """``camera`` after cropping to ``crop`` and resizing to ``resolution`` (H, W)."""
    if (crop.left, crop.top, crop.width, crop.height) != (0, 0, camera.width, camera.height):
        camera = camera.cropped(crop.left, crop.top, crop.width, crop.height)
    if (camera.height, camera.width) != tuple(resolution):
        camera = camera.resized(resolution[1], resolution[0])
    return camera


def scene_resolution(protocol: Protocol, scene: Scene) -> tuple[int, int]:
    """The working ``(height, width)``: the protocol's, or the scene's own for ``"native"``."""
    if protocol.images.resolution is not None:
        return protocol.images.resolution
    sizes = sorted({(f.camera.height, f.camera.width) for f in scene.frames})
    if len(sizes) != 1:
        raise ProtocolError(
            f'resolution = "native" needs one image size per scene; scene {scene.name!r} has '
            f"{', '.join(f'{w}x{h}' for h, w in sizes)}",
            protocol.path,
        )
    height, width = sizes[0]
    scale = protocol.images.downscale
    return max(1, round(height / scale)), max(1, round(width / scale))


def mask_source(protocol: Protocol, frame: Frame) -> tuple[Path | None, bool]:
    """``(mask file or None, invert)`` of a target under the protocol's mask rule."""
    if protocol.images.masks == "dataset":
        return frame.mask_path, False
    if protocol.images.masks == "foreground":
        path = frame.metadata.get("foreground_mask_path")
        return (Path(path), True) if path else (None, False)
    return None, False


def view_job(
    protocol: Protocol, frame: Frame, resolution: tuple[int, int], *, target: bool, score: float | None = None
) -> ViewJob:
    crop = crop_window(frame.camera.width, frame.camera.height, resolution, protocol.images.resize)
    mask, invert = mask_source(protocol, frame) if target else (None, False)
    return ViewJob(
        frame=frame.name,
        sensor=frame.sensor,
        traversal=frame.traversal,
        timestamp_us=frame.timestamp_us,
        image_path=frame.image_path,
        mask_path=mask,
        invert_mask=invert,
        crop=crop,
        camera=working_camera(frame.camera, crop, resolution),
        overlap_score=score,
    )


def chunk_sizes(total: int, per_packet: int) -> list[int]:
    """Sizes of ``⌈total / per_packet⌉`` consecutive chunks differing by at most one."""
    if total <= 0:
        return []
    count = math.ceil(total / per_packet)
    return [len(c) for c in np.array_split(np.arange(total), count)]


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
    centers = np.stack([f.camera.center for f in scene.frames])
    d_max = max_pairwise_distance(centers)
    center = tuple(float(v) for v in centers.mean(axis=0))
    bound = protocol.cmap_clip * d_max if protocol.cmap_clip > 0 and d_max > 0 else None
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
    fit_path, fit_sha = fit_path_for(scene.name, group.fit_key)
    n_ref = min(protocol.references_for(split), len(frames.fit))
    per_packet = protocol.views_for(split) - n_ref
    jobs, start = [], 0
    for index, size in enumerate(chunk_sizes(len(frames.targets), per_packet)):
        targets = frames.targets[start : start + size]
        start += size
        job = PacketJob(
            packet_id=packet_id(protocol.name, scene.name, group.name, index),
            dataset=scene.dataset,
            protocol=protocol.name,
            group=group.name,
            split=split,
            scene=scene.name,
            fit_key=group.fit_key,
            fit_path=fit_path,
            references=_references(
                protocol, [f.camera for f in targets], frames.fit, n_ref, d_max, resolution
            ),
            targets=tuple(view_job(protocol, f, resolution, target=True) for f in targets),
            resolution=resolution,
            cmap_bound=bound,
            cmap_center=center,
            cmap_half=cmap_half,
        )
        jobs.append(_with_recipe(job, protocol, fit_sha, backend))
    return GroupPlan(
        scene=scene.name, group=group.name, fit_key=group.fit_key, fit_frames=frames.fit, jobs=tuple(jobs)
    )


def _references(
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


def _with_recipe(job: PacketJob, protocol: Protocol, fit_sha: str, backend: str) -> PacketJob:
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
        "packet_id": job.packet_id,
        "dataset": job.dataset,
        "protocol": job.protocol,
        "group": job.group,
        "split": job.split,
        "scene": job.scene,
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
    return [job for plan in plans for job in plan.jobs]


# ---------------------------------------------------------------------- novel trajectories
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
    centers = np.stack([f.camera.center for f in scene.frames])
    d_max = max_pairwise_distance(centers)
    center = tuple(float(v) for v in centers.mean(axis=0))
    bound = protocol.cmap_clip * d_max if protocol.cmap_clip > 0 and d_max > 0 else None
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
            jobs, start = [], 0
            for index, size in enumerate(chunk_sizes(len(targets), per_packet)):
                chunk = targets[start : start + size]
                start += size
                job = PacketJob(
                    packet_id=packet_id(protocol.name, scene.name, name, index),
                    dataset=scene.dataset,
                    protocol=protocol.name,
                    group=name,
                    split=TRAJECTORY_SPLIT,
                    scene=scene.name,
                    fit_key=fit_key,
                    fit_path=fit_path,
                    references=_references(
                        protocol, [native for _, native in chunk], fit, n_ref, d_max, resolution
                    ),
                    targets=tuple(v for v, _ in chunk),
                    resolution=resolution,
                    cmap_bound=bound,
                    cmap_center=center,
                    cmap_half=cmap_half,
                    trajectory=spec.label,
                )
                jobs.append(_with_recipe(job, protocol, fit_sha, backend))
            plans.append(GroupPlan(scene.name, name, fit_key, fit, tuple(jobs)))
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


# ---------------------------------------------------------------------- training-pair recipes
def plan_recipe_pairs(
    protocol: Protocol,
    scene: Scene,
    split: str,
    fit_key: str,
    fit_keys: Sequence[str],
    pairs: Sequence[tuple[PairRecipe, RecipeFrames]],
    fit_path_for: Any,
    *,
    backend: str = "torch",
    cmap_half: bool = False,
) -> list[GroupPlan]:
    """Plan the training-pair packets of one (scene, protocol fit key): one group per recipe
    (:mod:`setdiff_bench.packets.recipes`).

    Each recipe's degraded fit is ``<fit_key><suffix>`` (``lane0@sparse4``).  Its targets are recorded
    frames with their ground truth and mask, cut into packets as the scene's split cuts protocol targets
    (``packets.<split>_views`` minus the references), and each chunk gets the protocol's ``N`` references
    chosen by Eq. 2 (:func:`_references`, the scene's ``d_max``) among the recorded frames the degraded fit
    saw.  For ``underfit`` the fit saw every target: a chunk's own targets are left out of its candidates
    (the clean capture of a target is never its reference), ``N`` is at most the fit frames minus one and a
    chunk holds at most ``fit frames − N`` targets.

    Args:
        protocol: the protocol.
        scene: the loaded scene.
        split: the scene's split (packet and reference counts).
        fit_key: the protocol fit key whose fit frames are the recorded frames.
        fit_keys: every fit key of the scene's groups (group names get ``@<fit key>`` when several).
        pairs: each recipe with its frames (:func:`~setdiff_bench.packets.recipes.recipe_frames`).
        fit_path_for: ``callable(scene_name, fit_key) -> (Path, sha256)`` of a fit PLY.
        backend, cmap_half: as :func:`plan_scene` (part of the recipe hash).
    """
    resolution = scene_resolution(protocol, scene)
    centers = np.stack([f.camera.center for f in scene.frames])
    d_max = max_pairwise_distance(centers)
    center = tuple(float(v) for v in centers.mean(axis=0))
    bound = protocol.cmap_clip * d_max if protocol.cmap_clip > 0 and d_max > 0 else None
    plans = []
    for recipe, frames in pairs:
        degraded_key = f"{fit_key}{frames.fit_suffix}"
        fit_path, fit_sha = fit_path_for(scene.name, degraded_key)
        name = trajectory_group_name(recipe.label, fit_key, fit_keys)
        if frames.disjoint:
            n_ref = min(protocol.references_for(split), len(frames.fit))
            per_packet = protocol.views_for(split) - n_ref
        else:
            n_ref = min(protocol.references_for(split), len(frames.fit) - 1)
            per_packet = min(protocol.views_for(split) - n_ref, len(frames.fit) - n_ref)
        jobs, start = [], 0
        for index, size in enumerate(chunk_sizes(len(frames.targets), per_packet)):
            chunk = frames.targets[start : start + size]
            start += size
            chosen = {f.name for f in chunk}
            candidates = [f for f in frames.fit if frames.disjoint or f.name not in chosen]
            job = PacketJob(
                packet_id=packet_id(protocol.name, scene.name, name, index),
                dataset=scene.dataset,
                protocol=protocol.name,
                group=name,
                split=split,
                scene=scene.name,
                fit_key=degraded_key,
                fit_path=fit_path,
                references=_references(
                    protocol, [f.camera for f in chunk], candidates, n_ref, d_max, resolution
                ),
                targets=tuple(view_job(protocol, f, resolution, target=True) for f in chunk),
                resolution=resolution,
                cmap_bound=bound,
                cmap_center=center,
                cmap_half=cmap_half,
                pairs=recipe.label,
            )
            jobs.append(_with_recipe(job, protocol, fit_sha, backend))
        plans.append(GroupPlan(scene.name, name, degraded_key, frames.fit, tuple(jobs)))
    return plans
