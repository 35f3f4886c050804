"""The far background and sky of the street world as Gaussians: hazy distant towers beyond the end of the
street and a dome of large Gaussians (horizon-to-zenith gradient, soft clouds) ``SKY_RADIUS_M`` around it.

Coordinates are metres in the world frame (x along the street, y left, z up).
"""

from __future__ import annotations

import math

import numpy as np

from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.layout import StreetLayout
from setdiff_bench.synthetic.soup import GaussianSoup
from setdiff_bench.synthetic.world._detail import Detail

SKY_RADIUS_M = 400.0


def far_background_soup(layout: StreetLayout, detail: Detail, rng: np.random.Generator) -> GaussianSoup:
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


def sky_soup(layout: StreetLayout, rng: np.random.Generator, step_deg: float = 6.0) -> GaussianSoup:
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
