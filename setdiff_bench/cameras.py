"""Pinhole cameras in the project convention, and the conversions every loader needs.

Convention (docs/architecture.md): OpenCV camera axes (x right, y down, z forward); extrinsics
stored world-to-camera as a 4×4 matrix ``w2c`` (COLMAP's and gsplat's ``viewmats``); ``K`` in
pixels with pixel centres at +0.5 (pixel (i, j) covers [j, j+1) × [i, i+1) and is sampled at its
centre).  Loaders convert at their boundary with the constructors here, nowhere else.

Numbers are float64 numpy arrays: poses are small and precision matters more than speed.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from setdiff_bench.camera_values import float_errors_raised, numeric_array
from setdiff_bench.errors import CameraError
from setdiff_bench.intrinsics import (
    Distortion,
    apply_distortion,
    intrinsics_from_colmap,
    invert_distortion,
)
from setdiff_bench.rotations import (
    QuaternionOrder,
    check_rotation,
    invert_rigid,
    quaternion_to_matrix,
)

__all__ = ["MAX_IMAGE_SIDE", "OPENGL_TO_OPENCV", "Camera"]

OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0, 1.0])
#: Largest image side accepted (pixels).  Larger sizes are corrupt data: pycolmap reads a width of -32 in
#: ``cameras.txt`` as 2**64 - 32.  Raise it here for gigapixel captures.
MAX_IMAGE_SIDE = 1 << 16


@dataclass(frozen=True, eq=False)
class Camera:
    """A pinhole camera (optionally with OpenCV distortion).

    Attributes:
        K: ``(3, 3)`` intrinsics in pixels, ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``.
        w2c: ``(4, 4)`` world-to-camera rigid transform, OpenCV axes.
        width, height: image size in pixels.
        distortion: ``None`` for an ideal pinhole.
        source: where the camera came from (file and record), named in every error.
    """

    K: np.ndarray
    w2c: np.ndarray
    width: int
    height: int
    distortion: Distortion | None = None
    source: str = field(default="", compare=False)

    def __post_init__(self) -> None:
        where = self.source or "camera"
        K = numeric_array(self.K, "intrinsics", where).copy()
        w2c = numeric_array(self.w2c, "extrinsics", where).copy()
        if K.shape != (3, 3):
            raise CameraError(f"intrinsics must be 3x3, got shape {K.shape}", where)
        if w2c.shape == (3, 4):
            w2c = np.vstack([w2c, [0.0, 0.0, 0.0, 1.0]])
        if w2c.shape != (4, 4):
            raise CameraError(f"extrinsics must be 4x4 (or 3x4), got shape {w2c.shape}", where)
        if not (np.isfinite(K).all() and np.isfinite(w2c).all()):
            raise CameraError("camera has NaN or infinite values", where)
        if not np.allclose(w2c[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
            raise CameraError(f"extrinsics last row must be [0 0 0 1], got {w2c[3].tolist()}", where)
        with float_errors_raised(where):
            check_rotation(w2c[:3, :3], where)
        if not (K[0, 0] > 0 and K[1, 1] > 0):
            raise CameraError(f"focal lengths must be positive, got fx={K[0, 0]:g} fy={K[1, 1]:g}", where)
        if not np.allclose(K[2], [0.0, 0.0, 1.0]) or K[1, 0] != 0.0:
            raise CameraError(
                f"intrinsics must be upper triangular with last row [0 0 1], got {K.tolist()}", where
            )
        if (
            int(self.width) != self.width
            or int(self.height) != self.height
            or self.width <= 0
            or self.height <= 0
        ):
            raise CameraError(f"image size must be positive integers, got {self.width}x{self.height}", where)
        if (
            self.width > MAX_IMAGE_SIDE or self.height > MAX_IMAGE_SIDE
        ):  # e.g. a negative size read as unsigned
            raise CameraError(
                f"image size {self.width}x{self.height} exceeds {MAX_IMAGE_SIDE} px per side", where
            )
        K.setflags(write=False)
        w2c.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "w2c", w2c)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    # ------------------------------------------------------------------ properties
    @property
    def R(self) -> np.ndarray:
        """``(3, 3)`` world-to-camera rotation."""
        return self.w2c[:3, :3]

    @property
    def t(self) -> np.ndarray:
        """``(3,)`` world-to-camera translation."""
        return self.w2c[:3, 3]

    @property
    def c2w(self) -> np.ndarray:
        """``(4, 4)`` camera-to-world transform, OpenCV axes."""
        return invert_rigid(self.w2c)

    @property
    def center(self) -> np.ndarray:
        """``(3,)`` camera centre in world coordinates (metres or the scene's unit)."""
        return -self.R.T @ self.t

    @property
    def view_direction(self) -> np.ndarray:
        """``(3,)`` unit optical axis (camera +z) in world coordinates."""
        return self.R[2].copy()

    @property
    def fx(self) -> float:
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        return float(self.K[1, 2])

    @property
    def size(self) -> tuple[int, int]:
        """``(height, width)``."""
        return self.height, self.width

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_c2w(
        cls,
        c2w: np.ndarray,
        K: np.ndarray,
        width: int,
        height: int,
        *,
        distortion: Distortion | None = None,
        source: str = "",
    ) -> Camera:
        """From an OpenCV-axes camera-to-world ``(4, 4)`` or ``(3, 4)`` matrix."""
        c2w = _finite_c2w(c2w, source or "camera")
        check_rotation(c2w[:3, :3], source or "camera")
        with float_errors_raised(source or "camera"):
            w2c = invert_rigid(c2w)
        return cls(K, w2c, width, height, distortion, source)

    @classmethod
    def from_opengl_c2w(
        cls,
        c2w: np.ndarray,
        K: np.ndarray,
        width: int,
        height: int,
        *,
        distortion: Distortion | None = None,
        source: str = "",
    ) -> Camera:
        """From an OpenGL/Blender/nerfstudio camera-to-world (x right, y up, z back)."""
        # checked before the product, which would warn about inf · 0
        c2w = _finite_c2w(c2w, source or "camera")
        with float_errors_raised(source or "camera"):
            c2w = c2w @ OPENGL_TO_OPENCV
        return cls.from_c2w(c2w, K, width, height, distortion=distortion, source=source)

    @classmethod
    def from_quaternion(
        cls,
        quaternion: Sequence[float],
        translation: Sequence[float],
        K: np.ndarray,
        width: int,
        height: int,
        *,
        order: QuaternionOrder,
        direction: Literal["w2c", "c2w"] = "w2c",
        distortion: Distortion | None = None,
        source: str = "",
    ) -> Camera:
        """From a rotation quaternion and a translation.

        Args:
            quaternion: four numbers in the named ``order`` (``"wxyz"`` scalar-first: COLMAP,
                nuScenes; ``"xyzw"`` scalar-last: Para-Lane ``lidar_poses.txt``, scipy).
            translation: ``(3,)``.
            direction: whether ``(q, t)`` map world→camera (COLMAP) or camera→world.
        """
        R = quaternion_to_matrix(quaternion, order=order, source=source or "camera")
        T = np.eye(4)
        T[:3, :3] = R
        t = numeric_array(translation, "translation", source or "camera").reshape(-1)
        if t.shape != (3,):
            raise CameraError(f"translation must be 3 numbers, got {t.size}", source or "camera")
        T[:3, 3] = t
        if direction == "c2w":
            return cls.from_c2w(T, K, width, height, distortion=distortion, source=source)
        return cls(K, T, width, height, distortion, source)

    @classmethod
    def from_pycolmap(cls, image: object, camera: object, *, source: str = "") -> Camera:
        """From a ``pycolmap.Image`` and its ``pycolmap.Camera`` (PINHOLE, SIMPLE_PINHOLE, OPENCV, ...).

        Distortion parameters are kept on the camera (never silently dropped); the undistortion
        policy is the loader's (see ``setdiff_bench.loaders.colmap``).
        """
        pose = image.cam_from_world() if callable(image.cam_from_world) else image.cam_from_world
        w2c = np.vstack([np.asarray(pose.matrix(), dtype=np.float64), [0.0, 0.0, 0.0, 1.0]])
        K, distortion = intrinsics_from_colmap(camera.model.name, list(camera.params), source=source)
        return cls(K, w2c, int(camera.width), int(camera.height), distortion, source)

    # ------------------------------------------------------------------ derived cameras
    def resized(self, width: int, height: int) -> Camera:
        """The same camera for an image resampled to ``width × height`` (K scaled per axis)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, :] *= sx
        K[1, :] *= sy
        return Camera(K, self.w2c, width, height, self.distortion, self.source)

    def cropped(self, left: int, top: int, width: int, height: int) -> Camera:
        """The camera of the crop ``[left, left + width) × [top, top + height)``."""
        if left < 0 or top < 0 or left + width > self.width or top + height > self.height:
            raise CameraError(
                f"crop {left},{top},{width}x{height} outside image {self.width}x{self.height}",
                self.source or "camera",
            )
        K = self.K.copy()
        K[0, 2] -= left
        K[1, 2] -= top
        return Camera(K, self.w2c, width, height, self.distortion, self.source)

    def with_w2c(self, w2c: np.ndarray) -> Camera:
        """Same intrinsics, new extrinsics."""
        return Camera(self.K, w2c, self.width, self.height, self.distortion, self.source)

    def with_world_transform(self, rotation: np.ndarray, translation: np.ndarray, scale: float) -> Camera:
        """The camera after the world is mapped by ``x' = scale · (rotation @ x + translation)``.

        Camera-frame coordinates scale by the same factor, so pixel projections are unchanged.
        """
        rotation = np.asarray(rotation, dtype=np.float64)
        translation = np.asarray(translation, dtype=np.float64)
        R_new = self.R @ rotation.T
        t_new = scale * (self.t - R_new @ translation)
        w2c = np.eye(4)
        w2c[:3, :3] = R_new
        w2c[:3, 3] = t_new
        return self.with_w2c(w2c)

    # ------------------------------------------------------------------ projection
    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """``(P, 3)`` world points → ``(P, 3)`` camera-frame points."""
        points = np.asarray(points, dtype=np.float64)
        return points @ self.R.T + self.t

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Project world points to pixels.

        Args:
            points: ``(P, 3)`` world coordinates.

        Returns:
            ``uv`` ``(P, 2)`` continuous pixel coordinates (pixel (i, j)'s centre is (j + 0.5, i + 0.5)),
            and ``depth`` ``(P,)`` camera-frame z.  Points behind the camera get NaN pixels.
        """
        cam = self.world_to_camera(points)
        z = cam[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xn = np.where(z > 0, cam[:, 0] / z, np.nan)
            yn = np.where(z > 0, cam[:, 1] / z, np.nan)
        if self.distortion is not None and not self.distortion.is_zero():
            xn, yn = apply_distortion(self.distortion, xn, yn)
        u = self.K[0, 0] * xn + self.K[0, 1] * yn + self.K[0, 2]
        v = self.K[1, 1] * yn + self.K[1, 2]
        return np.stack([u, v], axis=1), z

    def unproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """Pixels with camera-frame depth z → ``(P, 3)`` world points (distortion inverted if present)."""
        uv = np.asarray(uv, dtype=np.float64)
        depth = np.asarray(depth, dtype=np.float64)
        xn, yn = self.pixel_to_normalized(uv)
        cam = np.stack([xn * depth, yn * depth, depth], axis=1)
        return (cam - self.t) @ self.R

    def pixel_to_normalized(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates → normalised image-plane coordinates (x/z, y/z), undistorting if needed."""
        uv = np.asarray(uv, dtype=np.float64)
        yn = (uv[:, 1] - self.K[1, 2]) / self.K[1, 1]
        xn = (uv[:, 0] - self.K[0, 2] - self.K[0, 1] * yn) / self.K[0, 0]
        if self.distortion is not None and not self.distortion.is_zero():
            xn, yn = invert_distortion(self.distortion, xn, yn)
        return xn, yn

    def describe(self) -> str:
        return f"Camera({self.width}x{self.height}, f=({self.fx:.2f},{self.fy:.2f}), c={self.center.round(3).tolist()})"


def _finite_c2w(c2w: object, source: str) -> np.ndarray:
    """A camera-to-world ``(4, 4)`` matrix from a ``(4, 4)`` or ``(3, 4)`` one; :class:`CameraError` for another
    shape or a NaN or infinite value."""
    c2w = numeric_array(c2w, "camera-to-world", source)
    if c2w.shape == (3, 4):
        c2w = np.vstack([c2w, [0.0, 0.0, 0.0, 1.0]])
    if c2w.shape != (4, 4):
        raise CameraError(f"camera-to-world must be 4x4, got shape {c2w.shape}", source)
    if not np.isfinite(c2w).all():
        raise CameraError("camera has NaN or infinite values", source)
    return c2w
