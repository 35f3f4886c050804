"""Enhance benchmark: SetDiff (SD-Turbo architecture, random weights) — ms per target frame by stage.

GPU (the target setting, issue 8): bf16, 576×1024, 8 references + 8 targets in one set, geometry CFG
2.0.  It reports milliseconds per target frame split into VAE encode (all 16 views) / Ψ + UNet (both
CFG branches) / decode (8 targets), end to end, and peak GPU memory, along a cumulative ladder of
speed steps so that each step's gain is visible:

    baseline        bf16, SDPA math kernel (plain attention), CFG as two UNet calls, NCHW, eager
    +sdpa_flash     SDPA picks flash / memory-efficient kernels
    +batched_cfg    conditional and unconditional branches in one UNet call (2× batch)
    +channels_last  NHWC memory format for the convolutions
    +torch_compile  torch.compile (inductor) of the UNet and the VAE encoder/decoder walks
    +cuda_graphs    torch.compile mode="reduce-overhead" (CUDA graphs)

and the DiFix configuration beside it (ε-prediction, one reference + one target per set, no geometry,
no CFG; the 8 pairs batched).  Goals: the paper reports 555 ms per frame on an A100; ours is ≥ 10
frames per second per target frame on an H100 (≤ 100 ms).

Without CUDA it runs a small size on the CPU in float32 (bf16 convolutions are slow on CPUs), skips
the compile and CUDA-graph steps, and says so in the output and the JSON.

    python benchmarks/enhance.py [--device cuda|cpu] [--height H --width W] [--refs N --targets M] [--repeats R]
                                [--steps baseline,+sdpa_flash,...] [--threads T]
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import sys
from collections.abc import Callable
from contextlib import AbstractContextManager, nullcontext
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import add_device_and_size, machine, time_call, write_result
from setdiff_bench.models.setdiff.config_io import load_config
from setdiff_bench.models.setdiff.inputs import SetBatch
from setdiff_bench.models.setdiff.model import SetDiffModel

PAPER_MS_PER_FRAME_A100 = 555.0
GOAL_MS_PER_FRAME_H100 = 100.0
LADDER = ("baseline", "+sdpa_flash", "+batched_cfg", "+channels_last", "+torch_compile", "+cuda_graphs")


def build(name: str, device: torch.device, dtype: torch.dtype, **changes: Any) -> SetDiffModel:
    """The model of a packaged config (``changes`` replace fields of its model config, e.g. ``set_attention``),
    random weights (seed 0), in eval mode."""
    torch.manual_seed(0)
    model = SetDiffModel(dataclasses.replace(load_config(name).model, **changes), load_pretrained=False)
    if model.geometry_encoder is not None:  # a trained Ψ is not zero: give it weights so it does real work
        torch.nn.init.normal_(model.geometry_encoder.out.weight, std=1e-3)
    return model.to(device=device, dtype=dtype).eval()


def inputs(
    sets: int,
    views: int,
    refs: int,
    height: int,
    width: int,
    geometry: bool,
    device: torch.device,
    dtype: torch.dtype,
) -> SetBatch:
    g = torch.Generator().manual_seed(0)
    images = torch.rand(sets, views, 3, height, width, generator=g)
    geo = torch.randn(sets, views, 9, height, width, generator=g) if geometry else None
    return SetBatch(images, geo, refs).to(device, dtype)


def attention_kernels(fast: bool) -> AbstractContextManager[Any]:
    """``fast=False``: plain (math) attention; ``True``: let SDPA choose flash / memory-efficient kernels."""
    from torch.nn.attention import SDPBackend, sdpa_kernel

    return nullcontext() if fast else sdpa_kernel([SDPBackend.MATH])


def stage_times(
    model: SetDiffModel, batch: SetBatch, guidance: float, *, cuda: bool, repeats: int, warmup: int
) -> dict[str, Any]:
    """Median ms of encode, Ψ + UNet, decode and the whole ``enhance`` call, per call and per target frame."""
    sets, views, refs = batch.num_sets, batch.num_views, batch.num_references
    images = batch.images.reshape(sets * views, *batch.images.shape[2:])
    geometry = (
        None if batch.geometry is None else batch.geometry.reshape(sets * views, *batch.geometry.shape[2:])
    )
    targets = (torch.arange(sets)[:, None] * views + torch.arange(refs, views)[None, :]).reshape(-1)
    targets = targets.to(images.device)
    frames = sets * (views - refs)
    with torch.no_grad():
        torch.compiler.cudagraph_mark_step_begin()
        encoded = model.encode(images, targets)
        # clones: outputs of CUDA-graph replays are overwritten by the next replay of the same graph
        latents = encoded.latents.clone()
        skips = None if encoded.skips is None else tuple(s.clone() for s in encoded.skips)
        x0 = model.predict_x0(latents, geometry, views, guidance_scale=guidance)[targets].clone()
        stages: dict[str, Callable[[], Any]] = {
            "encode": lambda: model.encode(images, targets),
            "unet": lambda: model.predict_x0(latents, geometry, views, guidance_scale=guidance),
            "decode": lambda: model.decode(x0, skips),
            "total": lambda: model.enhance(batch, guidance_scale=guidance),
        }
        result: dict[str, Any] = {}
        for name, stage in stages.items():

            def fn(stage: Callable[[], Any] = stage) -> Any:
                torch.compiler.cudagraph_mark_step_begin()  # a new step for CUDA graph trees; no-op otherwise
                return stage()

            timing = time_call(fn, repeats=repeats, warmup=warmup, cuda=cuda)
            result[f"{name}_ms"] = timing["median_ms"]
            result[f"{name}_ms_per_frame"] = timing["median_ms"] / frames
    result["frames"] = frames
    result["frames_per_second"] = 1000.0 / result["total_ms_per_frame"]
    return result


def apply_step(model: SetDiffModel, step: str, device: torch.device) -> None:
    """Mutate ``model`` for a cumulative ladder step (those that change the model itself)."""
    if step == "+channels_last":
        model.to(memory_format=torch.channels_last)
    elif step in ("+torch_compile", "+cuda_graphs"):
        import torch._dynamo as dynamo

        dynamo.reset()
        mode = "reduce-overhead" if step == "+cuda_graphs" else "default"
        unet = getattr(model.unet, "_orig_mod", model.unet)
        model.unet = torch.compile(unet, mode=mode, fullgraph=False)
        codec = model.codec
        codec.encode = torch.compile(type(codec).encode.__get__(codec), mode=mode)  # type: ignore[method-assign]
        codec.decode = torch.compile(type(codec).decode.__get__(codec), mode=mode)  # type: ignore[method-assign]


def run_ladder(
    model: SetDiffModel,
    batch: SetBatch,
    guidance: float,
    steps: list[str],
    device: torch.device,
    repeats: int,
) -> dict[str, Any]:
    cuda = device.type == "cuda"
    results: dict[str, Any] = {}
    previous = None
    for step in LADDER:
        if step not in steps:
            continue
        if not cuda and step in ("+torch_compile", "+cuda_graphs"):
            results[step] = {
                "skipped": "CPU run: torch.compile of the SD UNet takes many minutes on 2 cores and "
                "CUDA graphs need CUDA"
            }
            continue
        fast_attention = step != "baseline"
        model.config = dataclasses.replace(
            model.config, cfg_batched=LADDER.index(step) >= LADDER.index("+batched_cfg")
        )
        apply_step(model, step, device)
        if cuda:
            torch.cuda.empty_cache()
            torch.cuda.reset_peak_memory_stats()
        warmup = 3 if step in ("+torch_compile", "+cuda_graphs") else 1
        try:
            with attention_kernels(fast_attention):
                timing = stage_times(model, batch, guidance, cuda=cuda, repeats=repeats, warmup=warmup)
        except torch.OutOfMemoryError as error:
            results[step] = {"failed": f"out of memory: {str(error).splitlines()[0]}"}
            gc.collect()
            torch.cuda.empty_cache()
            continue
        if cuda:
            timing["peak_gpu_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
        if previous is not None:
            timing["speedup_vs_previous_step"] = previous / timing["total_ms_per_frame"]
        previous = timing["total_ms_per_frame"]
        results[step] = timing
        print(
            f"  {step:<15} {timing['total_ms_per_frame']:9.1f} ms/frame  (encode {timing['encode_ms_per_frame']:.1f}"
            f" | unet {timing['unet_ms_per_frame']:.1f} | decode {timing['decode_ms_per_frame']:.1f})"
            + (f"  peak {timing['peak_gpu_memory_gib']:.1f} GiB" if cuda else ""),
            flush=True,
        )
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_device_and_size(parser)
    parser.add_argument("--steps", default=",".join(LADDER), help="comma-separated subset of the ladder")
    parser.add_argument("--threads", type=int, help="torch intra-op threads (CPU runs)")
    parser.add_argument("--no-difix", action="store_true")
    parser.add_argument(
        "--no-write", action="store_true", help="print only; do not write results/enhance.json"
    )
    args = parser.parse_args()
    device = torch.device(args.device)
    if args.threads:
        torch.set_num_threads(args.threads)
    cuda = device.type == "cuda"
    # target setting on GPU; a small CPU stand-in otherwise
    height = args.height or (576 if cuda else 64)
    width = args.width or (1024 if cuda else 128)
    refs = args.refs if args.refs is not None else (8 if cuda else 2)
    targets = args.targets or (8 if cuda else 2)
    repeats = args.repeats or (10 if cuda else 2)
    dtype = torch.bfloat16 if cuda else torch.float32
    steps = [s.strip() for s in args.steps.split(",") if s.strip()]
    unknown = sorted(set(steps) - set(LADDER))
    if unknown:
        parser.error(f"unknown steps {unknown}; known: {', '.join(LADDER)}")
    note = (
        "GPU run at the target setting"
        if cuda
        else f"CPU run at a SMALL size ({height}x{width}, {refs}+{targets} views, float32): no GPU in this task; "
        "numbers only show the relative effect of the CPU-applicable steps and are contended by other jobs"
    )
    print(
        f"enhance benchmark on {device}: SD-Turbo architecture, random weights, {height}x{width}, "
        f"{refs} refs + {targets} targets, CFG {args.guidance}, {str(dtype).removeprefix('torch.')}"
    )
    if not cuda:
        print(f"NOTE: {note}")

    print("SetDiff:")
    model = build("sd_turbo_setdiff", device, dtype)
    batch = inputs(1, refs + targets, refs, height, width, True, device, dtype)
    setdiff = run_ladder(model, batch, args.guidance, steps, device, repeats)
    del model, batch
    gc.collect()
    if cuda:
        torch.cuda.empty_cache()

    difix: dict[str, Any] = {}
    if not args.no_difix:
        print("DiFix (1 reference + 1 target per set, the sets batched, no geometry, no CFG):")
        model = build("sd_turbo_difix", device, dtype)
        pairs = inputs(targets, 2 if refs else 1, 1 if refs else 0, height, width, False, device, dtype)
        difix_steps = [
            s for s in ("+sdpa_flash", "+channels_last", "+torch_compile", "+cuda_graphs") if s in steps
        ]
        difix = run_ladder(model, pairs, 1.0, difix_steps, device, repeats)
        del model, pairs
        gc.collect()

    best = min((r["total_ms_per_frame"] for r in setdiff.values() if "total_ms_per_frame" in r), default=None)
    payload = {
        "benchmark": "enhance",
        "note": note,
        "device": str(device),
        "dtype": str(dtype).removeprefix("torch."),
        "architecture": "sd-turbo (random weights)",
        "height": height,
        "width": width,
        "references": refs,
        "targets": targets,
        "guidance_scale": args.guidance,
        "paper_ms_per_frame_a100": PAPER_MS_PER_FRAME_A100,
        "goal": f"<= {GOAL_MS_PER_FRAME_H100:.0f} ms per target frame (>= 10 fps) on an H100 at 576x1024, 8+8, CFG 2",
        "best_setdiff_ms_per_frame": best,
        "setdiff": setdiff,
        "difix": difix,
        "machine": machine(),
    }
    if not args.no_write:
        path = write_result("enhance", payload)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
