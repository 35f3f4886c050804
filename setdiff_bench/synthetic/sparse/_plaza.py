"""The plaza's furniture in a sparse-view scene: cars at any angle, façade-textured kiosks and stone
blocks or planters placed in the roadway around the walk (:func:`plaza_objects`), so that objects at
2-10 m occlude the parked cars and façades differently from frame to frame.

Coordinates are metres in the world frame (z up).
"""

from __future__ import annotations

import math

import numpy as np

from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.layout import StreetLayout, random_car, random_style
from setdiff_bench.synthetic.soup import GaussianSoup
from setdiff_bench.synthetic.sparse._preset import SparsePreset
from setdiff_bench.synthetic.sparse._walk import Walk
from setdiff_bench.synthetic.world import FACADE_DETAIL, Detail, car_soup


def _clear_of(points: np.ndarray, x: float, y: float, radius: float) -> bool:
    return bool(np.min(np.hypot(points[:, 0] - x, points[:, 1] - y)) >= radius)


def plaza_objects(
    preset: SparsePreset, layout: StreetLayout, walk: Walk, detail: Detail, rng: np.random.Generator
) -> GaussianSoup:
    """``preset.plaza_objects`` draws of a car at any angle (45 %), a façade-textured kiosk (30 %) or a stone
    block / planter (25 %) in the roadway around the walk, each at least 4 / 3 / 2 m from every camera
    position and 3.5 m from the others (a draw that finds no place in 60 tries is skipped)."""
    soup = GaussianSoup()
    placed: list[tuple[float, float]] = []
    reach = float(np.abs(walk.positions[:, 0] - walk.center[0]).max()) + 5.0
    lo_x, hi_x = walk.center[0] - reach, walk.center[0] + reach
    lo_y, hi_y = layout.road_right + 1.0, layout.road_left - 1.0
    for _ in range(preset.plaza_objects):
        kind = str(rng.choice(["car", "kiosk", "block"], p=[0.45, 0.3, 0.25]))
        clearance = {"car": 4.0, "kiosk": 3.0, "block": 2.0}[kind]
        for _attempt in range(60):
            x, y = float(rng.uniform(lo_x, hi_x)), float(rng.uniform(lo_y, hi_y))
            if _clear_of(walk.positions, x, y, clearance) and all(
                math.hypot(x - px, y - py) >= 3.5 for px, py in placed
            ):
                break
        else:
            continue
        placed.append((x, y))
        yaw = float(rng.uniform(-math.pi, math.pi))
        if kind == "car":
            soup.extend(car_soup(random_car(rng, x, y, yaw), detail, rng))
        elif kind == "kiosk":
            length, width, height = (
                float(rng.uniform(1.8, 3.2)),
                float(rng.uniform(1.4, 2.2)),
                float(rng.uniform(2.3, 3.0)),
            )
            style = random_style(rng, length)
            spacing = detail.spacing(np.array([x, y, 1.2]), FACADE_DETAIL)
            side = tx.facade_texture(rng, style, length, height)
            soup.add_box(
                np.array([x, y, 0.0]),
                (length, width, height),
                yaw,
                spacing,
                {"side": side, "front": tx.noisy_color(rng, style.wall, 0.08), "top": tx.solid(style.trim)},
            )
        else:  # a planter or a stone block: a low box with a textured top
            size = (float(rng.uniform(1.0, 2.2)), float(rng.uniform(0.8, 1.4)), float(rng.uniform(0.45, 0.9)))
            stone = tx.noisy_color(rng, (0.55, 0.53, 0.5), 0.1, 0.4)
            top = tx.noisy_color(rng, (0.3, 0.22, 0.15), 0.15, 0.2) if rng.random() < 0.6 else stone
            soup.add_box(
                np.array([x, y, 0.0]),
                size,
                yaw,
                min(detail.spacing(np.array([x, y, 0.3])), 0.2),
                {"side": stone, "top": top},
            )
    return soup
