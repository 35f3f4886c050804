"""Fit benchmark: what a 3DGS training step costs beyond the renderer, and the first iteration's overhead.

Peer, in the same run, on the same scene, views and Gaussians: the renderer's forward + backward
(``render(...).rgb`` → sum → ``backward``).  A fit step adds the photometric loss (L1 + D-SSIM), the Adam
step, density statistics and, every ``densify_every`` iterations, densification.  Goals (issue 16):
median step ≤ 1.3 × the peer, and the first iteration ≤ 10 s slower than a steady one.

The scene is the tiny synthetic street (generated in a temporary folder), or any capture through its
loader (``--dataset nerfstudio --root R --scene S -o missing=skip --downscale 4``).

    python benchmarks/fit.py [--steps 30] [--dataset D --root R --scene S [-o K=V] [--downscale N]]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import machine, time_call, write_result
from setdiff_bench.cli import parse_option
from setdiff_bench.cli.fit import fit_config
from setdiff_bench.gaussians.fit import (
    Trainer,
    initial_model,
    load_fit_scene,
    load_fit_views,
    select_fit_frames,
)
from setdiff_bench.gaussians.render import render


def load_views(args: argparse.Namespace, workdir: Path):
    """``(scene description, fit views, scene)`` for the chosen capture."""
    if args.dataset is None:
        from setdiff_bench.synthetic.generate import generate_scene
        from setdiff_bench.synthetic.presets import get_preset

        folder = generate_scene(workdir, get_preset(args.preset), 0, 0)
        scene = load_fit_scene(folder)
        label = f"synthetic {args.preset} preset scene 0"
    else:
        options = dict(parse_option(text) for text in args.option)
        scene = load_fit_scene(args.root, dataset=args.dataset, scene=args.scene, options=options)
        label = f"{args.dataset} {scene.name} (downscale {args.downscale})"
    views = load_fit_views(scene, select_fit_frames(scene, None), downscale=args.downscale)
    return label, views, scene


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=30, help="steady steps timed after the first")
    parser.add_argument("--preset", default="tiny", help="synthetic preset when no --dataset")
    parser.add_argument("--dataset")
    parser.add_argument("--root", type=Path)
    parser.add_argument("--scene")
    parser.add_argument("-o", "--option", action="append", default=[])
    parser.add_argument("--downscale", type=int, default=1)
    parser.add_argument(
        "--threads", type=int, default=1, help="torch threads (default 1, the shared-CPU setting)"
    )
    parser.add_argument("--out", default="fit", help="results name (benchmarks/results/<out>.json)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    device = torch.device("cuda" if torch.cuda.is_available() else "cpu")
    with tempfile.TemporaryDirectory() as tmp:
        label, views, scene = load_views(args, Path(tmp))
    config = fit_config("default", max(300, args.steps + 1), seed=0)

    start = time.perf_counter()
    trainer = Trainer(views, initial_model(views, scene.points3d, scene.points_rgb, config), config, device)
    setup_s = time.perf_counter() - start
    start = time.perf_counter()
    trainer.step()
    first_s = time.perf_counter() - start
    steady = []
    for _ in range(args.steps):
        start = time.perf_counter()
        trainer.step()
        steady.append(time.perf_counter() - start)
    step_ms = statistics.median(steady) * 1000.0

    model = trainer.params.model()
    camera = views[0].camera
    kwargs = {"tile_size": config.tile_size} if trainer.backend == "torch" else {}

    def forward_backward() -> None:
        params = trainer.params.model()
        out = render(
            params,
            [camera],
            trainer.backend,
            with_geometry=False,
            sh_degree=trainer.active_sh,
            background=config.background,
            **kwargs,
        )
        out.rgb.sum().backward()
        trainer.params.optimizer.zero_grad(set_to_none=True)

    peer = time_call(forward_backward, repeats=max(5, args.steps // 3), warmup=1, cuda=device.type == "cuda")
    ratio = step_ms / peer["median_ms"]
    overhead_s = first_s - step_ms / 1000.0
    payload = {
        "benchmark": "fit",
        "scene": label,
        "views": len(views),
        "image_size": [camera.width, camera.height],
        "gaussians": len(model),
        "backend": trainer.backend,
        "machine": machine(),
        "setup_s": setup_s,
        "first_iteration_s": first_s,
        "steady_step_median_ms": step_ms,
        "render_forward_backward": peer,
        "step_cost_ratio": ratio,
        "first_iteration_overhead_s": overhead_s,
        "goals": {"step_cost_ratio_max": 1.3, "first_iteration_overhead_s_max": 10.0},
        "within_goals": {"step_cost_ratio": ratio <= 1.3, "first_iteration_overhead": overhead_s <= 10.0},
    }
    path = write_result(args.out, payload)
    print(
        f"{label}: {len(views)} views {camera.width}x{camera.height}, {len(model)} Gaussians, {trainer.backend}"
    )
    print(
        f"step {step_ms:.0f} ms vs render fwd+bwd {peer['median_ms']:.0f} ms: ratio {ratio:.2f} (goal <= 1.3)"
    )
    print(
        f"first iteration {first_s:.2f} s, overhead {overhead_s:.2f} s (goal <= 10 s); setup {setup_s:.2f} s -> {path}"
    )


if __name__ == "__main__":
    main()
