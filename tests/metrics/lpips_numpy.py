"""An independent LPIPS v0.1 forward pass in numpy (NHWC, Flax-layout kernels), for tests only.

Written from the definition (docs/metrics.md, "LPIPS") and the torchvision layer lists, not
from the module under test: convolutions via sliding windows + tensordot, float64 throughout.
"""

from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

SHIFT = np.array([-0.030, -0.088, -0.188])
SCALE = np.array([0.458, 0.448, 0.450])

# (kernel, stride, padding, max-pool (size, stride) before the conv or None, is LPIPS tap)
ALEX = [
    (11, 4, 2, None, True),
    (5, 1, 2, (3, 2), True),
    (3, 1, 1, (3, 2), True),
    (3, 1, 1, None, True),
    (3, 1, 1, None, True),
]
VGG_BLOCKS = (2, 2, 3, 3, 3)  # convolutions per block; pool before blocks 2-5; tap after each block
VGG = [
    (3, 1, 1, (2, 2) if block and i == 0 else None, i == count - 1)
    for block, count in enumerate(VGG_BLOCKS)
    for i in range(count)
]


def conv2d_nhwc(
    x: np.ndarray, kernel_hwio: np.ndarray, bias: np.ndarray, stride: int, pad: int
) -> np.ndarray:
    """Cross-correlation of (H, W, Cin) with (k, k, Cin, Cout) kernels, zero padding."""
    x = np.pad(x, ((pad, pad), (pad, pad), (0, 0)))
    k = kernel_hwio.shape[0]
    windows = sliding_window_view(x, (k, k), axis=(0, 1))[::stride, ::stride]  # (Ho, Wo, Cin, k, k)
    return np.tensordot(windows, kernel_hwio, axes=([3, 4, 2], [0, 1, 2])) + bias


def max_pool_nhwc(x: np.ndarray, size: int, stride: int) -> np.ndarray:
    return sliding_window_view(x, (size, size), axis=(0, 1))[::stride, ::stride].max(axis=(3, 4))


def lpips_numpy(
    image0: np.ndarray, image1: np.ndarray, weights: dict[str, np.ndarray], net: str, rescale: bool = True
) -> float:
    """LPIPS between two (H, W, 3) images in [0, 1] with torch-layout weights ``convs.i.*``, ``lins.l.weight``."""
    layers = ALEX if net == "alex" else VGG
    feats = []
    for image in (image0, image1):
        x = image.astype(np.float64)
        x = x * 2 - 1 if rescale else x
        x = (x - SHIFT) / SCALE
        taps = []
        for index, (_, stride, pad, pool, tap) in enumerate(layers):
            if pool is not None:
                x = max_pool_nhwc(x, *pool)
            kernel = (
                weights[f"convs.{index}.weight"].astype(np.float64).transpose(2, 3, 1, 0)
            )  # → (k, k, in, out)
            x = np.maximum(
                conv2d_nhwc(x, kernel, weights[f"convs.{index}.bias"].astype(np.float64), stride, pad), 0
            )
            if tap:
                taps.append(x)
        feats.append(taps)
    total = 0.0
    for layer, (f0, f1) in enumerate(zip(*feats)):
        n0 = f0 / (np.sqrt((f0**2).sum(axis=-1, keepdims=True)) + 1e-10)
        n1 = f1 / (np.sqrt((f1**2).sum(axis=-1, keepdims=True)) + 1e-10)
        w = weights[f"lins.{layer}.weight"].astype(np.float64).reshape(-1)
        total += float((((n0 - n1) ** 2) @ w).mean())
    return total
