"""The handheld walk of a sparse-view scene: one camera on an arc around the plaza's centre, looking
inwards, with a heading sweep, varying height and pitch and handheld shake (:func:`random_walk`), and
the pinhole camera of each frame (:func:`walk_camera`).

Positions are metres in the world frame (z up); angles radians.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at
from setdiff_bench.synthetic.layout import StreetLayout
from setdiff_bench.synthetic.rig import intrinsics
from setdiff_bench.synthetic.sparse._names import frame_file
from setdiff_bench.synthetic.sparse._preset import SparsePreset


@dataclass(frozen=True)
class Walk:
    """The handheld path, one row per frame.

    Attributes:
        positions: ``(N, 3)`` camera centres (metres, world frame, z up).
        headings: ``(N,)`` yaw about +z (radians, 0 = along +x).
        pitches: ``(N,)`` radians (negative = looking down).
        center: ``(2,)`` the plaza centre the walk goes around (x, y metres).
    """

    positions: np.ndarray
    headings: np.ndarray
    pitches: np.ndarray
    center: np.ndarray


def random_walk(preset: SparsePreset, layout: StreetLayout, rng: np.random.Generator) -> Walk:
    """A walk around the plaza's centre ``(0, road middle)`` looking inwards (module docstring).

    The path is an arc of ``arc_deg`` (±10 %) of an ellipse with semi-axes ``radius_m`` × 1.1-1.5 along
    the street and ``radius_m`` × 0.85-1 across it (at most the roadway's half width − 1 m), at an uneven
    pace and a radius that breathes by ±8 %; the heading points at the centre (away from it with
    ``outward``), swept by ``sweep_deg`` over ``sweep_period`` frames, with handheld shake (±1.5° and 0.3°
    noise); height 1.55 ± 0.2 m (+1 cm noise), pitch ``pitch_deg`` ± 5°.  With ``strafe_m`` > 0 the walk
    instead goes ``strafe_m`` metres straight along one side of the roadway, looking across it.
    """
    n = preset.frames
    i = np.arange(n, dtype=np.float64)
    s = i / max(n - 1, 1)
    center = np.array([0.0, 0.5 * (layout.road_right + layout.road_left)])
    half_road = 0.5 * (layout.road_left - layout.road_right)
    ry = min(preset.radius_m * rng.uniform(0.85, 1.0), half_road - 1.0)
    rx = preset.radius_m * rng.uniform(1.1, 1.5)
    direction = float(rng.choice([-1.0, 1.0]))
    arc = math.radians(preset.arc_deg * rng.uniform(0.9, 1.1))
    pace = s + 0.03 * np.sin(2 * math.pi * s * rng.uniform(1.0, 2.0) + rng.uniform(0, 2 * math.pi))
    angle = rng.uniform(0, 2 * math.pi) + direction * arc * pace
    breathe = 1.0 + 0.08 * np.sin(2 * math.pi * s * rng.uniform(0.7, 1.5) + rng.uniform(0, 2 * math.pi))
    x = center[0] + rx * breathe * np.cos(angle)
    y = center[1] + ry * breathe * np.sin(angle)
    look = np.arctan2(center[1] - y, center[0] - x) + (math.pi if preset.outward else 0.0)
    if preset.strafe_m > 0:
        side = float(rng.choice([-1.0, 1.0]))  # +1: walk along the right curb looking left (+y)
        x = center[0] + direction * preset.strafe_m * (pace - 0.5)
        edge = layout.road_right + 1.2 if side > 0 else layout.road_left - 1.2
        y = edge + side * 0.6 * (breathe - 1.0) / 0.08
        look = np.full(n, side * math.pi / 2)
    period = preset.sweep_period * rng.uniform(0.9, 1.1)
    sweep = math.radians(rng.uniform(*preset.sweep_deg)) * np.sin(
        2 * math.pi * i / period + rng.uniform(0, 2 * math.pi)
    )
    shake = math.radians(1.5) * np.sin(2 * math.pi * i / (0.23 * period) + rng.uniform(0, 2 * math.pi))
    heading = look + sweep + shake + math.radians(0.3) * rng.standard_normal(n)
    height = 1.55 + 0.2 * np.sin(2 * math.pi * i / (1.3 * period) + rng.uniform(0, 2 * math.pi))
    height = height + 0.01 * rng.standard_normal(n)
    pitch = np.radians(
        preset.pitch_deg + 5.0 * np.sin(2 * math.pi * i / (0.8 * period) + rng.uniform(0, 2 * math.pi))
    )
    pitch = pitch + math.radians(0.3) * rng.standard_normal(n)
    return Walk(np.stack([x, y, height], axis=1), heading, pitch, center)


def walk_camera(walk: Walk, index: int, preset: SparsePreset) -> Camera:
    """The pinhole camera of frame ``index`` at the preset's image size (OpenCV axes, world-to-camera)."""
    center = walk.positions[index]
    yaw, pitch = float(walk.headings[index]), float(walk.pitches[index])
    direction = np.array([math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)])
    fx, fy, cx, cy = intrinsics(preset.width, preset.height, preset.hfov_deg)
    return Camera(
        intrinsics_matrix(fx, fy, cx, cy),
        look_at(center, center + direction),
        preset.width,
        preset.height,
        source=frame_file(index),
    )
