"""Undistort an image of a distorted camera into the pinhole camera with the same intrinsics.

Every consumer of images (fit, render, scoring) draws pinhole images; a camera that keeps its lens
distortion (COLMAP ``SIMPLE_RADIAL``/``RADIAL``/``OPENCV``, nerfstudio ``k1 k2 p1 p2``) is resampled
here first, as COLMAP's ``image_undistorter`` does, so its pixels and the pinhole camera agree.

The output camera keeps ``K`` and the image size (COLMAP instead picks a new ``K`` that trims the
border); output pixels whose source lies outside the distorted image are reported in the validity
mask so a fit or a metric can leave them out.

Mapping: output pixel centre ``(j + 0.5, i + 0.5)`` → normalised pinhole coordinates through ``K⁻¹``
→ :func:`setdiff_bench.cameras.apply_distortion` → source pixel through ``K`` (continuous, pixel
centres at +0.5, the project convention), sampled bilinearly.
"""

from __future__ import annotations

import cv2
import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.intrinsics import apply_distortion


def is_distorted(camera: Camera) -> bool:
    """True when the camera carries non-zero lens distortion."""
    return camera.distortion is not None and not camera.distortion.is_zero()


def pinhole_camera(camera: Camera) -> Camera:
    """The camera without its distortion (same ``K``, pose, size)."""
    return Camera(camera.K, camera.w2c, camera.width, camera.height, None, camera.source)


def undistortion_maps(camera: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Source coordinates for every pixel of the pinhole image.

    Returns:
        ``map_x``, ``map_y``: ``(H, W)`` float32 source pixel indices (OpenCV ``remap`` convention,
        integer = pixel centre); ``valid``: ``(H, W)`` bool, True where the source is inside the image.
    """
    height, width = camera.height, camera.width
    jj, ii = np.meshgrid(np.arange(width, dtype=np.float64) + 0.5, np.arange(height, dtype=np.float64) + 0.5)
    K = camera.K
    yn = (ii - K[1, 2]) / K[1, 1]
    xn = (jj - K[0, 2] - K[0, 1] * yn) / K[0, 0]
    if is_distorted(camera):
        xn, yn = apply_distortion(camera.distortion, xn, yn)
    u = K[0, 0] * xn + K[0, 1] * yn + K[0, 2] - 0.5
    v = K[1, 1] * yn + K[1, 2] - 0.5
    valid = (u >= 0) & (u <= width - 1) & (v >= 0) & (v <= height - 1)
    return u.astype(np.float32), v.astype(np.float32), valid


def undistort_image(image: np.ndarray, camera: Camera) -> tuple[np.ndarray, Camera, np.ndarray]:
    """Resample ``image`` (``(H, W, C)`` or ``(H, W)``, any dtype OpenCV remaps) to the pinhole camera.

    Returns:
        The undistorted image (same shape and dtype), the pinhole camera, and the ``(H, W)`` bool
        validity mask (all True for an undistorted camera, whose image is returned unchanged).
    """
    if not is_distorted(camera):
        return image, camera, np.ones((camera.height, camera.width), bool)
    map_x, map_y, valid = undistortion_maps(camera)
    out = cv2.remap(
        np.ascontiguousarray(image),
        map_x,
        map_y,
        interpolation=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=0,
    )
    if out.ndim < image.ndim:
        out = out[..., None]
    return out, pinhole_camera(camera), valid
