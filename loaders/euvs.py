"""EUVS (Extrapolated Urban View Synthesis) scenes in their released layout (docs/datasets.md, "EUVS scene layout"
to "EUVS masks").

A scene folder holds ``test_set.txt``, ``train_set.txt`` (or ``training_set.txt``), ``images/``,
``sparse/0`` (COLMAP, PINHOLE, world-to-camera), optionally ``dynamic_masks/``, ``sky_masks/`` and
``poses/images.txt``.  Zips unpack under ``Level 1/``, ``Level 2/``, ``Level 3/`` folders, so scenes
are found up to three levels below the root and named by their path relative to it.

Rules implemented here:

* Frames = every image of the COLMAP model (the 3DGS baseline trains on every model image that is
  not in ``test_set.txt``, not on ``train_set.txt``).  ``Frame.split`` = ``"test"`` for names in
  ``test_set.txt``, else ``"train"``.  Every test name must have a pose in the model; a name in both
  set files, an empty ``test_set.txt`` and a name listed twice are errors.
* Names are opaque keys shared by ``images/``, the set files, COLMAP and the masks (docs/datasets.md,
  "EUVS scene layout").  Only the MARS pattern ``trav_<t>_channel_<c>_img_<i>`` is parsed, into
  traversal ``trav_<t>`` and sensor (channel map of EUVS-data-process: 1 CAM_FRONT_CENTER …
  6 CAM_SIDE_RIGHT).
* Masks are paired **by name**: ``dynamic_masks/<image name with .png>``; 255 = keep, 0 = dynamic.
  Policy ``masks``: ``"require_test"`` (default; every test frame needs its mask, others optional),
  ``"optional"``, ``"none"`` (ignore the folder).  Masks must have the image's size.
* Ground-truth poses ``poses/images.txt`` (``j qw qx qy qz tx ty tz 1 NAME``, world-to-camera in the
  source dataset's map frame) are attached as ``metadata["gt_w2c"]`` when present; ``poses="gt"``
  uses them for the cameras (intrinsics from ``sparse/0``) instead of the SfM poses.  That file is
  not a COLMAP model (no cameras file, ten fields per line), so it is parsed here.
* Level: the ``level`` option when given; else inferred: (1) the nearest folder from the scene's
  parent up to the root (inclusive; the parent alone when the root is the scene) named ``Level N`` /
  ``level_N`` / ``LevelN_small`` (case-insensitive) gives N; (2)
  a scene name starting with ``MARS_`` is level 3 (only Level 3 uses MARS, docs/datasets.md, "EUVS levels");
  (3) otherwise unknown (``None``).  ``Scene.metadata["level_source"]`` records which rule applied.
* Image sizes are read from the headers and must equal the camera size.

Frame order: natural order of the image name (for MARS names: traversal, channel, index).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import Literal

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError
from setdiff_bench.io.paths import resolve_inside
from setdiff_bench.rotations import rigid_from_quaternion
from setdiff_bench.types import Frame, Scene

from .colmap import DistortionPolicy, read_colmap_model
from .common import (
    check_image_matches_camera,
    dataset_root,
    image_size,
    mask_name_for,
    natural_key,
    read_name_list,
    require_dir,
    require_scenes,
    selected_scene_dirs,
)

MaskPolicy = Literal["require_test", "optional", "none"]
PoseSource = Literal["sparse", "gt"]
TRAIN_SET_FILES = ("train_set.txt", "training_set.txt")
MARS_CHANNELS = {
    1: "CAM_FRONT_CENTER",
    2: "CAM_FRONT_LEFT",
    3: "CAM_FRONT_RIGHT",
    4: "CAM_BACK_CENTER",
    5: "CAM_SIDE_LEFT",
    6: "CAM_SIDE_RIGHT",
}
MARS_NAME = re.compile(r"^trav_(\d+)_channel_(\d+)_img_(\d+)\.[A-Za-z0-9]+$")
LEVEL_FOLDER = re.compile(r"^level[\s_-]*([123])(?:\D.*)?$", re.IGNORECASE)


def is_euvs_scene(folder: Path) -> bool:
    """A folder with ``test_set.txt`` and a ``sparse`` model folder."""
    return (folder / "test_set.txt").is_file() and (folder / "sparse").is_dir()


def infer_level(root: Path, scene_dir: Path) -> tuple[int | None, str | None]:
    """EUVS level from the folder names between ``root`` and the scene, or from a ``MARS_`` name.

    Returns:
        ``(level, source)`` with source ``"folder"``, ``"name"`` or ``None`` when unknown.
    """
    if scene_dir == root:  # the root is the scene itself: look at its parent folder only
        candidates: tuple[str, ...] = (root.parent.name,)
    else:
        candidates = (root.name, *scene_dir.relative_to(root).parts[:-1])
    for part in reversed(candidates):
        match = LEVEL_FOLDER.match(part)
        if match:
            return int(match.group(1)), "folder"
    if scene_dir.name.upper().startswith("MARS_"):
        return 3, "name"
    return None, None


def read_gt_poses(path: Path) -> dict[str, np.ndarray]:
    """Parse ``poses/images.txt``: image name → ``(4, 4)`` world-to-camera (quaternion w,x,y,z).

    Raises:
        DatasetError: a malformed line or a name listed twice.
        CameraError: a quaternion off unit norm by more than 1e-3.
    """
    poses: dict[str, np.ndarray] = {}
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        fields = line.split()
        if len(fields) < 10:
            raise DatasetError(
                f"line {number}: expected 'ID QW QX QY QZ TX TY TZ CAMERA_ID NAME', got {len(fields)} fields",
                path,
            )
        try:
            values = [float(v) for v in fields[1:8]]
        except ValueError as exc:
            raise DatasetError(f"line {number}: pose values are not numbers", path) from exc
        name = " ".join(fields[9:])
        if name in poses:
            raise DatasetError(f"line {number}: duplicate image name {name!r}", path)
        poses[name] = rigid_from_quaternion(
            values[:4], values[4:7], order="wxyz", source=f"{path} (line {number})"
        )
    return poses


def _scene_dirs(base: Path) -> dict[str, Path]:
    return require_scenes(base, is_euvs_scene, "EUVS", "<scene>/test_set.txt and <scene>/sparse/0")


def list_scenes(root: str | os.PathLike[str]) -> list[str]:
    """EUVS scene folders under ``root`` (itself or up to 3 levels down, e.g. ``Level 1/<location>``)."""
    return list(_scene_dirs(dataset_root(root)))


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    level: int | None = None,
    masks: MaskPolicy = "require_test",
    poses: PoseSource = "sparse",
    distortion: DistortionPolicy = "keep",
) -> list[Scene]:
    """Load EUVS scenes (rules in the module docstring).

    Args:
        root: dataset root.
        scenes: names from :func:`list_scenes` (or their last path component); ``None`` = all.
        level: EUVS level (1, 2, 3) for every selected scene; ``None`` infers it per scene.
        masks: ``"require_test"``, ``"optional"`` or ``"none"``.
        poses: ``"sparse"`` (SfM model, default) or ``"gt"`` (``poses/images.txt``).
        distortion: undistortion policy of :mod:`setdiff_bench.loaders.colmap`.
    """
    if level is not None and level not in (1, 2, 3):
        raise DatasetError(f"EUVS level must be 1, 2 or 3, got {level!r}", root)
    base = dataset_root(root)
    found = _scene_dirs(base)
    out = []
    for name, scene_dir in selected_scene_dirs(found, scenes, base, "euvs"):
        if level is not None:
            scene_level, source = level, "given"
        else:
            scene_level, source = infer_level(base, scene_dir)
        scene = load_layout(
            scene_dir, name=name, dataset="euvs", masks=masks, poses=poses, distortion=distortion
        )
        out.append(replace(scene, metadata={**scene.metadata, "level": scene_level, "level_source": source}))
    return out


def load_layout(
    scene_dir: Path,
    *,
    name: str,
    dataset: str,
    masks: MaskPolicy = "require_test",
    poses: PoseSource = "sparse",
    distortion: DistortionPolicy = "keep",
) -> Scene:
    """Read one scene folder in the EUVS layout (shared with the synthetic benchmark).

    Returns:
        The scene; ``metadata`` has ``test_set``, ``train_set`` (file names or ``None``), ``has_gt_poses``,
        ``poses`` and ``mask_policy``.
    """
    if masks not in ("require_test", "optional", "none"):
        raise DatasetError(f"unknown mask policy {masks!r}; use require_test, optional or none", scene_dir)
    if poses not in ("sparse", "gt"):
        raise DatasetError(f"unknown pose source {poses!r}; use sparse or gt", scene_dir)
    test_file = scene_dir / "test_set.txt"
    test_names = read_name_list(test_file)
    train_file = next((scene_dir / f for f in TRAIN_SET_FILES if (scene_dir / f).is_file()), None)
    train_names = read_name_list(train_file, allow_empty=True) if train_file else []
    overlap = sorted(set(test_names) & set(train_names), key=natural_key)
    if overlap:
        raise DatasetError(
            f"{len(overlap)} names are in both {train_file.name} and test_set.txt, e.g. {overlap[0]!r}",
            test_file,
        )
    sparse = next(
        (
            p
            for p in (scene_dir / "sparse" / "0", scene_dir / "sparse")
            if (p / "images.bin").is_file() or (p / "images.txt").is_file()
        ),
        scene_dir / "sparse" / "0",
    )
    model = read_colmap_model(sparse, distortion=distortion)
    missing = [n for n in test_names if n not in model.cameras]
    if missing:
        raise DatasetError(
            f"{len(missing)} test images have no pose in {model.images_file.name}, e.g. {missing[0]!r}",
            test_file,
        )
    gt_file = scene_dir / "poses" / "images.txt"
    gt_poses = read_gt_poses(gt_file) if gt_file.is_file() else {}
    if poses == "gt" and not gt_poses:
        raise DatasetError("poses='gt' but the ground-truth pose file is missing or empty", gt_file)

    image_root = require_dir(scene_dir / "images", "image folder")
    mask_root = scene_dir / "dynamic_masks"
    if masks == "require_test" and not mask_root.is_dir():
        raise DatasetError(
            "dynamic mask folder not found; every test image needs its mask "
            "(generate them with EUVS' GroundedSAM2/extract_masks.sh or pass masks='optional')",
            mask_root,
        )
    sky_root = scene_dir / "sky_masks"
    test_set = set(test_names)
    train_set = set(train_names)
    multi = model.num_cameras > 1
    mask_owner: dict[str, str] = {}
    frames = []
    for image_name in sorted(model.cameras, key=natural_key):
        camera = model.cameras[image_name]
        image_path = resolve_inside(image_root, image_name, source=model.images_file)
        check_image_matches_camera(image_path, camera)
        metadata: dict[str, object] = {
            "colmap_image_id": model.image_ids[image_name],
            "in_train_set": image_name in train_set,
        }
        if image_name in gt_poses:
            metadata["gt_w2c"] = gt_poses[image_name]
        if poses == "gt":
            if image_name not in gt_poses:
                raise DatasetError(f"image {image_name!r} has no ground-truth pose", gt_file)
            camera = Camera(
                camera.K,
                gt_poses[image_name],
                camera.width,
                camera.height,
                camera.distortion,
                f"{gt_file} ({image_name!r})",
            )
        split = "test" if image_name in test_set else "train"
        mask_path = None
        if masks != "none":
            mask_name = mask_name_for(image_name)
            if mask_name in mask_owner:
                raise DatasetError(
                    f"images {mask_owner[mask_name]!r} and {image_name!r} pair with the same mask "
                    f"{mask_name!r}",
                    image_root,
                )
            mask_owner[mask_name] = image_name
            candidate = (
                resolve_inside(mask_root, mask_name, source=model.images_file) if mask_root.is_dir() else None
            )
            if candidate is not None and candidate.is_file():
                _check_mask_size(candidate, camera)
                mask_path = candidate
            elif split == "test" and masks == "require_test":
                raise DatasetError(f"test image {image_name!r} has no dynamic mask {mask_name!r}", mask_root)
            sky = sky_root / mask_name
            if sky.is_file():
                metadata["sky_mask_path"] = sky
        traversal, sensor = "", f"camera_{model.camera_ids[image_name]}" if multi else ""
        mars = MARS_NAME.match(image_name)
        if mars:
            traversal = f"trav_{int(mars.group(1))}"
            sensor = MARS_CHANNELS.get(int(mars.group(2)), f"channel_{int(mars.group(2))}")
            metadata["frame_index"] = int(mars.group(3)) - 1
        frames.append(
            Frame(
                name=image_name,
                image_path=image_path,
                camera=camera,
                sensor=sensor,
                traversal=traversal,
                mask_path=mask_path,
                split=split,
                metadata=metadata,
            )
        )
    use_points = poses == "sparse" and len(model.points3d) > 0
    return Scene(
        dataset=dataset,
        name=name,
        root=scene_dir,
        frames=tuple(frames),
        points3d=model.points3d if use_points else None,
        points_rgb=model.points_rgb if use_points else None,
        metadata={
            "test_set": test_file.name,
            "train_set": train_file.name if train_file else None,
            "has_gt_poses": bool(gt_poses),
            "poses": poses,
            "mask_policy": masks,
            "sparse_dir": str(sparse),
        },
    )


def _check_mask_size(path: Path, camera: Camera) -> None:
    width, height = image_size(path)
    if (width, height) != (camera.width, camera.height):
        raise DatasetError(
            f"mask is {width}x{height} (WxH) but its image is {camera.width}x{camera.height}", path
        )
