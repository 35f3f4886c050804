"""Triangulated initial points: views of a textured plane z = 0 rendered analytically (ray-plane
intersection, texture lookup) give points on that plane, within their reprojection accuracy."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.fit import FitView, initial_points, triangulate_views
from setdiff_bench.rotations import look_at

WIDTH, HEIGHT = 240, 180
K = np.array([[200.0, 0.0, 120.0], [0.0, 200.0, 90.0], [0.0, 0.0, 1.0]])
HALF = 2.0  # the texture covers [-2, 2]² on z = 0


def _texture() -> np.ndarray:
    rng = np.random.default_rng(7)
    coarse = rng.random((48, 48, 3)).astype(np.float32)
    fine = cv2.resize(coarse, (512, 512), interpolation=cv2.INTER_CUBIC)
    blobs = cv2.GaussianBlur(rng.random((512, 512, 3)).astype(np.float32), (0, 0), 2.0)
    return np.clip(0.6 * fine + 0.8 * (blobs - 0.5) + 0.2, 0, 1)


def _view(eye, texture) -> FitView:
    w2c = look_at(eye, [0.0, 0.0, 0.0], up=(0.0, 1.0, 0.0))
    camera = Camera(K, w2c, WIDTH, HEIGHT)
    jj, ii = np.meshgrid(np.arange(WIDTH) + 0.5, np.arange(HEIGHT) + 0.5)
    rays_cam = np.stack([(jj - K[0, 2]) / K[0, 0], (ii - K[1, 2]) / K[1, 1], np.ones_like(jj)], -1)
    rays = rays_cam @ w2c[:3, :3]  # camera → world directions (R^T d)
    center = camera.center
    t = -center[2] / rays[..., 2]
    hit = center + t[..., None] * rays
    size = texture.shape[0]
    u = ((hit[..., 0] + HALF) / (2 * HALF) * size - 0.5).astype(np.float32)
    v = ((hit[..., 1] + HALF) / (2 * HALF) * size - 0.5).astype(np.float32)
    image = cv2.remap(texture, u, v, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
    return FitView(f"v{eye}", camera, torch.from_numpy(image).permute(2, 0, 1).contiguous(), None)


@pytest.fixture(scope="module")
def plane_views():
    texture = _texture()
    return [
        _view(eye, texture)
        for eye in ([0.0, -0.6, 3.0], [0.5, -0.5, 3.1], [-0.5, -0.4, 2.9], [0.2, 0.5, 3.2])
    ]


def test_triangulated_points_lie_on_the_plane(plane_views):
    xyz, rgb = triangulate_views(plane_views)
    assert len(xyz) >= 100 and rgb.shape == (len(xyz), 3) and rgb.dtype == np.uint8
    # a 0.5 px error at 3 m with f = 200 px is ~7.5 mm; allow a few times that
    assert np.median(np.abs(xyz[:, 2])) < 0.02
    assert np.abs(xyz[:, :2]).max() <= HALF + 0.1


def test_initial_points_modes(plane_views, tmp_path):
    from types import SimpleNamespace

    sparse = np.array([[1.0, 2.0, 3.0]])
    with_points = SimpleNamespace(points3d=sparse, points_rgb=np.zeros((1, 3), np.uint8), root=tmp_path)
    assert initial_points(with_points, plane_views, "auto")[0] is sparse
    assert initial_points(with_points, plane_views, "random") == (None, None)
    without = SimpleNamespace(points3d=None, points_rgb=None, root=tmp_path)
    xyz, _ = initial_points(without, plane_views, "auto")
    assert xyz is not None and len(xyz) >= 100
    with pytest.raises(UsageError, match="unknown init 'grid'"):
        initial_points(without, plane_views, "grid")
