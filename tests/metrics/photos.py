"""Test images: real photographs bundled with scikit-image, cropped, and graded distortions of them."""

from __future__ import annotations

import numpy as np
import torch
from skimage import data


def photo_batch(
    names: tuple[str, ...] = ("astronaut", "coffee"),
    size: tuple[int, int] = (256, 320),
    dtype: torch.dtype = torch.float64,
) -> torch.Tensor:
    """``(V, 3, H, W)`` crops in [0, 1] of scikit-image's bundled colour photographs."""
    crops = []
    for name in names:
        image = getattr(data, name)()[: size[0], : size[1]]
        crops.append(torch.from_numpy(image.astype(np.float64) / 255.0).permute(2, 0, 1))
    return torch.stack(crops).to(dtype)


def add_noise(images: torch.Tensor, sigma: float, seed: int = 0) -> torch.Tensor:
    """Add Gaussian noise of standard deviation ``sigma`` and clip to [0, 1]."""
    generator = torch.Generator().manual_seed(seed)
    noise = torch.randn(images.shape, generator=generator, dtype=torch.float64).to(images.dtype)
    return (images + sigma * noise).clamp(0, 1)


def random_images(shape: tuple[int, ...], seed: int, dtype: torch.dtype = torch.float64) -> torch.Tensor:
    """Uniform random images in [0, 1]."""
    generator = torch.Generator().manual_seed(seed)
    return torch.rand(shape, generator=generator, dtype=torch.float64).to(dtype)
