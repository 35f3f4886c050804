"""A growable set of 3D Gaussians built from geometric primitives (planes, boxes, cylinders, blobs).

The procedural world is assembled here in float64 numpy (activated values: standard deviations in
metres, unit quaternions ``w, x, y, z``, colours in [0, 1], opacities in (0, 1)) and converted once
to a :class:`~setdiff_bench.gaussians.model.GaussianModel` (degree-0 SH, pre-activation storage).

Surfaces are tiled by flat Gaussians: a planar patch becomes a grid of disks whose in-plane standard
deviation is ``overlap × spacing`` (neighbours overlap, so the surface looks continuous and opaque)
and whose normal standard deviation is a few millimetres.  Colour comes from a texture function
evaluated at each disk centre, so texture detail is limited by the spacing.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.sh import rgb_to_sh_dc
from setdiff_bench.rotations import matrix_to_quaternion

Texture = Callable[[np.ndarray, np.ndarray], np.ndarray]
"""``texture(u, v) -> rgb``: ``(P,)`` metres along the patch axes → ``(P, 3)`` colours in [0, 1]."""

MAX_OPACITY = 0.995
SURFACE_THICKNESS_M = 0.01
DISK_OVERLAP = 0.6


def basis_quaternion(u_axis: np.ndarray, v_axis: np.ndarray) -> np.ndarray:
    """Unit quaternion ``(4,)`` ``w, x, y, z`` of the rotation whose columns are ``u, v, u×v``."""
    u = np.asarray(u_axis, np.float64)
    u = u / np.linalg.norm(u)
    v = np.asarray(v_axis, np.float64)
    v = v - u * (u @ v)
    v = v / np.linalg.norm(v)
    return matrix_to_quaternion(np.stack([u, v, np.cross(u, v)], axis=1), order="wxyz")


def yaw_quaternion(yaw: float) -> np.ndarray:
    """Unit quaternion ``w, x, y, z`` of a rotation by ``yaw`` radians about world +z."""
    return np.array([math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)])


def quaternion_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of ``(..., 4)`` quaternions ``w, x, y, z`` (``a ∘ b`` = rotate by b, then a)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, np.float64), -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


@dataclass
class GaussianSoup:
    """Activated Gaussian parameters accumulated primitive by primitive (numpy, float64)."""

    means: list[np.ndarray] = field(default_factory=list)
    scales: list[np.ndarray] = field(default_factory=list)
    quats: list[np.ndarray] = field(default_factory=list)
    colors: list[np.ndarray] = field(default_factory=list)
    opacities: list[np.ndarray] = field(default_factory=list)

    def __len__(self) -> int:
        return int(sum(m.shape[0] for m in self.means))

    # ------------------------------------------------------------------ raw append
    def add(
        self,
        means: np.ndarray,
        scales: np.ndarray,
        quats: np.ndarray,
        colors: np.ndarray,
        opacities: np.ndarray | float,
    ) -> None:
        """Append ``P`` Gaussians: means ``(P, 3)`` m, std devs ``(P, 3)`` m, quats ``(P, 4)`` or ``(4,)``,
        colours ``(P, 3)`` or ``(3,)`` in [0, 1], opacities ``(P,)`` or scalar in (0, 1)."""
        means = np.asarray(means, np.float64).reshape(-1, 3)
        p = means.shape[0]
        if p == 0:
            return
        self.means.append(means)
        self.scales.append(np.broadcast_to(np.asarray(scales, np.float64), (p, 3)).copy())
        self.quats.append(np.broadcast_to(np.asarray(quats, np.float64), (p, 4)).copy())
        self.colors.append(np.clip(np.broadcast_to(np.asarray(colors, np.float64), (p, 3)), 0.0, 1.0).copy())
        self.opacities.append(
            np.clip(np.broadcast_to(np.asarray(opacities, np.float64), (p,)), 1e-3, MAX_OPACITY).copy()
        )

    def extend(self, other: GaussianSoup) -> None:
        for name in ("means", "scales", "quats", "colors", "opacities"):
            getattr(self, name).extend(getattr(other, name))

    # ------------------------------------------------------------------ primitives
    def add_plane(
        self,
        origin: np.ndarray,
        u_axis: np.ndarray,
        v_axis: np.ndarray,
        size_u: float,
        size_v: float,
        spacing: float,
        texture: Texture,
        *,
        opacity: float = MAX_OPACITY,
        thickness: float = SURFACE_THICKNESS_M,
    ) -> None:
        """Tile the rectangle ``origin + u·û + v·v̂`` (``0 ≤ u ≤ size_u``, ``0 ≤ v ≤ size_v``) with flat disks.

        Args:
            origin: ``(3,)`` corner in world metres.  u_axis, v_axis: ``(3,)`` orthogonal directions.
            size_u, size_v: extents in metres.  spacing: grid step in metres (≥ 1 cm).
            texture: colour at ``(u, v)``.  thickness: standard deviation along the normal.
        """
        u_hat = np.asarray(u_axis, np.float64) / np.linalg.norm(u_axis)
        v_hat = np.asarray(v_axis, np.float64) / np.linalg.norm(v_axis)
        nu = max(1, round(size_u / spacing))
        nv = max(1, round(size_v / spacing))
        su, sv = size_u / nu, size_v / nv
        uu, vv = np.meshgrid((np.arange(nu) + 0.5) * su, (np.arange(nv) + 0.5) * sv, indexing="xy")
        u, v = uu.reshape(-1), vv.reshape(-1)
        means = np.asarray(origin, np.float64) + u[:, None] * u_hat + v[:, None] * v_hat
        scales = np.array([DISK_OVERLAP * su, DISK_OVERLAP * sv, thickness])
        self.add(means, scales, basis_quaternion(u_hat, v_hat), texture(u, v), opacity)

    def add_box(
        self,
        center: np.ndarray,
        size: tuple[float, float, float],
        yaw: float,
        spacing: float,
        textures: dict[str, Texture],
        *,
        bottom: bool = False,
    ) -> None:
        """An axis-aligned (after ``yaw`` about +z) box's faces as textured planes.

        Args:
            center: ``(3,)`` centre of the box's bottom face.  size: ``(length, width, height)`` in metres
                along the box's local x, y, z.  textures: ``"side"``, ``"top"`` (and optionally ``"front"``,
                ``"back"``) → texture; local ``u`` runs along the face, ``v`` upward.
        """
        length, width, height = size
        c, s = math.cos(yaw), math.sin(yaw)
        ex, ey, ez = np.array([c, s, 0.0]), np.array([-s, c, 0.0]), np.array([0.0, 0.0, 1.0])
        base = np.asarray(center, np.float64)
        side = textures["side"]
        faces = [
            (base - ex * length / 2 - ey * width / 2, ex, ez, length, height, side),  # right (-y)
            (base + ex * length / 2 + ey * width / 2, -ex, ez, length, height, side),  # left (+y)
            (base + ex * length / 2 - ey * width / 2, ey, ez, width, height, textures.get("front", side)),
            (base - ex * length / 2 + ey * width / 2, -ey, ez, width, height, textures.get("back", side)),
            (base - ex * length / 2 - ey * width / 2 + ez * height, ex, ey, length, width, textures["top"]),
        ]
        if bottom:
            faces.append((base - ex * length / 2 - ey * width / 2, ex, ey, length, width, textures["top"]))
        for origin, u_axis, v_axis, su, sv, tex in faces:
            self.add_plane(origin, u_axis, v_axis, su, sv, spacing, tex)

    def add_rod(
        self, base: np.ndarray, radius: float, height: float, color: np.ndarray, *, spacing: float = 0.5
    ) -> None:
        """A thin vertical cylinder (pole, trunk) as one column of Gaussians elongated along +z, round
        in cross-section (standard deviation ``radius``), so it looks the same from every side."""
        n_z = max(1, round(height / spacing))
        dz = height / n_z
        zs = (np.arange(n_z) + 0.5) * dz
        means = np.asarray(base, np.float64) + np.stack([np.zeros_like(zs), np.zeros_like(zs), zs], axis=1)
        self.add(
            means,
            np.array([radius, radius, DISK_OVERLAP * dz]),
            np.array([1.0, 0.0, 0.0, 0.0]),
            color,
            MAX_OPACITY,
        )

    def add_segment(
        self,
        start: np.ndarray,
        end: np.ndarray,
        width: float,
        color: np.ndarray,
        *,
        normal: np.ndarray = (0.0, 0.0, 1.0),
        opacity: float = MAX_OPACITY,
        max_aspect: float = 8.0,
    ) -> None:
        """A painted strip from ``start`` to ``end`` (``width`` metres across, lying in the plane ⟂ ``normal``),
        as elongated disks with aspect ratio at most ``max_aspect``."""
        start, end = np.asarray(start, np.float64), np.asarray(end, np.float64)
        direction = end - start
        length = float(np.linalg.norm(direction))
        if length <= 0:
            return
        u_hat = direction / length
        n_hat = np.asarray(normal, np.float64)
        v_hat = np.cross(n_hat, u_hat)
        v_hat /= np.linalg.norm(v_hat)
        pieces = max(1, math.ceil(length / (max_aspect * width)))
        step = length / pieces
        centres = start + ((np.arange(pieces) + 0.5) * step)[:, None] * u_hat
        scales = np.array([0.5 * step, 0.35 * width, SURFACE_THICKNESS_M])
        self.add(centres, scales, basis_quaternion(u_hat, v_hat), color, opacity)

    def add_blob(
        self,
        center: np.ndarray,
        radii: np.ndarray,
        color: np.ndarray,
        count: int,
        rng: np.random.Generator,
        *,
        color_jitter: float = 0.08,
        blob_scale: float = 0.35,
        opacity: float = 0.9,
    ) -> None:
        """A fuzzy ellipsoid (foliage, bushes): ``count`` isotropic Gaussians uniform in the ellipsoid ``radii``."""
        directions = rng.normal(size=(count, 3))
        directions /= np.linalg.norm(directions, axis=1, keepdims=True)
        radius = rng.uniform(0.0, 1.0, size=(count, 1)) ** (1 / 3)
        means = np.asarray(center, np.float64) + directions * radius * np.asarray(radii, np.float64)
        colors = np.asarray(color, np.float64) * (1.0 + rng.normal(0.0, color_jitter, size=(count, 1)))
        colors = colors + rng.normal(0.0, color_jitter / 3, size=(count, 3))
        size = blob_scale * float(np.mean(radii)) / max(count, 1) ** (1 / 3) * 2.0
        scales = np.full((count, 3), size) * rng.uniform(0.7, 1.3, size=(count, 1))
        self.add(means, scales, np.array([1.0, 0.0, 0.0, 0.0]), colors, opacity)

    # ------------------------------------------------------------------ conversion
    def arrays(self) -> dict[str, np.ndarray]:
        """Concatenated ``means (N, 3)``, ``scales (N, 3)``, ``quats (N, 4)``, ``colors (N, 3)``, ``opacities (N,)``."""
        if not self.means:
            return {
                "means": np.zeros((0, 3)),
                "scales": np.zeros((0, 3)),
                "quats": np.zeros((0, 4)),
                "colors": np.zeros((0, 3)),
                "opacities": np.zeros((0,)),
            }
        return {
            name: np.concatenate(getattr(self, name))
            for name in ("means", "scales", "quats", "colors", "opacities")
        }

    def to_model(self) -> GaussianModel:
        """A float32 degree-0 :class:`GaussianModel` (log-scales, opacity logits, SH DC from colour)."""
        a = self.arrays()
        opacity = np.clip(a["opacities"], 1e-4, MAX_OPACITY)
        rgb = torch.from_numpy(a["colors"]).float()
        return GaussianModel(
            means=torch.from_numpy(a["means"]).float(),
            quats=torch.from_numpy(a["quats"]).float(),
            log_scales=torch.from_numpy(np.log(np.maximum(a["scales"], 1e-5))).float(),
            opacity_logits=torch.from_numpy(np.log(opacity / (1.0 - opacity))).float(),
            sh=rgb_to_sh_dc(rgb)[:, None, :].contiguous(),
        )
