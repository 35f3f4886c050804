"""Where SetDiff's inference time goes, per UNet block, and what each speed option saves (issue 39).

The SD-Turbo-architecture SetDiff (random weights: time and memory do not depend on them) enhances one set
of N references + M targets with geometry CFG.  Three parts, each written to the JSON as it finishes:

``profile``
    Eager run (bf16 on CUDA, SDPA picks its kernels, batched CFG).  Stage times of ``encode`` (all views),
    ``unet`` (Ψ + UNet, both CFG branches), ``decode`` (the targets) and the whole ``enhance`` call, then
    the UNet call split by block with forward hooks timed by CUDA events (host clock on the CPU): set
    attention (``attn1``) and text cross-attention (``attn2``) per resolution level with their token
    counts, ResNet blocks, samplers, Ψ.  Hooks nest, so the per-kind rows partition the blocks.
``options``
    Each option alone against the paper configuration, eager, total ms per target frame:
    ``cfg1`` (one UNet pass: what a guidance-distilled student costs), ``set_levels_lowest`` (set
    attention only in the lowest-resolution level and the mid block, per-view attention elsewhere),
    ``cached_references`` (reference latents reused: only the M targets are encoded) and their
    combination.  Only speed is measured here; an option's quality cost needs trained models.  The rows of
    the speed presets of ``run --speed`` (``paper``, ``fast``) are repeated under ``presets_eager`` and printed
    with frames/s.
``compiled``
    ``torch.compile`` (inductor, default mode) of the UNet and the VAE walks for the paper configuration
    and for the combination, and DiFix (1 reference + 1 target per set, the M pairs batched) eager and
    compiled.  Skipped on the CPU.

Hand-written because the question is per *model block* at the set mixer's token counts, which the torch
profiler reports per kernel; the hooks only bracket diffusers' own modules and change no computation.

    python benchmarks/profile_enhance.py [--device cuda|cpu] [--height H --width W] [--refs N --targets M]
                                         [--parts profile,options,compiled] [--out enhance_profile_h100]
"""

from __future__ import annotations

import argparse
import gc
import re
import sys
import time
from collections import defaultdict
from collections.abc import Callable, Iterator
from contextlib import contextmanager, nullcontext
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import add_device_and_size, machine, time_call, write_result
from benchmarks.enhance import apply_step, build, inputs, stage_times
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.packaged import SPEEDS
from setdiff_bench.models.setdiff.set_mixer import mixer_level, per_view_processor_class

PARTS = ("profile", "options", "compiled")
#: The options row each speed preset of ``run --speed`` runs (``fast``: the one-pass student, whose cost is
#: one conditional UNet pass; its quality: docs/performance.md).
PRESET_ROWS = {
    "paper": "paper (CFG 2 batched, set attention at every level)",
    "fast": "cfg1 (one UNet pass, as a guidance-distilled student)",
}
assert set(PRESET_ROWS) == set(SPEEDS)


class BlockTimer:
    """Forward hooks that time modules: CUDA events on a GPU, the host clock on the CPU (where kernels run
    synchronously).  ``totals()`` gives the summed milliseconds per label over the recorded calls."""

    def __init__(self, cuda: bool) -> None:
        self.cuda = cuda
        self.records: list[tuple[str, Any, Any]] = []
        self.handles: list[Any] = []

    def _now(self) -> Any:
        if self.cuda:
            event = torch.cuda.Event(enable_timing=True)
            event.record()
            return event
        return time.perf_counter()

    def watch(self, module: torch.nn.Module, label: str) -> None:
        starts: list[Any] = []

        def before(*_: Any, **__: Any) -> None:
            starts.append(self._now())

        def after(*_: Any, **__: Any) -> None:
            self.records.append((label, starts.pop(), self._now()))

        self.handles.append(module.register_forward_pre_hook(before, with_kwargs=True))
        self.handles.append(module.register_forward_hook(after, with_kwargs=True))

    def totals(self) -> dict[str, float]:
        if self.cuda:
            torch.cuda.synchronize()
        totals: dict[str, float] = defaultdict(float)
        for label, start, end in self.records:
            totals[label] += start.elapsed_time(end) if self.cuda else (end - start) * 1000.0
        return dict(totals)

    def remove(self) -> None:
        for handle in self.handles:
            handle.remove()
        self.handles.clear()


def level_of(name: str, levels: int) -> str:
    """``L0`` (full latent grid) … ``L3``, or ``mid``, for a module path under a down / mid / up block."""
    return "mid" if name.startswith("mid_block") else f"L{mixer_level(name, levels)}"


def watch_unet(timer: BlockTimer, model: SetDiffModel) -> None:
    """Hooks on the UNet's blocks (``block:*``) and on its parts by kind and level (``part:*``)."""
    unet = model.unet
    levels = len(unet.down_blocks)
    for index, block in enumerate(unet.down_blocks):
        timer.watch(block, f"block:down_blocks.{index}")
    timer.watch(unet.mid_block, "block:mid_block")
    for index, block in enumerate(unet.up_blocks):
        timer.watch(block, f"block:up_blocks.{index}")
    for name in ("conv_in", "time_embedding", "conv_out"):
        timer.watch(getattr(unet, name), f"block:{name}")
    if model.geometry_encoder is not None:
        timer.watch(model.geometry_encoder, "block:geometry_encoder")
    for name, module in unet.named_modules():
        if not name.startswith(("down_blocks", "mid_block", "up_blocks")):
            continue
        leaf = name.rsplit(".", 1)[-1]
        if leaf in ("attn1", "attn2"):
            kind = "set attention (attn1)" if leaf == "attn1" else "text cross-attention (attn2)"
        elif re.fullmatch(r"(down_blocks\.\d+|mid_block|up_blocks\.\d+)\.resnets\.\d+", name):
            kind = "resnets"
        elif re.fullmatch(r"(down_blocks|up_blocks)\.\d+\.(downsamplers|upsamplers)\.0", name):
            kind = "samplers"
        else:
            continue
        timer.watch(module, f"part:{kind} {level_of(name, levels)}")


def tokens_per_level(height: int, width: int, factor: int, levels: int) -> dict[str, int]:
    """Tokens per view at each level of a ``height × width`` image (latent ``/factor``, halved per level)."""
    h, w = -(-height // factor), -(-width // factor)
    counts = {}
    for level in range(levels):
        counts[f"L{level}"] = h * w
        h, w = -(-h // 2), -(-w // 2)
    counts["mid"] = counts[f"L{levels - 1}"]
    return counts


def profile_unet(
    model: SetDiffModel, batch: Any, guidance: float, *, cuda: bool, repeats: int
) -> dict[str, Any]:
    """Per-block milliseconds of one ``predict_x0`` (Ψ + both CFG branches), the mean over ``repeats``."""
    sets, views = batch.num_sets, batch.num_views
    images = batch.images.reshape(sets * views, *batch.images.shape[2:])
    geometry = batch.geometry.reshape(sets * views, *batch.geometry.shape[2:])
    with torch.no_grad():
        latents = model.encode(images).latents
        model.predict_x0(latents, geometry, views, guidance_scale=guidance)  # warm-up, unhooked
        timer = BlockTimer(cuda)
        watch_unet(timer, model)
        try:
            for _ in range(repeats):
                model.predict_x0(latents, geometry, views, guidance_scale=guidance)
            totals = timer.totals()
        finally:
            timer.remove()
    return {label: ms / repeats for label, ms in sorted(totals.items())}


@contextmanager
def set_attention_only_at(model: SetDiffModel, keep: set[str]) -> Iterator[None]:
    """Within the block, ``attn1`` layers whose level is not in ``keep`` attend per view (their own tokens);
    the others keep mixing across the set.  The processors are restored afterwards."""
    unet = model.unet
    levels = len(unet.down_blocks)
    original = dict(unet.attn_processors)
    per_view = per_view_processor_class()
    changed = {
        name: per_view()
        if name.removesuffix(".processor").endswith("attn1") and level_of(name, levels) not in keep
        else processor
        for name, processor in original.items()
    }
    unet.set_attn_processor(changed)
    try:
        yield
    finally:
        unet.set_attn_processor(original)


def total_per_frame(
    model: SetDiffModel,
    batch: Any,
    guidance: float,
    *,
    cuda: bool,
    repeats: int,
    warmup: int,
    cached_references: bool = False,
) -> dict[str, float]:
    """ms per target frame of one enhancement: ``enhance`` itself, or with ``cached_references`` the same
    stages with only the targets encoded and the reference latents taken from a tensor encoded beforehand.

    That is the ceiling of reference caching, what a cache keyed by camera or session would give.  The
    toolkit's own cache (:class:`setdiff_bench.evaluation.stream.ReferenceLatentCache`, the stream API's and
    the service's) keys each view by a hash of its bytes on the host, a copy per view per call on a GPU that
    this measurement does not include."""
    sets, views, refs = batch.num_sets, batch.num_views, batch.num_references
    frames = sets * (views - refs)
    images = batch.images.reshape(sets * views, *batch.images.shape[2:])
    geometry = batch.geometry.reshape(sets * views, *batch.geometry.shape[2:])
    targets = (torch.arange(sets)[:, None] * views + torch.arange(refs, views)[None, :]).reshape(-1)
    targets = targets.to(images.device)
    with torch.no_grad():
        cache = model.encode(images).latents.clone()

        def cached() -> torch.Tensor:
            encoded = model.encode(images[targets], torch.arange(len(targets), device=images.device))
            latents = cache.clone()
            latents[targets] = encoded.latents
            x0 = model.predict_x0(latents, geometry, views, guidance_scale=guidance)
            return model.output_images(x0[targets], latents[targets], images[targets], encoded.skips)

        def whole() -> torch.Tensor:
            return model.enhance(batch, guidance_scale=guidance)

        fn: Callable[[], Any] = cached if cached_references else whole
        timing = time_call(fn, repeats=repeats, warmup=warmup, cuda=cuda)
    return {
        "total_ms_per_frame": timing["median_ms"] / frames,
        "frames_per_second": 1000.0 * frames / timing["median_ms"],
    }


def options(
    model: SetDiffModel, batch: Any, guidance: float, *, cuda: bool, repeats: int, warmup: int
) -> dict[str, Any]:
    """Each option alone and all together, against the paper configuration (same model, same inputs)."""
    lowest = {
        f"L{len(model.unet.down_blocks) - 2}",
        "mid",
    }  # the last level with attention, and the mid block
    cases: dict[str, tuple[float, set[str] | None, bool]] = {
        PRESET_ROWS["paper"]: (guidance, None, False),
        PRESET_ROWS["fast"]: (1.0, None, False),
        "set_levels_lowest (set attention at " + "+".join(sorted(lowest)) + " only)": (
            guidance,
            lowest,
            False,
        ),
        "cached_references (only targets encoded)": (guidance, None, True),
        "combined (cfg1 + set_levels_lowest + cached_references)": (1.0, lowest, True),
    }
    results: dict[str, Any] = {}
    for label, (scale, keep, cached) in cases.items():
        context = set_attention_only_at(model, keep) if keep is not None else nullcontext()
        with context:
            if cuda:
                torch.cuda.reset_peak_memory_stats()
            row = total_per_frame(
                model, batch, scale, cuda=cuda, repeats=repeats, warmup=warmup, cached_references=cached
            )
        if cuda:
            row["peak_gpu_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
        results[label] = row
        print(f"  {label:<60} {row['total_ms_per_frame']:8.1f} ms/frame", flush=True)
    return results


@contextmanager
def all_views_per_call() -> Iterator[None]:
    """Within the block, ``enhance`` runs the VAE and Ψ on all views in one call: the view chunks that bound
    the CPU's peak memory (``model.INFERENCE_CHUNK_PIXELS``) are lifted."""
    from setdiff_bench.models.setdiff import model as model_module

    saved = model_module.INFERENCE_CHUNK_PIXELS
    model_module.INFERENCE_CHUNK_PIXELS = 1 << 40
    try:
        yield
    finally:
        model_module.INFERENCE_CHUNK_PIXELS = saved


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_device_and_size(parser)
    parser.add_argument("--parts", default=",".join(PARTS), help=f"comma list of {', '.join(PARTS)}")
    parser.add_argument(
        "--compiled-cases",
        default="paper,paper_unchunked,combined",
        help="compiled SetDiff cases, in this order: paper, paper_unchunked, combined",
    )
    parser.add_argument("--no-difix", action="store_true", help="compiled part: leave DiFix out")
    parser.add_argument("--out", default="enhance_profile", help="results/<out>.json")
    args = parser.parse_args()
    device = torch.device(args.device)
    cuda = device.type == "cuda"
    height, width = args.height or (576 if cuda else 64), args.width or (1024 if cuda else 128)
    refs, targets = args.refs or (8 if cuda else 2), args.targets or (8 if cuda else 2)
    repeats = args.repeats or (10 if cuda else 2)
    dtype = torch.bfloat16 if cuda else torch.float32
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    if set(parts) - set(PARTS):
        parser.error(f"unknown parts {sorted(set(parts) - set(PARTS))}; known: {', '.join(PARTS)}")
    payload: dict[str, Any] = {
        "benchmark": "profile_enhance",
        "architecture": "sd-turbo (random weights)",
        "device": str(device),
        "dtype": str(dtype).removeprefix("torch."),
        "height": height,
        "width": width,
        "references": refs,
        "targets": targets,
        "guidance_scale": args.guidance,
        "machine": machine(),
    }
    model = build("sd_turbo_setdiff", device, dtype)
    batch = inputs(1, refs + targets, refs, height, width, True, device, dtype)
    levels = len(model.unet.down_blocks)
    payload["tokens_per_view"] = tokens_per_level(height, width, model.config.latent_factor, levels)
    payload["tokens_per_set"] = {k: v * (refs + targets) for k, v in payload["tokens_per_view"].items()}

    def save() -> Path:  # after each part, so that a run stopped at its time limit keeps what it measured
        return write_result(args.out, payload)

    if "profile" in parts:
        print("profile (eager):", flush=True)
        stages = stage_times(model, batch, args.guidance, cuda=cuda, repeats=repeats, warmup=1)
        payload["stages"] = stages
        print(
            f"  stages ms/frame: encode {stages['encode_ms_per_frame']:.1f} | unet {stages['unet_ms_per_frame']:.1f}"
            f" | decode {stages['decode_ms_per_frame']:.1f} | total {stages['total_ms_per_frame']:.1f}",
            flush=True,
        )
        payload["unet_blocks_ms"] = profile_unet(model, batch, args.guidance, cuda=cuda, repeats=repeats)
        for label, ms in payload["unet_blocks_ms"].items():
            print(f"  {label:<45} {ms:8.2f} ms", flush=True)
        save()
    if "options" in parts:
        print("options (eager):", flush=True)
        payload["options_eager"] = options(model, batch, args.guidance, cuda=cuda, repeats=repeats, warmup=1)
        payload["presets_eager"] = {
            preset: {"row": row, **payload["options_eager"][row]} for preset, row in PRESET_ROWS.items()
        }
        for preset, row in payload["presets_eager"].items():
            ms = row["total_ms_per_frame"]
            print(f"  preset {preset:<10} {ms:8.1f} ms/frame ({1000.0 / ms:.1f} frames/s)", flush=True)
        save()
    if "compiled" in parts and cuda:
        print("compiled (inductor, default mode):", flush=True)
        apply_step(model, "+torch_compile", device)
        compiled: dict[str, Any] = {}
        cases = {
            "paper": (args.guidance, None, False, False),
            "paper_unchunked": (args.guidance, None, False, True),
            "combined": (1.0, {f"L{levels - 2}", "mid"}, True, True),
        }
        for label in [c.strip() for c in args.compiled_cases.split(",") if c.strip()]:
            scale, keep, cached, unchunked = cases[label]
            context = set_attention_only_at(model, keep) if keep is not None else nullcontext()
            with context, all_views_per_call() if unchunked else nullcontext():
                torch.cuda.reset_peak_memory_stats()
                row = total_per_frame(
                    model, batch, scale, cuda=cuda, repeats=repeats, warmup=3, cached_references=cached
                )
            row["peak_gpu_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
            compiled[f"setdiff {label}"] = row
            print(f"  setdiff {label:<20} {row['total_ms_per_frame']:8.1f} ms/frame", flush=True)
            payload["compiled"] = compiled
            save()
        del model, batch
        gc.collect()
        torch.cuda.empty_cache()
        if args.no_difix:
            print(f"wrote {save()}")
            return
        difix = build("sd_turbo_difix", device, dtype)
        pairs = inputs(targets, 2, 1, height, width, False, device, dtype)
        for label in ("eager", "compiled"):
            if label == "compiled":
                apply_step(difix, "+torch_compile", device)
            torch.cuda.reset_peak_memory_stats()
            with all_views_per_call():  # as SetDiff's unchunked cases
                timing = time_call(
                    lambda: difix.enhance(pairs, guidance_scale=1.0), repeats=repeats, warmup=3, cuda=True
                )
            compiled[f"difix {label}"] = {
                "total_ms_per_frame": timing["median_ms"] / targets,
                "frames_per_second": 1000.0 * targets / timing["median_ms"],
                "peak_gpu_memory_gib": torch.cuda.max_memory_allocated() / 2**30,
            }
            print(
                f"  difix {label:<22} {compiled[f'difix {label}']['total_ms_per_frame']:8.1f} ms/frame",
                flush=True,
            )
            save()
    elif "compiled" in parts:
        payload["compiled"] = {
            "skipped": "CPU run: torch.compile of the SD UNet takes many minutes on 2 cores"
        }
    print(f"wrote {save()}")


if __name__ == "__main__":
    main()
