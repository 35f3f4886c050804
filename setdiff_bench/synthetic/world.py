"""The procedural street world as 3D Gaussians: a :class:`StreetLayout` turned into a static
:class:`GaussianModel` plus vehicle templates that move per timestamp.

Level of detail: surfaces are tiled with a grid whose spacing grows with the distance to the stretch
of street the cameras drive along (``Detail``), so a ~100 m street stays at a few tens of thousands of
Gaussians while keeping roughly ``pixels_per_gaussian`` pixels between neighbouring disk centres at
the benchmark focal length.  Every Gaussian carries a category (ground, façade, object, foliage,
vehicle, far background, sky) so that the SfM-like point sampler can skip what SfM never triangulates.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import torch

from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.layout import (
    CURB_HEIGHT_M,
    EGO_LANES,
    Building,
    Car,
    StreetLayout,
    random_style,
)
from setdiff_bench.synthetic.soup import GaussianSoup, Texture, basis_quaternion

CATEGORIES = ("ground", "facade", "object", "foliage", "far", "sky")
"""Category names; ``World.categories`` holds indices into this tuple."""
SFM_CATEGORIES = (0, 1, 2, 3)
"""Categories whose surfaces may appear in the sparse SfM-like point cloud."""
SKY_RADIUS_M = 400.0
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


@dataclass
class World:
    """A scene's Gaussians.

    Attributes:
        layout: the street plan.
        static: the static Gaussians (world frame).
        categories: ``(N,)`` int64 index into :data:`CATEGORIES` per static Gaussian.
        vehicles: templates of moving vehicles in their own frame (x forward, y left, z up, origin at the
            centre of the footprint on the ground), one per traversal that has one.
    """

    layout: StreetLayout
    static: GaussianModel
    categories: torch.Tensor
    vehicles: dict[str, GaussianModel]


def build_static(
    layout: StreetLayout, detail: Detail, rng: np.random.Generator
) -> tuple[GaussianModel, torch.Tensor]:
    """All static Gaussians of ``layout`` → ``(model, categories (N,))``."""
    parts: list[tuple[int, GaussianSoup]] = [
        (0, _ground(layout, detail, rng)),
        (1, _facades(layout, detail, rng)),
        (2, _street_objects(layout, detail, rng)),
        (3, _foliage(layout, detail, rng)),
        (4, _far_background(layout, detail, rng)),
        (5, _sky(layout, rng)),
    ]
    soup = GaussianSoup()
    categories = []
    for category, part in parts:
        soup.extend(part)
        categories.append(np.full(len(part), category, np.int64))
    return soup.to_model(), torch.from_numpy(np.concatenate(categories))


# ---------------------------------------------------------------------- ground
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


def _road_texture(layout: StreetLayout, rng: np.random.Generator, y0: float) -> Texture:
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


def _ground(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
    soup = GaussianSoup()
    road_tex = _road_texture(layout, rng, layout.road_right)
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


# ---------------------------------------------------------------------- buildings
def _facades(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
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


# ---------------------------------------------------------------------- street furniture and cars
def car_soup(
    car: Car, detail: Detail, rng: np.random.Generator, *, local: bool = False, skip_side: int = 0
) -> GaussianSoup:
    """A car as textured boxes, wheels and lights; in its own frame when ``local`` (origin at the footprint
    centre, x forward) else placed at ``(car.x, car.y)`` with ``car.yaw``.  ``skip_side`` = ±1 omits the
    left (+1) or right (−1) body faces (hidden against the curb)."""
    soup = GaussianSoup()
    center = np.zeros(3) if local else np.array([car.x, car.y, 0.0])
    yaw = 0.0 if local else car.yaw
    s = detail.spacing(np.array([car.x, car.y, 1.0]), 0.9)
    s = min(s, 0.6)
    body = np.asarray(car.color)
    clearance = 0.28
    body_h = 0.48 * car.height
    cabin_h = car.height - clearance - body_h
    seam = tx.noisy_color(rng, tuple(body), 0.03, 0.5)

    def body_side(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        rgb = seam(u, v)
        door_seam = (np.abs(u - 0.45 * car.length) < 0.03) | (np.abs(u - 0.7 * car.length) < 0.03)
        rgb = np.where(door_seam[:, None], rgb * 0.5, rgb)
        return np.where((v < 0.12)[:, None], rgb * 0.45, rgb)

    glass = np.array([0.12, 0.14, 0.17]) + rng.uniform(-0.03, 0.03)

    def cabin_side(u: np.ndarray, v: np.ndarray) -> np.ndarray:
        rgb = np.broadcast_to(glass, (u.shape[0], 3)).copy()
        pillar = (
            (u < 0.12)
            | (u > 0.55 * car.length - 0.12)
            | (np.abs(u - 0.27 * car.length) < 0.06)
            | (v > cabin_h - 0.06)
        )
        return np.where(pillar[:, None], body * 0.9, rgb)

    top = tx.solid(body * 1.05)
    c, sn = math.cos(yaw), math.sin(yaw)
    forward = np.array([c, sn, 0.0])
    left = np.array([-sn, c, 0.0])
    body_soup = GaussianSoup()
    body_soup.add_box(
        center + np.array([0, 0, clearance]),
        (car.length, car.width, body_h),
        yaw,
        s,
        {"side": body_side, "top": top, "front": seam, "back": seam},
    )
    cabin_center = center + forward * (-0.05 * car.length) + np.array([0, 0, clearance + body_h])
    body_soup.add_box(
        cabin_center,
        (0.55 * car.length, 0.9 * car.width, cabin_h),
        yaw,
        s,
        {"side": cabin_side, "top": top, "front": cabin_side, "back": cabin_side},
    )
    if skip_side:
        arr = body_soup.arrays()
        lateral = (arr["means"] - center) @ left
        keep = ~(lateral * skip_side > 0.4 * car.width)
        body_soup = GaussianSoup()
        body_soup.add(
            arr["means"][keep],
            arr["scales"][keep],
            arr["quats"][keep],
            arr["colors"][keep],
            arr["opacities"][keep],
        )
    soup.extend(body_soup)
    # wheels: dark vertical disks on both sides, lights on front and back
    for fx in (0.33, -0.33):
        for sy in (-1, 1):
            if skip_side and sy == skip_side:
                continue
            p = (
                center
                + forward * fx * car.length
                + left * sy * (car.width / 2 + 0.01)
                + np.array([0, 0, 0.33])
            )
            soup.add(
                p[None],
                np.array([0.2, 0.2, 0.03]),
                basis_quaternion(forward, np.array([0, 0, 1.0])),
                np.array([0.06, 0.06, 0.07]),
                0.99,
            )
    for sy in (-1, 1):
        front = (
            center
            + forward * (car.length / 2 + 0.01)
            + left * sy * 0.35 * car.width
            + np.array([0, 0, clearance + 0.6 * body_h])
        )
        back = (
            center
            - forward * (car.length / 2 + 0.01)
            + left * sy * 0.38 * car.width
            + np.array([0, 0, clearance + 0.7 * body_h])
        )
        soup.add(
            front[None],
            np.array([0.08, 0.08, 0.05]),
            np.array([1.0, 0, 0, 0]),
            np.array([0.95, 0.95, 0.85]),
            0.95,
        )
        soup.add(
            back[None], np.array([0.1, 0.1, 0.05]), np.array([1.0, 0, 0, 0]), np.array([0.8, 0.1, 0.08]), 0.95
        )
    return soup


def _street_objects(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
    soup = GaussianSoup()
    for car in layout.parked_cars:
        side = -1 if car.y < layout.lane_center(1) else 1
        soup.extend(car_soup(car, detail, rng, skip_side=side))
    metal = np.array([0.35, 0.36, 0.38])
    for pole in layout.poles:
        base = np.array([pole.x, pole.y, CURB_HEIGHT_M])
        soup.add_rod(base, 0.07, pole.height, metal, spacing=0.4)
        top = base + np.array([0, 0, pole.height])
        tip = top + np.array([0, pole.arm_direction * 1.6, 0.1])
        soup.add_segment(top, tip, 0.1, metal, normal=np.array([1.0, 0, 0]))
        soup.add(
            tip[None] - np.array([0, 0, 0.1]),
            np.array([0.25, 0.15, 0.08]),
            np.array([1.0, 0, 0, 0]),
            np.array([0.85, 0.85, 0.75]),
            0.95,
        )
        if pole.has_sign:
            sign_color = [(0.1, 0.25, 0.65), (0.75, 0.1, 0.1), (0.95, 0.95, 0.95)][int(rng.integers(3))]
            center = base + np.array([-0.1, 0, 2.6])
            soup.add_plane(
                center - np.array([0, 0.35, 0.35]),
                np.array([0, 1.0, 0]),
                np.array([0, 0, 1.0]),
                0.7,
                0.7,
                0.12,
                tx.solid(sign_color),
            )
    trunk = np.array([0.33, 0.25, 0.18])
    for tree in layout.trees:
        soup.add_rod(
            np.array([tree.x, tree.y, CURB_HEIGHT_M]), 0.13, tree.trunk_height + 0.8, trunk, spacing=0.4
        )
    return soup


def _foliage(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
    soup = GaussianSoup()
    for tree in layout.trees:
        base = np.array([tree.x, tree.y, CURB_HEIGHT_M + tree.trunk_height + tree.crown_radius * 0.7])
        far = detail.distance(base) > 25.0
        count = max(12, detail.foliage_count // (3 if far else 1))
        for _ in range(3):
            offset = rng.normal(0, 0.35, 3) * tree.crown_radius
            radii = tree.crown_radius * rng.uniform(0.7, 1.0, 3) * np.array([1.0, 1.0, 0.85])
            soup.add_blob(base + offset, radii, np.asarray(tree.crown_color), count, rng, blob_scale=0.55)
    return soup


# ---------------------------------------------------------------------- far background and sky
def _far_background(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
    """Distant towers beyond the end of the street (hazy, coarse)."""
    soup = GaussianSoup()
    haze = np.asarray(layout.sky_horizon)
    y_mid = 0.5 * (layout.facade_left + layout.facade_right)
    for _ in range(int(rng.integers(8, 14))):
        distance = float(rng.uniform(90, 220))
        y = y_mid + float(rng.uniform(-1.0, 1.0)) * distance * 0.9
        x = layout.x_max + distance * 0.6
        width, height = float(rng.uniform(15, 40)), float(rng.uniform(18, 70))
        mix = min(0.75, distance / 260.0)
        color = np.asarray([0.45, 0.45, 0.48]) * (1 + rng.uniform(-0.2, 0.2)) * (1 - mix) + haze * mix
        spacing = max(2.0, 1.2 * detail.pixels_per_gaussian * distance / detail.focal_px)
        soup.add_plane(
            np.array([x, y + width / 2, 0.0]),
            np.array([0, -1.0, 0]),
            np.array([0, 0, 1.0]),
            width,
            height,
            spacing,
            tx.noisy_color(rng, tuple(color), 0.04, 6.0),
        )
    return soup


def _sky(layout: StreetLayout, rng: np.random.Generator, step_deg: float = 6.0) -> GaussianSoup:
    """A dome of large Gaussians (gradient from horizon to zenith, soft clouds) around the street."""
    soup = GaussianSoup()
    center = np.array(
        [0.5 * (layout.x_min + layout.x_max), 0.5 * (layout.facade_left + layout.facade_right), 0.0]
    )
    clouds = tx.value_noise(rng, 18.0, (400.0, 120.0))
    horizon, zenith = np.asarray(layout.sky_horizon), np.asarray(layout.sky_zenith)
    step = math.radians(step_deg)
    means, colors, scales = [], [], []
    for elevation in np.arange(-0.1, math.pi / 2, step):
        ring = max(1, round(2 * math.pi * math.cos(elevation) / step))
        for k in range(ring):
            azimuth = -math.pi + 2 * math.pi * (k + 0.5) / ring
            direction = np.array(
                [
                    math.cos(elevation) * math.cos(azimuth),
                    math.cos(elevation) * math.sin(azimuth),
                    math.sin(elevation),
                ]
            )
            means.append(center + SKY_RADIUS_M * direction)
            f = max(0.0, math.sin(elevation)) ** 0.6
            rgb = horizon * (1 - f) + zenith * f
            cloud = float(
                clouds(np.array([math.degrees(azimuth) + 180.0]), np.array([math.degrees(elevation) + 10]))[
                    0, 0
                ]
            )
            rgb = rgb + max(0.0, cloud - 0.25) * 0.6 * (np.array([0.97, 0.97, 0.98]) - rgb)
            colors.append(rgb)
            scales.append(0.75 * SKY_RADIUS_M * step)
    means_arr = np.asarray(means)
    size = np.asarray(scales)[:, None] * np.ones((1, 3))
    soup.add(means_arr, size, np.array([1.0, 0, 0, 0]), np.asarray(colors), 0.995)
    return soup
