"""Undistortion to the pinhole camera: a dot drawn where the distorted camera sees a 3D point lands,
after resampling, where the pinhole camera projects it (analytic OpenCV k1 k2 p1 p2 model)."""

from __future__ import annotations

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.intrinsics import Distortion
from setdiff_bench.undistort import undistort_image, undistortion_maps

WIDTH, HEIGHT = 160, 120
K = np.array([[100.0, 0.0, 81.3], [0.0, 98.0, 58.9], [0.0, 0.0, 1.0]])
LENS = Distortion("OPENCV", (0.12, -0.05, 0.003, -0.002))


def _distorted_uv(xn: float, yn: float) -> tuple[float, float]:
    """Hand-written OpenCV model (independent of the project's helper)."""
    k1, k2, p1, p2 = LENS.params
    r2 = xn * xn + yn * yn
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]


def _blob(u: float, v: float, sigma: float = 1.5) -> np.ndarray:
    jj, ii = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    return (
        np.exp(-((jj - u) ** 2 + (ii - v) ** 2) / (2 * sigma**2)).astype(np.float32)[..., None].repeat(3, 2)
    )


def _centroid(image: np.ndarray) -> tuple[float, float]:
    weight = image[..., 0].astype(np.float64)
    jj, ii = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    return float((weight * jj).sum() / weight.sum()), float((weight * ii).sum() / weight.sum())


def test_point_moves_to_its_pinhole_projection():
    camera = Camera(K, np.eye(4), WIDTH, HEIGHT, LENS)
    shifts = []
    for xn, yn in [(0.55, 0.4), (-0.6, -0.45), (0.0, 0.0), (0.3, -0.5)]:
        u_d, v_d = _distorted_uv(xn, yn)
        undistorted, pinhole, _ = undistort_image(_blob(u_d, v_d), camera)
        assert pinhole.distortion is None and np.allclose(pinhole.K, K)
        u_p, v_p = K[0, 0] * xn + K[0, 2], K[1, 1] * yn + K[1, 2]
        shifts.append(np.hypot(u_d - u_p, v_d - v_p))
        u, v = _centroid(undistorted)
        assert np.hypot(u - u_p, v - v_p) < 0.15, (xn, yn, shifts[-1])
    assert max(shifts) > 3.0  # the case is not trivially pinhole


def test_uncovered_border_is_invalid_and_pinhole_is_unchanged():
    barrel = Camera(K, np.eye(4), WIDTH, HEIGHT, Distortion("OPENCV", (0.3, 0.1, 0.0, 0.0)))
    _, _, valid = undistortion_maps(barrel)
    assert valid[HEIGHT // 2, WIDTH // 2] and not valid[0, 0] and 0.3 < valid.mean() < 1.0
    plain = Camera(K, np.eye(4), WIDTH, HEIGHT)
    image = np.random.default_rng(0).random((HEIGHT, WIDTH, 3)).astype(np.float32)
    same, camera, covered = undistort_image(image, plain)
    assert same is image and camera is plain and covered.all()
