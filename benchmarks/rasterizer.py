"""Rasteriser benchmark: the native CPU kernel against the pure-PyTorch rasteriser, and what it does to ``synth``.

Two comparisons, each against the other rasteriser in the same run (``SETDIFF_RASTERIZER=torch`` is the
peer, the path every CPU render took before the kernel existed):

* **kernel**: one render of the street-like scene of ``render.py`` (50 000 Gaussians, 288×512):
  RGB + C-map + depth without gradients, and RGB forward + backward to every Gaussian parameter;
  also the largest absolute difference of the two images and gradients.
* **synth** (``--synth``): wall time of ``setdiff-bench synth --preset default --indices 2 --jobs 1``
  (generate one demo test scene, then fit it: 250 iterations at 256×144) in a subprocess per
  rasteriser, plus the fitted model's PSNR against the ground truth of its training frames.

    python benchmarks/rasterizer.py [--threads 1] [--repeats 5] [--synth]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import machine, time_call, write_result
from benchmarks.render import camera, street_like_scene
from setdiff_bench.gaussians.backends import cpu_rasterizer
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render

PEER, NATIVE = "torch", "native"


def forward_backward(g: GaussianModel, cam) -> list[torch.Tensor]:
    """RGB render, loss = weighted sum, gradients of means, scales, opacities, SH."""
    params = [
        t.detach().clone().requires_grad_(True) for t in (g.means, g.log_scales, g.opacity_logits, g.sh)
    ]
    model = GaussianModel(params[0], g.quats, params[1], params[2], params[3])
    out = render(model, cam, with_geometry=False)
    weights = torch.linspace(-1.0, 1.0, out.rgb.numel()).reshape(out.rgb.shape)
    (out.rgb * weights).sum().backward()
    return [out.rgb.detach(), *(p.grad for p in params)]


def kernel_comparison(repeats: int) -> dict:
    g = street_like_scene(50_000)
    cam = camera(512, 288)
    results: dict[str, dict] = {}
    outputs: dict[str, list[torch.Tensor]] = {}
    for mode in (PEER, NATIVE):
        os.environ[cpu_rasterizer.MODE_ENV] = mode
        with torch.no_grad():
            full = time_call(lambda: render(g, cam, with_geometry=True), repeats=repeats, warmup=2)
        both = time_call(lambda: forward_backward(g, cam), repeats=repeats, warmup=1)
        outputs[mode] = forward_backward(g, cam)
        results[mode] = {"rgb_cmap_depth_forward": full, "rgb_forward_backward": both}
    os.environ.pop(cpu_rasterizer.MODE_ENV)
    names = ["rgb", "d_means", "d_log_scales", "d_opacity_logits", "d_sh"]
    differences = {
        name: {
            "max_abs": float((a - b).abs().max()),
            "reference_max_abs": float(b.abs().max()),
        }
        for name, a, b in zip(names, outputs[NATIVE], outputs[PEER], strict=True)
    }
    return {
        "scene": "street_like_scene(50000, seed=0) at 288x512",
        "timings": results,
        "speedup_forward": results[PEER]["rgb_cmap_depth_forward"]["median_ms"]
        / results[NATIVE]["rgb_cmap_depth_forward"]["median_ms"],
        "speedup_forward_backward": results[PEER]["rgb_forward_backward"]["median_ms"]
        / results[NATIVE]["rgb_forward_backward"]["median_ms"],
        "native_minus_torch": differences,
    }


def synth_comparison(threads: int) -> dict:
    from setdiff_bench.gaussians.ply import read_ply
    from setdiff_bench.io.images import read_rgb, to_tensor_chw
    from setdiff_bench.loaders.synthetic import load_scenes
    from setdiff_bench.metrics.psnr import psnr

    results: dict[str, dict] = {}
    for mode in (PEER, NATIVE):
        with tempfile.TemporaryDirectory() as tmp:
            env = {**os.environ, cpu_rasterizer.MODE_ENV: mode, "SETDIFF_THREADS": str(threads)}
            command = [sys.executable, "-m", "setdiff_bench", "synth", "--out", tmp, "--preset", "default"]
            command += ["--seed", "0", "--indices", "2", "--jobs", "1", "--no-progress"]
            start = time.perf_counter()
            subprocess.run(command, check=True, env=env, capture_output=True)
            seconds = time.perf_counter() - start
            scene = load_scenes(tmp)[0]
            fit = read_ply(next(Path(tmp, scene.name, "fits").glob("*.ply")))
            os.environ[cpu_rasterizer.MODE_ENV] = NATIVE  # score both fits with one renderer
            train = [f for f in scene.frames if f.split == "train"]
            scores = []
            with torch.no_grad():
                for frame in train:
                    rgb = render(fit, frame.camera, with_geometry=False).rgb[0]
                    truth = to_tensor_chw(read_rgb(frame.image_path))
                    scores.append(float(psnr(rgb.clamp(0, 1)[None], truth[None])))
            os.environ.pop(cpu_rasterizer.MODE_ENV)
            results[mode] = {
                "seconds": seconds,
                "train_view_psnr_db": sum(scores) / len(scores),
                "train_views": len(scores),
            }
    return {
        "command": "setdiff-bench synth --preset default --seed 0 --indices 2 --jobs 1",
        "timings": results,
        "speedup": results[PEER]["seconds"] / results[NATIVE]["seconds"],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--synth", action="store_true", help="also time one default-preset synth scene")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if cpu_rasterizer.load() is None:
        raise SystemExit("the native CPU rasteriser did not build (no C++ compiler?)")
    payload = {"benchmark": "rasterizer", "machine": machine(), "kernel": kernel_comparison(args.repeats)}
    kernel = payload["kernel"]
    print(
        f"50k Gaussians 288x512: forward {kernel['speedup_forward']:.1f}x, "
        f"forward+backward {kernel['speedup_forward_backward']:.1f}x faster than the torch rasteriser"
    )
    if args.synth:
        payload["synth"] = synth_comparison(args.threads)
        synth = payload["synth"]
        print(
            f"synth (1 default scene): torch {synth['timings'][PEER]['seconds']:.0f} s, "
            f"native {synth['timings'][NATIVE]['seconds']:.0f} s: {synth['speedup']:.2f}x"
        )
    print(f"wrote {write_result('rasterizer', payload)}")


if __name__ == "__main__":
    main()
