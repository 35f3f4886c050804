"""Rotations and rigid transforms: quaternions in a named order, the orthonormality check, the rigid
inverse and the look-at pose.

Rotations are ``(3, 3)`` float64; rigid transforms ``(4, 4)`` ``[R t; 0 1]``; camera poses follow the
project convention (OpenCV axes, world-to-camera, see :mod:`setdiff_bench.cameras`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from setdiff_bench.camera_values import numeric_array, value_preview
from setdiff_bench.errors import CameraError

QuaternionOrder = Literal["wxyz", "xyzw"]
ORTHONORMAL_TOLERANCE = 1e-4
QUATERNION_NORM_TOLERANCE = 1e-3


def check_rotation(R: np.ndarray, where: str) -> None:
    """Raise :class:`CameraError` unless ``R`` is orthonormal within 1e-4 with determinant +1."""
    R = np.asarray(R, dtype=np.float64)
    if not np.isfinite(R).all():
        raise CameraError("rotation has NaN or infinite values", where)
    largest = float(np.abs(R).max())
    if largest > 1.0 + ORTHONORMAL_TOLERANCE:  # checked first: R·Rᵀ of huge entries would overflow
        raise CameraError(f"rotation is not orthonormal (an entry has magnitude {largest:.3g} > 1)", where)
    error = float(np.abs(R @ R.T - np.eye(3)).max())
    if error > ORTHONORMAL_TOLERANCE:
        raise CameraError(
            f"rotation is not orthonormal (max |R·Rᵀ − I| = {error:.2e} > {ORTHONORMAL_TOLERANCE:g})", where
        )
    det = float(np.linalg.det(R))
    if det < 0:
        raise CameraError(f"rotation has determinant {det:.4f} (a reflection, expected +1)", where)


def invert_rigid(T: np.ndarray) -> np.ndarray:
    """Inverse of a ``(4, 4)`` rigid transform ``[R t; 0 1]`` → ``[Rᵀ −Rᵀt; 0 1]``."""
    T = np.asarray(T, dtype=np.float64)
    out = np.eye(4)
    out[:3, :3] = T[:3, :3].T
    out[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return out


def quaternion_to_matrix(
    q: Sequence[float],
    *,
    order: QuaternionOrder,
    source: str = "quaternion",
    tolerance: float = QUATERNION_NORM_TOLERANCE,
) -> np.ndarray:
    """Unit quaternion → ``(3, 3)`` rotation.

    Args:
        q: four numbers; ``order`` names their layout explicitly (``"wxyz"`` or ``"xyzw"``).
        tolerance: largest accepted deviation of the norm from 1 (the input is then renormalised).

    Raises:
        CameraError: wrong length, non-finite, or norm off by more than ``tolerance``.
    """
    q = numeric_array(q, "quaternion", source).reshape(-1)
    if q.shape != (4,):
        raise CameraError(f"quaternion must have 4 numbers, got {q.size}", source)
    if not np.isfinite(q).all():
        raise CameraError("quaternion has NaN or infinite values", source)
    if order == "xyzw":
        x, y, z, w = q
    elif order == "wxyz":
        w, x, y, z = q
    else:
        raise ValueError(f"unknown quaternion order {order!r}; use 'wxyz' or 'xyzw'")
    norm = math.hypot(w, x, y, z)  # no overflow for huge components
    if abs(norm - 1.0) > tolerance:
        raise CameraError(f"quaternion ({order}) has norm {norm:.6f}, not 1 within {tolerance:g}", source)
    w, x, y, z = w / norm, x / norm, y / norm, z / norm
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def rigid_from_quaternion(
    quaternion: Sequence[float],
    translation: Sequence[float],
    *,
    order: QuaternionOrder,
    source: str = "transform",
) -> np.ndarray:
    """``(4, 4)`` rigid transform ``[R(q) t; 0 1]`` from a pose record (quaternion norm checked).

    For chains of dataset poses, e.g. nuScenes camera-to-world
    ``rigid_from_quaternion(ego_pose...) @ rigid_from_quaternion(calibrated_sensor...)``.
    """
    T = np.eye(4)
    T[:3, :3] = quaternion_to_matrix(quaternion, order=order, source=source)
    t = numeric_array(translation, "translation", source).reshape(-1)
    if t.shape != (3,) or not np.isfinite(t).all():
        raise CameraError(f"translation must be 3 finite numbers, got {value_preview(translation)}", source)
    T[:3, 3] = t
    return T


def matrix_to_quaternion(R: np.ndarray, *, order: QuaternionOrder) -> np.ndarray:
    """``(3, 3)`` rotation → unit quaternion with non-negative scalar part, in the named order."""
    R = np.asarray(R, dtype=np.float64)
    trace = np.trace(R)
    if trace > 0:
        s = 2.0 * np.sqrt(trace + 1.0)
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] > R[1, 1] and R[0, 0] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] > R[2, 2]:
        s = 2.0 * np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2])
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1])
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    q = np.array([w, x, y, z])
    q /= np.linalg.norm(q)
    if q[0] < 0:
        q = -q
    return q if order == "wxyz" else q[[1, 2, 3, 0]]


def look_at(
    center: Sequence[float], target: Sequence[float], up: Sequence[float] = (0.0, 0.0, 1.0)
) -> np.ndarray:
    """``(4, 4)`` OpenCV world-to-camera matrix of a camera at ``center`` looking at ``target``.

    ``up`` is the world's up direction; the camera's −y axis points along its projection.
    """
    center = np.asarray(center, dtype=np.float64)
    forward = np.asarray(target, dtype=np.float64) - center
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, dtype=np.float64))
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])  # rows: camera axes in world coordinates
    w2c = np.eye(4)
    w2c[:3, :3] = R
    w2c[:3, 3] = -R @ center
    return w2c
