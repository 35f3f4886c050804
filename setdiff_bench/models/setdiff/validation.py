"""Validation while training: masked PSNR / SSIM (and LPIPS when the loss has it) of enhanced vs ground-truth
targets, as per-process sums reduced across the processes of a run."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import torch

from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.metrics.ssim import ssim
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.losses import ReconstructionLoss
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.types import TrainingSample


@torch.no_grad()
def validate(
    model: SetDiffModel, samples: Sequence[TrainingSample], reconstruction: ReconstructionLoss | None = None
) -> dict[str, float]:
    """Mean masked PSNR and SSIM (and LPIPS when the loss has it loaded) of enhanced vs ground-truth targets."""
    return _means(validation_totals(model, samples, reconstruction))


@torch.no_grad()
def validation_totals(
    model: SetDiffModel, samples: Sequence[TrainingSample], reconstruction: ReconstructionLoss | None = None
) -> dict[str, tuple[float, int]]:
    """Per metric, the sum over every target of ``samples`` and the number of targets (for reduction across
    processes): ``psnr`` and ``ssim`` (masked), ``lpips`` when the loss has LPIPS loaded."""
    was_training = model.training
    model.eval()
    scores: dict[str, list[float]] = {"psnr": [], "ssim": []}
    if reconstruction is not None and reconstruction.lpips is not None:
        scores["lpips"] = []
    try:
        for sample in samples:
            enhanced = enhance_packet(model, sample.packet)
            gt = sample.target_gt.float()
            masks = sample.target_masks.bool()
            scores["psnr"] += psnr(enhanced, gt, masks).tolist()
            scores["ssim"] += ssim(enhanced, gt, mask=masks).tolist()
            if "lpips" in scores:
                device = next(reconstruction.lpips.parameters()).device  # type: ignore[union-attr]
                composite = torch.where(masks, enhanced, gt).to(device)
                scores["lpips"] += reconstruction.lpips(composite, gt.to(device)).flatten().tolist()  # type: ignore[union-attr]
    finally:
        model.train(was_training)
    return {name: (float(sum(values)), len(values)) for name, values in scores.items()}


def _means(totals: Mapping[str, tuple[float, float]]) -> dict[str, float]:
    """``{metric: (sum, count)}`` → ``{metric: mean}``, leaving out metrics with no or non-finite values."""
    return {
        name: float(total / count)
        for name, (total, count) in totals.items()
        if count > 0 and math.isfinite(total)
    }


def reduce_means(accelerator: Any, totals: dict[str, tuple[float, int]]) -> dict[str, float]:
    """Means over every process's targets from per-process ``(sum, count)`` pairs (same keys on all ranks)."""
    if accelerator.num_processes == 1:
        return _means(totals)
    names = sorted(totals)
    sums = torch.tensor([[totals[n][0], float(totals[n][1])] for n in names], dtype=torch.float64)
    sums = accelerator.reduce(sums.to(accelerator.device), reduction="sum").cpu()
    return _means({name: (total, count) for name, (total, count) in zip(names, sums.tolist(), strict=True)})
