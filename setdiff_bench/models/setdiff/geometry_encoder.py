"""Ψ, the geometry encoder: C-map (3 ch) + Plücker rays (6 ch) → a latent-shaped additive condition.

Paper §3.1 "Geometry encoding": five convolutional blocks with GroupNorm and SiLU, 8× downsampling,
as many output channels as the VAE latent, combined with the image latent by element-wise addition.
Here: block 1 keeps the resolution, blocks 2–4 halve it (stride-2 3×3 convs → 8×), block 5 keeps it,
then a 3×3 output conv to the latent channels that is **zero-initialised**, so an untrained Ψ adds
exactly nothing and the model starts as the image-only one (docs/model.md, "Geometry encoder and guidance").
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from torch import nn

from setdiff_bench.cameras import Camera
from setdiff_bench.geometry import plucker_rays

GEOMETRY_CHANNELS = 9  # C-map xyz (3) + Plücker (o × d, d) (6)


def _groups(channels: int, wanted: int) -> int:
    """The largest divisor of ``channels`` that is <= ``wanted`` (GroupNorm needs exact division)."""
    return max(g for g in range(1, min(wanted, channels) + 1) if channels % g == 0)


class GeometryEncoder(nn.Module):
    """Ψ(c, p): ``(V, 9, H, W)`` → ``(V, out_channels, H/f, W/f)``.

    Args:
        widths: output channels of the five conv blocks.
        out_channels: the latent channel count (4 for SD VAEs).
        downsample: total downsampling f, a power of two ≤ 16 (8 for SD VAEs).
        groups: GroupNorm groups (reduced to a divisor of each width).
    """

    def __init__(
        self, widths: Sequence[int], out_channels: int = 4, downsample: int = 8, groups: int = 8
    ) -> None:
        super().__init__()
        if len(widths) != 5:
            raise ValueError(f"the geometry encoder has five blocks, got widths {list(widths)}")
        halvings = round(math.log2(downsample))
        if 2**halvings != downsample or halvings > 4:
            raise ValueError(f"downsample must be a power of two <= 16, got {downsample}")
        blocks: list[nn.Module] = []
        previous = GEOMETRY_CHANNELS
        for index, width in enumerate(widths):
            stride = 2 if 1 <= index <= halvings else 1
            blocks.append(
                nn.Sequential(
                    nn.Conv2d(previous, width, kernel_size=3, stride=stride, padding=1),
                    nn.GroupNorm(_groups(width, groups), width),
                    nn.SiLU(),
                )
            )
            previous = width
        self.blocks = nn.Sequential(*blocks)
        self.out = nn.Conv2d(previous, out_channels, kernel_size=3, padding=1)
        nn.init.zeros_(self.out.weight)
        nn.init.zeros_(self.out.bias)
        self.downsample = downsample

    def forward(self, geometry: torch.Tensor) -> torch.Tensor:
        """``geometry`` ``(V, 9, H, W)`` (C-map then Plücker) → ``(V, out_channels, H/f, W/f)``."""
        if geometry.ndim != 4 or geometry.shape[1] != GEOMETRY_CHANNELS:
            raise ValueError(f"geometry must be (V, {GEOMETRY_CHANNELS}, H, W), got {tuple(geometry.shape)}")
        return self.out(self.blocks(geometry))


GEOMETRY_INPUTS = ("cmap", "plucker")


def geometry_input(
    cmaps: torch.Tensor,
    cameras: Sequence[Camera],
    *,
    cmap_clip: float = 0.0,
    inputs: Sequence[str] = GEOMETRY_INPUTS,
) -> torch.Tensor:
    """Stack a view set's C-maps and Plücker rays into Ψ's input.

    Args:
        cmaps: ``(V, 3, H, W)`` C-maps in the packet's normalised frame (0 where nothing was hit).
        cameras: the V normalised cameras (Plücker moments depend on that normalisation).
        cmap_clip: clamp C-map coordinates to ``±cmap_clip`` packet units; 0 = no clamp.
        inputs: which cues Ψ sees, a subset of ``("cmap", "plucker")``; a cue left out is zeroed
            (its channels then carry no information: the geometry-grounding ablation, paper Table 5).

    Returns:
        ``(V, 9, H, W)`` float32: C-map xyz, then ``(o × d, d)`` per pixel (pixel centres at +0.5).
    """
    if cmaps.ndim != 4 or cmaps.shape[1] != 3 or cmaps.shape[0] != len(cameras):
        raise ValueError(f"cmaps must be (V, 3, H, W) with V = {len(cameras)}, got {tuple(cmaps.shape)}")
    height, width = int(cmaps.shape[-2]), int(cmaps.shape[-1])
    cmaps = cmaps.float()
    if cmap_clip > 0:
        cmaps = cmaps.clamp(-cmap_clip, cmap_clip)
    if not len(cameras):
        return cmaps.new_zeros((0, GEOMETRY_CHANNELS, height, width))
    unknown = set(inputs) - set(GEOMETRY_INPUTS)
    if unknown:
        raise ValueError(f"unknown geometry inputs {sorted(unknown)}; choose from {GEOMETRY_INPUTS}")
    if "plucker" in inputs:
        rays = torch.stack([plucker_rays(camera, height, width) for camera in cameras]).to(cmaps.device)
    else:
        rays = cmaps.new_zeros((len(cameras), GEOMETRY_CHANNELS - 3, height, width))
    if "cmap" not in inputs:
        cmaps = torch.zeros_like(cmaps)
    return torch.cat([cmaps, rays], dim=1)
