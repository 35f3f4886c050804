"""COLMAP sparse models (binary or text) through pycolmap.

Undistortion policy (explicit, per call): distortion parameters of OPENCV / RADIAL cameras are kept
on :class:`~setdiff_bench.cameras.Camera` (``camera.distortion``) and never dropped silently; the
renderers draw ideal pinhole images, so callers that render distorted cameras must either undistort
the images first (``colmap image_undistorter``) or accept ``distortion="ignore"`` explicitly, which
is what 3DGS-Enhancer does on DL3DV.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError, SetDiffBenchError

DistortionPolicy = Literal["keep", "ignore", "error"]


@dataclass(frozen=True)
class ColmapModel:
    """A COLMAP reconstruction reduced to what the toolkit uses.

    Attributes:
        path: the sparse folder (``sparse/0``).
        cameras: image name → camera (project convention).
        image_ids: image name → COLMAP image id.
        points3d: ``(P, 3)`` float64 world points.
        points_rgb: ``(P, 3)`` uint8 colours.
    """

    path: Path
    cameras: dict[str, Camera]
    image_ids: dict[str, int]
    points3d: np.ndarray
    points_rgb: np.ndarray


def read_colmap_model(sparse_dir: str | os.PathLike[str], *, distortion: DistortionPolicy = "keep") -> ColmapModel:
    """Read ``cameras``, ``images`` and ``points3D`` (``.bin`` preferred, else ``.txt``).

    Args:
        sparse_dir: folder holding the model files.
        distortion: ``"keep"`` distortion on the camera, ``"ignore"`` it (pinhole), or ``"error"`` on any.

    Raises:
        DatasetError: missing files, unreadable model, or an invalid camera.
    """
    sparse = Path(sparse_dir)
    if not sparse.is_dir():
        raise DatasetError("COLMAP sparse folder not found", sparse)
    for stem in ("cameras", "images"):
        if not ((sparse / f"{stem}.bin").is_file() or (sparse / f"{stem}.txt").is_file()):
            raise DatasetError(f"missing COLMAP file {stem}.bin (or {stem}.txt)", sparse)
    import pycolmap

    try:
        reconstruction = pycolmap.Reconstruction(str(sparse))
    except Exception as exc:  # pycolmap raises plain exceptions for corrupt files
        raise DatasetError(f"cannot read COLMAP model ({str(exc).strip().splitlines()[0] if str(exc) else type(exc).__name__})",
                           sparse) from exc
    cameras: dict[str, Camera] = {}
    image_ids: dict[str, int] = {}
    for image_id in sorted(reconstruction.images):
        image = reconstruction.images[image_id]
        if image.name in cameras:
            raise DatasetError(f"duplicate image name {image.name!r}", sparse / "images.bin")
        colmap_camera = reconstruction.cameras[image.camera_id]
        source = f"{sparse}/images (image {image_id} {image.name!r})"
        try:
            camera = Camera.from_pycolmap(image, colmap_camera, source=source)
        except SetDiffBenchError:
            raise
        if camera.distortion is not None and not camera.distortion.is_zero():
            if distortion == "error":
                raise DatasetError(f"camera {image.camera_id} is {colmap_camera.model.name} with non-zero distortion; "
                                   "undistort the images first", sparse)
            if distortion == "ignore":
                camera = Camera(camera.K, camera.w2c, camera.width, camera.height, None, source)
        cameras[image.name] = camera
        image_ids[image.name] = int(image_id)
    ids = sorted(reconstruction.points3D)
    if ids:
        points = np.stack([np.asarray(reconstruction.points3D[i].xyz, dtype=np.float64) for i in ids])
        colors = np.stack([np.asarray(reconstruction.points3D[i].color, dtype=np.uint8) for i in ids])
    else:
        points, colors = np.zeros((0, 3)), np.zeros((0, 3), np.uint8)
    return ColmapModel(sparse, cameras, image_ids, points, colors)
