"""DL3DV-10K scenes: ``<batch>/<hash>/`` with a downscaled image folder and poses.

Dataset facts: docs/datasets.md, "DL3DV and the 3DGS-Enhancer protocol".

Layouts accepted for a scene folder ``<hash>`` (the first data folder that has the image folder and
poses wins, in this order):

* ``<hash>/`` — 960P / 3DGS-Enhancer: ``images_4/`` + ``colmap/sparse/0`` (or ``sparse/0``) and/or
  ``transforms.json``;
* ``<hash>/colmap/`` — the HF sample: ``colmap/images_4/`` + ``colmap/colmap/sparse/0`` + ``colmap/transforms.json``;
* ``<hash>/nerfstudio/`` and ``<hash>/gaussian_splat/`` — the benchmark packaging.

Scenes are searched in ``root`` itself, its children and grandchildren, so ``root`` may be the
dataset root (``1K/<hash>``), one batch folder or one scene; the batch (``1K`` …) is recorded in
``Scene.metadata["batch"]``.  Scenes are named by their folder (the 64-hex hash), must be unique, and
are listed in lexicographic order of the hash.

Poses (``poses``): ``"auto"`` (default) uses the COLMAP model when there is one (world-to-camera,
OpenCV; unambiguous), else ``transforms.json`` (nerfstudio reader, OpenGL → OpenCV, ``applied_transform``
undone so both sources share the COLMAP world).  Intrinsics refer to the full-resolution images and
are rescaled per axis to the real size of the chosen image folder (``images_4`` = 960×540 for 4K
captures), read from each image header.

Distortion: DL3DV cameras are OPENCV (k1 k2 p1 p2); ``distortion="keep"`` (default) keeps them on the
camera, ``"ignore"`` reproduces 3DGS-Enhancer, which treats them as pinhole.

Frame name: the image file name (``frame_00001.png``); frame order: natural order of that name
(the order 3DGS-Enhancer's sparse-view selection indexes).
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path, PurePosixPath
from typing import Literal

from setdiff_bench.errors import DatasetError
from setdiff_bench.io.paths import resolve_inside
from setdiff_bench.types import Frame, Scene

from .colmap import DistortionPolicy, find_sparse_dir, read_colmap_model
from .common import (
    dataset_root,
    find_scene_dirs,
    fit_camera_to_image,
    natural_key,
    selected_scene_dirs,
)
from .nerfstudio import read_transforms

PoseSource = Literal["auto", "colmap", "transforms"]
DATA_DIRS = (".", "colmap", "nerfstudio", "gaussian_splat")
BATCH_NAME = re.compile(r"^\d+K$")


def _sparse(data_dir: Path) -> Path | None:
    return find_sparse_dir(data_dir / "colmap") or find_sparse_dir(data_dir)


def _data_dir(scene_dir: Path, images_dir: str | None) -> Path | None:
    """The first data folder holding images (``images_dir``, or any ``images*`` folder) and poses."""
    for sub in DATA_DIRS:
        folder = scene_dir / sub if sub != "." else scene_dir
        if not folder.is_dir():
            continue
        if images_dir is not None:
            has_images = (folder / images_dir).is_dir()
        else:
            has_images = any(p.is_dir() and p.name.startswith("images") for p in folder.iterdir())
        if has_images and (_sparse(folder) is not None or (folder / "transforms.json").is_file()):
            return folder
    return None


def _scene_dirs(base: Path, images_dir: str | None) -> dict[str, Path]:
    found: dict[str, Path] = {}
    for folder in find_scene_dirs(base, lambda f: _data_dir(f, images_dir) is not None, max_depth=2):
        if folder.name in found:
            raise DatasetError(f"scene {folder.name!r} found twice: {found[folder.name]} and {folder}", base)
        found[folder.name] = folder
    if not found:
        wanted = images_dir or "images*"
        raise DatasetError(
            f"no DL3DV scenes found (expected [<batch>/]<hash>/{wanted}/ with colmap/sparse/0 or "
            "transforms.json)",
            base,
        )
    return dict(sorted(found.items()))  # plain order: natural order would split hex hashes at digits


def list_scenes(root: str | os.PathLike[str], *, images_dir: str = "images_4") -> list[str]:
    """Scene hashes under ``root`` that hold ``images_dir`` and poses, in lexicographic order."""
    return list(_scene_dirs(dataset_root(root), images_dir))


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    images_dir: str = "images_4",
    poses: PoseSource = "auto",
    distortion: DistortionPolicy = "keep",
) -> list[Scene]:
    """Load DL3DV scenes (rules in the module docstring).

    Args:
        root: dataset root, batch folder or scene folder.
        scenes: scene hashes; ``None`` = all.
        images_dir: image folder to use (``images_4``; ``images`` for full resolution).
        poses: ``"auto"``, ``"colmap"`` or ``"transforms"``.
        distortion: ``"keep"``, ``"ignore"`` or ``"error"``.
    """
    if poses not in ("auto", "colmap", "transforms"):
        raise DatasetError(f"unknown pose source {poses!r}; use auto, colmap or transforms", root)
    base = dataset_root(root)
    found = _scene_dirs(base, images_dir)
    out = []
    for name, scene_dir in selected_scene_dirs(found, scenes, base, "dl3dv"):
        data_dir = _data_dir(scene_dir, images_dir)
        assert data_dir is not None
        sparse = _sparse(data_dir)
        source = poses if poses != "auto" else ("colmap" if sparse is not None else "transforms")
        points = colors = None
        frames: list[Frame] = []
        if source == "colmap":
            if sparse is None:
                raise DatasetError("poses='colmap' but there is no colmap/sparse/0 model", data_dir)
            model = read_colmap_model(sparse, distortion=distortion)
            image_root = data_dir / images_dir
            for image_name in model.cameras:
                path = resolve_inside(image_root, image_name, source=model.images_file)
                camera = fit_camera_to_image(model.cameras[image_name], path, allow_rescale=True)
                frames.append(
                    Frame(
                        name=PurePosixPath(image_name).name,
                        image_path=path,
                        camera=camera,
                        metadata={"colmap_image_id": model.image_ids[image_name]},
                    )
                )
            if len(model.points3d):
                points, colors = model.points3d, model.points_rgb
        else:
            entries = read_transforms(
                data_dir / "transforms.json", images_dir=images_dir, world="colmap", distortion=distortion
            )
            frames = [
                Frame(
                    name=e.image_path.name,
                    image_path=e.image_path,
                    camera=e.camera,
                    metadata={"colmap_image_id": e.colmap_im_id, "transforms_index": e.index},
                )
                for e in entries
            ]
        frames.sort(key=lambda f: natural_key(f.name))
        batch = (
            scene_dir.parent.name if scene_dir != base and BATCH_NAME.match(scene_dir.parent.name) else None
        )
        out.append(
            Scene(
                dataset="dl3dv",
                name=name,
                root=scene_dir,
                frames=tuple(frames),
                points3d=points,
                points_rgb=colors,
                metadata={
                    "batch": batch,
                    "poses": source,
                    "data_dir": str(data_dir),
                    "images_dir": images_dir,
                },
            )
        )
    return out
