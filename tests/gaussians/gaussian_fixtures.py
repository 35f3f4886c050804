"""Small 3DGS models (:func:`random_model`; :func:`random_scene`, a cloud in front of a camera at the origin)
and PLY headers for the tests, written independently of :mod:`setdiff_bench.gaussians.ply`."""

from __future__ import annotations

import torch

from setdiff_bench.gaussians.model import GaussianModel


def random_model(n: int = 20, degree: int = 3, generator: torch.Generator | None = None) -> GaussianModel:
    """``n`` Gaussians of SH ``degree`` with standard-normal parameters (``generator``: seed 3 by default)."""
    g = generator if generator is not None else torch.Generator().manual_seed(3)
    return GaussianModel(
        torch.randn(n, 3, generator=g),
        torch.randn(n, 4, generator=g),
        torch.randn(n, 3, generator=g),
        torch.randn(n, generator=g),
        torch.randn(n, (degree + 1) ** 2, 3, generator=g),
    )


def random_scene(n: int, seed: int, dtype=torch.float32) -> GaussianModel:
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g, dtype=torch.float64) * torch.tensor(
        [1.5, 1.0, 1.0], dtype=torch.float64
    )
    means[:, 2] += 6.0
    return GaussianModel(
        means=means.to(dtype),
        quats=torch.randn(n, 4, generator=g, dtype=torch.float64).to(dtype),
        log_scales=(torch.rand(n, 3, generator=g, dtype=torch.float64) * 1.2 - 2.6).to(dtype),
        opacity_logits=torch.randn(n, generator=g, dtype=torch.float64).to(dtype),
        sh=(torch.randn(n, 4, 3, generator=g, dtype=torch.float64) * 0.4).to(dtype),
    )


def ply_property_names(rest: int = 0, *, normals: bool = False) -> list[str]:
    """The vertex properties of graphdeco-inria's ``save_ply`` in its order: position, normals (when
    ``normals``), SH DC, ``rest`` SH rest coefficients, opacity, scale, rotation."""
    names = ["x", "y", "z", *(["nx", "ny", "nz"] if normals else []), *(f"f_dc_{i}" for i in range(3))]
    names += [f"f_rest_{i}" for i in range(rest)]
    return [*names, "opacity", *(f"scale_{i}" for i in range(3)), *(f"rot_{i}" for i in range(4))]


def ply_header(encoding: str, vertices: int, names: list[str]) -> str:
    """A PLY header (``encoding``: ascii, binary_little_endian, …) of ``vertices`` float ``names``."""
    properties = "".join(f"property float {name}\n" for name in names)
    return f"ply\nformat {encoding} 1.0\nelement vertex {vertices}\n{properties}end_header\n"
