"""Input checks shared by the metrics: shapes, dtypes and masks of ``(V, C, H, W)`` image batches."""

from __future__ import annotations

import torch

from setdiff_bench.errors import ImageError


def check_pair(pred: torch.Tensor, target: torch.Tensor, name: str) -> None:
    """Raise :class:`ImageError` unless ``pred`` and ``target`` are equal-shape float ``(V, C, H, W)`` batches.

    Args:
        pred: ``(V, C, H, W)`` floating tensor.
        target: ``(V, C, H, W)`` floating tensor on the same device.
        name: metric name used in the message (``"psnr"``, ``"ssim"``...).
    """
    for label, tensor in (("pred", pred), ("target", target)):
        if not isinstance(tensor, torch.Tensor):
            raise ImageError(f"{name}: {label} must be a torch.Tensor, got {type(tensor).__name__}")
        if tensor.ndim != 4:
            raise ImageError(f"{name}: {label} must have shape (V, C, H, W), got {tuple(tensor.shape)}")
        if not tensor.is_floating_point():
            raise ImageError(f"{name}: {label} must be a float tensor in [0, 1], got dtype {tensor.dtype}")
    if pred.shape != target.shape:
        raise ImageError(f"{name}: pred {tuple(pred.shape)} and target {tuple(target.shape)} differ in shape")
    if pred.device != target.device:
        raise ImageError(f"{name}: pred on {pred.device} and target on {target.device}")


def check_mask(mask: torch.Tensor, images: torch.Tensor, name: str) -> torch.Tensor:
    """Validate a ``(V, 1, H, W)`` mask against ``(V, C, H, W)`` images; return it as float (1 = evaluate).

    Bool masks are converted to 0/1; float masks must already be in {0, 1}-like [0, 1] values.
    """
    if not isinstance(mask, torch.Tensor) or mask.ndim != 4 or mask.shape[1] != 1:
        shape = tuple(mask.shape) if isinstance(mask, torch.Tensor) else type(mask).__name__
        raise ImageError(f"{name}: mask must have shape (V, 1, H, W), got {shape}")
    v, _, h, w = images.shape
    if (mask.shape[0], mask.shape[2], mask.shape[3]) != (v, h, w):
        raise ImageError(f"{name}: mask {tuple(mask.shape)} does not match images {tuple(images.shape)}")
    return mask.to(device=images.device, dtype=images.dtype)
