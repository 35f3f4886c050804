"""Registry of metric specs (name, direction, display, lazy function) and named presets.

Each metric is declared once, here: its ranking direction and how tables show it (label, decimals,
arrow) live on its :class:`MetricSpec`, and leaderboards, ablation tables and plots read them from it.
Specs reference their function as ``"module:attr"`` so that listing metrics imports nothing heavy
(LPIPS weights, OpenCV flow).  Image metrics are called as ``fn(pred, target, mask=mask, **kwargs)`` on
``(V, 3, H, W)`` batches and return ``(V,)``; the sequence metric (warp error) is called as
``fn(frames, reference, mask, **kwargs)`` per sequence and returns a 0-dim tensor.  The profile metrics
(EUVS's DINOv2 cosine and ``Final_Score``) are per-target values that ``setdiff-bench evaluate`` computes
from DINOv2 features and the EUVS metrics (:mod:`setdiff_bench.evaluation.profile_scoring`); ``run`` cannot select them.
The distribution metrics (FID, KID) compare two sets of Inception features, ``fn(features_a, features_b)``
(:mod:`setdiff_bench.metrics.distribution`); ``run`` / ``evaluate --inception FILE`` compute them per block.

Presets (the metric sets papers report; docs/metrics.md, "Presets"):

- ``standard``: per-image PSNR, SSIM with ``valid`` border (tf / dm_pix / skimage), LPIPS-alex on [-1, 1].
- ``gaussian_splatting``: the 3DGS repo's ``metrics.py``: PSNR, SSIM ``same`` zero-padded border, LPIPS-vgg
  fed [0, 1] unscaled.
- ``euvs_official``: EUVS ``metrics_with_dyn_masks.py``: masked PSNR, SSIM of mask-multiplied images over
  the whole ``same`` map, LPIPS-alex of mask-multiplied images fed [0, 1] unscaled.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.runtime.lazy import load_attribute


@dataclass(frozen=True)
class MetricSpec:
    """One metric.

    Attributes:
        name: registry key, also the column name in results.
        higher_is_better: ranking direction (PSNR/SSIM True; LPIPS/warp error False); tables show it as
            :attr:`arrow` and bold the best value by it.
        function: ``"module:attr"`` of the implementation.
        scope: ``"image"`` (per target image), ``"sequence"`` (per ordered sequence of frames),
            ``"profile"`` (per target, computed by profile scoring only) or ``"distribution"`` (per set
            of images against a set of recorded frames, ``run`` / ``evaluate --inception``).
        kwargs: fixed keyword arguments that select the variant (border, net, input scaling, scale...).
        unit: unit of the values, for tables.
        needs_mask: the variant is defined with a mask (EUVS); without one, an all-ones mask is used.
        description: one line for listings.
        label: column header in tables (``"PSNR"`` for every PSNR variant; the table's caption or profile
            says which variant).
        decimals: digits after the point in tables; the best value per column is decided on the value
            rounded to them.
    """

    name: str
    higher_is_better: bool
    function: str
    scope: Literal["image", "sequence", "profile", "distribution"] = "image"
    kwargs: Mapping[str, Any] = field(default_factory=dict)
    unit: str = ""
    needs_mask: bool = False
    description: str = ""
    label: str = field(kw_only=True)
    decimals: int = field(kw_only=True)

    @property
    def arrow(self) -> str:
        """``"↑"`` when higher is better, ``"↓"`` otherwise."""
        return "↑" if self.higher_is_better else "↓"

    def load(self) -> Callable[..., torch.Tensor]:
        """Import and return the implementation."""
        return load_attribute(self.function, f"metric {self.name!r}")

    def compute(
        self, pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor | None = None
    ) -> torch.Tensor:
        """Image metric on ``(V, 3, H, W)`` batches with an optional ``(V, 1, H, W)`` mask → ``(V,)``."""
        if self.scope != "image":
            raise UsageError(
                f"metric {self.name} is a {self.scope} metric, not an image metric; "
                + {
                    "sequence": "call its function per sequence",
                    "distribution": "call its function on two feature sets (run / evaluate --inception)",
                }.get(self.scope, "setdiff-bench evaluate computes it")
            )
        if mask is None and self.needs_mask:
            mask = torch.ones(pred.shape[0], 1, *pred.shape[-2:], dtype=torch.bool, device=pred.device)
        return self.load()(pred, target, mask=mask, **self.kwargs)


def _spec(
    name: str,
    higher: bool,
    label: str,
    decimals: int,
    function: str,
    unit: str,
    description: str,
    **kwargs: Any,
) -> MetricSpec:
    needs_mask = name.endswith("_euvs")
    return MetricSpec(
        name,
        higher,
        function,
        "image",
        MappingProxyType(kwargs),
        unit,
        needs_mask,
        description,
        label=label,
        decimals=decimals,
    )


_PSNR = "setdiff_bench.metrics.psnr:psnr"
_SSIM = "setdiff_bench.metrics.ssim:ssim"
_LPIPS = "setdiff_bench.metrics.lpips:lpips"
_DINOV2 = "setdiff_bench.metrics.dinov2"
_DISTRIBUTION = "setdiff_bench.metrics.distribution"

METRICS: Mapping[str, MetricSpec] = MappingProxyType(
    {
        spec.name: spec
        for spec in (
            _spec(
                "psnr",
                True,
                "PSNR",
                2,
                _PSNR,
                "dB",
                "per-image PSNR, data range 1; masked: MSE over valid pixels",
            ),
            _spec(
                "ssim",
                True,
                "SSIM",
                3,
                _SSIM,
                "",
                "SSIM, Gaussian 11/1.5, valid border (tf/dm_pix/skimage)",
                border="valid",
            ),
            _spec(
                "ssim_same",
                True,
                "SSIM",
                3,
                _SSIM,
                "",
                "SSIM with zero-padded same border (3DGS)",
                border="same",
            ),
            _spec(
                "lpips",
                False,
                "LPIPS",
                3,
                _LPIPS,
                "",
                "LPIPS v0.1 AlexNet, input [0,1] mapped to [-1,1]",
                net="alex",
            ),
            _spec(
                "lpips_vgg",
                False,
                "LPIPS",
                3,
                _LPIPS,
                "",
                "LPIPS v0.1 VGG16, input [0,1] mapped to [-1,1]",
                net="vgg",
            ),
            _spec(
                "lpips_vgg_unscaled",
                False,
                "LPIPS",
                3,
                _LPIPS,
                "",
                "LPIPS v0.1 VGG16 fed [0,1] unscaled (3DGS metrics.py)",
                net="vgg",
                rescale_input=False,
            ),
            _spec(
                "psnr_euvs", True, "PSNR", 2, "setdiff_bench.metrics.psnr:psnr_euvs", "dB", "EUVS psnr_mask"
            ),
            _spec(
                "ssim_euvs",
                True,
                "SSIM",
                3,
                "setdiff_bench.metrics.ssim:ssim_euvs",
                "",
                "EUVS ssim_mask (mask-multiplied, same border)",
            ),
            _spec(
                "lpips_euvs",
                False,
                "LPIPS",
                3,
                "setdiff_bench.metrics.lpips:lpips_euvs",
                "",
                "EUVS lpips_mask (alex, [0,1] unscaled)",
            ),
            MetricSpec(
                "warp",
                False,
                "setdiff_bench.metrics.warp:warp_error",
                "sequence",
                MappingProxyType({"scale": 255.0**2}),
                "MSE on 0-255 scale",
                False,
                "warp error (Lai et al. 2018), flow+occlusion from ground truth, DeepFlow",
                label="Warp",
                decimals=1,
            ),
            MetricSpec(
                "cos_dinov2",
                True,
                f"{_DINOV2}:masked_cosine",
                "profile",
                MappingProxyType({}),
                "",
                False,
                "EUVS Cos_Similarity: mean DINOv2 ViT-B/14 patch cosine (evaluate --dinov2)",
                label="Cos",
                decimals=3,
            ),
            MetricSpec(
                "final_score",
                True,
                f"{_DINOV2}:final_score",
                "profile",
                MappingProxyType({}),
                "",
                False,
                "EUVS Final_Score: 0.25 SSIM + 0.15 PSNR + 0.35 (1 - LPIPS) + 0.25 Cos (evaluate --dinov2)",
                label="Final",
                decimals=3,
            ),
            MetricSpec(
                "fid",
                False,
                f"{_DISTRIBUTION}:fid",
                "distribution",
                MappingProxyType({}),
                "",
                False,
                "FID: Frechet distance of Inception-v3 pool3 statistics vs the recorded frames (--inception)",
                label="FID",
                decimals=2,
            ),
            MetricSpec(
                "kid",
                False,
                f"{_DISTRIBUTION}:kid",
                "distribution",
                MappingProxyType({}),
                "",
                False,
                "KID: unbiased MMD^2, cubic polynomial kernel, Inception-v3 pool3 vs the recorded frames "
                "(--inception)",
                label="KID",
                decimals=4,
            ),
        )
    }
)

PRESETS: Mapping[str, tuple[str, ...]] = MappingProxyType(
    {
        "standard": ("psnr", "ssim", "lpips"),
        "gaussian_splatting": ("psnr", "ssim_same", "lpips_vgg_unscaled"),
        "euvs_official": ("psnr_euvs", "ssim_euvs", "lpips_euvs"),
    }
)


def get_metric(name: str) -> MetricSpec:
    """The spec called ``name``; :class:`~setdiff_bench.errors.UsageError` listing the known names otherwise."""
    try:
        return METRICS[name]
    except KeyError:
        raise UsageError(f"unknown metric {name!r}; known: {', '.join(METRICS)}") from None


def preset(name: str) -> tuple[MetricSpec, ...]:
    """The specs of a named preset (``standard``, ``gaussian_splatting``, ``euvs_official``)."""
    try:
        return tuple(METRICS[metric] for metric in PRESETS[name])
    except KeyError:
        raise UsageError(f"unknown metric preset {name!r}; known: {', '.join(PRESETS)}") from None
