"""Peak signal-to-noise ratio per image, plain and masked.

``PSNR = 10·log10(L² / MSE)`` with ``L`` the data range (1 for images in [0, 1]).  The MSE of one image is
the mean over its channels and pixels; a dataset score is the **mean of per-image PSNRs** (as NeRF, 3DGS
and nerfbaselines report), never the PSNR of a pooled MSE (torchmetrics' default, which is lower by
Jensen's inequality).  A hand-written function because it is three lines and every library pools or
clamps differently (docs/metrics.md, "PSNR").
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from setdiff_bench.metrics._inputs import check_mask, check_pair


def mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """Mean squared error per image.

    Args:
        pred: ``(V, C, H, W)`` float images.
        target: ``(V, C, H, W)`` float images, same shape.
        mask: optional ``(V, 1, H, W)`` bool/0-1 mask, True = evaluate.  The mean is then taken over the
            valid pixels × channels only (EUVS ``psnr_mask``); an empty mask gives NaN.

    Returns:
        ``(V,)`` MSE in squared data units.
    """
    check_pair(pred, target, "mse")
    squared = F.mse_loss(pred, target, reduction="none")  # fused (p - t)², one pass
    if mask is None:
        return squared.flatten(1).mean(dim=1)
    weights = check_mask(mask, pred, "mse")
    valid = weights.flatten(1).sum(dim=1) * pred.shape[1]
    return (squared * weights).flatten(1).sum(dim=1) / valid


def psnr(
    pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None, *, data_range: float = 1.0
) -> torch.Tensor:
    """PSNR per image in dB.

    Args:
        pred: ``(V, C, H, W)`` float images in [0, ``data_range``].
        target: ``(V, C, H, W)`` float images, same shape.
        mask: optional ``(V, 1, H, W)`` mask, True = evaluate: MSE over valid pixels × channels only.
        data_range: ``L`` in ``10·log10(L²/MSE)``; 1 for [0, 1] images.

    Returns:
        ``(V,)`` PSNR in dB; ``+inf`` for identical images, NaN for an empty mask.
    """
    error = mse(pred, target, mask)
    return 10.0 * torch.log10(data_range**2 / error)


def psnr_euvs(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """EUVS-official ``psnr_mask``: MSE over pixels where the mask ≠ 0 (×3 channels), data range 1.

    Args:
        pred, target: ``(V, 3, H, W)`` images in [0, 1].
        mask: ``(V, 1, H, W)`` dynamic-object mask, 1 = static (evaluated).

    Returns:
        ``(V,)`` PSNR in dB.
    """
    return psnr(pred, target, (mask != 0))
