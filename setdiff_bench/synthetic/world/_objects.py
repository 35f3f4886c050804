"""Objects of the street world as Gaussians: cars (parked, or as templates of moving vehicles in their own
frame), lamp poles with signs, tree trunks and the foliage of the tree crowns.

Coordinates are metres in the world frame (x along the street, y left, z up), or a car's own frame
(x forward, y left, z up, origin at the centre of its footprint on the ground).
"""

from __future__ import annotations

import math

import numpy as np

from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.layout import CURB_HEIGHT_M, Car, StreetLayout
from setdiff_bench.synthetic.soup import GaussianSoup, basis_quaternion
from setdiff_bench.synthetic.world._detail import Detail


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


def street_object_soup(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
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


def foliage_soup(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
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
