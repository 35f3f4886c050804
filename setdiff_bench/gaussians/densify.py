"""Adaptive density control of 3DGS (Kerbl et al. 2023, §5) as a strategy object: gradient statistics,
clone, split, prune, opacity reset — the rules of graphdeco-inria/gaussian-splatting ``densify_and_prune``.

:class:`DensificationStrategy` owns the thresholds and the schedule (frozen, part of the fit
configuration); :class:`DensityState` is what evolves during a fit (the statistics, the scene extent,
the random stream).  The fit loop calls, in gsplat's ``Strategy`` shape::

    state = strategy.initialize_state(len(params), extent=..., generator=...)
    for step in 1, 2, …:                      # 1-based, as in Inria
        render → loss.backward() → Adam step
        strategy.step_post_backward(params, state, step, meta, width, height)

* Statistics (every step before ``densify_until``): for every Gaussian visible in the view, accumulate
  the norm of the gradient of the loss w.r.t. its projected 2D centre in NDC units (pixel gradient ×
  (W/2, H/2), as gsplat's ``DefaultStrategy`` converts), count the views, and keep the largest screen
  radius.
* Every ``densify_every`` steps after ``densify_from`` and before ``densify_until``: densify where the
  mean accumulated gradient ≥ ``grad_threshold``: Gaussians whose largest scale is
  ≤ ``percent_dense · extent`` are cloned (an identical copy); larger ones are split into two, sampled
  from the Gaussian itself, with scales divided by 1.6.  Then prune Gaussians with opacity
  < ``min_opacity`` and, once opacities have been reset at least once (step > ``opacity_reset_every``),
  those whose screen radius exceeded ``max_screen_size`` px or whose world scale exceeds
  ``max_world_fraction · extent``.  The statistics restart from zero.
* Opacity reset every ``opacity_reset_every`` steps before ``densify_until``: ``opacity ← min(opacity,
  0.01)``, Adam moments zeroed.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import ClassVar

import torch

from setdiff_bench.errors import FallbackWarning
from setdiff_bench.gaussians.backends.torch_ref import quaternion_to_rotation
from setdiff_bench.gaussians.optim import GaussianParameters
from setdiff_bench.gaussians.portable import logistic, standard_normal, vector_norm

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
        return cls(
            torch.zeros(n, device=device), torch.zeros(n, device=device), torch.zeros(n, device=device)
        )

    def tensors(self) -> dict[str, torch.Tensor]:
        return {"grad_sum": self.grad_sum, "count": self.count, "max_radius": self.max_radius}

    def mean_grad(self) -> torch.Tensor:
        """``(N,)`` average gradient norm per visible view (0 where never visible)."""
        return torch.where(
            self.count > 0, self.grad_sum / self.count.clamp_min(1), torch.zeros_like(self.grad_sum)
        )

    def accumulate(self, meta: dict[str, torch.Tensor], width: int, height: int) -> None:
        """Add one view's statistics from a render's ``meta`` (``means2d`` with ``.grad``, ``radii``, ``visible``)."""
        means2d = meta["means2d"]
        if means2d is None or means2d.grad is None:
            return
        visible = meta["visible"].reshape(-1)
        grad = means2d.grad.detach().reshape(-1, 2)
        ndc = grad * torch.tensor([width / 2.0, height / 2.0], device=grad.device, dtype=grad.dtype)
        norm = vector_norm(ndc)
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


@dataclass
class DensityState:
    """What density control carries from one fit step to the next (checkpointed with the fit).

    Attributes:
        stats: the accumulators since the last densification (or the start).
        extent: the scene radius (world units) that ``percent_dense`` and ``max_world_fraction`` scale.
        generator: the random stream split samples are drawn from (the fit's own, which also orders its views).
        warned_no_grad: the "no view-space gradient statistics" warning has been given.
    """

    stats: DensityStats
    extent: float
    generator: torch.Generator
    warned_no_grad: bool = False


@dataclass(frozen=True)
class DensificationStrategy:
    """Inria's adaptive density control: its thresholds and schedule, the defaults of a 30 000-step run.

    Steps are 1-based fit iterations.  The rules are in the module docstring.

    Attributes:
        densify_from, densify_until, densify_every: densify at every ``densify_every``-th step with
            ``densify_from < step < densify_until``; statistics are gathered at every step < ``densify_until``.
        opacity_reset_every: reset opacities at every ``opacity_reset_every``-th step < ``densify_until``;
            pruning by screen and world size starts after the first reset.
        grad_threshold: mean view-space gradient norm (NDC units) from which a Gaussian is densified.
        percent_dense: a densified Gaussian whose largest scale is ≤ ``percent_dense`` × extent is cloned,
            a larger one split.
        min_opacity: Gaussians below this opacity are pruned.
        max_screen_size: … and, after the first reset, those whose screen radius exceeded this (pixels) …
        max_world_fraction: … or whose largest scale exceeds this × extent.
        max_gaussians: cap on the count densification grows to (the largest gradients are densified
            first); ``None``: no cap.
    """

    densify_from: int = 500
    densify_until: int = 15_000
    densify_every: int = 100
    grad_threshold: float = 2e-4
    percent_dense: float = 0.01
    opacity_reset_every: int = 3000
    min_opacity: float = 0.005
    max_screen_size: float = 20.0
    max_world_fraction: float = 0.1
    max_gaussians: int | None = None

    #: the fields counted in steps, which change with the length of a run
    SCHEDULE_FIELDS: ClassVar[tuple[str, ...]] = (
        "densify_from",
        "densify_until",
        "densify_every",
        "opacity_reset_every",
    )

    @classmethod
    def schedule(cls, iterations: int, *, densify_every: int, **overrides: object) -> DensificationStrategy:
        """The standard schedule compressed to ``iterations``: densify from 10 % to 60 % of the run every
        ``densify_every`` steps, reset opacities every 30 %; ``overrides`` replace any field."""
        values: dict[str, object] = {
            "densify_every": densify_every,
            "densify_from": max(1, round(0.1 * iterations)),
            "densify_until": round(0.6 * iterations),
            "opacity_reset_every": max(densify_every, round(0.3 * iterations)),
        }
        values.update(overrides)
        return cls(**values)  # type: ignore[arg-type]

    def initialize_state(
        self, n: int, *, extent: float, generator: torch.Generator, device: torch.device | str = "cpu"
    ) -> DensityState:
        """The state of a fit starting with ``n`` Gaussians in a scene of radius ``extent``."""
        return DensityState(DensityStats.zeros(n, device), extent, generator)

    def step_post_backward(
        self,
        params: GaussianParameters,
        state: DensityState,
        step: int,
        meta: Mapping[str, torch.Tensor],
        width: int,
        height: int,
    ) -> DensifyResult | None:
        """Density control after step ``step``'s backward pass and optimiser step, on ``params`` in place.

        Gathers the statistics of the rendered view (``meta``: a render's per-camera ``means2d`` with
        ``.grad``, ``radii`` and ``visible``; ``width`` × ``height`` pixels), then densifies and prunes
        and resets opacities when the schedule says so.

        Returns:
            The densification's counts, or ``None`` when this step did not densify.
        """
        if step >= self.densify_until:
            return None
        state.stats.accumulate(meta, width, height)
        result = None
        if step > self.densify_from and step % self.densify_every == 0:
            if not bool((state.stats.count > 0).any()) and not state.warned_no_grad:
                warnings.warn(
                    "densification found no view-space gradient statistics (the render backend's "
                    "meta['means2d'] had no .grad); no Gaussians were added",
                    FallbackWarning,
                    stacklevel=2,
                )
                state.warned_no_grad = True
            result = self.densify_and_prune(params, state, prune_large=step > self.opacity_reset_every)
        if step % self.opacity_reset_every == 0:
            reset_opacity(params)
        return result

    def densify_and_prune(
        self, params: GaussianParameters, state: DensityState, *, prune_large: bool
    ) -> DensifyResult:
        """One Inria ``densify_and_prune`` on ``params`` (in place) from ``state``'s statistics, which then
        restart from zero; ``prune_large`` also prunes by screen radius and world scale."""
        with torch.no_grad():
            stats, extent = state.stats, state.extent
            n = len(params)
            device = params.params["means"].device
            grads = stats.mean_grad()
            scales = torch.exp(params.params["log_scales"].detach())
            max_scale = scales.amax(dim=1)
            selected = grads >= self.grad_threshold
            if self.max_gaussians is not None:
                room = max(0, self.max_gaussians - n)
                if int(selected.sum()) > room:
                    top = torch.topk(torch.where(selected, grads, torch.full_like(grads, -1.0)), room).indices
                    selected = torch.zeros_like(selected)
                    selected[top] = True
            clone = selected & (max_scale <= self.percent_dense * extent)
            split = selected & (max_scale > self.percent_dense * extent)

            old_rows = torch.arange(n, device=device)
            clone_rows = old_rows[clone]
            split_rows = old_rows[split].repeat(SPLIT_COUNT)
            p = {k: v.detach() for k, v in params.params.items()}
            # split samples: x ~ N(mean, R diag(s²) Rᵀ)
            s = scales[split_rows]
            rotation = quaternion_to_rotation(p["quats"][split_rows])
            noise = standard_normal(split_rows.numel(), 3, state.generator).to(device) * s
            split_means = p["means"][split_rows] + torch.einsum("nij,nj->ni", rotation, noise)
            split_log_scales = torch.log(s / SPLIT_SCALE_DIVISOR)

            rows = torch.cat([old_rows, clone_rows, split_rows])
            source = torch.cat([old_rows, torch.full_like(clone_rows, -1), torch.full_like(split_rows, -1)])
            values = {k: v[rows] for k, v in p.items()}
            start = n + clone_rows.numel()
            values["means"][start:] = split_means
            values["log_scales"][start:] = split_log_scales

            opacity = logistic(values["opacity_logits"])
            prune = opacity < self.min_opacity
            prune[:n] |= split  # split originals are replaced by their samples
            if prune_large:
                big_screen = torch.cat(
                    [
                        stats.max_radius > self.max_screen_size,
                        torch.zeros(rows.numel() - n, dtype=torch.bool, device=device),
                    ]
                )
                big_world = torch.exp(values["log_scales"]).amax(dim=1) > self.max_world_fraction * extent
                prune |= big_screen | big_world
            keep = ~prune
            params.remap(source[keep], {k: v[keep] for k, v in values.items()})
            total = len(params)
            n_split = int(split.sum())
            state.stats = DensityStats.zeros(total, device)
            return DensifyResult(int(clone.sum()), n_split, int(rows.numel() - total) - n_split, total)


def reset_opacity(params: GaussianParameters, value: float = RESET_OPACITY) -> None:
    """Clamp every opacity to at most ``value`` (Inria ``reset_opacity``) and zero its Adam moments."""
    logit_cap = math.log(value / (1 - value))
    current = params.params["opacity_logits"].detach()
    params.set_values("opacity_logits", torch.minimum(current, torch.full_like(current, logit_cap)))
