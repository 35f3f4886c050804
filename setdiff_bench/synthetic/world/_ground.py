"""The ground of the street world as Gaussians: the road with its painted markings baked into the
asphalt texture, the parking strips, the curbs' vertical faces and the sidewalks.

Ground is seen at a grazing angle, so its grid is foreshortened along the street (:func:`_ground_grid`).
Coordinates are metres in the world frame (x along the street, y left, z up).
"""

from __future__ import annotations

import numpy as np

from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.layout import CURB_HEIGHT_M, EGO_LANES, StreetLayout
from setdiff_bench.synthetic.soup import GaussianSoup, Texture
from setdiff_bench.synthetic.world._detail import Detail


def _chunks(
    start: float, stop: float, detail: Detail, y: float, z: float, factor: float, max_chunk: float = 4.0
) -> list[tuple[float, float, float]]:
    """Split ``[start, stop]`` along x into pieces ``(x0, length, spacing)`` with distance-based spacing."""
    out = []
    x = start
    while x < stop - 1e-6:
        s = detail.spacing(np.array([x, y, z]), factor)
        length = min(max(max_chunk, 6 * s), stop - x)
        s_mid = detail.spacing(np.array([x + length / 2, y, z]), factor)
        out.append((x, length, s_mid))
        x += length
    return out


def road_texture(layout: StreetLayout, rng: np.random.Generator, y0: float) -> Texture:
    """Asphalt with painted markings baked in; ``u`` = x − x_min, ``v`` = y − y0."""
    asphalt = tx.asphalt_texture(rng, layout.asphalt_color, lane_width=layout.lane_width)
    white = np.array([0.92, 0.92, 0.9])
    yellow = np.array([0.9, 0.75, 0.2])
    lw = layout.lane_width
    dash_phase = float(rng.uniform(0, 9))

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        x = u + layout.x_min
        y = v + y0
        rgb = asphalt(u, v)
        boundary = (y + lw / 2) / lw  # integer at lane boundaries
        k = np.round(boundary)
        near = np.abs(boundary - k) * lw
        dashed_line = (near < 0.09) & (k >= 1) & (k <= layout.num_lanes - 1) & (k != EGO_LANES)
        dash_on = ((x + dash_phase) % 9.0) < 3.0
        rgb = np.where((dashed_line & dash_on)[:, None], white, rgb)
        double = (k == EGO_LANES) & (np.abs(np.abs(boundary - k) * lw - 0.12) < 0.07)
        rgb = np.where(double[:, None], yellow, rgb)
        edge = ((k == 0) | (k == layout.num_lanes)) & (near < 0.09)
        rgb = np.where(edge[:, None], white, rgb)
        if layout.crosswalk_x is not None:
            zebra = (
                (np.abs(x - layout.crosswalk_x) < 1.6)
                & (((y - layout.road_right) % 1.0) < 0.5)
                & (y > layout.road_right)
                & (y < layout.road_left)
            )
            rgb = np.where(zebra[:, None], white * 0.97, rgb)
        return rgb

    return sample


def ground_soup(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
    soup = GaussianSoup()
    road_tex = road_texture(layout, rng, layout.road_right)
    _ground_grid(
        soup, layout, detail, layout.road_right, layout.road_left, 0.0, road_tex, 1.0, align=layout.lane_width
    )
    parking_tex = tx.asphalt_texture(rng, tuple(np.asarray(layout.asphalt_color) * 0.93))
    for y_lo, y_hi in (
        (layout.curb_right, layout.road_right - 0.1),
        (layout.road_left + 0.1, layout.curb_left),
    ):
        _ground_grid(soup, layout, detail, y_lo, y_hi, 0.0, parking_tex, 1.5)
    # Curbs (vertical faces) and sidewalks.
    curb_tex = tx.noisy_color(rng, (0.7, 0.69, 0.66), 0.05)
    for y_curb, y_out in (
        (layout.curb_right, layout.facade_right - 2.0),
        (layout.curb_left, layout.facade_left + 2.0),
    ):
        for x0, length, s in _chunks(layout.x_min, layout.x_max, detail, y_curb, 0.1, 1.0):
            soup.add_plane(
                np.array([x0, y_curb, 0.0]),
                np.array([1.0, 0, 0]),
                np.array([0, 0, 1.0]),
                length,
                CURB_HEIGHT_M,
                max(s, 0.15),
                curb_tex,
            )
        paving = tx.paving_texture(rng, layout.sidewalk_color, layout.paving_tile)
        _ground_grid(soup, layout, detail, min(y_curb, y_out), max(y_curb, y_out), CURB_HEIGHT_M, paving, 1.3)
    return soup


def _ground_grid(
    soup: GaussianSoup,
    layout: StreetLayout,
    detail: Detail,
    y_lo: float,
    y_hi: float,
    z: float,
    texture: Texture,
    factor: float,
    *,
    align: float | None = None,
) -> None:
    """Tile the horizontal strip ``y_lo ≤ y ≤ y_hi`` at height ``z`` along the whole street.

    Ground is seen at a grazing angle, foreshortened along x, so the longitudinal spacing grows with the
    squared distance (pixel footprint ≈ D² / (f · camera height)) while the lateral spacing follows the
    usual rule.  With ``align``, the lateral grid puts disk centres exactly on multiples of ``align``
    from ``y_lo`` (lane boundaries), so markings baked into the texture stay crisp.  ``texture`` gets
    ``u = x − x_min`` and ``v = y − y_lo``.
    """
    x = layout.x_min
    y_mid = 0.5 * (y_lo + y_hi)
    width = y_hi - y_lo
    while x < layout.x_max - 1e-6:
        point = np.array([x, y_mid, z])
        distance = detail.distance(point)
        lateral_target = detail.spacing(point, factor)
        if align is not None:
            cells = max(2, round(align / lateral_target))
            lateral = align / cells
            v = np.arange(round(width / lateral) + 1) * lateral
        else:
            cells = max(1, round(width / lateral_target))
            lateral = width / cells
            v = (np.arange(cells) + 0.5) * lateral
        s_x = float(
            np.clip(
                0.5 * detail.pixels_per_gaussian * distance**2 / (detail.focal_px * 1.6),
                detail.min_spacing * factor,
                1.0 * factor,
            )
        )
        length = min(max(4.0, 4 * s_x), layout.x_max - x)
        nu = max(1, round(length / s_x))
        su = length / nu
        uu, vv = np.meshgrid((np.arange(nu) + 0.5) * su + (x - layout.x_min), v, indexing="xy")
        u, v_flat = uu.reshape(-1), vv.reshape(-1)
        means = np.stack([u + layout.x_min, v_flat + y_lo, np.full_like(u, z)], axis=1)
        soup.add(
            means,
            np.array([0.6 * su, 0.6 * lateral, 0.01]),
            np.array([1.0, 0, 0, 0]),
            texture(u, v_flat),
            0.995,
        )
        x += length
