"""Plücker rays, packet normalisation and the view-overlap score (Eq. 2) against hand-derived values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.geometry import (
    normalize_packet,
    plucker_rays,
    select_references,
    view_overlap_score,
)
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at


def camera_at(center, target, width=16, height=12) -> Camera:
    return Camera(intrinsics_matrix(20, 20, width / 2, height / 2), look_at(center, target), width, height)


def test_plucker_properties_and_hand_value() -> None:
    camera = camera_at([1.0, -2.0, 0.5], [4.0, 10.0, 1.0])
    rays = plucker_rays(camera).double()
    moment, direction = rays[:3], rays[3:]
    assert rays.shape == (6, 12, 16)
    assert torch.allclose(direction.norm(dim=0), torch.ones(12, 16, dtype=torch.float64), atol=1e-6)
    assert torch.allclose((moment * direction).sum(0), torch.zeros(12, 16, dtype=torch.float64), atol=1e-5)
    # the moment is the same for any point on the ray: p = o + s d gives p × d = o × d
    o = torch.tensor(camera.center)
    for s in (0.5, 3.0, 17.0):
        p = o[:, None, None] + s * direction
        assert torch.allclose(torch.linalg.cross(p, direction, dim=0), moment, atol=1e-5)
    # pixel (row 3, col 5): centre (5.5, 3.5); direction = Rᵀ K⁻¹ [u, v, 1], normalised
    d_cam = np.array([(5.5 - 8) / 20, (3.5 - 6) / 20, 1.0])
    d_world = camera.R.T @ d_cam
    d_world /= np.linalg.norm(d_world)
    assert np.allclose(direction[:, 3, 5].numpy(), d_world, atol=1e-6)
    # lower resolution = same rays through the resized camera
    low = plucker_rays(camera, 6, 8)
    assert low.shape == (6, 6, 8)


def test_eq2_three_cameras_by_hand() -> None:
    a = camera_at([0, 0, 0], [0, 1, 0])
    b = camera_at([3, 0, 0], [3, 1, 0])
    c = camera_at([0, 4, 0], [1, 4, 0])
    d_max = 5.0  # pairwise distances 3, 4, 5
    assert view_overlap_score(a, b, d_max) == pytest.approx(0.8 * 1 + 0.2 * (1 - 3 / 5))
    assert view_overlap_score(a, c, d_max) == pytest.approx(0.8 * 0 + 0.2 * (1 - 4 / 5), abs=1e-12)
    assert view_overlap_score(b, c, d_max) == pytest.approx(0.0, abs=1e-12)
    assert select_references([a], [c, b], 2, d_max=d_max) == [1, 0]
    # mean aggregation over two targets: for targets {a, c}, b scores (0.88 + 0)/2 = 0.44, a copy of c scores
    # (0.04 + 1.0)/2 = 0.52
    c_copy = camera_at([0, 4, 0], [1, 4, 0])
    assert select_references([a, c], [b, c_copy], 1, d_max=d_max) == [1]


def test_select_references_ties_by_index() -> None:
    a = camera_at([0, 0, 0], [0, 1, 0])
    same = [camera_at([1, 0, 0], [1, 1, 0]) for _ in range(4)]
    assert select_references([a], same, 3, d_max=2.0) == [0, 1, 2]


def test_normalize_packet_identity_unit_scale_and_reprojection() -> None:
    rng = np.random.default_rng(0)
    cameras = [
        camera_at(rng.uniform(-5, 5, 3) + np.array([0, 0, 1]), rng.uniform(-1, 1, 3) + np.array([0, 20, 1]))
        for _ in range(4)
    ]
    H, W = cameras[0].height, cameras[0].width
    cmaps, alphas, points = [], [], []
    for cam in cameras:
        v, u = np.meshgrid(np.arange(H) + 0.5, np.arange(W) + 0.5, indexing="ij")
        uv = np.stack([u.ravel(), v.ravel()], 1)
        depth = rng.uniform(2, 30, size=uv.shape[0])
        world = cam.unproject(uv, depth).reshape(H, W, 3)
        alpha = rng.uniform(0.2, 1.0, size=(H, W, 1))
        cmaps.append(torch.from_numpy((world * alpha).transpose(2, 0, 1)))
        alphas.append(torch.from_numpy(alpha.transpose(2, 0, 1)))
        points.append(world)
    cmaps_t, alphas_t = torch.stack(cmaps), torch.stack(alphas)
    result = normalize_packet(cameras, cmaps_t, 2, alphas=alphas_t)
    assert np.allclose(result.cameras[2].w2c, np.eye(4), atol=1e-12)
    centers = np.stack([c.center for c in result.cameras])
    dists = np.linalg.norm(centers[:, None] - centers[None], axis=-1)
    assert dists.max() == pytest.approx(1.0)
    for cam, cmap, alpha in zip(result.cameras, result.cmaps, alphas_t):
        expected_point = (cmap / alpha).permute(1, 2, 0).reshape(-1, 3).numpy()
        uv, depth = cam.project(expected_point)
        v, u = np.meshgrid(np.arange(H) + 0.5, np.arange(W) + 0.5, indexing="ij")
        assert np.allclose(uv, np.stack([u.ravel(), v.ravel()], 1), atol=1e-6)
        assert (depth > 0).all()


def test_normalize_packet_single_camera_scale_one_and_empty_pixels_stay_zero() -> None:
    cam = camera_at([2, 3, 1], [2, 10, 1])
    cmap = torch.zeros(1, 3, 12, 16, dtype=torch.float64)
    alpha = torch.zeros(1, 1, 12, 16, dtype=torch.float64)
    result = normalize_packet([cam], cmap, 0, alphas=alpha)
    assert result.scale == 1.0
    assert torch.count_nonzero(result.cmaps) == 0
