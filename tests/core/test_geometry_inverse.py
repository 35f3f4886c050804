"""Issue 40: geometry.denormalize_cmaps inverts normalize_packet's C-map map (the stream API's world frame)."""

from __future__ import annotations

import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.geometry import denormalize_cmaps, normalize_packet
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at


def camera_at(center, target, width=16, height=12) -> Camera:
    return Camera(intrinsics_matrix(20, 20, width / 2, height / 2), look_at(center, target), width, height)


def packet(dtype: torch.dtype = torch.float64):
    cameras = [
        camera_at([1.0, -2.0, 0.5], [4.0, 10.0, 1.0]),
        camera_at([3.0, 5.0, 1.5], [0.0, 20.0, 0.0]),
        camera_at([-4.0, 1.0, 2.0], [2.0, 9.0, 1.0]),
    ]
    generator = torch.Generator().manual_seed(0)
    alphas = torch.rand(3, 1, 12, 16, generator=generator, dtype=torch.float64)
    alphas[:, :, :3] = 0.0  # nothing hit: the C-map is exactly zero there
    cmaps = alphas * (torch.randn(3, 3, 12, 16, generator=generator, dtype=torch.float64) * 20 + 5)
    return cameras, cmaps.to(dtype), alphas.to(dtype)


def test_denormalize_inverts_normalize() -> None:
    cameras, cmaps, alphas = packet()
    normalized = normalize_packet(cameras, cmaps, 1, alphas=alphas)
    assert not torch.allclose(normalized.cmaps, cmaps)
    world = denormalize_cmaps(
        normalized.cmaps, alphas, normalized.rotation, normalized.translation, normalized.scale
    )
    assert world.dtype == torch.float64
    torch.testing.assert_close(world, cmaps, rtol=0, atol=1e-10)
    assert torch.equal(world[:, :, :3], torch.zeros_like(world[:, :, :3]))


def test_denormalize_float32_and_dtype() -> None:
    cameras, cmaps, alphas = packet(torch.float32)
    normalized = normalize_packet(cameras, cmaps, 0, alphas=alphas)
    world = denormalize_cmaps(
        normalized.cmaps, alphas, normalized.rotation, normalized.translation, normalized.scale
    )
    assert world.dtype == torch.float32
    torch.testing.assert_close(world, cmaps, rtol=1e-5, atol=1e-4)
    as_half = denormalize_cmaps(
        normalized.cmaps.half(),
        alphas.half(),
        normalized.rotation,
        normalized.translation,
        normalized.scale,
        dtype=torch.float32,
    )
    assert as_half.dtype == torch.float32
