"""PSNR against plain numpy transcriptions of the definitions (per image, masked, EUVS psnr_mask)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from setdiff_bench.errors import ImageError
from setdiff_bench.metrics.psnr import mse, psnr, psnr_euvs

from .photos import add_noise, photo_batch, random_images


def numpy_psnr(pred: np.ndarray, target: np.ndarray) -> float:
    """``10·log10(1 / mean((p - t)²))`` for one (C, H, W) image."""
    return 10.0 * math.log10(1.0 / float(np.mean((pred - target) ** 2)))


def test_psnr_equals_numpy_per_image() -> None:
    target = photo_batch()
    pred = add_noise(target, 0.05)
    expected = [numpy_psnr(p, t) for p, t in zip(pred.numpy(), target.numpy())]
    np.testing.assert_allclose(psnr(pred, target).numpy(), expected, rtol=0, atol=1e-10)


def test_psnr_float32_matches_float64_reference() -> None:
    target = random_images((3, 3, 40, 50), seed=1)
    pred = random_images((3, 3, 40, 50), seed=2)
    expected = [numpy_psnr(p, t) for p, t in zip(pred.numpy(), target.numpy())]
    got = psnr(pred.float(), target.float())
    assert got.dtype == torch.float32
    np.testing.assert_allclose(got.numpy(), expected, atol=1e-4)


def test_known_value_and_data_range() -> None:
    target = torch.zeros(1, 3, 4, 4, dtype=torch.float64)
    pred = torch.full_like(target, 0.1)  # MSE = 0.01 → exactly 20 dB
    assert psnr(pred, target).item() == pytest.approx(20.0, abs=1e-12)
    assert psnr(pred * 255, target * 255, data_range=255.0).item() == pytest.approx(20.0, abs=1e-12)
    assert math.isinf(psnr(target, target).item())


def test_masked_psnr_uses_only_valid_pixels() -> None:
    target = photo_batch()
    pred = add_noise(target, 0.1, seed=3)
    generator = torch.Generator().manual_seed(4)
    mask = torch.rand(2, 1, *target.shape[-2:], generator=generator) > 0.4
    expected = []
    for p, t, m in zip(pred.numpy(), target.numpy(), mask.numpy()):
        valid = np.broadcast_to(m, p.shape)
        expected.append(10.0 * math.log10(1.0 / float(np.mean((p[valid] - t[valid]) ** 2))))
    np.testing.assert_allclose(psnr(pred, target, mask).numpy(), expected, atol=1e-10)
    np.testing.assert_allclose(psnr_euvs(pred, target, mask.double()).numpy(), expected, atol=1e-10)


def test_masked_out_errors_do_not_count() -> None:
    target = photo_batch()
    pred = target.clone()
    pred[:, :, :10] = 1.0 - pred[:, :, :10]
    mask = torch.ones(2, 1, *target.shape[-2:], dtype=torch.bool)
    mask[:, :, :10] = False
    assert torch.isinf(psnr(pred, target, mask)).all()
    assert torch.isnan(mse(pred, target, torch.zeros_like(mask))).all()


def test_dataset_mean_of_per_image_psnr_exceeds_pooled() -> None:
    target = photo_batch()
    pred = torch.stack([add_noise(target[0], 0.01), add_noise(target[1], 0.2)])
    pooled = 10 * math.log10(1 / float(torch.mean((pred - target) ** 2)))
    assert psnr(pred, target).mean().item() > pooled  # Jensen: the documented per-image mean is higher


@pytest.mark.parametrize(
    ("pred_shape", "target_shape"), [((1, 3, 8, 8), (1, 3, 8, 9)), ((3, 8, 8), (3, 8, 8))]
)
def test_bad_shapes_raise(pred_shape: tuple[int, ...], target_shape: tuple[int, ...]) -> None:
    with pytest.raises(ImageError, match=r"psnr|mse"):
        psnr(torch.zeros(pred_shape), torch.zeros(target_shape))


def test_bad_mask_raises() -> None:
    with pytest.raises(ImageError, match="mask"):
        psnr(torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 8), torch.ones(1, 3, 8, 8, dtype=torch.bool))
