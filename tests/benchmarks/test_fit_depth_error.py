"""``benchmarks/fit_depth_error.py``'s per-Gaussian ray-peak depth against the ray-plane intersection of a flat,
tilted Gaussian (where the density peak along every ray is exactly the plane), worked by hand."""

from __future__ import annotations

import math

import numpy as np
import torch

from benchmarks.fit_depth_error import ray_peak_depth
from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.intrinsics import intrinsics_matrix

FOCAL, WIDTH, HEIGHT = 50.0, 64, 48
CENTRE = np.array([0.0, 0.0, 5.0])
TILT = math.radians(40.0)  # the disc's normal turned from the optical axis towards +y


def tilted_disc() -> GaussianModel:
    """One opaque Gaussian, 2 m wide and 0.1 mm thick, centred on the optical axis 5 m away, turned about x."""
    quaternion = [math.cos(TILT / 2), math.sin(TILT / 2), 0.0, 0.0]
    return GaussianModel(
        means=torch.tensor(CENTRE[None], dtype=torch.float32),
        quats=torch.tensor([quaternion], dtype=torch.float32),
        log_scales=torch.log(torch.tensor([[2.0, 2.0, 1e-4]], dtype=torch.float32)),
        opacity_logits=torch.tensor([4.0]),
        sh=torch.zeros(1, 1, 3),
    )


def plane_depth(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Depth of the ray through pixel centre ``(u, v)`` where it meets the disc's plane."""
    normal = np.array([0.0, -math.sin(TILT), math.cos(TILT)])  # R_x(TILT) · (0, 0, 1)
    x, y = (u + 0.5 - (WIDTH / 2)) / FOCAL, (v + 0.5 - (HEIGHT / 2)) / FOCAL
    return (normal @ CENTRE) / (normal[0] * x + normal[1] * y + normal[2])


def test_ray_peak_depth_follows_the_tilted_plane_where_the_centre_depth_does_not() -> None:
    camera = Camera(intrinsics_matrix(FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2), np.eye(4), WIDTH, HEIGHT)
    model = tilted_disc()
    peak = ray_peak_depth(model, camera)[0].numpy()
    with torch.no_grad():
        out = render(model, camera)
    centre = (out.depth / out.alpha.clamp_min(1e-6))[0, 0].numpy()
    rows = np.arange(HEIGHT // 2 - 6, HEIGHT // 2 + 6)
    columns = np.full_like(rows, WIDTH // 2)
    truth = plane_depth(columns, rows)
    # within 6 px of the centre the plane's depth changes by ±10 %; the linearised peak keeps within 1.5 %
    assert np.abs(truth / 5.0 - 1).max() > 0.08
    np.testing.assert_allclose(peak[rows, columns], truth, rtol=0.015)
    np.testing.assert_allclose(centre[rows, columns], 5.0, rtol=1e-4)
