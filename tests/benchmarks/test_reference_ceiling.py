"""The visibility test of ``benchmarks/reference_ceiling.py`` on an analytic plane scene.

Expected visibility and colours come from numpy projections through :meth:`Camera.project` (float64)
and the plane's texture function — not from the script's torch code.
"""

from __future__ import annotations

import numpy as np
import torch

from benchmarks.reference_ceiling import reference_samples
from tests.evaluation.run.store_fixtures import HEIGHT, WIDTH, camera_at, plane_view, texture

DEPTH = 2.5


def inverse_depth_maps(camera, points: np.ndarray) -> torch.Tensor:
    """``(1, 2, H, W)``: inverse camera depth × validity and validity of world ``points`` ``(H, W, 3)``."""
    depth = (points.reshape(-1, 3) @ camera.R.T + camera.t)[:, 2].reshape(1, 1, HEIGHT, WIDTH)
    inverse = torch.from_numpy(1.0 / depth).float()
    return torch.cat([inverse, torch.ones_like(inverse)], dim=1)


def test_a_slanted_plane_is_seen_wherever_it_projects_inside() -> None:
    """The reference is yawed, so the plane's depth varies across its pixels: bilinear inverse depth keeps
    every inside point within a 0.1 % tolerance, and the colours are the plane's texture there."""
    reference, target = camera_at(-0.4, yaw_deg=20.0), camera_at(0.2)
    ref_image, ref_points, _ = plane_view(reference, DEPTH)
    _, target_points, _ = plane_view(target, DEPTH)
    flat = target_points.reshape(-1, 3).astype(np.float64)
    images = torch.from_numpy(ref_image.transpose(2, 0, 1).copy())[None]
    mismatch, colours = reference_samples(
        torch.from_numpy(flat).float(), [reference], inverse_depth_maps(reference, ref_points), images
    )
    seen = mismatch <= 1e-3
    uv, z = reference.project(flat)
    inside = (
        (z > 0)
        & (uv[:, 0] >= 0.5)
        & (uv[:, 0] <= WIDTH - 0.5)
        & (uv[:, 1] >= 0.5)
        & (uv[:, 1] <= HEIGHT - 0.5)
    )
    assert 0.3 < inside.mean() < 0.95
    np.testing.assert_array_equal(seen[0].numpy(), inside)
    expected = texture(flat[:, 0], flat[:, 1])[inside]
    assert np.abs(colours[0].T.numpy()[inside] - expected).mean() < 0.01


def test_an_occluder_in_the_reference_hides_what_is_behind_it() -> None:
    reference, target = camera_at(-0.4), camera_at(0.1)
    ref_image, ref_points, _ = plane_view(reference, DEPTH)
    region = np.zeros((HEIGHT, WIDTH), bool)
    region[8:24, 14:30] = True
    ref_points = ref_points.copy()
    ref_points[region] = reference.center + 0.4 * (ref_points[region] - reference.center)
    _, target_points, _ = plane_view(target, DEPTH)
    flat = target_points.reshape(-1, 3).astype(np.float64)
    images = torch.from_numpy(ref_image.transpose(2, 0, 1).copy())[None]
    mismatch, _ = reference_samples(
        torch.from_numpy(flat).float(), [reference], inverse_depth_maps(reference, ref_points), images
    )
    seen = mismatch <= 0.03
    uv, _ = reference.project(flat)
    col, row = np.floor(uv[:, 0]).astype(int), np.floor(uv[:, 1]).astype(int)
    inside = (col >= 1) & (col < WIDTH - 1) & (row >= 1) & (row < HEIGHT - 1)
    # pixels whose projection falls on the occluder with a one-pixel margin (bilinear neighbours)
    hidden = np.zeros(len(uv), bool)
    core = np.zeros_like(region)
    core[9:23, 15:29] = True
    hidden[inside] = core[row[inside], col[inside]]
    assert hidden.sum() > 50
    assert not seen[0].numpy()[hidden].any()
    near = np.zeros_like(region)
    near[6:26, 12:32] = True  # the occluder grown by two pixels
    free = inside & ~near[row.clip(0, HEIGHT - 1), col.clip(0, WIDTH - 1)]
    assert free.sum() > 200
    assert seen[0].numpy()[free].all()
