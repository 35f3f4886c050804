"""The training views of a 3DGS fit, read through the dataset loaders.

A scene folder is recognised by what it holds: ``scene.json`` → the synthetic loader, ``test_set.txt``
→ the EUVS loader (both with optional masks), otherwise a generic COLMAP scene.  The fit frames are
the scene's training split (EUVS rule: every posed image not listed in ``test_set.txt``) unless a
list of frame names is given.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError, UsageError
from setdiff_bench.io.images import read_mask, read_rgb, to_tensor_chw
from setdiff_bench.types import Scene


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


def load_fit_scene(scene_dir: str | os.PathLike[str]) -> Scene:
    """Load the scene folder with the loader its files call for (see the module docstring)."""
    from setdiff_bench.loaders import load_scenes

    folder = Path(scene_dir)
    if not folder.is_dir():
        raise DatasetError("scene folder not found", folder)
    if (folder / "scene.json").is_file():
        scenes = load_scenes("synthetic", folder, masks="optional")
    elif (folder / "test_set.txt").is_file():
        scenes = load_scenes("euvs", folder, masks="optional")
    else:
        scenes = load_scenes("colmap", folder)
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


def load_fit_views(scene: Scene, names: Sequence[str]) -> list[FitView]:
    """Images, cameras and masks of the frames ``names`` (in that order)."""
    views = []
    for frame in scene.select(names):
        camera = frame.camera
        image = to_tensor_chw(read_rgb(frame.image_path, expected_size=(camera.height, camera.width)))
        mask = None
        if frame.mask_path is not None:
            keep = read_mask(frame.mask_path, expected_size=(camera.height, camera.width))
            if not keep.all():
                mask = torch.from_numpy(np.ascontiguousarray(keep))[None]
        views.append(FitView(frame.name, camera, image, mask))
    return views
