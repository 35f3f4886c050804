"""Novel trajectories: camera paths away from the recorded one, for frames that have no ground truth.

A trajectory spec (``--trajectory``) is one of:

``shift:N``
    every recorded camera moved ``N`` metres (scene units) along its own right axis (OpenCV +x; for a
    forward-facing driving camera, the lateral direction: ``shift:3`` is ReconDreamer's 3 m lane
    shift to the right, ``shift:-3`` to the left); orientation unchanged.
``yaw:D``
    every recorded camera turned ``D`` degrees about its own vertical axis (OpenCV +y, pointing down),
    centre unchanged: positive turns right, clockwise seen from above.
``FILE.json``
    a list of poses, each ``{"name": str, "c2w": 4×4}`` (OpenCV camera-to-world, scene units) with
    optional ``"K"`` (3×3 pixels), ``"width"``, ``"height"``; poses without them take the first
    recorded camera's intrinsics and size.  A top-level ``{"poses": [...]}`` is accepted too.

Every novel camera must lie inside the scene's bounds: the box between the 1st and 99th percentile
of the fit's Gaussian centres per axis (floaters excluded), joined with the recorded camera centres,
grown by :data:`BOUNDS_MARGIN` of its size on each side.  A camera outside — a shift that leaves the scene — is refused, as are a
non-rigid pose (rotation not orthonormal, or a reflection), NaN / infinite values and a malformed
file: one line naming the spec or file and the problem, before anything is rendered or written.
"""

from __future__ import annotations

import json
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError

#: The bounds box is grown by this fraction of its size on each side.
BOUNDS_MARGIN = 0.05
#: Percentiles of the Gaussian centres that bound the scene (per axis).
BOUNDS_PERCENTILES = (1.0, 99.0)
_NUMBER = r"[-+]?(?:\d+(?:\.\d*)?|\.\d+)(?:[eE][-+]?\d+)?"


@dataclass(frozen=True)
class TrajectorySpec:
    """A parsed ``--trajectory``.

    Attributes:
        kind: ``shift`` (metres right), ``yaw`` (degrees right) or ``poses`` (a JSON file).
        value: the shift in scene units or the yaw in degrees (0 for ``poses``).
        path: the JSON file (``poses`` only).
    """

    kind: Literal["shift", "yaw", "poses"]
    value: float = 0.0
    path: Path | None = None

    @property
    def label(self) -> str:
        """A short name for folders and groups: ``shift+3m``, ``yaw-10deg``, ``poses-<file stem>``."""
        if self.kind == "shift":
            return f"shift{self.value:+g}m"
        if self.kind == "yaw":
            return f"yaw{self.value:+g}deg"
        return f"poses-{self.path.stem if self.path else ''}"


def parse_trajectory(text: str, option: str = "--trajectory") -> TrajectorySpec:
    """Parse ``shift:N``, ``yaw:D`` or a ``.json`` path (module docstring).

    Raises:
        UsageError: another form, a value that is not a finite number, or a JSON file that does not exist.
    """
    spec = text.strip()
    match = re.fullmatch(rf"(shift|yaw):({_NUMBER})", spec)
    if match:
        value = float(match.group(2))
        if not math.isfinite(value):
            raise UsageError(f"{match.group(1)} must be a finite number, got {match.group(2)!r}", option)
        return TrajectorySpec(match.group(1), value)  # type: ignore[arg-type]
    if spec.lower().endswith(".json"):
        path = Path(spec).expanduser()
        if not path.is_file():
            raise UsageError("trajectory file not found", path)
        return TrajectorySpec("poses", 0.0, path)
    raise UsageError(
        f"unknown trajectory {text!r}; use shift:METRES, yaw:DEGREES or a JSON file of poses", option
    )


def shifted(camera: Camera, metres: float) -> Camera:
    """``camera`` moved ``metres`` along its right axis (OpenCV +x), orientation unchanged."""
    right = camera.R[0]  # world direction of the camera's x axis: the first row of the world-to-camera R
    c2w = np.eye(4)
    c2w[:3, :3] = camera.R.T
    c2w[:3, 3] = camera.center + metres * right
    return Camera.from_c2w(c2w, camera.K, camera.width, camera.height, distortion=camera.distortion)


def yawed(camera: Camera, degrees: float) -> Camera:
    """``camera`` turned ``degrees`` about its own vertical (OpenCV +y) axis; positive turns right."""
    angle = math.radians(degrees)
    turn = np.array(
        [[math.cos(angle), 0.0, math.sin(angle)], [0.0, 1.0, 0.0], [-math.sin(angle), 0.0, math.cos(angle)]]
    )
    c2w = np.eye(4)
    c2w[:3, :3] = camera.R.T @ turn
    c2w[:3, 3] = camera.center
    return Camera.from_c2w(c2w, camera.K, camera.width, camera.height, distortion=camera.distortion)


def _pose_cameras(path: Path, template: Camera) -> list[tuple[str, Camera]]:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise UsageError(f"unreadable trajectory file ({type(error).__name__}: {error})", path) from None
    poses = data.get("poses") if isinstance(data, dict) else data
    if not isinstance(poses, list) or not poses:
        raise UsageError('expected a non-empty JSON list of poses (or {"poses": [...]})', path)
    out: list[tuple[str, Camera]] = []
    for i, pose in enumerate(poses):
        where = f"{path} (pose {i})"
        if not isinstance(pose, dict) or "c2w" not in pose:
            raise UsageError(f"pose {i} must be an object with a 'c2w' 4x4 matrix", path)
        name = str(pose.get("name", f"pose_{i:04d}"))
        try:
            c2w = np.asarray(pose["c2w"], dtype=np.float64)
            K = np.asarray(pose.get("K", template.K), dtype=np.float64)
        except (TypeError, ValueError):
            raise UsageError(f"pose {i}: 'c2w' and 'K' must be numeric matrices", path) from None
        width, height = pose.get("width", template.width), pose.get("height", template.height)
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (width, height)):
            raise UsageError(f"pose {i}: width and height must be integers", path)
        out.append((name, Camera.from_c2w(c2w, K, width, height, source=where)))
    names = [name for name, _ in out]
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise UsageError(f"duplicate pose name {duplicates[0]!r}", path)
    return out


def novel_cameras(spec: TrajectorySpec, recorded: Sequence[tuple[str, Camera]]) -> list[tuple[str, Camera]]:
    """The trajectory's ``(name, camera)`` list: the recorded cameras moved (``shift``, ``yaw``; named
    ``<recorded name>@<label>``) or the file's poses.

    Raises:
        UsageError: no recorded camera to start from, or a malformed pose file.
        CameraError: a non-rigid pose or NaN / infinite values (naming the file and the pose).
    """
    if not recorded:
        raise UsageError("no recorded cameras to build the trajectory from", "--trajectory")
    if spec.kind == "poses":
        assert spec.path is not None
        return _pose_cameras(spec.path, recorded[0][1])
    move = shifted if spec.kind == "shift" else yawed
    return [(f"{name}@{spec.label}", move(camera, spec.value)) for name, camera in recorded]


def scene_bounds(
    points: np.ndarray, recorded_centres: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``(low, high)`` corners of the scene box: the 1st–99th percentile of ``(N, 3)`` points per axis
    (the fit's Gaussian centres), joined with the recorded camera centres ``(C, 3)`` (a capture's cameras
    may stand outside the reconstructed bulk), grown by :data:`BOUNDS_MARGIN` of the box size on each side.

    Raises:
        UsageError: fewer than 2 finite points.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) < 2:
        raise UsageError("the fit has fewer than 2 Gaussians: no scene bounds to check a trajectory against")
    low, high = np.percentile(points, BOUNDS_PERCENTILES, axis=0)
    if recorded_centres is not None and len(recorded_centres):
        centres = np.asarray(recorded_centres, dtype=np.float64).reshape(-1, 3)
        low, high = np.minimum(low, centres.min(axis=0)), np.maximum(high, centres.max(axis=0))
    margin = BOUNDS_MARGIN * (high - low)
    return low - margin, high + margin


def check_within_bounds(
    cameras: Sequence[tuple[str, Camera]], bounds: tuple[np.ndarray, np.ndarray], what: str
) -> None:
    """Refuse the trajectory when a camera centre lies outside ``bounds`` (:func:`scene_bounds`).

    Raises:
        UsageError: naming the first camera outside, its centre and the box; ``what`` names the spec.
    """
    low, high = bounds
    outside = [
        (name, camera.center)
        for name, camera in cameras
        if (camera.center < low).any() or (camera.center > high).any()
    ]
    if outside:
        name, centre = outside[0]
        fmt = lambda v: "(" + ", ".join(f"{x:.2f}" for x in v) + ")"  # noqa: E731
        raise UsageError(
            f"{len(outside)} of {len(cameras)} cameras leave the scene bounds {fmt(low)}–{fmt(high)} "
            f"(the fit's Gaussian centres, 1st–99th percentile, and the recorded cameras, + {BOUNDS_MARGIN:.0%}); "
            f"first {name!r} at "
            f"{fmt(centre)}",
            what,
        )
