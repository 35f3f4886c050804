"""Procedural surface textures: ``texture(u, v) -> (P, 3) rgb`` closures over seeded parameters.

Every texture is a pure function of the patch coordinates ``(u, v)`` in metres and of numbers drawn
from the scene's random generator when the texture is built, so a world is reproducible from its seed.
Detail is designed for the ~5–40 cm surface footprint of one pixel at the benchmark resolutions.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from setdiff_bench.synthetic.soup import Texture


def value_noise(
    rng: np.random.Generator, cell_m: float, extent_m: tuple[float, float] = (400.0, 120.0)
) -> Texture:
    """Smooth scalar noise in [-1, 1] (bilinear value noise on a ``cell_m`` lattice), returned as a
    texture whose three channels are equal; deterministic from ``rng``."""
    nx = int(extent_m[0] / cell_m) + 3
    ny = int(extent_m[1] / cell_m) + 3
    lattice = rng.uniform(-1.0, 1.0, size=(ny, nx))

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        x = np.clip(np.asarray(u) / cell_m, 0.0, nx - 2.001)
        y = np.clip(np.asarray(v) / cell_m, 0.0, ny - 2.001)
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        fx, fy = x - x0, y - y0
        fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
        top = lattice[y0, x0] * (1 - fx) + lattice[y0, x0 + 1] * fx
        bottom = lattice[y0 + 1, x0] * (1 - fx) + lattice[y0 + 1, x0 + 1] * fx
        value = top * (1 - fy) + bottom * fy
        return np.repeat(value[:, None], 3, axis=1)

    return sample


def noisy_color(
    rng: np.random.Generator, base: Sequence[float], amplitude: float = 0.06, cell_m: float = 0.7
) -> Texture:
    """``base`` colour modulated by two octaves of value noise (stains, weathering)."""
    coarse = value_noise(rng, cell_m * 4)
    fine = value_noise(rng, cell_m)
    base_arr = np.asarray(base, np.float64)

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        n = 0.6 * coarse(u, v) + 0.4 * fine(u, v)
        return np.clip(base_arr * (1.0 + amplitude * 2 * n), 0, 1)

    return sample


@dataclass(frozen=True)
class FacadeStyle:
    """Parameters of one building façade (all lengths in metres, colours rgb in [0, 1])."""

    wall: tuple[float, float, float]
    trim: tuple[float, float, float]
    glass: tuple[float, float, float]
    door: tuple[float, float, float]
    pattern: str  # "plaster" | "brick" | "panels" | "glass"
    floor_height: float
    window_width: float
    window_height: float
    window_pitch: float
    ground_floor_shop: bool
    door_positions: tuple[float, ...]
    door_width: float = 1.2
    door_height: float = 2.3


def facade_texture(rng: np.random.Generator, style: FacadeStyle, width: float, height: float) -> Texture:
    """A building front: wall pattern, floor bands, a window grid, doors and an optional shop window.

    ``u`` runs along the street (0…``width``), ``v`` upward from the pavement (0…``height``).
    """
    wall = noisy_color(rng, style.wall, amplitude=0.08, cell_m=0.8)
    brick_rows = 0.45
    brick_jitter = rng.uniform(-0.07, 0.07, size=(int(height / brick_rows) + 2, int(width / 0.9) + 3))
    glass_tint = rng.uniform(-0.05, 0.05, size=(64, 64))
    lit = rng.uniform(0.0, 1.0, size=(64, 64)) < 0.18
    _wall_rgb, trim_rgb = np.asarray(style.wall), np.asarray(style.trim)
    glass_rgb, door_rgb = np.asarray(style.glass), np.asarray(style.door)
    n_cols = max(1, int((width - 0.8) / style.window_pitch))
    margin = (width - n_cols * style.window_pitch) / 2

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        u, v = np.asarray(u, np.float64), np.asarray(v, np.float64)
        rgb = wall(u, v)
        if style.pattern == "brick":
            row = np.floor(v / brick_rows).astype(int)
            col = np.floor((u + 0.45 * (row % 2)) / 0.9).astype(int)
            rgb = (
                rgb
                * (
                    1.0
                    + brick_jitter[
                        np.clip(row, 0, brick_jitter.shape[0] - 1), np.clip(col, 0, brick_jitter.shape[1] - 1)
                    ]
                )[:, None]
            )
            mortar = (np.abs(v / brick_rows - np.round(v / brick_rows)) * brick_rows) < 0.035
            rgb = np.where(mortar[:, None], 0.8 * rgb + 0.2 * 0.85, rgb)
        elif style.pattern == "panels":
            seam = np.abs(u / 1.5 - np.round(u / 1.5)) * 1.5 < 0.05
            rgb = np.where(seam[:, None], rgb * 0.72, rgb)
        # floor bands (cornices) between storeys
        storey = v / style.floor_height
        band = (np.abs(storey - np.round(storey)) * style.floor_height < 0.12) & (v > 0.5)
        rgb = np.where(band[:, None], trim_rgb, rgb)
        # window grid above the ground floor (or everywhere for glass façades)
        col = np.floor((u - margin) / style.window_pitch)
        cu = u - margin - (col + 0.5) * style.window_pitch
        floor = np.floor(storey)
        cv = v - (floor + 0.55) * style.floor_height
        in_cols = (col >= 0) & (col < n_cols)
        first_floor = 0 if style.pattern == "glass" else 1
        window_rows = (floor >= first_floor) & (v < height - 0.6)
        half_w, half_h = style.window_width / 2, style.window_height / 2
        frame = in_cols & window_rows & (np.abs(cu) < half_w + 0.1) & (np.abs(cv) < half_h + 0.1)
        pane = in_cols & window_rows & (np.abs(cu) < half_w) & (np.abs(cv) < half_h)
        ci = np.clip(col.astype(int) % 64, 0, 63)
        fi = np.clip(floor.astype(int) % 64, 0, 63)
        reflection = 0.12 * (cv / max(half_h, 1e-3))[:, None]
        pane_rgb = glass_rgb + glass_tint[fi, ci][:, None] - reflection
        pane_rgb = np.where(lit[fi, ci][:, None], np.array([0.93, 0.82, 0.55]), pane_rgb)
        mullion = pane & (np.abs(cu) < 0.04)
        rgb = np.where(frame[:, None], trim_rgb, rgb)
        rgb = np.where(pane[:, None], pane_rgb, rgb)
        rgb = np.where(mullion[:, None], trim_rgb * 0.8, rgb)
        # ground floor: shop window band and doors
        if style.ground_floor_shop and style.pattern != "glass":
            shop = (v > 0.5) & (v < style.floor_height - 0.6) & (u > 0.6) & (u < width - 0.6)
            rgb = np.where(shop[:, None], glass_rgb * 0.8 + 0.04, rgb)
        for door_u in style.door_positions:
            door = (np.abs(u - door_u) < style.door_width / 2) & (v < style.door_height)
            door_frame = (np.abs(u - door_u) < style.door_width / 2 + 0.12) & (v < style.door_height + 0.12)
            rgb = np.where(door_frame[:, None] & ~door[:, None], trim_rgb * 0.7, rgb)
            rgb = np.where(door[:, None], door_rgb, rgb)
        return np.clip(rgb, 0.0, 1.0)

    return sample


def asphalt_texture(
    rng: np.random.Generator,
    base: Sequence[float],
    *,
    lane_width: float | None = None,
    extent_m: tuple[float, float] = (400.0, 40.0),
) -> Texture:
    """Road surface: grey with large stains, fine grain, sharp-edged repair patches, manhole covers and,
    with ``lane_width``, darker tyre tracks 0.9 m either side of each lane centre (``v`` = 0 on a lane edge)."""
    patches = value_noise(rng, 2.5)
    grain = value_noise(rng, 0.35)
    base_arr = np.asarray(base, np.float64)
    n_repairs = int(extent_m[0] * extent_m[1] / 60)
    repairs = np.stack(
        [
            rng.uniform(0, extent_m[0], n_repairs),
            rng.uniform(0, extent_m[1], n_repairs),
            rng.uniform(0.6, 3.5, n_repairs),
            rng.uniform(0.5, 2.0, n_repairs),
            rng.uniform(-0.25, 0.2, n_repairs),
        ],
        axis=1,
    )
    n_covers = int(extent_m[0] / 25)
    covers = np.stack([rng.uniform(0, extent_m[0], n_covers), rng.uniform(0, extent_m[1], n_covers)], axis=1)

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        u, v = np.asarray(u, np.float64), np.asarray(v, np.float64)
        shade = 1.0 + 0.14 * patches(u, v)[:, 0] + 0.12 * grain(u, v)[:, 0]
        if lane_width is not None:
            across = np.mod(v, lane_width) - lane_width / 2
            shade -= 0.12 * np.exp(-0.5 * ((np.abs(across) - 0.9) / 0.25) ** 2)
        near = (
            (repairs[:, 0] + repairs[:, 2] > u.min()) & (repairs[:, 0] - repairs[:, 2] < u.max())
            if u.size
            else []
        )
        for x0, y0, length, width, tone in repairs[near]:
            inside = (np.abs(u - x0) < length / 2) & (np.abs(v - y0) < width / 2)
            shade = np.where(inside, shade + tone, shade)
        for x0, y0 in covers[(np.abs(covers[:, 0] - u.mean()) < np.ptp(u) + 1.0)] if u.size else []:
            shade = np.where((u - x0) ** 2 + (v - y0) ** 2 < 0.36, 0.55, shade)
        return np.clip(base_arr * shade[:, None], 0, 1)

    return sample


def paving_texture(rng: np.random.Generator, base: Sequence[float], tile_m: float) -> Texture:
    """Sidewalk slabs of ``tile_m`` metres with thin dark joints and per-slab tint."""
    tint = rng.uniform(-0.06, 0.06, size=(256, 64))
    base_arr = np.asarray(base, np.float64)

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        iu = np.clip(np.floor(u / tile_m).astype(int), 0, 255)
        iv = np.clip(np.floor(v / tile_m).astype(int), 0, 63)
        rgb = base_arr * (1.0 + tint[iu, iv])[:, None]
        joint = (np.abs(u / tile_m - np.round(u / tile_m)) * tile_m < 0.05) | (
            np.abs(v / tile_m - np.round(v / tile_m)) * tile_m < 0.05
        )
        return np.clip(np.where(joint[:, None], rgb * 0.7, rgb), 0, 1)

    return sample


def vertical_gradient(bottom: Sequence[float], top: Sequence[float], height: float) -> Texture:
    """Colour blending from ``bottom`` at ``v = 0`` to ``top`` at ``v = height``."""
    b, t = np.asarray(bottom, np.float64), np.asarray(top, np.float64)

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        f = np.clip(np.asarray(v) / height, 0, 1)[:, None]
        return b * (1 - f) + t * f

    return sample


def solid(color: Sequence[float]) -> Texture:
    """A constant colour."""
    c = np.asarray(color, np.float64)

    def sample(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.broadcast_to(c, (np.asarray(u).shape[0], 3)).copy()

    return sample
