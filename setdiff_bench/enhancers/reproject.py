"""``--method reproject``: a geometry-only baseline that copies reference colours through the C-maps.

For every target pixel with a valid C-map point (Eq. 1 map divided by the render's alpha, where
alpha > ``alpha_threshold``), take its surface point ``X``: with ``surface="ray"`` (default) the point on
the pixel's ray at the C-map point's depth — the 3DGS expected depth, since the alpha-weighted
Gaussian *centres* of Eq. 1 can lie far off the ray for large Gaussians (a road splat several metres
wide) — or, with ``surface="cmap"``, the raw C-map point.  Reference surface points are built the
same way.  Then:

1. project ``X`` into each reference camera (pixel centres at +0.5), giving pixel ``uv`` and depth ``z``;
2. visibility / depth test: read the reference's own C-map point ``Y`` at ``uv`` (nearest pixel) and
   accept the reference when ``Y`` is valid and ``‖Y − X‖ ≤ tolerance · z`` — a reference whose
   surface at ``uv`` is nearer (an occluder) or farther (the point is not what it sees) is rejected;
3. sample the reference's clean colour at ``uv`` (bilinear);
4. blend the accepted colours with weights ``max(Eq. 2 score(target, reference), min_weight)``
   (α = 0.8, β = 0.2, ``d_max`` = the packet's largest camera-centre distance).

Pixels that no reference accepts, or with no valid C-map point (sky, holes), keep the render.  The
packet is already in one normalised frame, so C-maps and cameras agree; the tolerance is relative to
depth and therefore independent of the packet scale.

Written by hand because no maintained library does C-map-based reprojection with this depth test; the
work is vectorised over references and pixels in torch (one Python iteration per target view).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np
import torch
import torch.nn.functional as F

from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.base import enhancer_repr
from setdiff_bench.errors import PacketError, UsageError
from setdiff_bench.geometry import (
    OVERLAP_ALPHA,
    OVERLAP_BETA,
    max_pairwise_distance,
    overlap_score_matrix,
    snap_to_rays,
)
from setdiff_bench.types import Packet


@dataclass(frozen=True)
class ReprojectConfig:
    """Parameters of the baseline (all recorded in run manifests).

    Attributes:
        alpha_threshold: a C-map point is valid where the render's alpha exceeds this (in (0, 1)).
        tolerance: accept a reference when its surface point is within ``tolerance × depth`` of the
            target's point (depth in the reference camera; 0.03 = 3 %).
        surface: ``"ray"`` (C-map depth on the pixel's ray) or ``"cmap"`` (the raw Eq. 1 point).
        min_weight: floor of the Eq. 2 blend weight (scores can be ≤ 0 for opposing views).
        overlap_alpha, overlap_beta: Eq. 2 coefficients.
        pixel_chunk: target pixels processed at once (bounds memory: ~60 bytes × references × chunk).
    """

    alpha_threshold: float = 0.5
    tolerance: float = 0.03
    surface: str = "ray"
    min_weight: float = 1e-3
    overlap_alpha: float = OVERLAP_ALPHA
    overlap_beta: float = OVERLAP_BETA
    pixel_chunk: int = 1 << 18

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha_threshold < 1.0:
            raise UsageError(f"alpha_threshold must be in (0, 1), got {self.alpha_threshold}", "reproject")
        if self.surface not in ("ray", "cmap"):
            raise UsageError(f"surface must be 'ray' or 'cmap', got {self.surface!r}", "reproject")
        if not self.tolerance > 0.0:
            raise UsageError(f"tolerance must be > 0, got {self.tolerance}", "reproject")
        if not self.min_weight > 0.0:
            raise UsageError(f"min_weight must be > 0, got {self.min_weight}", "reproject")
        if self.pixel_chunk < 1:
            raise UsageError(f"pixel_chunk must be >= 1, got {self.pixel_chunk}", "reproject")


def cmap_points(
    cmaps: torch.Tensor, alphas: torch.Tensor, alpha_threshold: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """Expected surface points from Eq. 1 maps.

    Args:
        cmaps: ``(V, 3, H, W)`` alpha-weighted point sums ``Σ wᵢ xᵢ`` (packet frame).
        alphas: ``(V, 1, H, W)`` accumulated opacities.

    Returns:
        ``points`` ``(V, 3, H, W)`` = cmap / alpha where valid (0 elsewhere), ``valid`` ``(V, 1, H, W)`` bool.
    """
    valid = alphas > alpha_threshold
    points = torch.where(valid, cmaps / alphas.clamp_min(alpha_threshold), torch.zeros_like(cmaps))
    return points, valid


def project(cameras: tuple[Camera, ...], points: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Project points into several cameras.

    Args:
        cameras: ``N`` cameras (OpenCV axes, world-to-camera, pixel centres at +0.5).
        points: ``(P, 3)`` points in the cameras' world frame.

    Returns:
        ``uv`` ``(N, P, 2)`` pixel coordinates and ``z`` ``(N, P)`` camera-frame depth (same dtype and
        device as ``points``).  Cameras with lens distortion go through :meth:`Camera.project` (numpy).
    """
    uvs, depths = [], []
    for camera in cameras:
        if camera.distortion is not None and not camera.distortion.is_zero():
            uv_np, z_np = camera.project(points.detach().cpu().double().numpy())
            uvs.append(torch.from_numpy(np.nan_to_num(uv_np, nan=-1e9)).to(points))
            depths.append(torch.from_numpy(z_np).to(points))
            continue
        w2c = torch.tensor(camera.w2c, dtype=points.dtype, device=points.device)
        K = torch.tensor(camera.K, dtype=points.dtype, device=points.device)
        cam = points @ w2c[:3, :3].T + w2c[:3, 3]
        z = cam[:, 2]
        safe = torch.where(z > 0, z, torch.ones_like(z))
        xn, yn = cam[:, 0] / safe, cam[:, 1] / safe
        uvs.append(torch.stack([K[0, 0] * xn + K[0, 1] * yn + K[0, 2], K[1, 1] * yn + K[1, 2]], dim=-1))
        depths.append(z)
    return torch.stack(uvs), torch.stack(depths)


def blend_weights(packet: Packet, config: ReprojectConfig) -> torch.Tensor:
    """``(M, N)`` float64 Eq. 2 weights of every (target, reference) pair, floored at ``min_weight``."""
    cameras = (*packet.targets.cameras, *packet.references.cameras)
    d_max = max_pairwise_distance(np.stack([c.center for c in cameras]))
    scores = overlap_score_matrix(
        packet.targets.cameras,
        packet.references.cameras,
        d_max,
        alpha=config.overlap_alpha,
        beta=config.overlap_beta,
    )
    return torch.from_numpy(np.maximum(scores, config.min_weight))


class ReprojectEnhancer:
    """The geometry-only baseline (see the module docstring)."""

    name = "reproject"

    def __init__(self, config: ReprojectConfig | None = None, device: str | torch.device = "cpu") -> None:
        self.config = config or ReprojectConfig()
        self.device = torch.device(device)
        self.options = {**asdict(self.config), "device": str(self.device)}

    def __repr__(self) -> str:
        """The device and the options that differ from :class:`ReprojectConfig`'s defaults."""
        changed = {
            f.name: getattr(self.config, f.name)
            for f in fields(self.config)
            if getattr(self.config, f.name) != f.default
        }
        return enhancer_repr(self, device=str(self.device), **changed)

    def enhance(self, packet: Packet) -> torch.Tensor:
        """``(M, 3, H, W)`` float32 in [0, 1] on the CPU, packet order."""
        _check(packet)
        render = packet.targets.images.to(self.device, torch.float32)
        if len(packet.references) == 0:
            return render.cpu().clone()
        cfg = self.config
        refs = packet.references
        ref_points, ref_valid = cmap_points(
            refs.cmaps.to(self.device, torch.float32),
            refs.alphas.to(self.device, torch.float32),
            cfg.alpha_threshold,
        )
        if cfg.surface == "ray":
            ref_points = snap_to_rays(ref_points, ref_valid, refs.cameras)
        # (N, 4, Hr, Wr): point xyz + validity, sampled together with nearest-neighbour lookups
        ref_geometry = torch.cat([ref_points, ref_valid.float()], dim=1)
        ref_images = refs.images.to(self.device, torch.float32)
        tgt_points, tgt_valid = cmap_points(
            packet.targets.cmaps.to(self.device, torch.float32),
            packet.targets.alphas.to(self.device, torch.float32),
            cfg.alpha_threshold,
        )
        if cfg.surface == "ray":
            tgt_points = snap_to_rays(tgt_points, tgt_valid, packet.targets.cameras)
        weights = blend_weights(packet, cfg).to(self.device, torch.float32)
        output = render.clone()
        for m in range(len(packet.targets)):
            points = tgt_points[m].reshape(3, -1).T  # (HW, 3)
            valid = tgt_valid[m].reshape(-1)
            flat = output[m].reshape(3, -1)  # a view: writes go to output
            for start in range(0, points.shape[0], cfg.pixel_chunk):
                stop = min(start + cfg.pixel_chunk, points.shape[0])
                colour, found = self.gather(
                    points[start:stop], refs.cameras, ref_geometry, ref_images, weights[m]
                )
                keep = found & valid[start:stop]
                flat[:, start:stop] = torch.where(keep[None], colour, flat[:, start:stop])
        return output.clamp(0.0, 1.0).cpu()

    def gather(
        self,
        points: torch.Tensor,
        cameras: tuple[Camera, ...],
        ref_geometry: torch.Tensor,
        ref_images: torch.Tensor,
        weights: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Blend of accepted reference colours for ``P`` points → ``(3, P)`` colours, ``(P,)`` found mask."""
        ref_h, ref_w = ref_images.shape[-2:]
        uv, z = project(cameras, points)  # (N, P, 2), (N, P)
        inside = (z > 0) & (uv[..., 0] >= 0) & (uv[..., 0] < ref_w) & (uv[..., 1] >= 0) & (uv[..., 1] < ref_h)
        grid = torch.stack([uv[..., 0] * (2.0 / ref_w) - 1.0, uv[..., 1] * (2.0 / ref_h) - 1.0], dim=-1)
        grid = torch.where(inside[..., None], grid, torch.full_like(grid, -2.0))[:, None]  # (N, 1, P, 2)
        seen = F.grid_sample(ref_geometry, grid, mode="nearest", padding_mode="zeros", align_corners=False)[
            :, :, 0
        ]
        seen_points, seen_valid = seen[:, :3], seen[:, 3] > 0.5  # (N, 3, P), (N, P)
        distance = (seen_points - points.T[None]).norm(dim=1)
        accept = inside & seen_valid & (distance <= self.config.tolerance * z)
        colours = F.grid_sample(
            ref_images, grid, mode="bilinear", padding_mode="border", align_corners=False
        )[:, :, 0]
        w = weights[:, None] * accept  # (N, P)
        total = w.sum(dim=0)
        blended = (colours * w[:, None]).sum(dim=0) / total.clamp_min(1e-12)
        return blended, total > 0


def _check(packet: Packet) -> None:
    targets, refs = packet.targets, packet.references
    m, h, w = len(targets), packet.height, packet.width
    where = f"packet {packet.packet_id}"
    expected = {"targets.images": (m, 3, h, w), "targets.cmaps": (m, 3, h, w), "targets.alphas": (m, 1, h, w)}
    if len(refs):
        n, rh, rw = len(refs), int(refs.images.shape[-2]), int(refs.images.shape[-1])
        expected |= {
            "references.images": (n, 3, rh, rw),
            "references.cmaps": (n, 3, rh, rw),
            "references.alphas": (n, 1, rh, rw),
        }
    for key, shape in expected.items():
        role, attr = key.split(".")
        actual = tuple(getattr(getattr(packet, role), attr).shape)
        if actual != shape:
            raise PacketError(f"reproject: {key} has shape {actual}, expected {shape}", where)


def create(
    alpha_threshold: float = ReprojectConfig.alpha_threshold,
    tolerance: float = ReprojectConfig.tolerance,
    min_weight: float = ReprojectConfig.min_weight,
    surface: str = ReprojectConfig.surface,
    device: str | None = None,
) -> ReprojectEnhancer:
    """Factory of ``--method reproject`` (``device`` defaults to the CPU)."""
    config = ReprojectConfig(
        alpha_threshold=alpha_threshold, tolerance=tolerance, min_weight=min_weight, surface=surface
    )
    return ReprojectEnhancer(config, device=device or "cpu")
