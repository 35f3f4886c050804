"""The torch rasteriser against the compositing formula worked by hand, finite differences and gsplat."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.gaussians.sh import SH_C0
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at
from tests.gaussians.gaussian_fixtures import random_scene

F = 50.0


def centred_camera(width: int = 64, height: int = 48) -> Camera:
    # principal point on pixel (24, 32)'s centre, so a Gaussian on the optical axis lands exactly there
    return Camera(intrinsics_matrix(F, F, 32.5, 24.5), np.eye(4), width, height)


def gaussians(centres, sigmas, opacities, colours, dtype=torch.float32) -> GaussianModel:
    n = len(centres)
    opac = torch.tensor(opacities, dtype=torch.float64)
    return GaussianModel(
        means=torch.tensor(centres, dtype=dtype),
        quats=torch.tensor([[1.0, 0.0, 0.0, 0.0]] * n, dtype=dtype),
        log_scales=torch.log(torch.tensor(sigmas, dtype=dtype))[:, None].repeat(1, 3),
        opacity_logits=torch.log(opac / (1 - opac)).to(dtype),
        sh=((torch.tensor(colours, dtype=dtype) - 0.5) / SH_C0)[:, None, :],
    )


def test_single_isotropic_gaussian_cmap_is_alpha_times_centre() -> None:
    x = [0.0, 0.0, 5.0]
    out = render(gaussians([x], [0.2], [0.6], [[0.9, 0.5, 0.1]]), centred_camera())
    # on the centre pixel σ = 0, so α = opacity exactly; C-map = α · x (Eq. 1, not divided by alpha)
    assert torch.allclose(out.cmap[0, :, 24, 32], torch.tensor(x) * 0.6, atol=1e-5)
    assert out.alpha[0, 0, 24, 32].item() == pytest.approx(0.6, abs=1e-6)
    assert torch.allclose(out.rgb[0, :, 24, 32], torch.tensor([0.9, 0.5, 0.1]) * 0.6, atol=1e-5)
    assert out.depth[0, 0, 24, 32].item() == pytest.approx(5.0 * 0.6, abs=1e-5)
    # one pixel to the right: 2D variance = (f·s/z)² + 0.3 (EWA + dilation), α = o·exp(−½ d²/var)
    var = (F * 0.2 / 5.0) ** 2 + 0.3
    assert out.alpha[0, 0, 24, 33].item() == pytest.approx(0.6 * math.exp(-0.5 / var), abs=1e-6)
    # far away nothing contributes: exactly zero
    assert torch.count_nonzero(out.cmap[0, :, :5, :5]) == 0
    assert torch.count_nonzero(out.alpha[0, :, 40:, 55:]) == 0


def test_two_gaussians_on_one_ray_composite_front_to_back() -> None:
    near, far = [0.0, 0.0, 4.0], [0.0, 0.0, 8.0]
    o1, o2 = 0.7, 0.5
    c1, c2 = [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]
    # listed far first: the renderer must sort by depth
    out = render(gaussians([far, near], [0.3, 0.1], [o2, o1], [c2, c1]), centred_camera())
    w1, w2 = o1, (1 - o1) * o2
    assert torch.allclose(out.rgb[0, :, 24, 32], torch.tensor([w1, 0.0, w2]), atol=1e-5)
    expected_cmap = w1 * torch.tensor(near) + w2 * torch.tensor(far)
    assert torch.allclose(out.cmap[0, :, 24, 32], expected_cmap, atol=1e-5)
    assert out.alpha[0, 0, 24, 32].item() == pytest.approx(w1 + w2, abs=1e-6)
    assert out.depth[0, 0, 24, 32].item() == pytest.approx(w1 * 4 + w2 * 8, abs=1e-5)


def test_alpha_clamp_and_transmittance_stop() -> None:
    clamped = render(gaussians([[0.0, 0.0, 3.0]], [0.2], [0.9999], [[1, 1, 1]]), centred_camera())
    assert clamped.alpha[0, 0, 24, 32].item() == pytest.approx(0.99, abs=1e-6)
    # three Gaussians of α = 0.98: T goes 1 → 0.02 → 4e-4 (≥ 1e-4, kept) → 8e-6 (< 1e-4: the third is dropped)
    centres = [[0.0, 0.0, 3.0], [0.0, 0.0, 4.0], [0.0, 0.0, 5.0]]
    out = render(
        gaussians(centres, [0.2] * 3, [0.98] * 3, [[1, 0, 0], [0, 1, 0], [0, 0, 1]]), centred_camera()
    )
    rgb = out.rgb[0, :, 24, 32]
    assert rgb[0].item() == pytest.approx(0.98, abs=1e-5)
    assert rgb[1].item() == pytest.approx(0.02 * 0.98, abs=1e-6)
    assert rgb[2].item() == 0.0
    assert out.alpha[0, 0, 24, 32].item() == pytest.approx(1 - 4e-4, abs=1e-6)


def test_background_fills_remaining_transmittance() -> None:
    out = render(
        gaussians([[0.0, 0.0, 5.0]], [0.2], [0.25], [[0, 0, 0]]), centred_camera(), background=(1, 1, 1)
    )
    assert torch.allclose(out.rgb[0, :, 24, 32], torch.full((3,), 0.75), atol=1e-6)
    assert torch.allclose(out.rgb[0, :, 0, 0], torch.ones(3))


def test_rgb_only_render_matches_full_render() -> None:
    g = random_scene(300, seed=5)
    cam = scene_camera()
    full = render(g, cam)
    rgb_only = render(g, cam, with_geometry=False)
    assert rgb_only.cmap is None
    assert torch.allclose(full.rgb, rgb_only.rgb, atol=1e-6)


def scene_camera(width: int = 40, height: int = 30) -> Camera:
    return Camera(
        intrinsics_matrix(35, 35, width / 2 + 0.1, height / 2 - 0.2),
        look_at([0.3, -0.2, 0.0], [0.0, 0.1, 6.0], up=(0.0, -1.0, 0.0)),
        width,
        height,
    )


def test_gradients_match_finite_differences_float64() -> None:
    g = random_scene(6, seed=2, dtype=torch.float64)
    cam = scene_camera(16, 12)
    params = g.tensors()
    for value in params.values():
        value.requires_grad_(True)
    weights = torch.randn(7, 12, 16, dtype=torch.float64, generator=torch.Generator().manual_seed(9))

    def loss() -> torch.Tensor:
        out = render(GaussianModel(**params), cam)
        stacked = torch.cat([out.rgb[0], out.cmap[0], out.depth[0]])
        return (stacked * weights).sum()

    loss().backward()
    eps = 1e-6
    for name, value in params.items():
        flat = value.detach().view(-1)
        picks = torch.randperm(flat.numel(), generator=torch.Generator().manual_seed(1))[:6]
        for i in picks.tolist():
            with torch.no_grad():
                original = flat[i].item()
                flat[i] = original + eps
                plus = loss().item()
                flat[i] = original - eps
                minus = loss().item()
                flat[i] = original
            numeric = (plus - minus) / (2 * eps)
            analytic = value.grad.view(-1)[i].item()
            assert analytic == pytest.approx(numeric, rel=1e-4, abs=1e-6), f"{name}[{i}]"


def test_means2d_gradient_is_retained_for_densification() -> None:
    g = random_scene(50, seed=4)
    g.means.requires_grad_(True)
    out = render(g, scene_camera())
    out.rgb.sum().backward()
    grad = out.meta[0]["means2d"].grad
    assert grad is not None and grad.shape == (50, 2)
    visible = out.meta[0]["visible"]
    assert torch.count_nonzero(grad[~visible]) == 0
    assert torch.count_nonzero(grad[visible]) > 0


@pytest.mark.gpu
def test_torch_matches_gsplat_on_random_2k_scene() -> None:
    pytest.importorskip("gsplat")
    g = random_scene(2000, seed=11)
    cam = scene_camera(128, 96)
    reference = render(g, cam, backend="torch")
    cuda = render(g.to("cuda"), cam, backend="gsplat")
    assert (cuda.rgb.cpu() - reference.rgb).abs().mean() <= 1e-3
    assert (cuda.cmap.cpu() - reference.cmap).abs().mean() <= 1e-3


def test_compiled_rasteriser_equals_eager(monkeypatch: pytest.MonkeyPatch) -> None:
    """Large renders go through torch.compile; its values and gradients must equal the eager maths."""
    g = random_scene(400, seed=8)
    cam = scene_camera(48, 32)
    results = {}
    for mode in ("0", "1"):
        monkeypatch.setenv("SETDIFF_COMPILE", mode)
        params = {k: v.detach().clone().requires_grad_(True) for k, v in g.tensors().items()}
        out = render(GaussianModel(**params), cam)
        (out.rgb.sum() + 0.1 * out.cmap.sum() + 0.01 * out.depth.sum()).backward()
        results[mode] = (out, {k: v.grad for k, v in params.items()})
    eager, compiled = results["0"], results["1"]
    for field in ("rgb", "cmap", "depth", "alpha"):
        assert torch.allclose(getattr(eager[0], field), getattr(compiled[0], field), atol=1e-5), field
    for name in eager[1]:
        assert torch.allclose(eager[1][name], compiled[1][name], rtol=1e-3, atol=1e-4), name
