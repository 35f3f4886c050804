"""Drives and the camera rig: per-timestep ego poses of each traversal and the three cameras on the car.

Each traversal is a separate drive of the same street at 10 Hz.  ``lane0`` (the training drive),
``lane1`` and ``lane2`` follow lane centres 0, 1 and 2 (lateral shifts of 0, 3.5 and 7 m); ``turn``
changes from lane 0 to lane 1 or 2 mid-drive, its heading following the path (EUVS level-3-like).
Small seeded jitter (start position, lateral offset, camera height) makes the drives distinct.
Cameras share the car's position and differ in yaw; OpenCV axes, world-to-camera, via ``look_at``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at

FRAME_RATE_HZ = 10
CAMERA_HEIGHT_M = 1.6
CAMERA_PITCH_DEG = -2.0


@dataclass(frozen=True)
class CameraSpec:
    """A camera on the car: ``yaw_deg`` relative to the driving direction (positive = left)."""

    name: str
    yaw_deg: float


RIG = (CameraSpec("front", 0.0), CameraSpec("front_left", 45.0), CameraSpec("front_right", -45.0))


@dataclass(frozen=True)
class Traversal:
    """One drive.

    Attributes:
        name: ``lane0`` / ``lane1`` / ``lane2`` / ``turn``.
        kind: ``"straight"`` or ``"lane_change"``.
        lane_offset: lateral shift in lanes from ``lane0``; ``None`` for the lane change.
        poses: ``(T, 3)`` ego ``x, y`` (metres) and heading (radians about +z) per timestep.
        camera_height: metres above the road.
    """

    name: str
    kind: str
    lane_offset: int | None
    poses: np.ndarray
    camera_height: float

    @property
    def num_steps(self) -> int:
        return int(self.poses.shape[0])


def timestamp_us(index: int) -> int:
    """Integer microseconds of timestep ``index`` at 10 Hz."""
    return index * (1_000_000 // FRAME_RATE_HZ)


def straight_drive(
    name: str, lane: int, lane_width: float, steps: int, step_m: float, rng: np.random.Generator
) -> Traversal:
    """A drive along lane ``lane`` with slight lateral wander (±10 cm) and start jitter (±30 cm)."""
    x = float(rng.uniform(-0.3, 0.3)) + step_m * np.arange(steps)
    wander = 0.1 * np.sin(
        2 * math.pi * (np.arange(steps) / max(steps, 2)) * float(rng.uniform(0.3, 0.8))
        + float(rng.uniform(0, 2 * math.pi))
    )
    y = lane * lane_width + wander
    heading = np.arctan2(np.gradient(y), step_m) if steps > 1 else np.zeros(steps)
    return _traversal(name, "straight", lane, x, y, heading, rng)


def lane_change_drive(
    name: str, lane_width: float, steps: int, step_m: float, rng: np.random.Generator
) -> Traversal:
    """A drive from lane 0 to lane 1 or 2: a smoothstep in y between 15 % and 85 % of the drive."""
    target = int(rng.choice([1, 2]))
    x = float(rng.uniform(-0.3, 0.3)) + step_m * np.arange(steps)
    span = max(x[-1] - x[0], 1e-6)
    start, stop = x[0] + 0.15 * span, x[0] + 0.85 * span
    f = np.clip((x - start) / (stop - start), 0.0, 1.0)
    y = target * lane_width * f * f * (3 - 2 * f)
    dydx = target * lane_width * 6 * f * (1 - f) / (stop - start)
    heading = np.arctan(dydx)
    return _traversal(name, "lane_change", None, x, y, heading, rng)


def _traversal(
    name: str,
    kind: str,
    lane_offset: int | None,
    x: np.ndarray,
    y: np.ndarray,
    heading: np.ndarray,
    rng: np.random.Generator,
) -> Traversal:
    """A :class:`Traversal` of the ego path ``(x, y, heading)``; draws the camera height's jitter (±3 cm)."""
    return Traversal(
        name,
        kind,
        lane_offset,
        np.stack([x, y, heading], axis=1),
        CAMERA_HEIGHT_M + float(rng.uniform(-0.03, 0.03)),
    )


def intrinsics(width: int, height: int, hfov_deg: float = 90.0) -> tuple[float, float, float, float]:
    """``(fx, fy, cx, cy)`` of a square-pixel pinhole with the horizontal field of view ``hfov_deg``."""
    fx = round(width / 2 / math.tan(math.radians(hfov_deg) / 2), 9)
    return fx, fx, width / 2, height / 2


def rig_camera(traversal: Traversal, step: int, spec: CameraSpec, width: int, height: int) -> Camera:
    """The camera ``spec`` of ``traversal`` at timestep ``step``."""
    x, y, heading = (float(v) for v in traversal.poses[step])
    yaw = heading + math.radians(spec.yaw_deg)
    pitch = math.radians(CAMERA_PITCH_DEG)
    center = np.array([x, y, traversal.camera_height])
    direction = np.array([math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)])
    fx, fy, cx, cy = intrinsics(width, height)
    return Camera(
        intrinsics_matrix(fx, fy, cx, cy),
        look_at(center, center + direction),
        width,
        height,
        source=f"{traversal.name}_{spec.name}_{step:03d}",
    )
