"""Image and video quality metrics: PSNR, SSIM, LPIPS, warp error, and their registry.

Importing this package is cheap: :data:`METRICS` and :data:`PRESETS` hold lazy ``"module:attr"`` specs;
the implementations (LPIPS weights, OpenCV flow) load on first use.  Direct imports:
``setdiff_bench.metrics.psnr.psnr``, ``.ssim.ssim``, ``.lpips.lpips`` / ``.lpips.load_lpips``,
``.warp.warp_reference`` / ``.warp.warp_error``.
"""

from setdiff_bench.metrics.registry import METRICS, PRESETS, MetricSpec, get_metric, preset

__all__ = ["METRICS", "PRESETS", "MetricSpec", "get_metric", "preset"]
