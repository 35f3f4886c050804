"""The training views of a 3DGS fit, read through the dataset loaders.

A scene folder is read by the loader the registry recognises it as
(:func:`setdiff_bench.loaders.detect_dataset`: synthetic, EUVS, COLMAP or nerfstudio layout), with
masks optional where the loader has masks.  The fit frames are the scene's training split (EUVS
rule: every posed image not listed in ``test_set.txt``) unless a list of frame names is given.  Any
registered dataset is read with ``dataset=``/``root=``/``scene=`` and the loader's own options.

Images reach the fit as pinhole images: a camera with lens distortion is undistorted first
(:mod:`setdiff_bench.undistort`; the border its lens does not cover leaves the loss through the
mask), then the image is downscaled by ``downscale`` (area average, ``K`` scaled to match).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError, UsageError
from setdiff_bench.io.images import read_mask, read_rgb, to_tensor_chw
from setdiff_bench.types import Scene
from setdiff_bench.undistort import is_distorted, undistort_image


@dataclass
class FitView:
    """One training view.

    Attributes:
        name: frame name.  camera: its camera (project convention).
        image: ``(3, H, W)`` float32 in [0, 1].
        mask: ``(1, H, W)`` bool, True where the loss applies (EUVS dynamic mask 255), or ``None``.
    """

    name: str
    camera: Camera
    image: torch.Tensor
    mask: torch.Tensor | None


def load_fit_scene(
    scene_dir: str | os.PathLike[str],
    *,
    dataset: str | None = None,
    scene: str | None = None,
    options: Mapping[str, Any] | None = None,
) -> Scene:
    """Load the scene folder with the loader the registry recognises it as (see the module docstring);
    with ``dataset``, ``scene_dir`` is that dataset's root and ``scene`` picks one of its scenes.

    Raises:
        DatasetError: the folder is missing, no loader recognises it, or it holds more than one scene.
    """
    from setdiff_bench.loaders import SCENE_DETECTORS, detect_dataset, load_scenes, loader_options

    if dataset is not None:
        scenes = load_scenes(dataset, scene_dir, None if scene is None else [scene], **dict(options or {}))
        if len(scenes) != 1:
            raise DatasetError(f"{dataset} root holds {len(scenes)} scenes; pick one with --scene", scene_dir)
        return scenes[0]
    folder = Path(scene_dir)
    if not folder.is_dir():
        raise DatasetError("scene folder not found", folder)
    key = detect_dataset(folder)
    if key is None:
        layouts = ", ".join(name for name, _ in SCENE_DETECTORS)
        raise DatasetError(
            f"no loader recognises this folder as a scene (layouts: {layouts}); "
            "for a dataset root pass --dataset and --root",
            folder,
        )
    scenes = load_scenes(key, folder, **({"masks": "optional"} if "masks" in loader_options(key) else {}))
    if len(scenes) != 1:
        raise DatasetError(f"expected one scene in the folder, found {len(scenes)}", folder)
    return scenes[0]


def parse_frame_list(spec: str | None) -> list[str] | None:
    """``--frames``: ``None``/``"train"`` = the training split; ``@FILE`` or an existing ``.txt`` path = one
    name per line; otherwise comma-separated names."""
    if spec is None or spec == "train":
        return None
    path = Path(spec[1:]) if spec.startswith("@") else Path(spec)
    if spec.startswith("@") or (spec.endswith(".txt") and path.is_file()):
        if not path.is_file():
            raise UsageError("frame list file not found", path)
        names = [line.strip() for line in path.read_text(encoding="utf-8").splitlines() if line.strip()]
    else:
        names = [name.strip() for name in spec.split(",") if name.strip()]
    if not names:
        raise UsageError("the frame list is empty", "--frames")
    return names


def select_fit_frames(scene: Scene, names: Sequence[str] | None) -> list[str]:
    """Frame names to fit: ``names`` (checked) or the scene's training split (all frames if it has none)."""
    if names is not None:
        scene.select(names)  # raises DatasetError naming the missing frames
        return list(names)
    train = [f.name for f in scene.frames if f.split == "train"]
    if not train and all(f.split is None for f in scene.frames):
        train = [f.name for f in scene.frames]
    if not train:
        raise DatasetError("the scene has no training frames", scene.root)
    return train


def load_fit_views(scene: Scene, names: Sequence[str], *, downscale: int = 1) -> list[FitView]:
    """Pinhole images, cameras and masks of the frames ``names`` (in that order), downscaled by
    ``downscale`` (module docstring)."""
    if not isinstance(downscale, int) or downscale < 1:
        raise UsageError(f"--downscale must be an integer ≥ 1, got {downscale!r}", "--downscale")
    views = []
    for frame in scene.select(names):
        camera = frame.camera
        pixels = read_rgb(frame.image_path, expected_size=(camera.height, camera.width))
        keep = np.ones((camera.height, camera.width), bool)
        if frame.mask_path is not None:
            keep = read_mask(frame.mask_path, expected_size=(camera.height, camera.width))
        if is_distorted(camera):
            pixels, pinhole, covered = undistort_image(pixels, camera)
            keep = undistort_image(keep.astype(np.float32), camera)[0] > 0.5
            keep &= covered
            camera = pinhole
        if downscale > 1:
            width, height = max(1, round(camera.width / downscale)), max(1, round(camera.height / downscale))
            pixels = cv2.resize(pixels, (width, height), interpolation=cv2.INTER_AREA)
            keep = cv2.resize(keep.astype(np.float32), (width, height), interpolation=cv2.INTER_AREA) > 0.999
            camera = camera.resized(width, height)
        mask = None if keep.all() else torch.from_numpy(np.ascontiguousarray(keep))[None]
        views.append(FitView(frame.name, camera, to_tensor_chw(pixels), mask))
    return views
