"""Structural similarity (Wang et al., IEEE TIP 2004) per image, with every choice explicit.

``SSIM = ((2μxμy + C1)(2σxy + C2)) / ((μx² + μy² + C1)(σx² + σy² + C2))``, ``C1 = (K1·L)²``,
``C2 = (K2·L)²``; local statistics under a separable Gaussian window (11 taps, σ 1.5) with population
covariance; per channel, then averaged over channels and pixels.  Choices (docs/metrics.md, "SSIM"):

- ``border="valid"`` (default): only pixels whose window lies inside the image, ``(H-10)×(W-10)``; equal
  to tf.image.ssim / dm_pix / skimage(gaussian_weights=True, sigma=1.5,
  use_sample_covariance=False, data_range=1).  Unlike dm_pix we do not clamp variances at ε² (the clamp
  only touches float-rounding negatives and would break the 3DGS formula below).
- ``border="same"``: zero-padded ``H×W`` map, exactly graphdeco-inria/gaussian-splatting
  ``utils/loss_utils.py:ssim`` (also its training loss, ``1 - ssim``).
- ``border="reflect"``: mirror-padded ``H×W`` map averaged whole, which is what torchmetrics 1.9
  ``structural_similarity_index_measure(data_range=1)`` does (it reflect-pads by 5 and, unlike the older
  release described in docs/metrics.md, no longer crops the padded border before the mean; it also clamps
  variances at 0, which only matters for float-rounding negatives).
- ``grayscale=True``: SSIM of BT.601 luma ``0.299R + 0.587G + 0.114B`` (MATLAB ``rgb2gray``, the Y of
  YIQ that pyiqa uses) instead of the RGB channel mean.
- ``mask``: mean of the SSIM map over valid pixels only (the map is cropped like the image for
  ``valid``).  The EUVS-official variant (:func:`ssim_euvs`) instead multiplies both images by the mask
  and averages the whole ``same`` map.

Written by hand because no installed library offers both borders, masks and gradients at once; on
CPU without gradients the filtering runs through OpenCV (see :mod:`.gaussian_filter`).
"""

from __future__ import annotations

import numpy as np
import torch

from setdiff_bench.errors import ImageError, UsageError
from setdiff_bench.metrics._inputs import check_mask, check_pair
from setdiff_bench.metrics.gaussian_filter import (
    BORDERS,
    Backend,
    Border,
    blur_exact,
    blur_opencv,
    blur_torch,
    use_opencv,
)

#: BT.601 luma weights used by ``grayscale=True``.
LUMA_BT601 = (0.299, 0.587, 0.114)


def to_luma(images: torch.Tensor) -> torch.Tensor:
    """``(V, 3, H, W)`` RGB → ``(V, 1, H, W)`` BT.601 luma, same dtype and device."""
    if images.shape[1] != 3:
        raise ImageError(f"ssim: grayscale needs 3-channel RGB images, got {images.shape[1]} channels")
    weights = torch.tensor(LUMA_BT601, dtype=images.dtype, device=images.device).view(1, 3, 1, 1)
    return (images * weights).sum(dim=1, keepdim=True)


def _combine(
    mu_x: torch.Tensor, mu_y: torch.Tensor, squares: torch.Tensor, cross: torch.Tensor, c1: float, c2: float
) -> torch.Tensor:
    """SSIM map from the local means of x, y, x² + y² and x·y (any equal shapes).

    Filtering ``x² + y²`` once is enough because only ``σx² + σy²`` enters the formula (the filter is
    linear), which saves a fifth of the filtering work.
    """
    mu_xy = mu_x * mu_y
    mu_squares = mu_x * mu_x + mu_y * mu_y
    numerator = (2 * mu_xy + c1) * (2 * (cross - mu_xy) + c2)
    denominator = (mu_squares + c1) * (squares - mu_squares + c2)
    return numerator / denominator


def ssim_map(
    pred: torch.Tensor,
    target: torch.Tensor,
    *,
    border: Border = "valid",
    window_size: int = 11,
    sigma: float = 1.5,
    k1: float = 0.01,
    k2: float = 0.03,
    data_range: float = 1.0,
    backend: Backend = "auto",
) -> torch.Tensor:
    """Per-pixel, per-channel SSIM map.

    Args:
        pred, target: ``(V, C, H, W)`` float images in [0, ``data_range``].
        border: ``"valid"`` → ``(V, C, H-k+1, W-k+1)``; ``"same"`` (zero padding) or ``"reflect"``
            → ``(V, C, H, W)``.
        window_size, sigma: Gaussian window taps and standard deviation (pixels).
        k1, k2, data_range: stability constants ``C1 = (k1·L)²``, ``C2 = (k2·L)²``.
        backend: ``"auto"`` (OpenCV on CPU without gradients, else torch), ``"torch"``, ``"opencv"`` or
            ``"exact"`` (the same bits on every CPU; what scene fits use, see :mod:`.gaussian_filter`).

    Returns:
        ``(V, C, H', W')`` SSIM values (1 = identical); differentiable on the torch path.
    """
    check_pair(pred, target, "ssim")
    if border not in BORDERS:
        raise UsageError(f"ssim: border must be one of {', '.join(BORDERS)}; got {border!r}")
    if border != "same" and min(pred.shape[-2:]) < window_size:
        raise ImageError(
            f"ssim: images {tuple(pred.shape[-2:])} are smaller than the {window_size}-pixel window"
        )
    c1, c2 = (k1 * data_range) ** 2, (k2 * data_range) ** 2
    dtype = torch.promote_types(pred.dtype, target.dtype)
    pred, target = pred.to(dtype), target.to(dtype)
    if use_opencv(pred, target, backend=backend):
        return _ssim_map_opencv(pred, target, border, window_size, sigma, c1, c2)
    channels = pred.shape[1]
    stacked = torch.cat([pred, target, pred * pred + target * target, pred * target], dim=1)
    blur = blur_exact if backend == "exact" else blur_torch
    means = blur(stacked, window_size, sigma, border).split(channels, dim=1)
    return _combine(*means, c1, c2)


def _ssim_map_opencv(
    pred: torch.Tensor,
    target: torch.Tensor,
    border: Border,
    window_size: int,
    sigma: float,
    c1: float,
    c2: float,
) -> torch.Tensor:
    """SSIM map with OpenCV filtering and in-place numpy arithmetic, one ``(H, W)`` plane at a time.

    Same algebra as :func:`_combine`.  Five plane-sized work buffers are allocated once per call and
    reused (fresh multi-megabyte temporaries per operation cost page faults that doubled the run time).
    """
    x_all = np.ascontiguousarray(pred.detach().numpy())
    y_all = np.ascontiguousarray(target.detach().numpy())
    v, c, h, w = x_all.shape
    half = window_size // 2 if border == "valid" else 0
    out = np.empty((v, c, h - 2 * half, w - 2 * half), dtype=x_all.dtype)
    mu_x, mu_y, squares, cross, work = (np.empty((h, w), dtype=x_all.dtype) for _ in range(5))
    crop = (slice(half, h - half), slice(half, w - half))
    for image in range(v):
        for channel in range(c):
            x, y = x_all[image, channel], y_all[image, channel]
            np.multiply(x, x, out=squares)
            np.multiply(y, y, out=work)
            squares += work
            np.multiply(x, y, out=cross)
            for plane, dst in ((x, mu_x), (y, mu_y), (squares, work), (cross, squares)):
                blur_opencv(plane, window_size, sigma, "same" if border == "valid" else border, dst=dst)
            mx, my, sq, cr = mu_x[crop], mu_y[crop], work[crop], squares[crop]
            mu_xy = np.multiply(mx, my, out=cross[crop])
            mx *= mx
            my *= my
            mx += my  # μx² + μy²
            cr -= mu_xy
            cr *= 2
            cr += c2  # 2σxy + C2
            mu_xy *= 2
            mu_xy += c1  # 2μxμy + C1
            cr *= mu_xy  # numerator
            sq -= mx
            sq += c2  # σx² + σy² + C2
            mx += c1
            sq *= mx  # denominator
            np.divide(cr, sq, out=out[image, channel])
    return torch.from_numpy(out)


def reduce_map(
    values: torch.Tensor, mask: torch.Tensor | None, border: Border, window_size: int
) -> torch.Tensor:
    """Mean of a ``(V, C, H', W')`` SSIM map per image, optionally over the valid pixels of a mask.

    Args:
        values: SSIM map from :func:`ssim_map`.
        mask: ``None`` or a float ``(V, 1, H, W)`` 0/1 mask at the *image* size; cropped by ``k//2`` for
            the ``valid`` border so that it lines up with the map.  An empty mask gives NaN.
        border, window_size: as passed to :func:`ssim_map`.

    Returns:
        ``(V,)`` mean SSIM.
    """
    if mask is None:
        return values.flatten(1).mean(dim=1)
    if border == "valid":
        half = window_size // 2
        mask = mask[:, :, half : mask.shape[2] - half, half : mask.shape[3] - half]
    per_pixel = values.mean(dim=1, keepdim=True)
    return (per_pixel * mask).flatten(1).sum(dim=1) / mask.flatten(1).sum(dim=1)


def ssim(
    pred: torch.Tensor,
    target: torch.Tensor,
    *,
    border: Border = "valid",
    grayscale: bool = False,
    mask: torch.Tensor | None = None,
    window_size: int = 11,
    sigma: float = 1.5,
    k1: float = 0.01,
    k2: float = 0.03,
    data_range: float = 1.0,
    backend: Backend = "auto",
) -> torch.Tensor:
    """Mean SSIM per image (see the module docstring for every convention).

    Args:
        pred, target: ``(V, C, H, W)`` float images in [0, ``data_range``], same shape and device.
        border: ``"valid"`` (tf/dm_pix/skimage), ``"same"`` (3DGS, zero padding) or ``"reflect"``
            (torchmetrics 1.9).
        grayscale: SSIM of BT.601 luma instead of the mean over RGB channels.
        mask: optional ``(V, 1, H, W)`` bool/0-1 mask, True = evaluate: mean of the map over valid pixels.
        window_size, sigma, k1, k2, data_range: the SSIM constants (defaults: 11, 1.5, 0.01, 0.03, 1).
        backend: filter implementation, see :func:`ssim_map`.

    Returns:
        ``(V,)`` SSIM in [-1, 1]; differentiable when inputs require grad (D-SSIM loss = ``1 - ssim``).
    """
    check_pair(pred, target, "ssim")
    weights = None if mask is None else check_mask(mask, pred, "ssim")
    if grayscale:
        pred, target = to_luma(pred), to_luma(target)
    values = ssim_map(
        pred,
        target,
        border=border,
        window_size=window_size,
        sigma=sigma,
        k1=k1,
        k2=k2,
        data_range=data_range,
        backend=backend,
    )
    return reduce_map(values, weights, border, window_size)


def ssim_euvs(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """EUVS-official ``ssim_mask``: 3DGS SSIM (``same`` border) of ``pred·mask`` vs ``target·mask``.

    The mean runs over the whole map, masked-out area included (so it is not a true masked SSIM);
    reproduced on purpose to match published EUVS numbers (docs/datasets.md, "EUVS official metric script").

    Args:
        pred, target: ``(V, 3, H, W)`` images in [0, 1].
        mask: ``(V, 1, H, W)`` mask, 1 = static (evaluated).

    Returns:
        ``(V,)`` SSIM.
    """
    check_pair(pred, target, "ssim")
    weights = check_mask(mask, pred, "ssim")
    return ssim(pred * weights, target * weights, border="same")
