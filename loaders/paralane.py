"""Para-Lane scenes: three parallel-lane clips per scene (docs/datasets.md, "Para-Lane protocol").

Layout read::

    <root>/scene_<i>/clip_<k>/images/<timestamp_us>/CAMERA_FRONT.png
                             foreground_mask/<timestamp_us>/CAMERA_FRONT.png   (or foreground_masks/, foreground_labels/)
                             sparse/0/cameras.txt, images.txt                  (COLMAP text, world-to-camera, w,x,y,z)
                             sparse/0/lidar_poses.txt                          ("<name>.ply QX QY QZ QW X Y Z", lidar-to-world)

One :class:`Scene` per ``scene_<i>``, with the frames of every clip; ``Frame.traversal`` is the clip
name and ``metadata["lane"]`` its lane index (``clip_k`` → lane ``k``; the project page labels
tracks 0/1/2 Left/Middle/Right — UNCONFIRMED, override with ``lane_of_clip``).  The clips' COLMAP
models are assumed to share one world frame, as cross-lane evaluation requires (UNCONFIRMED).

Image names: a COLMAP ``NAME`` is looked up as ``images/<NAME>``, then as
``images/<stem of NAME>/CAMERA_FRONT.png``; only if no name of a clip resolves, and the model has as
many images as there are timestamp folders, are they paired by order (names naturally sorted against
sorted folders) with a warning (docs/datasets.md, "Loader pitfalls").  ``timestamp_us`` is the
integer folder name.

Foreground masks: the folder's name says it marks foreground (moving) objects, so by default
(``mask_polarity="foreground"``) the path goes to ``metadata["foreground_mask_path"]`` and
``Frame.mask_path`` (255 = keep) stays ``None``; pass ``mask_polarity="keep"`` if your masks are
255 = static.  The encoding is UNCONFIRMED (docs/datasets.md, "Para-Lane protocol").

``lidar_poses.txt`` quaternions are **scalar-last** (x, y, z, w), unlike ``images.txt``.  A pose whose
``.ply`` stem equals a frame's timestamp folder is attached as ``metadata["lidar_to_world"]``; all
poses are in ``Scene.metadata["lidar_poses"][clip]``.

Frame order: lane index, then timestamp (natural name order where there is none).
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path, PurePosixPath
from typing import Literal

import numpy as np

from setdiff_bench.errors import DatasetError, DatasetWarning
from setdiff_bench.io.paths import resolve_inside
from setdiff_bench.rotations import rigid_from_quaternion
from setdiff_bench.types import Frame, Scene

from .colmap import DistortionPolicy, read_colmap_model
from .common import (
    check_image_matches_camera,
    dataset_root,
    frames_by_key,
    image_size,
    natural_key,
    require_dir,
    require_scenes,
    selected_scene_dirs,
)

MaskPolarity = Literal["foreground", "keep"]
MASK_FOLDERS = ("foreground_mask", "foreground_masks", "foreground_labels", "foreground_label")
SENSOR_FILE = "CAMERA_FRONT.png"
CLIP_NAME = re.compile(r"^clip_(\d+)$")
LANE_NAMES = {0: "left", 1: "middle", 2: "right"}


def _clip_dirs(scene_dir: Path) -> list[Path]:
    try:
        children = sorted(
            (p for p in scene_dir.iterdir() if p.is_dir() and CLIP_NAME.match(p.name)),
            key=lambda p: natural_key(p.name),
        )
    except OSError:
        return []
    return [p for p in children if (p / "sparse").is_dir()]


def _scene_dirs(base: Path) -> dict[str, Path]:
    return require_scenes(
        base, lambda folder: bool(_clip_dirs(folder)), "Para-Lane", "scene_<i>/clip_<k>/sparse/0", max_depth=2
    )


def list_scenes(root: str | os.PathLike[str]) -> list[str]:
    """Para-Lane scene folders (holding ``clip_<k>/sparse``) under ``root``, in natural order."""
    return list(_scene_dirs(dataset_root(root)))


def read_lidar_poses(path: Path) -> dict[str, np.ndarray]:
    """Parse ``lidar_poses.txt``: ``.ply`` stem → ``(4, 4)`` lidar-to-world (quaternion x, y, z, w).

    Lines without a leading file name (seven numbers) are keyed by their 0-based line index.

    Raises:
        DatasetError: malformed lines or a name listed twice.
        CameraError: a quaternion off unit norm by more than 1e-3.
    """
    poses: dict[str, np.ndarray] = {}
    index = 0
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        fields = line.split()
        if not fields or fields[0].startswith("#"):
            continue
        name = str(index)
        if len(fields) == 8:
            name, fields = PurePosixPath(fields[0]).stem, fields[1:]
        if len(fields) != 7:
            raise DatasetError(f"line {number}: expected '<name>.ply QX QY QZ QW X Y Z'", path)
        try:
            values = [float(v) for v in fields]
        except ValueError as exc:
            raise DatasetError(f"line {number}: pose values are not numbers", path) from exc
        if name in poses:
            raise DatasetError(f"line {number}: duplicate lidar frame {name!r}", path)
        poses[name] = rigid_from_quaternion(
            values[:4], values[4:], order="xyzw", source=f"{path} (line {number})"
        )
        index += 1
    return poses


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    mask_polarity: MaskPolarity = "foreground",
    lane_of_clip: Mapping[str, int] | None = None,
    distortion: DistortionPolicy = "keep",
) -> list[Scene]:
    """Load Para-Lane scenes (rules in the module docstring).

    Args:
        root: dataset root holding ``scene_<i>`` folders (or one scene folder).
        scenes: names from :func:`list_scenes`; ``None`` = all.
        mask_polarity: ``"foreground"`` (255 = moving object) or ``"keep"`` (255 = static).
        lane_of_clip: clip name → lane index; default ``clip_k`` → ``k``.
        distortion: undistortion policy of :mod:`setdiff_bench.loaders.colmap`.
    """
    if mask_polarity not in ("foreground", "keep"):
        raise DatasetError(f"unknown mask polarity {mask_polarity!r}; use foreground or keep", root)
    base = dataset_root(root)
    found = _scene_dirs(base)
    out = []
    for name, scene_dir in selected_scene_dirs(found, scenes, base, "paralane"):
        frames: list[tuple[tuple, Frame]] = []
        lidar: dict[str, dict[str, np.ndarray]] = {}
        lanes: dict[str, int] = {}
        for clip_dir in _clip_dirs(scene_dir):
            lane = _lane(clip_dir, lane_of_clip)
            lanes[clip_dir.name] = lane
            clip_frames, lidar[clip_dir.name] = _load_clip(clip_dir, lane, mask_polarity, distortion)
            frames.extend(clip_frames)
        out.append(
            Scene(
                dataset="paralane",
                name=name,
                root=scene_dir,
                frames=frames_by_key(frames),
                metadata={
                    "lanes": lanes,
                    "lidar_poses": lidar,
                    "mask_polarity": mask_polarity,
                    "shared_world": "assumed",
                },
            )
        )
    return out


def _lane(clip_dir: Path, lane_of_clip: Mapping[str, int] | None) -> int:
    if lane_of_clip is not None:
        if clip_dir.name not in lane_of_clip:
            raise DatasetError(f"lane_of_clip has no entry for {clip_dir.name!r}", clip_dir)
        return int(lane_of_clip[clip_dir.name])
    match = CLIP_NAME.match(clip_dir.name)
    assert match is not None
    return int(match.group(1))


def _resolve_images(clip_dir: Path, names: list[str], source: Path) -> dict[str, Path]:
    """COLMAP image name → image file (rules in the module docstring)."""
    image_root = require_dir(clip_dir / "images", "image folder")
    resolved: dict[str, Path] = {}
    for name in names:
        direct = resolve_inside(image_root, name, source=source)
        by_stem = resolve_inside(image_root, f"{PurePosixPath(name).stem}/{SENSOR_FILE}", source=source)
        if direct.is_file():
            resolved[name] = direct
        elif by_stem.is_file():
            resolved[name] = by_stem
    if len(resolved) == len(names):
        return resolved
    if resolved:
        missing = next(n for n in names if n not in resolved)
        raise DatasetError(f"image {missing!r} listed in {source.name} not found", image_root)
    folders = sorted(
        (p for p in image_root.iterdir() if p.is_dir() and (p / SENSOR_FILE).is_file()),
        key=lambda p: natural_key(p.name),
    )
    if len(folders) != len(names):
        raise DatasetError(
            f"no image name of {source.name} matches a file, and its {len(names)} images cannot be "
            f"paired by order with {len(folders)} timestamp folders",
            image_root,
        )
    warnings.warn(
        f"{source}: image names do not match images/<timestamp>/{SENSOR_FILE}; pairing the "
        f"{len(names)} images with the timestamp folders by sorted order",
        DatasetWarning,
        stacklevel=3,
    )
    return {name: folder / SENSOR_FILE for name, folder in zip(sorted(names, key=natural_key), folders)}


def _load_clip(
    clip_dir: Path, lane: int, mask_polarity: MaskPolarity, distortion: DistortionPolicy
) -> tuple[list[tuple[tuple, Frame]], dict[str, np.ndarray]]:
    sparse = clip_dir / "sparse" / "0"
    model = read_colmap_model(sparse, distortion=distortion)
    paths = _resolve_images(clip_dir, list(model.cameras), model.images_file)
    lidar_file = sparse / "lidar_poses.txt"
    lidar = read_lidar_poses(lidar_file) if lidar_file.is_file() else {}
    mask_root = next((clip_dir / m for m in MASK_FOLDERS if (clip_dir / m).is_dir()), None)
    image_root = (clip_dir / "images").resolve()
    frames = []
    for image_name, path in paths.items():
        camera = model.cameras[image_name]
        check_image_matches_camera(path, camera)
        relative = path.relative_to(image_root).as_posix()
        stamp = path.parent.name if path.parent != image_root else PurePosixPath(relative).stem
        timestamp = int(stamp) if stamp.isdigit() else None
        metadata: dict[str, object] = {
            "lane": lane,
            "lane_name": LANE_NAMES.get(lane, str(lane)),
            "colmap_name": image_name,
            "colmap_image_id": model.image_ids[image_name],
        }
        if stamp in lidar:
            metadata["lidar_to_world"] = lidar[stamp]
        mask_path = None
        if mask_root is not None:
            candidate = resolve_inside(mask_root, relative, source=model.images_file)
            if candidate.is_file():
                size = image_size(candidate)
                if size != (camera.width, camera.height):
                    raise DatasetError(
                        f"mask is {size[0]}x{size[1]} (WxH) but its image is {camera.width}x{camera.height}",
                        candidate,
                    )
                if mask_polarity == "keep":
                    mask_path = candidate
                else:
                    metadata["foreground_mask_path"] = candidate
        frame = Frame(
            name=f"{clip_dir.name}/{relative}",
            image_path=path,
            camera=camera,
            timestamp_us=timestamp,
            sensor=PurePosixPath(relative).stem if path.parent != image_root else "CAMERA_FRONT",
            traversal=clip_dir.name,
            mask_path=mask_path,
            metadata=metadata,
        )
        key = (lane, timestamp if timestamp is not None else -1, natural_key(frame.name))
        frames.append((key, frame))
    return frames, lidar
