"""Pseudo-view poses: interpolation from the nearest training pose to the target, against hand-built cameras."""

from __future__ import annotations

import math

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.refit.poses import interpolate_pose, nearest_poses

K = np.array([[20.0, 0.0, 16.0], [0.0, 20.0, 12.0], [0.0, 0.0, 1.0]])


def yawed_camera(centre: tuple[float, float, float], degrees: float, k: np.ndarray = K) -> Camera:
    """A camera at ``centre`` turned ``degrees`` about its own +y (OpenCV down) axis."""
    a = math.radians(degrees)
    turn = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    c2w = np.eye(4)
    c2w[:3, :3] = turn
    c2w[:3, 3] = centre
    return Camera.from_c2w(c2w, k, 32, 24)


def test_halfway_is_the_midpoint_and_the_half_angle() -> None:
    start = yawed_camera((0.0, 0.0, 0.0), 0.0)
    end = yawed_camera((4.0, 0.0, 2.0), 90.0, K * np.array([[2.0], [2.0], [1.0]]))
    half = interpolate_pose(start, end, 0.5)
    np.testing.assert_allclose(half.center, [2.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(half.R, yawed_camera((2.0, 0.0, 1.0), 45.0).R, atol=1e-12)
    np.testing.assert_array_equal(half.K, end.K)  # the target's intrinsics throughout


def test_ends_are_the_two_poses() -> None:
    start, end = yawed_camera((1.0, 2.0, 3.0), -30.0), yawed_camera((5.0, 2.0, 3.0), 20.0)
    np.testing.assert_allclose(interpolate_pose(start, end, 0.0).w2c, start.w2c, atol=1e-12)
    assert interpolate_pose(start, end, 1.0) is end


def test_nearest_training_pose_by_centre() -> None:
    training = [yawed_camera((x, 0.0, 0.0), 0.0) for x in (0.0, 2.0, 4.0)]
    targets = [
        yawed_camera((1.9, 3.5, 0.0), 0.0),
        yawed_camera((-5.0, 0.0, 0.0), 0.0),
        yawed_camera((3.0, 0, 0), 0),
    ]
    assert nearest_poses(targets, training) == [1, 0, 1]  # a tie (3.0: 1.0 from both) takes the lower index
