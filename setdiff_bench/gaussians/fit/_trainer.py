"""One fit's optimisation state and step (:class:`Trainer`): the seeded per-epoch view order, the render,
the photometric loss ``(1 − λ)·L1 + λ·(1 − SSIM)`` (:func:`photometric_loss`), the Adam step with the
decayed position learning rate, the SH degree schedule and the densification strategy's step.

Images are ``(1, 3, H, W)`` float32 in [0, 1] on the fit's device; masks ``(1, 1, H, W)`` bool (False =
moving object, excluded from the loss).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import torch

from setdiff_bench.gaussians.fit._config import FitConfig
from setdiff_bench.gaussians.fit._data import FitView
from setdiff_bench.gaussians.fit._init import scene_extent
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.optim import GaussianParameters, exponential_lr
from setdiff_bench.gaussians.render import render


def photometric_loss(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None, lambda_dssim: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(loss, l1)`` for ``(1, 3, H, W)`` images; masked-out pixels take the target value."""
    from setdiff_bench.metrics.ssim import ssim

    if mask is not None:
        pred = torch.where(mask, pred, target)
    l1 = (pred - target).abs().mean()
    d_ssim = 1.0 - ssim(pred, target, border="same", backend="exact").mean()
    return (1.0 - lambda_dssim) * l1 + lambda_dssim * d_ssim, l1


class Trainer:
    """The mutable state of one fit (kept together so that it can be checkpointed as a whole)."""

    def __init__(
        self, views: Sequence[FitView], init: GaussianModel, config: FitConfig, device: torch.device
    ) -> None:
        self.views = list(views)
        self.config = config
        self.device = device
        self.backend = "gsplat" if device.type == "cuda" else "torch"
        _, self.extent = scene_extent(views)
        self.params = GaussianParameters(init.to(device, torch.float32), config.learning_rates(self.extent))
        self.generator = torch.Generator().manual_seed(config.seed)
        self.density = config.strategy.initialize_state(
            len(self.params), extent=self.extent, generator=self.generator, device=device
        )
        self.order = torch.randperm(len(self.views), generator=self.generator)
        self.position = 0
        self.iteration = 0  # iterations completed
        self.active_sh = 0
        self.images = [v.image.to(device)[None] for v in self.views]
        self.masks = [None if v.mask is None else v.mask.to(device)[None] for v in self.views]

    def next_view(self) -> int:
        if self.position >= len(self.order):
            self.order = torch.randperm(len(self.views), generator=self.generator)
            self.position = 0
        index = int(self.order[self.position])
        self.position += 1
        return index

    def step(self) -> tuple[float, float, dict[str, int] | None]:
        c = self.config
        it = self.iteration + 1
        self.params.set_lr(
            "means",
            exponential_lr(
                it,
                c.lr_means * self.extent,
                c.lr_means_final * self.extent,
                c.iterations,
                delay_mult=c.lr_means_delay_mult,
            ),
        )
        if it % c.sh_increase_every == 0:
            self.active_sh = min(self.active_sh + 1, c.sh_degree)
        index = self.next_view()
        view = self.views[index]
        model = self.params.model()
        kwargs = {"tile_size": c.tile_size} if self.backend == "torch" else {}
        out = render(
            model,
            [view.camera],
            self.backend,
            with_geometry=False,
            sh_degree=self.active_sh,
            background=c.background,
            **kwargs,
        )
        loss, l1 = photometric_loss(out.rgb, self.images[index], self.masks[index], c.lambda_dssim)
        if loss.requires_grad:  # False only when no Gaussian is visible in the view
            loss.backward()
        with torch.no_grad():
            self.params.optimizer.step()
            self.params.optimizer.zero_grad(set_to_none=True)  # parameters only: means2d keeps its .grad
            result = c.strategy.step_post_backward(
                self.params, self.density, it, out.meta[0], view.camera.width, view.camera.height
            )
        event = None if result is None else {"iteration": it, **dataclasses.asdict(result)}
        self.iteration = it
        return float(loss.detach()), float(l1.detach()), event
