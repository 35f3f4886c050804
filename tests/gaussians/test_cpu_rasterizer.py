"""The native CPU rasteriser against the pure-PyTorch one (values and gradients) and a hand-derived case."""

from __future__ import annotations

import math

import pytest
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.backends import cpu_rasterizer, torch_ref

WIDTH, HEIGHT = 40, 28
K = torch.tensor([[30.0, 0.0, WIDTH / 2], [0.0, 30.0, HEIGHT / 2], [0.0, 0.0, 1.0]])

pytestmark = pytest.mark.skipif(cpu_rasterizer.load() is None, reason="no C++ compiler for the native kernel")


def random_gaussians(count: int, seed: int, opaque: bool) -> list[torch.Tensor]:
    """Means, quaternions, scales, opacities, 5 feature channels; ``opaque`` makes most alphas clamp at 0.99."""
    gen = torch.Generator().manual_seed(seed)
    means = torch.randn(count, 3, generator=gen) * torch.tensor([2.0, 1.5, 1.0]) + torch.tensor(
        [0.0, 0.0, 6.0]
    )
    quats = torch.randn(count, 4, generator=gen)
    scales = torch.rand(count, 3, generator=gen) * 0.4 + 0.05
    low = 0.97 if opaque else 0.02
    opacities = low + (0.999 - low) * torch.rand(count, generator=gen)
    features = torch.rand(count, 5, generator=gen)
    return [means, quats, scales, opacities, features]


def render_with_gradients(rasterize, tensors: list[torch.Tensor]) -> list[torch.Tensor]:
    """Image, alpha, and the gradients of a fixed linear loss w.r.t. means, scales, opacities, features, means2d."""
    means, quats, scales, opacities, features = (
        t.clone().requires_grad_(i != 1) for i, t in enumerate(tensors)
    )
    proj = torch_ref.project(means, quats, scales, opacities, torch.eye(4), K, WIDTH, HEIGHT)
    image, alpha = rasterize(proj, features, WIDTH, HEIGHT, tile_size=8)
    image_weights = torch.linspace(-1.0, 1.0, image.numel()).reshape(image.shape)
    alpha_weights = torch.linspace(1.0, -0.5, alpha.numel()).reshape(alpha.shape)
    ((image * image_weights).sum() + (alpha * alpha_weights).sum()).backward()
    return [
        image.detach(),
        alpha.detach(),
        means.grad,
        scales.grad,
        opacities.grad,
        features.grad,
        proj.means2d.grad,
    ]


@pytest.mark.parametrize(
    ("count", "opaque", "threads"), [(300, False, 1), (300, True, 1), (300, False, 2), (1, False, 1)]
)
def test_values_and_gradients_match_the_torch_rasteriser(
    count: int, opaque: bool, threads: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("SETDIFF_COMPILE", "0")
    tensors = random_gaussians(count, seed=count + int(opaque), opaque=opaque)
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        native = render_with_gradients(cpu_rasterizer.rasterize, tensors)
    finally:
        torch.set_num_threads(previous)
    reference = render_with_gradients(torch_ref.rasterize, tensors)
    names = ["image", "alpha", "d means", "d scales", "d opacities", "d features", "d means2d"]
    for name, got, want in zip(names, native, reference, strict=True):
        scale = float(want.abs().max()) or 1.0
        assert torch.allclose(got, want, rtol=1e-4, atol=2e-5 * scale), name
    assert float(reference[1].max()) > 0.5, "the scene should cover pixels"
    if opaque:  # early termination was exercised: some pixel stopped with transmittance left above zero
        assert float(reference[1].max()) > 0.999


def test_single_isotropic_gaussian_matches_the_closed_form() -> None:
    """One Gaussian of std s px at the image centre: pixel value = f · o · exp(−d² / (2 s²))."""
    sigma_px, opacity, value = 3.0, 0.8, 0.5
    depth = 5.0
    world_std = sigma_px * depth / 30.0  # fx = 30 px at depth 5
    means = torch.tensor([[0.0, 0.0, depth]])
    proj = torch_ref.project(
        means,
        torch.tensor([[1.0, 0.0, 0.0, 0.0]]),
        torch.full((1, 3), world_std),
        torch.tensor([opacity]),
        torch.eye(4),
        K,
        WIDTH,
        HEIGHT,
        eps2d=0.0,
    )
    image, alpha = cpu_rasterizer.rasterize(proj, torch.tensor([[value]]), WIDTH, HEIGHT)
    for y, x in [(14, 20), (14, 22), (10, 17), (0, 0)]:
        dx, dy = x + 0.5 - WIDTH / 2, y + 0.5 - HEIGHT / 2
        a = opacity * math.exp(-(dx * dx + dy * dy) / (2 * sigma_px**2))
        expected = a if a >= 1 / 255 else 0.0
        assert float(image[0, y, x]) == pytest.approx(value * expected, abs=1e-6)
        assert float(alpha[0, y, x]) == pytest.approx(expected, abs=1e-6)


def test_mode_setting_is_validated(monkeypatch: pytest.MonkeyPatch) -> None:
    features = torch.zeros(3, 3)
    monkeypatch.setenv(cpu_rasterizer.MODE_ENV, "torch")
    assert not cpu_rasterizer.handles(features)
    monkeypatch.setenv(cpu_rasterizer.MODE_ENV, "auto")
    assert cpu_rasterizer.handles(features)
    assert not cpu_rasterizer.handles(features.double())  # float64 stays on the torch path
    monkeypatch.setenv(cpu_rasterizer.MODE_ENV, "native")
    with pytest.raises(UsageError, match="CPU float32 only"):
        cpu_rasterizer.handles(features.double())
    monkeypatch.setenv(cpu_rasterizer.MODE_ENV, "fast")
    with pytest.raises(UsageError, match="SETDIFF_RASTERIZER"):
        cpu_rasterizer.handles(features)


def test_without_a_compiler_the_torch_path_is_used_with_a_warning(
    monkeypatch: pytest.MonkeyPatch, tmp_path
) -> None:
    monkeypatch.setattr(cpu_rasterizer, "_library", None)
    monkeypatch.setattr(cpu_rasterizer, "_build_error", None)
    monkeypatch.setenv("SETDIFF_KERNEL_CACHE", str(tmp_path / "empty-cache"))
    monkeypatch.setenv("CXX", "")
    monkeypatch.setenv("PATH", str(tmp_path))  # no g++, c++ or clang++ to be found
    with pytest.warns(UserWarning, match="native CPU rasteriser unavailable"):
        assert not cpu_rasterizer.handles(torch.zeros(2, 3))
    assert not (tmp_path / "empty-cache").exists() or not any((tmp_path / "empty-cache").iterdir())


def test_the_kernel_is_compiled_once_into_the_cache(monkeypatch: pytest.MonkeyPatch, tmp_path) -> None:
    monkeypatch.setattr(cpu_rasterizer, "_library", None)
    monkeypatch.setattr(cpu_rasterizer, "_build_error", None)
    monkeypatch.setenv("SETDIFF_KERNEL_CACHE", str(tmp_path))
    assert cpu_rasterizer.load() is not None
    built = list(tmp_path.glob("cpu_rasterizer-*.so"))
    assert len(built) == 1
    stamp = built[0].stat().st_mtime_ns
    monkeypatch.setattr(cpu_rasterizer, "_library", None)
    assert cpu_rasterizer.load() is not None
    assert built[0].stat().st_mtime_ns == stamp
    assert [p.name for p in tmp_path.iterdir()] == [built[0].name]  # no scratch left behind
