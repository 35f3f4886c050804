"""What every rasterisation backend shares: the :class:`RenderOutput` it returns and the C-map's centre
clipping.  :mod:`setdiff_bench.gaussians.render` dispatches to the backends and imports this module; the
backends import it too and never :mod:`~setdiff_bench.gaussians.render`, so there is no import cycle.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch


@dataclass
class RenderOutput:
    """Rendered views of V cameras of equal size.

    Attributes:
        rgb: ``(V, 3, H, W)`` colour (composited over ``background``).
        cmap: ``(V, 3, H, W)`` C-map, world coordinates weighted by the compositing weights, or ``None``
            when geometry was not requested.
        depth: ``(V, 1, H, W)`` accumulated camera-space z, or ``None``.
        alpha: ``(V, 1, H, W)`` accumulated opacity ``Σ wᵢ``.
        meta: per-camera projection data (``means2d``, ``radii``, ``visible``) for densification.
    """

    rgb: torch.Tensor
    cmap: torch.Tensor | None
    depth: torch.Tensor | None
    alpha: torch.Tensor
    meta: list[dict[str, torch.Tensor]] = field(default_factory=list)


@dataclass(frozen=True)
class RenderOptions:
    """The settings of one render call, as every backend takes them (see
    :func:`setdiff_bench.gaussians.render.render` for their meaning and defaults)."""

    with_geometry: bool
    sh_degree: int | None
    background: Sequence[float] | None
    cmap_bound: float | None
    cmap_center: Sequence[float]
    near: float
    far: float
    eps2d: float
    tile_size: int


def clip_centres(means: torch.Tensor, bound: float | None, center: Sequence[float]) -> torch.Tensor:
    """Gaussian centres ``(N, 3)`` clipped to ``center ± bound`` (no-op when ``bound`` is None)."""
    if bound is None:
        return means
    c = torch.as_tensor(np.asarray(center, dtype=np.float64), device=means.device, dtype=means.dtype)
    return torch.minimum(torch.maximum(means, c - bound), c + bound)
