"""The metric registry: directions, lazy loading, presets, and that each spec selects its variant."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.metrics import METRICS, PRESETS, get_metric, preset
from setdiff_bench.metrics.lpips import lpips
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.metrics.ssim import ssim, ssim_euvs
from setdiff_bench.metrics.warp import PAPER_SCALE

from .photos import add_noise, photo_batch


def test_directions() -> None:
    higher = {name for name, spec in METRICS.items() if spec.higher_is_better}
    assert higher == {"psnr", "ssim", "ssim_same", "psnr_euvs", "ssim_euvs", "cos_dinov2", "final_score"}
    assert get_metric("warp").scope == "sequence"
    assert get_metric("warp").kwargs["scale"] == PAPER_SCALE
    assert {name for name, spec in METRICS.items() if spec.scope == "profile"} == {
        "cos_dinov2",
        "final_score",
    }
    assert {name for name, spec in METRICS.items() if spec.scope == "distribution"} == {"fid", "kid"}


# The tables' label, decimals and arrow of every metric, written out by hand (the leaderboards' format):
# every variant of a metric is displayed as the metric.
DISPLAY = {
    **dict.fromkeys(("psnr", "psnr_euvs"), ("PSNR", 2, "↑")),
    **dict.fromkeys(("ssim", "ssim_same", "ssim_euvs"), ("SSIM", 3, "↑")),
    **dict.fromkeys(("lpips", "lpips_vgg", "lpips_vgg_unscaled", "lpips_euvs"), ("LPIPS", 3, "↓")),
    "warp": ("Warp", 1, "↓"),
    "cos_dinov2": ("Cos", 3, "↑"),
    "final_score": ("Final", 3, "↑"),
    "fid": ("FID", 2, "↓"),
    "kid": ("KID", 4, "↓"),
}


def test_every_metric_declares_its_display() -> None:
    for name, spec in METRICS.items():
        assert spec.label and isinstance(spec.decimals, int) and spec.decimals >= 0, name
        assert isinstance(spec.higher_is_better, bool), name
    assert {name: (s.label, s.decimals, s.arrow) for name, s in METRICS.items()} == DISPLAY


def test_listing_imports_nothing_heavy() -> None:
    code = (
        "import sys, setdiff_bench.metrics as m; m.METRICS; "
        "print(any(k in sys.modules for k in ('cv2', 'safetensors', 'setdiff_bench.metrics.lpips')))"
    )
    assert (
        subprocess.run(
            [sys.executable, "-c", code], capture_output=True, text=True, check=True
        ).stdout.strip()
        == "False"
    )


def test_specs_select_their_variant() -> None:
    target = photo_batch(size=(40, 48), dtype=torch.float32)
    pred = add_noise(target, 0.05)
    mask = torch.ones(2, 1, 40, 48, dtype=torch.bool)
    mask[:, :, :20] = False
    torch.testing.assert_close(get_metric("psnr").compute(pred, target), psnr(pred, target))
    torch.testing.assert_close(get_metric("psnr").compute(pred, target, mask), psnr(pred, target, mask))
    torch.testing.assert_close(
        get_metric("ssim_same").compute(pred, target), ssim(pred, target, border="same")
    )
    torch.testing.assert_close(
        get_metric("ssim_euvs").compute(pred, target, mask), ssim_euvs(pred, target, mask)
    )
    torch.testing.assert_close(
        get_metric("ssim_euvs").compute(pred, target), ssim(pred, target, border="same")
    )
    torch.testing.assert_close(
        get_metric("lpips_vgg_unscaled").compute(pred, target),
        lpips(pred, target, net="vgg", rescale_input=False),
    )
    for spec in preset("euvs_official") + preset("standard") + preset("gaussian_splatting"):
        values = spec.compute(pred, target, mask)
        assert values.shape == (2,) and torch.isfinite(values).all()
    assert all(callable(spec.load()) for spec in METRICS.values())
    assert set(PRESETS) == {"standard", "gaussian_splatting", "euvs_official"}


def test_unknown_names_and_misuse() -> None:
    with pytest.raises(UsageError, match="known: psnr"):
        get_metric("psnrr")
    with pytest.raises(UsageError, match="preset"):
        preset("nope")
    with pytest.raises(UsageError, match="sequence"):
        get_metric("warp").compute(torch.zeros(1, 3, 16, 16), torch.zeros(1, 3, 16, 16))
    with pytest.raises(UsageError, match="profile metric"):
        get_metric("final_score").compute(torch.zeros(1, 3, 16, 16), torch.zeros(1, 3, 16, 16))
