"""Adaptive density control of 3DGS (Kerbl et al. 2023, §5): gradient statistics, clone, split, prune,
opacity reset — the rules of graphdeco-inria/gaussian-splatting ``densify_and_prune``.

* Statistics: after each backward pass, for every Gaussian visible in the view, accumulate the norm
  of the gradient of the loss w.r.t. its projected 2D centre in NDC units (pixel gradient × (W/2, H/2),
  as gsplat's ``DefaultStrategy`` converts), count the views, and keep the largest screen radius.
* Densify where the mean accumulated gradient ≥ ``grad_threshold``: Gaussians whose largest scale is
  ≤ ``percent_dense · extent`` are cloned (an identical copy); larger ones are split into two, sampled
  from the Gaussian itself, with scales divided by 1.6.
* Prune Gaussians with opacity < ``min_opacity`` and, once opacities have been reset at least once,
  those whose screen radius exceeded ``max_screen_size`` px or whose world scale exceeds
  ``max_world_fraction · extent``.
* Opacity reset: ``opacity ← min(opacity, 0.01)``, Adam moments zeroed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from setdiff_bench.gaussians.backends.torch_ref import quaternion_to_rotation
from setdiff_bench.gaussians.optim import GaussianParameters

SPLIT_SCALE_DIVISOR = 1.6  # Inria: scale / (0.8 · N) with N = 2
SPLIT_COUNT = 2
RESET_OPACITY = 0.01


@dataclass
class DensityStats:
    """Per-Gaussian accumulators between densification steps.

    Attributes:
        grad_sum: ``(N,)`` sum of view-space positional gradient norms (NDC units).
        count: ``(N,)`` number of views in which the Gaussian was visible.
        max_radius: ``(N,)`` largest screen-space radius in pixels.
    """

    grad_sum: torch.Tensor
    count: torch.Tensor
    max_radius: torch.Tensor

    @classmethod
    def zeros(cls, n: int, device: torch.device | str = "cpu") -> DensityStats:
        return cls(torch.zeros(n, device=device), torch.zeros(n, device=device), torch.zeros(n, device=device))

    def tensors(self) -> dict[str, torch.Tensor]:
        return {"grad_sum": self.grad_sum, "count": self.count, "max_radius": self.max_radius}

    def mean_grad(self) -> torch.Tensor:
        """``(N,)`` average gradient norm per visible view (0 where never visible)."""
        return torch.where(self.count > 0, self.grad_sum / self.count.clamp_min(1), torch.zeros_like(self.grad_sum))

    def accumulate(self, meta: dict[str, torch.Tensor], width: int, height: int) -> None:
        """Add one view's statistics from a render's ``meta`` (``means2d`` with ``.grad``, ``radii``, ``visible``)."""
        means2d = meta["means2d"]
        if means2d is None or means2d.grad is None:
            return
        visible = meta["visible"].reshape(-1)
        grad = means2d.grad.detach().reshape(-1, 2)
        ndc = grad * torch.tensor([width / 2.0, height / 2.0], device=grad.device, dtype=grad.dtype)
        norm = ndc.norm(dim=-1)
        self.grad_sum += torch.where(visible, norm, torch.zeros_like(norm))
        self.count += visible.to(self.count.dtype)
        radii = meta["radii"].reshape(len(visible), -1).to(self.max_radius.dtype).amax(dim=-1)
        self.max_radius = torch.where(visible, torch.maximum(self.max_radius, radii), self.max_radius)


@dataclass(frozen=True)
class DensifyResult:
    """Counts of one densification step."""

    cloned: int
    split: int
    pruned: int
    total: int


def densify_and_prune(params: GaussianParameters, stats: DensityStats, *, grad_threshold: float, percent_dense: float,
                      extent: float, min_opacity: float, max_screen_size: float | None, max_world_fraction: float,
                      generator: torch.Generator, max_gaussians: int | None = None) -> DensifyResult:
    """One Inria ``densify_and_prune`` step on ``params`` (in place); returns what changed.

    ``max_gaussians`` (optional) caps growth: when the candidates would exceed it, only the ones with the
    largest gradients are densified.
    """
    with torch.no_grad():
        n = len(params)
        device = params.params["means"].device
        grads = stats.mean_grad()
        scales = torch.exp(params.params["log_scales"].detach())
        max_scale = scales.amax(dim=1)
        selected = grads >= grad_threshold
        if max_gaussians is not None:
            room = max(0, max_gaussians - n)
            if int(selected.sum()) > room:
                top = torch.topk(torch.where(selected, grads, torch.full_like(grads, -1.0)), room).indices
                selected = torch.zeros_like(selected)
                selected[top] = True
        clone = selected & (max_scale <= percent_dense * extent)
        split = selected & (max_scale > percent_dense * extent)

        old_rows = torch.arange(n, device=device)
        clone_rows = old_rows[clone]
        split_rows = old_rows[split].repeat(SPLIT_COUNT)
        p = {k: v.detach() for k, v in params.params.items()}
        # split samples: x ~ N(mean, R diag(s²) Rᵀ)
        s = scales[split_rows]
        rotation = quaternion_to_rotation(p["quats"][split_rows])
        noise = torch.randn(split_rows.numel(), 3, generator=generator, device="cpu").to(device) * s
        split_means = p["means"][split_rows] + torch.einsum("nij,nj->ni", rotation, noise)
        split_log_scales = torch.log(s / SPLIT_SCALE_DIVISOR)

        rows = torch.cat([old_rows, clone_rows, split_rows])
        source = torch.cat([old_rows, torch.full_like(clone_rows, -1), torch.full_like(split_rows, -1)])
        values = {k: v[rows] for k, v in p.items()}
        start = n + clone_rows.numel()
        values["means"][start:] = split_means
        values["log_scales"][start:] = split_log_scales

        opacity = torch.sigmoid(values["opacity_logits"])
        prune = opacity < min_opacity
        prune[:n] |= split  # split originals are replaced by their samples
        if max_screen_size is not None:
            big_screen = torch.cat([stats.max_radius > max_screen_size,
                                    torch.zeros(rows.numel() - n, dtype=torch.bool, device=device)])
            big_world = torch.exp(values["log_scales"]).amax(dim=1) > max_world_fraction * extent
            prune |= big_screen | big_world
        keep = ~prune
        params.remap(source[keep], {k: v[keep] for k, v in values.items()})
        total = len(params)
        n_split = int(split.sum())
        return DensifyResult(int(clone.sum()), n_split, int(rows.numel() - total) - n_split, total)


def reset_opacity(params: GaussianParameters, value: float = RESET_OPACITY) -> None:
    """Clamp every opacity to at most ``value`` (Inria ``reset_opacity``) and zero its Adam moments."""
    logit_cap = math.log(value / (1 - value))
    current = params.params["opacity_logits"].detach()
    params.set_values("opacity_logits", torch.minimum(current, torch.full_like(current, logit_cap)))
