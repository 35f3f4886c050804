"""Separable Gaussian filtering of image batches: a differentiable torch path and a fast OpenCV path.

SSIM needs five local means (x, y, x², y², xy) under an 11-tap Gaussian window.  PyTorch's CPU
depthwise convolution is slow for this shape (about 0.2 s for 15 maps of 576×1024 on 2 cores), while
OpenCV's SIMD ``sepFilter2D`` does the same work ~10× faster; so inference on CPU uses OpenCV and
everything that needs gradients, or runs on a GPU, uses ``torch.nn.functional.conv2d``.  Both paths
compute the same correlation with the same kernel (they agree to float rounding, ~1e-7; tested).

A third path, ``"exact"`` (:func:`blur_exact`), gives the same bits on every CPU: the correlation as
``window_size`` shifted, scaled and added copies per axis, in a fixed order, with separate multiplies
and adds.  ``conv2d`` (oneDNN) and OpenCV pick kernels by the CPU's instruction set (AVX2 / AVX-512
fused multiply-adds, other blockings), so their last bits differ between CPUs, and a 3DGS fit, whose
D-SSIM gradient goes through this filter thousands of times, amplifies those bits into visible
differences (docs/reproducibility.md).  Element-wise IEEE multiplies and adds are rounded the same way
by every vector width, so the exact path is what scene fits use.

Borders: ``"valid"`` returns only the pixels whose window lies inside the image, ``(H-k+1) × (W-k+1)``
(tf / dm_pix / skimage); ``"same"`` zero-pads so the output is ``H × W`` (3DGS); ``"reflect"`` mirrors the
image without repeating the edge pixel (``numpy``/``torch`` "reflect", OpenCV ``BORDER_REFLECT_101``) and
returns ``H × W`` (torchmetrics ≥ 1.x, which averages that whole map).
"""

from __future__ import annotations

import functools
from typing import Literal

import cv2
import numpy as np
import torch
import torch.nn.functional as F

from setdiff_bench.errors import UsageError

Border = Literal["valid", "same", "reflect"]
BORDERS: tuple[str, ...] = ("valid", "same", "reflect")
Backend = Literal["auto", "torch", "opencv", "exact"]


@functools.lru_cache(maxsize=16)
def gaussian_window_1d(window_size: int = 11, sigma: float = 1.5) -> np.ndarray:
    """Normalised 1-D Gaussian taps ``exp(-d²/2σ²)``, ``d = i - (k-1)/2``; float64 array of length ``k``.

    Equal to dm_pix / torchmetrics / 3DGS ``gaussian()`` and, for σ=1.5, to scipy's 11-tap kernel
    (truncate 3.5) that skimage uses.
    """
    if window_size < 1 or window_size % 2 == 0:
        raise UsageError(f"gaussian window size must be a positive odd integer, got {window_size}")
    if not sigma > 0:
        raise UsageError(f"gaussian sigma must be > 0, got {sigma}")
    offsets = np.arange(window_size, dtype=np.float64) - (window_size - 1) / 2
    taps = np.exp(-0.5 * (offsets / sigma) ** 2)
    return taps / taps.sum()


def use_opencv(*tensors: torch.Tensor, backend: Backend = "auto") -> bool:
    """Whether the OpenCV path applies: CPU float32/float64 tensors that need no gradient (or forced)."""
    if backend in ("torch", "exact"):
        return False
    eligible = all(t.device.type == "cpu" and t.dtype in (torch.float32, torch.float64) for t in tensors)
    needs_grad = torch.is_grad_enabled() and any(t.requires_grad for t in tensors)
    if backend == "opencv":
        if not eligible or needs_grad:
            raise UsageError("backend='opencv' needs CPU float32/float64 tensors without gradients")
        return True
    if backend != "auto":
        raise UsageError(f"unknown filter backend {backend!r}; expected 'auto', 'torch', 'opencv' or 'exact'")
    return eligible and not needs_grad


def blur_torch(maps: torch.Tensor, window_size: int, sigma: float, border: Border) -> torch.Tensor:
    """Differentiable separable Gaussian filter with ``conv2d`` (any device, any float dtype).

    Args:
        maps: ``(B, C, H, W)`` tensor; every channel is filtered independently.
        window_size, sigma: Gaussian window (taps, standard deviation in pixels).
        border: ``"valid"`` → ``(B, C, H-k+1, W-k+1)``; ``"same"`` (zero padding) and ``"reflect"``
            → ``(B, C, H, W)``.
    """
    channels = maps.shape[1]
    taps = torch.as_tensor(gaussian_window_1d(window_size, sigma), dtype=maps.dtype, device=maps.device)
    pad = window_size // 2 if border == "same" else 0
    if border == "reflect":
        half = window_size // 2
        maps = F.pad(maps, (half, half, half, half), mode="reflect")
    rows = taps.view(1, 1, 1, window_size).expand(channels, 1, 1, window_size)
    cols = taps.view(1, 1, window_size, 1).expand(channels, 1, window_size, 1)
    out = F.conv2d(maps, rows, padding=(0, pad), groups=channels)
    return F.conv2d(out, cols, padding=(pad, 0), groups=channels)


def blur_exact(maps: torch.Tensor, window_size: int, sigma: float, border: Border) -> torch.Tensor:
    """:func:`blur_torch`'s filter with the same bits on every CPU (differentiable, any device).

    Each axis is ``Σₖ tapₖ · shiftₖ(maps)``, accumulated from ``k = 0`` upwards with one rounding per
    multiply and per add (no fused multiply-add, no reduction whose order depends on the vector width);
    autograd's backward is made of the same element-wise operations.

    Args, returns: as :func:`blur_torch`.
    """
    taps = [float(t) for t in gaussian_window_1d(window_size, sigma)]  # rounded to the maps' dtype
    half = window_size // 2
    if border == "reflect":
        maps = F.pad(maps, (half, half, half, half), mode="reflect")
    elif border == "same":
        maps = F.pad(maps, (half, half, half, half))
    height = maps.shape[-2] - window_size + 1
    width = maps.shape[-1] - window_size + 1
    rows = maps[..., 0:width] * taps[0]
    for k in range(1, window_size):
        rows = rows + maps[..., k : k + width] * taps[k]
    out = rows[..., 0:height, :] * taps[0]
    for k in range(1, window_size):
        out = out + rows[..., k : k + height, :] * taps[k]
    return out


def blur_opencv(
    plane: np.ndarray, window_size: int, sigma: float, border: Border, dst: np.ndarray | None = None
) -> np.ndarray:
    """OpenCV separable Gaussian filter of one ``(H, W)`` float32/float64 plane.

    Zero padding (``BORDER_CONSTANT``) for ``"same"``, ``BORDER_REFLECT_101`` for ``"reflect"``; for
    ``"valid"`` the ``k//2`` border rows and columns are cropped (a view), so the padding never reaches the
    result.  ``dst`` (``(H, W)``, same dtype, not aliasing ``plane``) receives the full-size output.

    Returns:
        ``(H', W')`` filtered plane (a view of ``dst`` when given).
    """
    taps = gaussian_window_1d(window_size, sigma).astype(plane.dtype)
    depth = cv2.CV_32F if plane.dtype == np.float32 else cv2.CV_64F
    border_type = cv2.BORDER_REFLECT_101 if border == "reflect" else cv2.BORDER_CONSTANT
    out = cv2.sepFilter2D(plane, depth, taps, taps, dst=dst, borderType=border_type)
    if border == "valid":
        half = window_size // 2
        out = out[half : out.shape[0] - half, half : out.shape[1] - half]
    return out
