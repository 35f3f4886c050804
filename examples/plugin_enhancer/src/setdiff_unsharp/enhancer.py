"""An unsharp mask: ``render + amount * (render - blur(render))``, clipped to [0, 1], one target at a time.

It uses only the targets' renders; a real method would also use ``packet.references`` (clean images of
nearby views), the C-maps (each pixel's 3D point) and the cameras: docs/api.md lists every field.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from setdiff_bench.enhancers.base import enhancer_repr
from setdiff_bench.errors import UsageError
from setdiff_bench.types import Packet


def gaussian_kernel(sigma: float) -> torch.Tensor:
    """``(2r + 1,)`` float32 normalised Gaussian weights, radius ``r = int(3 * sigma + 0.5)`` pixels."""
    radius = int(3.0 * sigma + 0.5)
    offsets = torch.arange(-radius, radius + 1, dtype=torch.float64)
    weights = torch.exp(-0.5 * (offsets / sigma) ** 2)
    return (weights / weights.sum()).float()


def gaussian_blur(images: torch.Tensor, sigma: float) -> torch.Tensor:
    """``(V, C, H, W)`` blurred by a separable Gaussian of ``sigma`` pixels, borders mirrored (``d c b | a b c d``)."""
    kernel = gaussian_kernel(sigma).to(images.device)
    radius = (len(kernel) - 1) // 2
    channels = images.shape[1]
    rows = kernel.view(1, 1, 1, -1).expand(channels, 1, 1, -1)
    cols = kernel.view(1, 1, -1, 1).expand(channels, 1, -1, 1)
    padded = F.pad(images, (radius, radius, 0, 0), mode="reflect")
    blurred = F.conv2d(padded, rows, groups=channels)
    padded = F.pad(blurred, (0, 0, radius, radius), mode="reflect")
    return F.conv2d(padded, cols, groups=channels)


class UnsharpMaskEnhancer:
    """Sharpens every target render; the ``Enhancer`` protocol of setdiff-bench.

    Attributes:
        name: the method's registry name.
        options: what the run manifest records.
    """

    name = "unsharp"

    def __init__(self, amount: float, sigma: float) -> None:
        if not amount >= 0.0:
            raise UsageError(f"amount must be >= 0, got {amount}", parameter="amount")
        if not sigma > 0.0 or not math.isfinite(sigma):
            raise UsageError(f"sigma must be a positive number of pixels, got {sigma}", parameter="sigma")
        self.amount = float(amount)
        self.sigma = float(sigma)
        self.options = {"amount": self.amount, "sigma": self.sigma}

    def __repr__(self) -> str:
        return enhancer_repr(self, amount=self.amount, sigma=self.sigma)

    def enhance(self, packet: Packet) -> torch.Tensor:
        """``(M, 3, H, W)`` float32 in [0, 1], one image per target in packet order (ground truth and masks
        never reach an enhancer)."""
        renders = packet.targets.images.to(torch.float32)
        radius = int(3.0 * self.sigma + 0.5)
        if radius >= min(renders.shape[-2:]):  # reflect padding needs a kernel smaller than the image
            raise UsageError(
                f"sigma {self.sigma} px is too wide for {renders.shape[-1]}x{renders.shape[-2]} images",
                parameter="sigma",
            )
        sharpened = renders + self.amount * (renders - gaussian_blur(renders, self.sigma))
        return sharpened.clamp(0.0, 1.0)


def create(amount: float = 1.0, sigma: float = 1.0) -> UnsharpMaskEnhancer:
    """The factory ``SPEC`` names: ``run -o amount=... -o sigma=...`` (or ``create_enhancer("unsharp", ...)``)."""
    return UnsharpMaskEnhancer(amount, sigma)
