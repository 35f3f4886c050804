"""The paper-sized SetDiff training step: peak memory and steps per second (issue 39).

One process trains ``sd_turbo_setdiff`` (the SD-Turbo architecture with random weights: memory and speed do
not depend on the weights) through the toolkit's own training step (``models.setdiff.train``: accelerate,
bf16 mixed precision on CUDA, AdamW, gradient clipping, latent + L2 + SSIM + LPIPS-VGG losses on the
decoded targets, geometry dropout) on synthetic 8-view packets (4 references + 4 targets) at 576×1024.
It reports the median seconds per optimiser step after warm-up and the peak GPU memory, with gradient
checkpointing on (the packaged config) and off.

Without the converted LPIPS weights (``setdiff-bench weights lpips``), ``--random-lpips`` builds the loss
network with random weights of the same shapes (speed and memory only; refused otherwise, as training is).

    python benchmarks/train_step.py [--device cuda|cpu] [--height H --width W] [--views V] [--steps N]
                                    [--checkpointing on,off] [--random-lpips] [--out train_step_h100]
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import math
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import add_device_and_size, machine, write_result
from setdiff_bench.cameras import Camera
from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.types import Packet, TrainingSample, ViewSet


def camera(index: int, height: int, width: int) -> Camera:
    """A pinhole camera stepping along x and turning 4° per view (distinct poses for Plücker rays)."""
    yaw = math.radians(4.0 * index)
    rotation = np.array([[math.cos(yaw), 0, -math.sin(yaw)], [0, 1, 0], [math.sin(yaw), 0, math.cos(yaw)]])
    w2c = np.eye(4)
    w2c[:3, :3] = rotation
    w2c[:3, 3] = -rotation @ np.array([0.3 * index, 0.0, 0.0])
    focal = 0.8 * width
    K = np.array([[focal, 0, width / 2], [0, focal, height / 2], [0, 0, 1.0]])
    return Camera(K=K, w2c=w2c, width=width, height=height)


def views(prefix: str, first: int, count: int, height: int, width: int, g: torch.Generator) -> ViewSet:
    coarse = torch.rand(count, 3, height // 16, width // 16, generator=g)
    return ViewSet(
        names=tuple(f"{prefix}{i}" for i in range(count)),
        images=F.interpolate(coarse, size=(height, width), mode="bilinear", align_corners=False),
        cmaps=torch.randn(count, 3, height, width, generator=g)
        + torch.tensor([0.0, 0.0, 5.0]).view(1, 3, 1, 1),
        alphas=torch.ones(count, 1, height, width),
        cameras=tuple(camera(first + i, height, width) for i in range(count)),
    )


def sample(seed: int, refs: int, targets: int, height: int, width: int) -> TrainingSample:
    """A packet of smooth random images and C-maps; the targets' ground truth is another smooth image."""
    g = torch.Generator().manual_seed(seed)
    packet = Packet(
        packet_id=f"bench{seed}",
        dataset="bench",
        protocol="bench",
        group="g",
        split="train",
        scene="s",
        references=views("ref", 0, refs, height, width, g),
        targets=views("tgt", refs, targets, height, width, g),
    )
    gt = views("gt", refs, targets, height, width, g).images
    return TrainingSample(packet, gt, torch.ones(targets, 1, height, width, dtype=torch.bool))


def random_lpips_weights(folder: Path) -> None:
    """Random-valued LPIPS-VGG weights of the real names and shapes, pointed to by ``SETDIFF_LPIPS_WEIGHTS``."""
    from safetensors.torch import save_file

    from setdiff_bench.metrics.lpips import LPIPS
    from setdiff_bench.metrics.weights import ENV_VAR, weights_filename

    path = folder / weights_filename("vgg")
    torch.manual_seed(0)
    save_file({k: v.contiguous() for k, v in LPIPS("vgg").state_dict().items()}, str(path))
    os.environ[ENV_VAR] = str(path)


def measure(config: Any, dataset: list[TrainingSample], steps: int, device: str) -> dict[str, Any]:
    """Median seconds per optimiser step over ``steps`` steps after two warm-up steps, and peak memory."""
    from setdiff_bench.models.setdiff import train as training

    cuda = device == "cuda"
    with tempfile.TemporaryDirectory() as out:
        if cuda:
            torch.cuda.empty_cache()
            torch.cuda.reset_peak_memory_stats()
        run = training._setup(config, dataset, Path(out), resume=False, cpu=not cuda)
        seconds = []
        running: dict[str, float] = {}
        for step in range(steps + 2):
            start = time.perf_counter()
            training._optimiser_step(run, step, running)
            if cuda:
                torch.cuda.synchronize()
            seconds.append(time.perf_counter() - start)
        row: dict[str, Any] = {
            "seconds_per_step": statistics.median(seconds[2:]),
            "steps_per_second": 1.0 / statistics.median(seconds[2:]),
            "timed_steps": steps,
            "trainable_parameters": sum(p.numel() for p in run.core.trainable_parameters()),
        }
        if cuda:
            row["peak_gpu_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
        del run
    gc.collect()
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_device_and_size(parser, views=False)
    parser.add_argument("--views", type=int, default=8, help="views per training packet (half references)")
    parser.add_argument("--steps", type=int, default=5, help="timed steps after two warm-up steps")
    parser.add_argument("--checkpointing", default="on,off", help="gradient checkpointing settings to run")
    parser.add_argument("--random-lpips", action="store_true", help="random LPIPS-VGG weights if none found")
    parser.add_argument("--out", default="train_step")
    args = parser.parse_args()
    cuda = args.device == "cuda"
    height, width = args.height or (576 if cuda else 64), args.width or (1024 if cuda else 128)
    base = load_config("sd_turbo_setdiff")
    train = dataclasses.replace(base.train, min_views=args.views, max_views=args.views, num_workers=0)
    payload: dict[str, Any] = {
        "benchmark": "train_step",
        "architecture": "sd-turbo (random weights)",
        "config": "sd_turbo_setdiff",
        "height": height,
        "width": width,
        "views": args.views,
        "decode_targets": train.decode_targets,
        "lpips_net": train.lpips_net,
        "mixed_precision": "bf16" if cuda else "no",
        "machine": machine(),
        "runs": {},
    }
    with tempfile.TemporaryDirectory() as scratch:
        from setdiff_bench.errors import WeightsError
        from setdiff_bench.metrics.weights import resolve_lpips_weights

        try:
            resolve_lpips_weights(train.lpips_net)
            payload["lpips_weights"] = "real"
        except WeightsError:
            if not args.random_lpips:
                raise
            random_lpips_weights(Path(scratch))
            payload["lpips_weights"] = "random (same shapes; speed and memory only)"
        refs = args.views // 2
        dataset = [sample(seed, refs, args.views - refs, height, width) for seed in range(2)]
        for setting in [s.strip() for s in args.checkpointing.split(",") if s.strip()]:
            config = dataclasses.replace(
                base, train=dataclasses.replace(train, gradient_checkpointing=setting == "on")
            )
            label = f"gradient_checkpointing={setting}"
            try:
                row = measure(config, dataset, args.steps, args.device)
            except torch.OutOfMemoryError as error:
                row = {"failed": f"out of memory: {str(error).splitlines()[0]}"}
                gc.collect()
                torch.cuda.empty_cache()
            payload["runs"][label] = row
            print(f"{label}: {row}", flush=True)
            write_result(args.out, payload)
    print(f"wrote benchmarks/results/{args.out}.json")


if __name__ == "__main__":
    main()
