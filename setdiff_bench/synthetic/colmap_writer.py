"""Write a COLMAP binary model (``cameras.bin``, ``images.bin``, ``points3D.bin``) with pycolmap.

pycolmap 4.x always writes the rig-aware layout (``rigs.bin`` and ``frames.bin`` besides the three
classic files).  EUVS scenes carry the classic three-file layout, which pycolmap and COLMAP still
read (each camera then gets a trivial rig), so the two extra files are removed after writing.
Images are PINHOLE, posed world-to-camera (OpenCV axes); points have empty tracks, as SfM points
whose observations were not exported.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.rotations import matrix_to_quaternion

LEGACY_FILES = ("cameras.bin", "images.bin", "points3D.bin")


@dataclass(frozen=True)
class ColmapImage:
    """One posed image: file ``name``, the ``sensor`` whose intrinsics it uses, and its camera."""

    name: str
    sensor: str
    camera: Camera


def write_colmap_model(
    sparse_dir: str | os.PathLike[str],
    images: Sequence[ColmapImage],
    points_xyz: np.ndarray,
    points_rgb: np.ndarray,
    *,
    camera_model: str = "PINHOLE",
) -> None:
    """Write the model into ``sparse_dir`` (created; the three files are moved in only when complete).

    Camera ids follow the order in which sensors first appear in ``images`` (1-based); image ids
    follow ``images`` order (1-based); point ids follow ``points_xyz`` order (1-based).

    Args:
        images: posed images; all images of one sensor must share intrinsics and size.
        points_xyz: ``(P, 3)`` world coordinates (metres).  points_rgb: ``(P, 3)`` uint8.
        camera_model: ``"PINHOLE"`` (EUVS) or ``"OPENCV"`` (DL3DV's model, written with zero distortion
            ``k1 = k2 = p1 = p2 = 0``).
    """
    if camera_model not in ("PINHOLE", "OPENCV"):
        raise ValueError(f"camera_model must be PINHOLE or OPENCV, got {camera_model!r}")
    import pycolmap

    reconstruction = pycolmap.Reconstruction()
    camera_ids: dict[str, int] = {}
    for image in images:
        cam = image.camera
        if image.sensor not in camera_ids:
            camera_ids[image.sensor] = len(camera_ids) + 1
            reconstruction.add_camera_with_trivial_rig(
                pycolmap.Camera(
                    camera_id=camera_ids[image.sensor],
                    model=camera_model,
                    width=cam.width,
                    height=cam.height,
                    params=[cam.fx, cam.fy, cam.cx, cam.cy]
                    + ([0.0, 0.0, 0.0, 0.0] if camera_model == "OPENCV" else []),
                )
            )
    for image_id, image in enumerate(images, start=1):
        quat_xyzw = matrix_to_quaternion(image.camera.R, order="xyzw")
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(quat_xyzw), np.asarray(image.camera.t, np.float64))
        reconstruction.add_image_with_trivial_frame(
            pycolmap.Image(name=image.name, camera_id=camera_ids[image.sensor], image_id=image_id), pose
        )
    for xyz, rgb in zip(np.asarray(points_xyz, np.float64), np.asarray(points_rgb, np.uint8)):
        reconstruction.add_point3D(xyz, pycolmap.Track(), rgb)
    target = Path(sparse_dir)
    target.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".colmap.", dir=target))
    try:
        reconstruction.write_binary(str(staging))
        for name in LEGACY_FILES:
            os.replace(staging / name, target / name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
