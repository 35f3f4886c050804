"""Intrinsics: the pinhole matrix ``K`` and lens distortion (COLMAP camera models, OpenCV radial-tangential).

``K`` is ``(3, 3)`` in pixels, ``[[fx, s, cx], [0, fy, cy], [0, 0, 1]]``, pixel centres at +0.5.  Distortion
acts on normalised image-plane coordinates ``(x/z, y/z)``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from setdiff_bench.errors import CameraError


@dataclass(frozen=True)
class Distortion:
    """Lens distortion kept on a camera; ``model`` follows COLMAP names (``OPENCV``: k1 k2 p1 p2)."""

    model: str
    params: tuple[float, ...]

    def is_zero(self) -> bool:
        return all(abs(p) == 0.0 for p in self.params)


def intrinsics_matrix(fx: float, fy: float, cx: float, cy: float) -> np.ndarray:
    """``(3, 3)`` pinhole K."""
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def intrinsics_from_colmap(
    model: str, params: Sequence[float], *, source: str = ""
) -> tuple[np.ndarray, Distortion | None]:
    """COLMAP camera model + params → ``(K, distortion)``.

    Supported: SIMPLE_PINHOLE (f cx cy), PINHOLE (fx fy cx cy), SIMPLE_RADIAL (f cx cy k),
    RADIAL (f cx cy k1 k2), OPENCV (fx fy cx cy k1 k2 p1 p2).
    """
    p = [float(v) for v in params]
    counts = {"SIMPLE_PINHOLE": 3, "PINHOLE": 4, "SIMPLE_RADIAL": 4, "RADIAL": 5, "OPENCV": 8}
    if model not in counts:
        raise CameraError(
            f"unsupported COLMAP camera model {model}; supported: {', '.join(counts)}", source or "camera"
        )
    if len(p) != counts[model]:
        raise CameraError(f"{model} needs {counts[model]} parameters, got {len(p)}", source or "camera")
    if model == "SIMPLE_PINHOLE":
        return intrinsics_matrix(p[0], p[0], p[1], p[2]), None
    if model == "PINHOLE":
        return intrinsics_matrix(*p), None
    if model == "SIMPLE_RADIAL":
        return intrinsics_matrix(p[0], p[0], p[1], p[2]), Distortion("OPENCV", (p[3], 0.0, 0.0, 0.0))
    if model == "RADIAL":
        return intrinsics_matrix(p[0], p[0], p[1], p[2]), Distortion("OPENCV", (p[3], p[4], 0.0, 0.0))
    return intrinsics_matrix(*p[:4]), Distortion("OPENCV", tuple(p[4:8]))


def apply_distortion(distortion: Distortion, xn: np.ndarray, yn: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV radial-tangential distortion (k1 k2 p1 p2) of normalised coordinates."""
    k1, k2, p1, p2 = (list(distortion.params) + [0.0] * 4)[:4]
    r2 = xn * xn + yn * yn
    radial = 1.0 + k1 * r2 + k2 * r2 * r2
    xd = xn * radial + 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
    yd = yn * radial + p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
    return xd, yd


def invert_distortion(
    distortion: Distortion, xd: np.ndarray, yd: np.ndarray, iterations: int = 20
) -> tuple[np.ndarray, np.ndarray]:
    """Undo :func:`apply_distortion` by fixed-point iteration (as OpenCV's ``undistortPoints``)."""
    k1, k2, p1, p2 = (list(distortion.params) + [0.0] * 4)[:4]
    xn, yn = xd.copy(), yd.copy()
    for _ in range(iterations):
        r2 = xn * xn + yn * yn
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        dx = 2 * p1 * xn * yn + p2 * (r2 + 2 * xn * xn)
        dy = p1 * (r2 + 2 * yn * yn) + 2 * p2 * xn * yn
        xn = (xd - dx) / radial
        yn = (yd - dy) / radial
    return xn, yn
