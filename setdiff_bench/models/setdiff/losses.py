"""Training losses: the latent loss and the L2 + SSIM + LPIPS reconstruction loss (paper §3.2).

Latent loss (Eq. 3 read with v-prediction): the UNet's output v̂ is turned into x̂0 analytically
(``x̂0 = √ᾱ·z − √(1−ᾱ)·v̂``) and regressed onto the ground truth's latent, i.e. the frozen VAE
encoder's scaled posterior mean ``E(y)``: ``‖x̂0 − E(y)‖²``.  This equals a v-loss
``(1−ᾱ)·‖v̂ − v*‖²`` with the implied target ``v* = (√ᾱ·z − E(y))/√(1−ᾱ)`` (docs/model.md,
"One-step formulation"), so the paper's "predict the clean target y" and "v-prediction objective"
agree.  Pixels outside the evaluation mask are down-weighted in the latent grid by the valid fraction of each 8×8 cell.

Reconstruction loss on decoded targets, in [0, 1]: masked-mean L2; SSIM as ``1 − SSIM`` and LPIPS,
both on the prediction composited with the ground truth outside the mask (masked pixels then agree
exactly and give no gradient).  SSIM and LPIPS come from :mod:`setdiff_bench.metrics`; LPIPS needs
its trunk weights, and a missing file raises that module's ``WeightsError`` — a loss term is never
dropped silently (set ``lpips_weight = 0`` to train without it).
"""

from __future__ import annotations

from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

from setdiff_bench.metrics.ssim import ssim


def latent_loss(
    predicted: torch.Tensor, target: torch.Tensor, masks: torch.Tensor | None = None
) -> torch.Tensor:
    """Mean squared error between latents ``(K, C, h, w)``, weighted by ``masks`` ``(K, 1, H, W)`` if given."""
    squared = (predicted.float() - target.float()).square()
    if masks is None:
        return squared.mean()
    factor = masks.shape[-1] // predicted.shape[-1]
    weights = F.avg_pool2d(masks.float(), factor) if factor > 1 else masks.float()
    total = weights.sum() * predicted.shape[1]
    return (squared * weights).sum() / total.clamp_min(1e-8)


class ReconstructionLoss(nn.Module):
    """``l2·L2 + ssim·(1 − SSIM) + lpips·LPIPS`` on ``(K, 3, H, W)`` images in [0, 1].

    Args:
        l2_weight, ssim_weight, lpips_weight: term weights (a term with weight 0 is not computed).
        lpips_net: ``vgg`` or ``alex``.
        device: where the LPIPS network lives.

    Raises:
        WeightsError: ``lpips_weight > 0`` and the LPIPS weights are not available.
    """

    def __init__(
        self,
        l2_weight: float = 1.0,
        ssim_weight: float = 1.0,
        lpips_weight: float = 1.0,
        lpips_net: str = "vgg",
        device: torch.device | str = "cpu",
    ) -> None:
        super().__init__()
        self.l2_weight, self.ssim_weight, self.lpips_weight = (
            float(l2_weight),
            float(ssim_weight),
            float(lpips_weight),
        )
        self.lpips: Any = None
        if self.lpips_weight > 0:
            # lazy: LPIPS (and its weight files) load only when the loss uses it; tests stand in for the module
            from setdiff_bench.metrics.lpips import load_lpips

            self.lpips = load_lpips(net=lpips_net, device=device)
            self.lpips.requires_grad_(False)

    def forward(
        self, predicted: torch.Tensor, target: torch.Tensor, masks: torch.Tensor | None = None
    ) -> dict[str, torch.Tensor]:
        """Terms and their weighted sum (key ``"total"``), each a scalar tensor."""
        predicted, target = predicted.float(), target.float()
        if masks is None:
            masks = torch.ones_like(predicted[:, :1], dtype=torch.bool)
        weights = masks.to(predicted.dtype)
        terms: dict[str, torch.Tensor] = {}
        total = predicted.new_zeros(())
        if self.l2_weight > 0:
            valid = weights.sum() * predicted.shape[1]
            terms["l2"] = ((predicted - target).square() * weights).sum() / valid.clamp_min(1.0)
            total = total + self.l2_weight * terms["l2"]
        composite = torch.where(masks.bool(), predicted, target)
        if self.ssim_weight > 0:
            terms["ssim"] = 1.0 - ssim(composite, target, border="valid", backend="torch").mean()
            total = total + self.ssim_weight * terms["ssim"]
        if self.lpips_weight > 0:
            terms["lpips"] = self.lpips(composite, target).mean()
            total = total + self.lpips_weight * terms["lpips"]
        terms["total"] = total
        return terms
