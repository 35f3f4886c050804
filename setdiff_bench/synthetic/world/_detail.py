"""The world's level of detail: the grid spacing of every surface as a function of its distance to the
stretch of street the cameras move along (:class:`Detail`).

Spacing keeps roughly ``pixels_per_gaussian`` pixels between neighbouring disk centres at the benchmark
focal length, so a ~100 m street stays at a few tens of thousands of Gaussians.  Distances and spacings
are metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

FACADE_DETAIL = 0.8
"""Façades get a finer grid than other surfaces (windows, doors and frames are their detail)."""


@dataclass(frozen=True)
class Detail:
    """Grid spacing policy (metres).

    Attributes:
        focal_px: focal length of the benchmark cameras in pixels.
        pixels_per_gaussian: target pixels between neighbouring disk centres at the surface's distance.
        min_spacing, max_spacing: clamps on the spacing.
        path_x, path_y: x and y ranges of the camera trajectories (distance is measured to this box at
            camera height 1.6 m).
        foliage_count: Gaussians per tree-crown blob.
    """

    focal_px: float
    pixels_per_gaussian: float
    min_spacing: float
    max_spacing: float
    path_x: tuple[float, float]
    path_y: tuple[float, float]
    foliage_count: int

    def distance(self, point: np.ndarray) -> float:
        x, y, z = (float(v) for v in point)
        dx = max(self.path_x[0] - x, 0.0, x - self.path_x[1])
        dy = max(self.path_y[0] - y, 0.0, y - self.path_y[1])
        return math.sqrt(dx * dx + dy * dy + (z - 1.6) ** 2)

    def spacing(self, point: np.ndarray, factor: float = 1.0) -> float:
        """Grid spacing for a surface around ``point``: ``pixels_per_gaussian · distance / focal``, clamped."""
        raw = self.pixels_per_gaussian * self.distance(point) / self.focal_px
        return float(np.clip(raw * factor, self.min_spacing * factor, self.max_spacing * factor))
