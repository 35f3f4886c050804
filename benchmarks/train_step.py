"""The paper-sized SetDiff training step: peak memory and steps per second (issue 39).

One process trains ``sd_turbo_setdiff`` (the SD-Turbo architecture with random weights: memory and speed do
not depend on the weights) through the toolkit's own training step (``models.setdiff.train``: accelerate,
bf16 mixed precision on CUDA, AdamW, gradient clipping, latent + L2 + SSIM + LPIPS-VGG losses on the
decoded targets, geometry dropout) on one synthetic 8-view packet at 576×1024 (4 references + 4 targets;
the packet of ``benchmarks/memory.py``).  It reports the median seconds per optimiser step after warm-up
and the peak GPU memory, with gradient checkpointing on (the packaged config) and off, for each objective:
``ground_truth`` (the paper's) and ``student`` (issue 55's guidance distillation: a one-pass student, guidance 1
and no geometry dropout, whose loss targets are a frozen teacher's CFG-2 outputs, computed in the same step; the
teacher is the same architecture with other random weights, saved as a checkpoint and loaded as ``[train]
distill_from`` loads it).

Without the converted LPIPS weights (``setdiff-bench weights lpips``), ``--random-lpips`` builds the loss
network with random weights of the same shapes (speed and memory only; refused otherwise, as training is).

    python benchmarks/train_step.py [--device cuda|cpu] [--height H --width W] [--views V] [--steps N]
                                    [--checkpointing on,off] [--objective ground_truth,student]
                                    [--config sd_turbo_setdiff] [--random-lpips] [--out train_step_h100]
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import add_device_and_size, machine, write_result
from benchmarks.memory import plane_packet
from setdiff_bench.models.setdiff.config import Config
from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.types import TrainingSample


def sample(refs: int, targets: int, height: int, width: int) -> TrainingSample:
    """The memory benchmark's packet (:func:`benchmarks.memory.plane_packet`: smooth random images, C-maps of
    a textured plane, cameras along a line) as a training sample; the targets' ground truth is their images
    mirrored (any image does: speed and memory do not depend on it)."""
    packet = plane_packet(refs, targets, height, width)
    gt = packet.targets.images.flip(-1)
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


def student_config(config: Config, folder: Path) -> Config:
    """``config`` as a one-pass student (guidance 1, no geometry dropout) of a teacher of its architecture with
    random weights (seed 1), saved to ``folder`` with the config's guidance scale (the paper's 2)."""
    from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
    from setdiff_bench.models.setdiff.train import initial_model

    teacher = initial_model(config.model, seed=1, load_pretrained=False)
    save_checkpoint(folder, teacher, config)
    del teacher
    gc.collect()
    return dataclasses.replace(
        config,
        model=dataclasses.replace(config.model, guidance_scale=1.0, geometry_dropout=0.0),
        train=dataclasses.replace(
            config.train, distill_from=str(folder), distill_guidance_scale=config.model.guidance_scale
        ),
    )


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
    parser.add_argument("--objective", default="ground_truth", help="comma list of ground_truth, student")
    parser.add_argument("--config", default="sd_turbo_setdiff", help="packaged config (a test's small one)")
    parser.add_argument("--random-lpips", action="store_true", help="random LPIPS-VGG weights if none found")
    parser.add_argument("--out", default="train_step")
    args = parser.parse_args()
    cuda = args.device == "cuda"
    height, width = args.height or (576 if cuda else 64), args.width or (1024 if cuda else 128)
    objectives = [o.strip() for o in args.objective.split(",") if o.strip()]
    if set(objectives) - {"ground_truth", "student"}:
        parser.error(f"unknown objectives {sorted(set(objectives) - {'ground_truth', 'student'})}")
    base = load_config(args.config)
    train = dataclasses.replace(base.train, min_views=args.views, max_views=args.views, num_workers=0)
    payload: dict[str, Any] = {
        "benchmark": "train_step",
        "architecture": "sd-turbo (random weights)",
        "config": args.config,
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
        dataset = [sample(refs, args.views - refs, height, width)]
        runs = [
            (objective, setting)
            for objective in objectives
            for setting in [s.strip() for s in args.checkpointing.split(",") if s.strip()]
        ]
        for objective, setting in runs:
            config = dataclasses.replace(
                base, train=dataclasses.replace(train, gradient_checkpointing=setting == "on")
            )
            if objective == "student":
                config = student_config(config, Path(scratch) / "teacher")
            label = f"gradient_checkpointing={setting}"
            if objective != "ground_truth":
                label = f"objective={objective}, {label}"
            try:
                row = measure(config, dataset, args.steps, args.device)
            except torch.OutOfMemoryError as error:
                row = {"failed": f"out of memory: {str(error).splitlines()[0]}"}
                gc.collect()
                torch.cuda.empty_cache()
            payload["runs"][label] = row
            print(f"{label}: {row}", flush=True)
            path = write_result(args.out, payload)  # after each run: a stopped run keeps what it measured
            print(f"wrote {path}")


if __name__ == "__main__":
    main()
