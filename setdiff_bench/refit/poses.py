"""Pseudo-view poses of a progressive refit: each target's nearest training pose moved toward the target.

The path from a training pose ``(R₀, c₀)`` to a target pose ``(R₁, c₁)`` (world-to-camera rotation, camera
centre, world units) is the camera centre interpolated linearly and the rotation by spherical linear
interpolation of unit quaternions (shortest arc); the intrinsics and image size stay the target's, so every
pseudo-view renders at the target's working resolution.  At ``t = 1`` the pose is the target's exactly.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.rotations import matrix_to_quaternion, quaternion_to_matrix


def slerp(q0: np.ndarray, q1: np.ndarray, t: float) -> np.ndarray:
    """Unit quaternion ``t`` of the way from ``q0`` to ``q1`` along the shorter arc (``(4,)`` each, any order
    as long as both use it); nearly parallel quaternions are interpolated linearly and renormalised."""
    q0 = np.asarray(q0, dtype=np.float64) / np.linalg.norm(q0)
    q1 = np.asarray(q1, dtype=np.float64) / np.linalg.norm(q1)
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + t * (q1 - q0)
        return q / np.linalg.norm(q)
    theta = np.arccos(min(dot, 1.0))
    return (np.sin((1.0 - t) * theta) * q0 + np.sin(t * theta) * q1) / np.sin(theta)


def interpolate_pose(start: Camera, end: Camera, t: float) -> Camera:
    """The camera ``t`` ∈ [0, 1] of the way from ``start``'s pose to ``end``'s, with ``end``'s intrinsics and
    size (module docstring); ``t = 1`` returns ``end`` itself."""
    if t >= 1.0:
        return end
    q = slerp(matrix_to_quaternion(start.R, order="wxyz"), matrix_to_quaternion(end.R, order="wxyz"), t)
    c2w = np.eye(4)
    c2w[:3, :3] = quaternion_to_matrix(q, order="wxyz").T
    c2w[:3, 3] = (1.0 - t) * start.center + t * end.center
    return Camera.from_c2w(c2w, end.K, end.width, end.height, source=f"{end.source} (t={t:g})")


def nearest_poses(targets: Sequence[Camera], training: Sequence[Camera]) -> list[int]:
    """For each target, the index of the training camera whose centre is nearest (ties: the lower index)."""
    centres = np.stack([c.center for c in training])
    return [int(np.argmin(np.linalg.norm(centres - t.center, axis=1))) for t in targets]


def pseudo_cameras(
    targets: Sequence[Camera], training: Sequence[Camera], nearest: Sequence[int], t: float
) -> list[Camera]:
    """Each target's pseudo-view camera at ``t`` of the way from its nearest training pose (``nearest``,
    :func:`nearest_poses`) to it."""
    return [interpolate_pose(training[i], target, t) for target, i in zip(targets, nearest, strict=True)]
