"""The buildings of the street world as Gaussians: textured façades along both sides, their end walls, the
back walls seen through the gaps between buildings, and the building closing a dead-end street.

Façades get a finer grid than other surfaces (``FACADE_DETAIL``).  Coordinates are metres in the world
frame (x along the street, y left, z up).
"""

from __future__ import annotations

import itertools

import numpy as np

from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.layout import Building, StreetLayout, random_style
from setdiff_bench.synthetic.soup import GaussianSoup
from setdiff_bench.synthetic.world._detail import FACADE_DETAIL, Detail


def facade_soup(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
    soup = GaussianSoup()
    for side, buildings, line in (
        (-1, layout.buildings_right, layout.facade_right),
        (1, layout.buildings_left, layout.facade_left),
    ):
        for b in buildings:
            _building(soup, b, side, line + side * b.setback, detail, rng)
        # Gaps between buildings show a back wall (courtyards, fences) instead of the sky.
        edges = sorted((b.x0, b.x0 + b.width) for b in buildings)
        back_tex = tx.noisy_color(rng, (0.55, 0.53, 0.5), 0.1, 1.5)
        for (_, end), (start, _) in itertools.pairwise(edges):
            if start - end > 0.05:
                origin = np.array([end, line + side * 9.0, 0.0])
                soup.add_plane(
                    origin,
                    np.array([1.0, 0, 0]),
                    np.array([0, 0, 1.0]),
                    start - end,
                    7.0,
                    detail.spacing(origin, 2.0),
                    back_tex,
                )
    if layout.street_end == "closed":
        width = layout.facade_left - layout.facade_right + 20.0
        style = random_style(rng, width)
        height = float(rng.uniform(12, 24))
        origin = np.array([layout.x_max, layout.facade_left + 10.0, 0.0])
        tex = tx.facade_texture(rng, style, width, height)
        spacing = detail.spacing(origin, 1.0)
        soup.add_plane(origin, np.array([0, -1.0, 0]), np.array([0, 0, 1.0]), width, height, spacing, tex)
    return soup


def _building(
    soup: GaussianSoup, b: Building, side: int, y: float, detail: Detail, rng: np.random.Generator
) -> None:
    """Façade of ``b`` at lateral position ``y`` (``side`` −1 = right of the street), plus its end walls."""
    tex = tx.facade_texture(rng, b.style, b.width, b.height)
    x = b.x0
    while x < b.x0 + b.width - 1e-6:
        length = min(3.0, b.x0 + b.width - x)
        for z0, z1 in ((0.0, min(b.height, 6.0)), (min(b.height, 6.0), b.height)):
            if z1 - z0 < 1e-6:
                continue
            s = detail.spacing(np.array([x + length / 2, y, 0.5 * (z0 + z1)]), FACADE_DETAIL)

            def piece(u: np.ndarray, v: np.ndarray, du: float = x - b.x0, dv: float = z0) -> np.ndarray:
                return tex(u + du, v + dv)

            soup.add_plane(
                np.array([x, y, z0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0]), length, z1 - z0, s, piece
            )
        x += length
    wall = tx.noisy_color(rng, b.style.wall, 0.08)
    for x_end in (b.x0, b.x0 + b.width):
        origin = np.array([x_end, y, 0.0])
        s = detail.spacing(origin, 1.5)
        soup.add_plane(origin, np.array([0, side * 1.0, 0]), np.array([0, 0, 1.0]), 8.0, b.height, s, wall)
