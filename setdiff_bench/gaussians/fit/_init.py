"""The initial Gaussians of a fit: the scene extent (Inria ``getNerfppNorm``), Gaussians at the sparse
points or random ones in the camera box grown by the scene radius, and optional image-coloured points on a
far background sphere.

Points are ``(P, 3)`` float64 in world units; colours ``(P, 3)`` uint8.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from setdiff_bench.gaussians.fit._config import FitConfig
from setdiff_bench.gaussians.fit._data import FitView
from setdiff_bench.gaussians.model import GaussianModel


def scene_extent(views: Sequence[FitView]) -> tuple[np.ndarray, float]:
    """Inria ``getNerfppNorm``: centre of the camera centres and 1.1 × the largest distance to it (≥ 1e-3... 1)."""
    centers = np.stack([v.camera.center for v in views])
    center = centers.mean(axis=0)
    radius = float(np.linalg.norm(centers - center, axis=1).max()) * 1.1
    return center, radius if radius > 1e-6 else 1.0


def initial_model(
    views: Sequence[FitView], points: np.ndarray | None, colors: np.ndarray | None, config: FitConfig
) -> GaussianModel:
    """Gaussians at the sparse points, or random ones in the camera box grown by the scene radius; plus
    ``config.background_points`` image-coloured points on a far sphere."""
    if points is not None and len(points) > 0:
        xyz = np.asarray(points, np.float64)
        rgb = None if colors is None else np.asarray(colors)
        if rgb is not None and rgb.dtype != np.uint8:
            rgb = np.rint(np.clip(rgb, 0, 1) * 255).astype(np.uint8)
    else:
        centers = np.stack([v.camera.center for v in views])
        _, radius = scene_extent(views)
        low, high = centers.min(axis=0) - radius, centers.max(axis=0) + radius
        count = random_init_count(views, config)
        generator = torch.Generator().manual_seed(config.seed)
        unit = torch.rand(count, 3, generator=generator, dtype=torch.float64).numpy()
        xyz, rgb = low + unit * (high - low), np.full((count, 3), 128, np.uint8)
    if config.background_points > 0:
        far_xyz, far_rgb = background_sphere(
            views, config.background_points, config.background_radius, config.seed
        )
        xyz, rgb = (
            np.concatenate([xyz, far_xyz]),
            np.concatenate([rgb if rgb is not None else np.full((len(xyz), 3), 128, np.uint8), far_rgb]),
        )
    return GaussianModel.from_points(
        xyz, rgb, sh_degree=config.sh_degree, initial_opacity=config.initial_opacity
    )


def random_init_count(views: Sequence[FitView], config: FitConfig) -> int:
    """Random Gaussians for a scene without sparse points, sized to it: one per 4×4-pixel block of an
    average training view (≥ 1000), at most ``config.random_init_points`` and half the strategy's
    Gaussian cap.
    A 270×480 view gets 8100 instead of the fixed 100 000 that made every step of a short CPU fit
    cost seconds."""
    pixels = float(np.mean([v.camera.width * v.camera.height for v in views]))
    count = min(config.random_init_points, max(1000, round(pixels / 16)))
    cap = config.strategy.max_gaussians
    if cap is not None:
        count = min(count, max(1, cap // 2))
    return count


def background_sphere(
    views: Sequence[FitView], count: int, radius_factor: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """``count`` points on a Fibonacci sphere of ``radius_factor`` × extent around the camera centres, each
    coloured with the pixel it projects to in the first training view that sees it.  Points below 5° under
    the cameras' horizon (mean camera up = −y axis) and points no view sees are dropped.

    Returns:
        ``xyz (P, 3)`` world units and ``rgb (P, 3)`` uint8.
    """
    center, extent = scene_extent(views)
    k = np.arange(count) + 0.5
    polar = np.arccos(1 - 2 * k / count)
    azimuth = np.pi * (1 + 5**0.5) * k + 2 * np.pi * (seed % 997) / 997
    unit = np.stack([np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1)
    up = -np.mean([v.camera.R[1] for v in views], axis=0)
    up /= max(float(np.linalg.norm(up)), 1e-12)
    unit = unit[unit @ up > -np.sin(np.radians(5.0))]
    xyz = center + radius_factor * extent * unit
    count = len(xyz)
    rgb = np.zeros((count, 3), np.uint8)
    seen = np.zeros(count, bool)
    for view in views:
        uv, z = view.camera.project(xyz)
        h, w = view.image.shape[1:]
        with np.errstate(invalid="ignore"):
            inside = ~seen & (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        cols, rows = np.floor(uv[inside]).astype(int).T
        rgb[inside] = np.rint(view.image[:, rows, cols].T.numpy() * 255).astype(np.uint8)
        seen |= inside
    return xyz[seen], rgb[seen]
