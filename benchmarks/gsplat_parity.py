"""gsplat against the toolkit's own rasterisers on one scene: values (parity) and ms per frame (speed).

The street-like scene of ``benchmarks/render.py`` (50 000 Gaussians) is rendered at 288×512 and 576×1024 with
RGB + C-map + depth by three rasterisers: the native CPU kernel (``SETDIFF_RASTERIZER=native``, the path every
CPU render takes), the pure-PyTorch rasteriser on CUDA (the differentiable reference the CPU kernel is tested
against) and gsplat on CUDA (``backend="gsplat"``, what ``prepare`` and the fits use on a GPU).  For each pair it
reports the largest and mean absolute difference per output and the share of pixels differing by more than
1e-3 (gsplat clamps a Gaussian's alpha at 0.999 where the toolkit clamps at 0.99, its one documented
convention difference, so single opaque Gaussians differ by design); for each rasteriser the median ms per
frame of a forward render and of an RGB forward + backward to every Gaussian parameter.

    python benchmarks/gsplat_parity.py [--repeats 10] [--threads 16] [--out gsplat_parity_h200]

Needs CUDA and gsplat (``pip install 'setdiff-bench[gpu]'``); refuses in one line otherwise.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import machine, time_call, write_result
from benchmarks.rasterizer import forward_backward
from benchmarks.render import camera, street_like_scene
from setdiff_bench.gaussians.backends import cpu_rasterizer
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render

OUTPUTS = ("rgb", "cmap", "depth", "alpha")
SIZES = ((512, 288), (1024, 576))
GAUSSIANS = 50_000


def rasterise(g: GaussianModel, cam: Any, name: str) -> Any:
    """One forward render (RGB + C-map + depth) by rasteriser ``name``: native (CPU), torch_cuda, gsplat."""
    if name == "native":
        os.environ[cpu_rasterizer.MODE_ENV] = "native"
        try:
            return render(g, cam, with_geometry=True)
        finally:
            os.environ.pop(cpu_rasterizer.MODE_ENV)
    return render(g, cam, with_geometry=True, backend="gsplat" if name == "gsplat" else "torch")


def differences(a: Any, b: Any) -> dict[str, dict[str, float]]:
    """Per output: max and mean |a − b| and the share of values differing by more than 1e-3."""
    rows = {}
    for field in OUTPUTS:
        x, y = getattr(a, field).float().cpu(), getattr(b, field).float().cpu()
        d = (x - y).abs()
        rows[field] = {
            "max_abs": float(d.max()),
            "mean_abs": float(d.mean()),
            "share_above_1e-3": float((d > 1e-3).float().mean()),
            "reference_max_abs": float(y.abs().max()),
        }
    return rows


def cuda_forward_backward(g: GaussianModel, cam: Any, backend: str) -> None:
    """RGB render by ``backend`` (``gsplat`` or ``torch``) on CUDA, loss = weighted sum, gradients of means,
    scales, opacities and SH (the CPU kernel's counterpart: ``benchmarks.rasterizer.forward_backward``)."""
    params = [
        t.detach().clone().requires_grad_(True) for t in (g.means, g.log_scales, g.opacity_logits, g.sh)
    ]
    model = GaussianModel(params[0], g.quats, params[1], params[2], params[3])
    out = render(model, cam, with_geometry=False, backend=backend)
    weights = torch.linspace(-1.0, 1.0, out.rgb.numel(), device=out.rgb.device).reshape(out.rgb.shape)
    (out.rgb * weights).sum().backward()


def compare_at(scene: GaussianModel, on_gpu: GaussianModel, cam: Any, repeats: int) -> dict[str, Any]:
    """Differences and timings of the three rasterisers at one camera."""
    with torch.no_grad():
        outputs = {
            "native": rasterise(scene, cam, "native"),
            "torch_cuda": rasterise(on_gpu, cam, "torch_cuda"),
            "gsplat": rasterise(on_gpu, cam, "gsplat"),
        }
        forward = {
            name: time_call(
                lambda name=name: rasterise(scene if name == "native" else on_gpu, cam, name),
                repeats=repeats,
                warmup=2,
                cuda=name != "native",
            )
            for name in outputs
        }
    backward = {
        "native": time_call(lambda: forward_backward(scene, cam), repeats=repeats, warmup=1),
        "torch_cuda": time_call(
            lambda: cuda_forward_backward(on_gpu, cam, "torch"), repeats=repeats, warmup=1, cuda=True
        ),
        "gsplat": time_call(
            lambda: cuda_forward_backward(on_gpu, cam, "gsplat"), repeats=repeats, warmup=1, cuda=True
        ),
    }
    return {
        "gsplat_minus_native": differences(outputs["gsplat"], outputs["native"]),
        "torch_cuda_minus_native": differences(outputs["torch_cuda"], outputs["native"]),
        "gsplat_minus_torch_cuda": differences(outputs["gsplat"], outputs["torch_cuda"]),
        "forward_ms": {name: t["median_ms"] for name, t in forward.items()},
        "rgb_forward_backward_ms": {name: t["median_ms"] for name, t in backward.items()},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument(
        "--threads", type=int, default=os.cpu_count() or 1, help="torch threads of the CPU kernel"
    )
    parser.add_argument("--out", default="gsplat_parity")
    args = parser.parse_args()
    if not torch.cuda.is_available():
        raise SystemExit("gsplat_parity.py: needs a CUDA GPU (gsplat renders on CUDA only)")
    try:
        import gsplat
    except ImportError:
        raise SystemExit(
            "gsplat_parity.py: gsplat is not installed: pip install 'setdiff-bench[gpu]'"
        ) from None
    if cpu_rasterizer.load() is None:
        raise SystemExit("gsplat_parity.py: the native CPU rasteriser did not build (no C++ compiler?)")
    torch.set_num_threads(args.threads)
    scene = street_like_scene(GAUSSIANS)
    on_gpu = scene.to("cuda")
    payload: dict[str, Any] = {
        "benchmark": "gsplat_parity",
        "scene": f"street_like_scene({GAUSSIANS}, seed=0)",
        "gsplat": gsplat.__version__,
        "machine": {**machine(), "cuda_version": torch.version.cuda},
        "sizes": {},
    }
    for width, height in SIZES:
        row = compare_at(scene, on_gpu, camera(width, height), args.repeats)
        payload["sizes"][f"{height}x{width}"] = row
        print(
            f"{height}x{width}: forward ms native {row['forward_ms']['native']:.1f} | torch_cuda "
            f"{row['forward_ms']['torch_cuda']:.1f} | gsplat {row['forward_ms']['gsplat']:.2f}; gsplat - native "
            f"rgb max {row['gsplat_minus_native']['rgb']['max_abs']:.2e} mean "
            f"{row['gsplat_minus_native']['rgb']['mean_abs']:.2e}",
            flush=True,
        )
        print(f"wrote {write_result(args.out, payload)}", flush=True)


if __name__ == "__main__":
    main()
