"""SSIM against skimage, torchmetrics and a transcription of the 3DGS formula; masks, EUVS, gradients."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch
import torch.nn.functional as F
from skimage.metrics import structural_similarity
from torchmetrics.functional.image import structural_similarity_index_measure

from setdiff_bench.errors import ImageError, UsageError
from setdiff_bench.metrics.ssim import ssim, ssim_euvs

from .photos import add_noise, photo_batch, random_images

BACKENDS = ("torch", "opencv")


def skimage_ssim(pred: torch.Tensor, target: torch.Tensor, full: bool = False):
    """The standard SSIM through skimage, one (C, H, W) or (H, W) image."""
    channel_axis = -1 if pred.ndim == 3 else None
    to_np = (lambda t: t.permute(1, 2, 0).numpy()) if pred.ndim == 3 else (lambda t: t.numpy())
    return structural_similarity(
        to_np(pred),
        to_np(target),
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=1,
        channel_axis=channel_axis,
        full=full,
    )


def gaussian_splatting_ssim(img1: torch.Tensor, img2: torch.Tensor) -> torch.Tensor:
    """Direct transcription of graphdeco-inria/gaussian-splatting utils/loss_utils.py ``ssim`` (per image).

    2-D 11×11 window from the outer product of the 1-D Gaussian, conv2d with padding 5 (zeros),
    groups = channels, C1 = 0.01², C2 = 0.03², mean over channels and pixels.
    """
    size, sigma = 11, 1.5
    gauss = torch.tensor(
        [math.exp(-((x - size // 2) ** 2) / float(2 * sigma**2)) for x in range(size)], dtype=img1.dtype
    )
    gauss = gauss / gauss.sum()
    channel = img1.shape[1]
    window = (gauss[:, None] @ gauss[None, :]).expand(channel, 1, size, size).contiguous()
    mu1 = F.conv2d(img1, window, padding=size // 2, groups=channel)
    mu2 = F.conv2d(img2, window, padding=size // 2, groups=channel)
    mu1_sq, mu2_sq, mu1_mu2 = mu1.pow(2), mu2.pow(2), mu1 * mu2
    sigma1_sq = F.conv2d(img1 * img1, window, padding=size // 2, groups=channel) - mu1_sq
    sigma2_sq = F.conv2d(img2 * img2, window, padding=size // 2, groups=channel) - mu2_sq
    sigma12 = F.conv2d(img1 * img2, window, padding=size // 2, groups=channel) - mu1_mu2
    c1, c2 = 0.01**2, 0.03**2
    ssim_map = ((2 * mu1_mu2 + c1) * (2 * sigma12 + c2)) / (
        (mu1_sq + mu2_sq + c1) * (sigma1_sq + sigma2_sq + c2)
    )
    return ssim_map.flatten(1).mean(dim=1)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("dtype", [torch.float64, torch.float32])
def test_valid_border_equals_skimage_on_photographs(backend: str, dtype: torch.dtype) -> None:
    target = photo_batch(("astronaut", "coffee", "chelsea"), size=(256, 320))
    for sigma in (0.02, 0.1):
        pred = add_noise(target, sigma, seed=int(sigma * 100))
        expected = [skimage_ssim(p, t) for p, t in zip(pred, target)]
        got = ssim(pred.to(dtype), target.to(dtype), backend=backend)
        np.testing.assert_allclose(
            got.double().numpy(), expected, atol=1e-4 if dtype == torch.float32 else 1e-9
        )


@pytest.mark.parametrize("backend", BACKENDS)
def test_valid_border_equals_skimage_on_random_images(backend: str) -> None:
    pred = random_images((3, 3, 37, 61), seed=10)
    target = (0.6 * pred + 0.4 * random_images((3, 3, 37, 61), seed=11)).clamp(0, 1)
    expected = [skimage_ssim(p, t) for p, t in zip(pred, target)]
    np.testing.assert_allclose(ssim(pred, target, backend=backend).numpy(), expected, atol=1e-9)
    np.testing.assert_allclose(
        ssim(pred.float(), target.float(), backend=backend).numpy(), expected, atol=1e-4
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_reflect_border_equals_torchmetrics(backend: str) -> None:
    target = photo_batch(size=(128, 160))
    pred = add_noise(target, 0.05, seed=5)
    expected = structural_similarity_index_measure(pred, target, data_range=1.0, reduction="none")
    np.testing.assert_allclose(
        ssim(pred, target, border="reflect", backend=backend).numpy(), expected.numpy(), atol=1e-9
    )


@pytest.mark.parametrize("backend", BACKENDS)
def test_same_border_equals_gaussian_splatting_formula(backend: str) -> None:
    target = photo_batch(("astronaut", "rocket"), size=(128, 160))
    pred = add_noise(target, 0.07, seed=6)
    expected = gaussian_splatting_ssim(pred, target)
    np.testing.assert_allclose(
        ssim(pred, target, border="same", backend=backend).numpy(), expected.numpy(), atol=1e-10
    )
    np.testing.assert_allclose(
        ssim(pred.float(), target.float(), border="same", backend=backend).numpy(),
        expected.numpy(),
        atol=1e-5,
    )


def test_same_and_valid_differ_as_documented() -> None:
    target = photo_batch(size=(64, 64))
    pred = add_noise(target, 0.1)
    assert not torch.allclose(
        ssim(pred, target, border="same"), ssim(pred, target, border="valid"), atol=1e-4
    )


def test_gradient_of_dssim_loss_matches_3dgs_and_finite_differences() -> None:
    target = photo_batch(("astronaut",), size=(24, 28))
    pred = add_noise(target, 0.1, seed=7).requires_grad_(True)
    loss = (1 - ssim(pred, target, border="same")).sum()
    (grad,) = torch.autograd.grad(loss, pred)
    reference = pred.detach().clone().requires_grad_(True)
    (expected,) = torch.autograd.grad((1 - gaussian_splatting_ssim(reference, target)).sum(), reference)
    np.testing.assert_allclose(grad.numpy(), expected.numpy(), atol=1e-12)
    small = pred.detach()[:, :1, :12, :13].clone().requires_grad_(True)
    for border in ("valid", "reflect"):
        assert torch.autograd.gradcheck(
            lambda x, b=border: ssim(x, target[:, :1, :12, :13], border=b), (small,), fast_mode=True
        )


def test_float32_gradient_flows_for_training() -> None:
    target = photo_batch(size=(32, 32), dtype=torch.float32)
    pred = add_noise(target, 0.1).requires_grad_(True)
    (1 - ssim(pred, target, border="same")).mean().backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0


def test_identical_images_give_one() -> None:
    images = photo_batch(size=(64, 80))
    for border in ("valid", "same"):
        np.testing.assert_allclose(ssim(images, images, border=border).numpy(), 1.0, atol=1e-12)


def test_grayscale_equals_skimage_on_luma() -> None:
    target = photo_batch(size=(96, 128))
    pred = add_noise(target, 0.05, seed=8)
    weights = torch.tensor([0.299, 0.587, 0.114], dtype=torch.float64).view(3, 1, 1)
    expected = [skimage_ssim((p * weights).sum(0), (t * weights).sum(0)) for p, t in zip(pred, target)]
    np.testing.assert_allclose(ssim(pred, target, grayscale=True).numpy(), expected, atol=1e-9)


@pytest.mark.parametrize("backend", BACKENDS)
def test_masked_ssim_is_mean_of_skimage_map_over_valid_pixels(backend: str) -> None:
    target = photo_batch(size=(96, 128))
    pred = add_noise(target, 0.08, seed=9)
    generator = torch.Generator().manual_seed(12)
    mask = torch.rand(2, 1, 96, 128, generator=generator) > 0.3
    expected = []
    for p, t, m in zip(pred, target, mask):
        _, full_map = skimage_ssim(p, t, full=True)  # (H, W, C); its mean is taken over the cropped interior
        interior = full_map[5:-5, 5:-5].mean(axis=-1)
        expected.append(interior[m[0, 5:-5, 5:-5].numpy()].mean())
    np.testing.assert_allclose(ssim(pred, target, mask=mask, backend=backend).numpy(), expected, atol=1e-9)
    all_valid = torch.ones_like(mask)
    np.testing.assert_allclose(
        ssim(pred, target, mask=all_valid).numpy(), ssim(pred, target).numpy(), atol=1e-12
    )


def test_euvs_ssim_multiplies_by_mask_and_averages_whole_map() -> None:
    target = photo_batch(size=(80, 96))
    pred = add_noise(target, 0.08, seed=13)
    mask = torch.ones(2, 1, 80, 96)
    mask[:, :, 20:50, 30:70] = 0
    expected = gaussian_splatting_ssim(pred * mask, target * mask)
    np.testing.assert_allclose(ssim_euvs(pred, target, mask).numpy(), expected.numpy(), atol=1e-10)


def test_errors_name_the_problem() -> None:
    with pytest.raises(ImageError, match="smaller than"):
        ssim(torch.zeros(1, 3, 8, 8), torch.zeros(1, 3, 8, 8))
    with pytest.raises(UsageError, match="border"):
        ssim(torch.zeros(1, 3, 16, 16), torch.zeros(1, 3, 16, 16), border="circular")  # type: ignore[arg-type]
    x = torch.zeros(1, 3, 16, 16, requires_grad=True)
    with pytest.raises(UsageError, match="opencv"):
        ssim(x, torch.zeros(1, 3, 16, 16), backend="opencv")
