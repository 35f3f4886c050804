"""LPIPS with the real v0.1 weights: zero on identity, monotone on graded distortions, equal to numpy."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from setdiff_bench.errors import ImageError, WeightsError
from setdiff_bench.metrics.lpips import LPIPS, load_lpips, lpips, lpips_euvs
from setdiff_bench.metrics.weights import resolve_lpips_weights

from .lpips_numpy import lpips_numpy
from .photos import add_noise, photo_batch


@pytest.fixture(scope="module", params=["alex", "vgg"])
def net(request: pytest.FixtureRequest) -> str:
    return request.param


@pytest.fixture(scope="module")
def model(net: str) -> LPIPS:
    """The real LPIPS; fails loudly (with the how-to line) when the weights were never converted."""
    try:
        return load_lpips(net)
    except WeightsError as error:
        pytest.fail(f"real LPIPS weights are required for these tests: {error}")


def blur(images: torch.Tensor, sigma: float) -> torch.Tensor:
    """Gaussian blur each image with OpenCV (reflect-101 border)."""
    out = [cv2.GaussianBlur(image.permute(1, 2, 0).numpy(), (0, 0), sigma) for image in images]
    return torch.stack([torch.from_numpy(o).permute(2, 0, 1) for o in out])


def test_identical_images_give_zero(model: LPIPS) -> None:
    images = photo_batch(size=(96, 128), dtype=torch.float32)
    assert torch.equal(model(images, images), torch.zeros(2))


def test_monotone_in_noise_and_blur(model: LPIPS) -> None:
    target = photo_batch(size=(64, 96), dtype=torch.float32)
    for distort, levels in ((add_noise, (0.01, 0.03, 0.08, 0.2)), (blur, (0.5, 1.0, 2.0, 4.0))):
        distorted = torch.cat([distort(target, level) for level in levels])  # (levels·V, 3, H, W)
        scores = model(distorted, target.repeat(len(levels), 1, 1, 1)).view(len(levels), -1)
        assert (scores[0] > 0).all()
        assert (scores.diff(dim=0) > 0).all(), f"{distort.__name__}: {scores.T.tolist()}"


def test_equals_independent_numpy_forward(model: LPIPS, net: str) -> None:
    size = (48, 56) if net == "alex" else (24, 28)
    target = photo_batch(("astronaut", "coffee"), size=size)
    pred = blur(add_noise(target, 0.05, seed=3), 0.8)
    weights = load_file(str(resolve_lpips_weights(net)))
    for rescale in (True, False) if net == "alex" else (True,):  # the unscaled mode matters for EUVS (alex)
        expected = [
            lpips_numpy(p.permute(1, 2, 0).numpy(), t.permute(1, 2, 0).numpy(), weights, net, rescale)
            for p, t in zip(pred, target)
        ]
        tested = LPIPS(net, rescale_input=rescale)
        tested.load_state_dict(model.state_dict())
        np.testing.assert_allclose(tested.double()(pred, target).numpy(), expected, rtol=0, atol=1e-9)
        np.testing.assert_allclose(
            tested.float()(pred.float(), target.float()).numpy(), expected, rtol=0, atol=1e-5
        )


def test_trunk_is_frozen_and_gradients_reach_inputs(model: LPIPS) -> None:
    assert not any(p.requires_grad for p in model.parameters())
    target = photo_batch(size=(64, 64), dtype=torch.float32)
    pred = add_noise(target, 0.05).requires_grad_(True)
    model(pred, target).sum().backward()
    assert pred.grad is not None and torch.isfinite(pred.grad).all() and pred.grad.abs().sum() > 0
    assert all(p.grad is None for p in model.parameters())
    model.train()
    assert not model.training


def test_functional_mask_and_euvs_variant(model: LPIPS, net: str) -> None:
    target = photo_batch(size=(40, 56), dtype=torch.float32)
    pred = add_noise(target, 0.05, seed=4)
    mask = torch.ones(2, 1, 40, 56, dtype=torch.bool)
    mask[:, :, 10:30, 20:40] = False
    expected = model(pred * mask, target * mask)
    np.testing.assert_allclose(
        lpips(pred, target, net=net, mask=mask, chunk=1).numpy(), expected.numpy(), atol=1e-6
    )
    if net == "alex":
        unscaled = LPIPS("alex", rescale_input=False)
        unscaled.load_state_dict(model.state_dict())
        np.testing.assert_allclose(
            lpips_euvs(pred, target, mask.float()).numpy(),
            unscaled(pred * mask, target * mask).numpy(),
            atol=1e-6,
        )
        assert not torch.allclose(lpips_euvs(pred, target, mask.float()), expected, atol=1e-3)


def test_too_small_or_out_of_range_images_raise(model: LPIPS, net: str) -> None:
    with pytest.raises(ImageError, match="too small"):
        model(torch.zeros(1, 3, 12, 12), torch.zeros(1, 3, 12, 12))
    with pytest.raises(ImageError, match=r"must be in \[0, 1\]"):
        lpips(torch.full((1, 3, 40, 40), 255.0), torch.zeros(1, 3, 40, 40), net=net)
    with pytest.raises(ImageError, match=r"must be in \[0, 1\]"):
        lpips(torch.zeros(1, 3, 40, 40), torch.full((1, 3, 40, 40), -1.0), net=net)
