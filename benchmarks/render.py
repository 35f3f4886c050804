"""Render benchmark: one compositing pass for RGB + C-map + depth versus RGB alone.

50 k Gaussians at 288×512 (issue 2).  The peer is the same renderer asked for RGB only; the goal is
a ratio ≤ 1.15 for the full one-pass render.  For reference it also times the naive alternative of
three separate passes (RGB, then C-map, then depth).  Runs the torch backend on the CPU, and gsplat
too when CUDA is available.

    python benchmarks/render.py [--gaussians 50000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import machine, time_call, write_result
from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.backends import torch_ref
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import camera_tensors, render
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.rotations import look_at


def street_like_scene(n: int, seed: int = 0) -> GaussianModel:
    """Gaussians on a ground plane and two façades 8 m either side, plus a far backdrop (opaque, like a fit)."""
    g = torch.Generator().manual_seed(seed)
    kind = torch.randint(0, 4, (n,), generator=g)
    u, v = torch.rand(n, generator=g), torch.rand(n, generator=g)
    x = torch.where(
        kind == 0,
        u * 16 - 8,
        torch.where(
            kind == 1, torch.full((n,), -8.0), torch.where(kind == 2, torch.full((n,), 8.0), u * 120 - 60)
        ),
    )
    y = torch.where(kind == 3, torch.full((n,), 80.0), v * 60)
    z = torch.where(kind == 0, torch.zeros(n), torch.where(kind == 3, v * 30, u * 10))
    means = torch.stack([x, y, z], 1) + torch.randn(n, 3, generator=g) * 0.05
    scales = torch.log(torch.rand(n, 3, generator=g) * 0.25 + 0.05)
    return GaussianModel(
        means,
        torch.randn(n, 4, generator=g),
        scales,
        torch.randn(n, generator=g) + 2.0,
        torch.randn(n, 1, 3, generator=g) * 0.5,
    )


def camera(width: int, height: int) -> Camera:
    return Camera(
        intrinsics_matrix(0.6 * width, 0.6 * width, width / 2, height / 2),
        look_at([0.5, -2.0, 1.5], [0.0, 40.0, 1.5]),
        width,
        height,
    )


def three_pass(g: GaussianModel, cam: Camera) -> None:
    """The naive peer: RGB, C-map and depth each composited in its own pass."""
    w2c, K = camera_tensors(cam, g.device, g.means.dtype)
    proj = torch_ref.project(g.means, g.quats, g.scales, g.opacities, w2c, K, cam.width, cam.height)
    center = -w2c[:3, :3].T @ w2c[:3, 3]
    for features in (g.colors(center), g.means, proj.depths[:, None]):
        torch_ref.rasterize(proj, features, cam.width, cam.height)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gaussians", type=int, default=50_000)
    parser.add_argument("--width", type=int, default=512)
    parser.add_argument("--height", type=int, default=288)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    g = street_like_scene(args.gaussians)
    cam = camera(args.width, args.height)
    results: dict[str, dict] = {}
    with torch.no_grad():
        rgb = time_call(lambda: render(g, cam, with_geometry=False), repeats=args.repeats, warmup=2)
        full = time_call(lambda: render(g, cam, with_geometry=True), repeats=args.repeats, warmup=2)
        naive = time_call(lambda: three_pass(g, cam), repeats=args.repeats, warmup=1)
    results["torch_cpu"] = {
        "rgb_only": rgb,
        "rgb_cmap_depth_one_pass": full,
        "three_separate_passes": naive,
        "one_pass_ratio": full["median_ms"] / rgb["median_ms"],
        "three_pass_ratio": naive["median_ms"] / rgb["median_ms"],
    }
    if torch.cuda.is_available():
        try:
            import gsplat  # noqa: F401

            gc = g.to("cuda")
            with torch.no_grad():
                rgb_g = time_call(
                    lambda: render(gc, cam, "gsplat", with_geometry=False), repeats=20, cuda=True
                )
                full_g = time_call(
                    lambda: render(gc, cam, "gsplat", with_geometry=True), repeats=20, cuda=True
                )
            results["gsplat_cuda"] = {
                "rgb_only": rgb_g,
                "rgb_cmap_depth_one_pass": full_g,
                "one_pass_ratio": full_g["median_ms"] / rgb_g["median_ms"],
            }
        except ImportError:
            results["gsplat_cuda"] = {"skipped": "gsplat not installed"}
    else:
        results["gsplat_cuda"] = {"skipped": "no CUDA device on this machine"}
    payload = {
        "benchmark": "render",
        "gaussians": args.gaussians,
        "width": args.width,
        "height": args.height,
        "goal": "one_pass_ratio <= 1.15",
        "machine": machine(),
        "results": results,
        "scene": "street_like_scene(seed=0)",
    }
    path = write_result("render", payload)
    print(f"{'backend':<12}{'RGB ms':>10}{'RGB+C+D ms':>12}{'ratio':>8}{'3-pass ratio':>14}")
    tc = results["torch_cpu"]
    print(
        f"{'torch cpu':<12}{tc['rgb_only']['median_ms']:>10.1f}{tc['rgb_cmap_depth_one_pass']['median_ms']:>12.1f}"
        f"{tc['one_pass_ratio']:>8.3f}{tc['three_pass_ratio']:>14.3f}"
    )
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
