"""What the two scene kinds' presets (:mod:`.presets` for driving, :mod:`.sparse` for sparse-view) share
tier by tier, declared once: the world's level of detail of the ``tiny`` tier (seconds, for tests) and the
``large`` tier (a GPU), and the fit schedules of the CPU tier (``default``, ``sparse``: under 10 minutes on
2 CPU cores) and the ``large`` tier.  Each kind's ``tiny`` fit and CPU-tier level of detail are its own.
"""

from __future__ import annotations

from typing import TypedDict

from setdiff_bench.gaussians.fit import FitConfig


class WorldDetail(TypedDict):
    """A preset's world level of detail (``world.Detail``) and its number of SfM-like points."""

    pixels_per_gaussian: float
    min_spacing: float
    max_spacing: float
    foliage_count: int
    points3d: int


#: ``tiny`` and ``sparse_tiny``.
TINY_DETAIL: WorldDetail = {
    "pixels_per_gaussian": 5.0,
    "min_spacing": 0.7,
    "max_spacing": 4.0,
    "foliage_count": 12,
    "points3d": 1500,
}

#: ``large`` and ``sparse_large``.
LARGE_DETAIL: WorldDetail = {
    "pixels_per_gaussian": 3.0,
    "min_spacing": 0.12,
    "max_spacing": 3.0,
    "foliage_count": 200,
    "points3d": 30000,
}

#: ``default`` and ``sparse``: 250 iterations, at most 16 000 Gaussians (benchmarks/results/fit_quality.md).
CPU_FIT = FitConfig.schedule(
    iterations=250,
    densify_every=20,
    opacity_reset_every=10_000,
    max_gaussians=16_000,
    background_points=3000,
    tile_size=8,
)

#: ``large`` and ``sparse_large``: 7000 iterations, for a GPU.
LARGE_FIT = FitConfig.schedule(iterations=7000, densify_every=100, background_points=10_000, tile_size=16)
