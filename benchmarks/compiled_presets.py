"""Compiled speed of each speed option and their combinations at the paper's size, one process per case
(issue 55's GPU table).

Each case is a configuration of the SD-Turbo-architecture SetDiff (random weights: time and memory do not
depend on them) or DiFix, with its UNet and VAE walks under ``torch.compile`` (inductor, default mode),
enhancing one set of N references + M targets (bf16, 576×1024, 8 + 8 on CUDA):

``paper``        geometry CFG 2 (both branches batched), set attention at every level, the VAE in the
                 view chunks ``enhance`` uses: what ``run --speed paper`` runs.
``fast``         one conditional UNet pass (the guidance-distilled student: ``run --speed fast``), the VAE
                 on all views at once.
``fast_view0``   ``fast`` with per-view set attention at level 0 (``set_attention = ["view"]``, the
                 student_view0 combination whose quality docs/performance.md lists) and the references'
                 latents cached (only the targets encoded, which changes no output).
``fast_view01``  as ``fast_view0`` with level 1 per-view too (the 2026-11-27 H100 "combined" row; the quality
                 of per-view attention at level 1 is not measured).
``difix``        DiFix, the M (reference, target) pairs batched.

Restricted attention is the model's own ``set_attention`` config (the path a model trained that way runs),
not a processor swap.  Compiling one configuration of this UNet takes minutes, mostly single-threaded
tracing, so the cases compile side by side, one process each; a barrier then lets them time one after
another, each alone on the device (a file lock), so no compilation or warm-up overlaps a timing.  A case
still compiling when the barrier's time is up is timed later with ``"timed_alone": false`` in its row.

Hand-written orchestration: the process-per-case barrier is specific to timing compiled models inside a
short GPU lease; the measurement itself is ``benchmarks/profile_enhance.total_per_frame``.

    python benchmarks/compiled_presets.py [--cases paper,fast,fast_view0,fast_view01,difix] [--device cuda|cpu]
        [--height H --width W] [--refs N --targets M] [--repeats R] [--barrier-s 300] [--no-compile]
        [--out enhance_presets_h200]
"""

from __future__ import annotations

import argparse
import dataclasses
import fcntl
import json
import os
import subprocess
import sys
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.common import add_device_and_size, machine, time_call, write_result
from benchmarks.enhance import apply_step, build, inputs
from benchmarks.profile_enhance import all_views_per_call, total_per_frame
from setdiff_bench.models.setdiff.model import SetDiffModel


@dataclasses.dataclass(frozen=True)
class Case:
    """One timed configuration: the packaged config it starts from and what it changes."""

    config: str
    guidance: float
    set_attention: tuple[str, ...] = ()
    cached_references: bool = False
    unchunked: bool = True
    pairs: bool = False  # DiFix: M (reference, target) sets of 2 views


CASES: dict[str, Case] = {
    "paper": Case("sd_turbo_setdiff", 2.0, unchunked=False),
    "fast": Case("sd_turbo_setdiff", 1.0),
    "fast_view0": Case("sd_turbo_setdiff", 1.0, ("view",), cached_references=True),
    "fast_view01": Case("sd_turbo_setdiff", 1.0, ("view", "view"), cached_references=True),
    "difix": Case("sd_turbo_difix", 1.0, pairs=True),
}
RESULT_PREFIX = "RESULT "


def build_case(
    case: Case, device: torch.device, dtype: torch.dtype, config: str | None = None
) -> SetDiffModel:
    """The case's model with random weights (:func:`benchmarks.enhance.build`); ``config`` replaces the packaged
    config's name (a test's small architecture)."""
    changes = {"set_attention": case.set_attention} if case.set_attention else {}
    return build(config or case.config, device, dtype, **changes)


def wait_for_siblings(sync: Path, expected: int, deadline: float) -> bool:
    """Block until ``expected`` cases are ready or failed (``True``), or until ``deadline`` (``False``)."""
    while time.monotonic() < deadline:
        if len(list(sync.glob("ready.*"))) + len(list(sync.glob("failed.*"))) >= expected:
            return True
        time.sleep(0.5)
    return False


def measure_case(
    name: str, args: argparse.Namespace, sync: Path | None, expected: int, deadline: float
) -> dict[str, Any]:
    """Build, compile and warm up one case, wait for the siblings, then time it holding the device lock."""
    case = CASES[name]
    device = torch.device(args.device)
    cuda = device.type == "cuda"
    dtype = torch.bfloat16 if cuda else torch.float32
    height, width = args.height or (576 if cuda else 64), args.width or (1024 if cuda else 128)
    refs, targets = args.refs or (8 if cuda else 2), args.targets or (8 if cuda else 2)
    repeats = args.repeats or (10 if cuda else 2)
    config = None
    if args.small_config:
        config = "tiny_difix" if case.pairs else "tiny_setdiff"
    model = build_case(case, device, dtype, config)
    if not args.no_compile:
        apply_step(model, "+torch_compile", device)
    if case.pairs:
        batch = inputs(targets, 2, 1, height, width, False, device, dtype)
    else:
        batch = inputs(1, refs + targets, refs, height, width, True, device, dtype)
    frames = batch.num_sets * (batch.num_views - batch.num_references)
    started = time.perf_counter()
    chunks = all_views_per_call() if case.unchunked else nullcontext()
    with chunks:

        def run(repeats: int, warmup: int) -> dict[str, float]:
            if case.pairs:
                timing = time_call(
                    lambda: model.enhance(batch, guidance_scale=case.guidance),
                    repeats=repeats,
                    warmup=warmup,
                    cuda=cuda,
                )
                ms = timing["median_ms"] / frames
                return {"total_ms_per_frame": ms, "frames_per_second": 1000.0 / ms}
            return total_per_frame(
                model,
                batch,
                case.guidance,
                cuda=cuda,
                repeats=repeats,
                warmup=warmup,
                cached_references=case.cached_references,
            )

        run(1, 3)  # compile and warm up
        compile_s = time.perf_counter() - started
        timed_alone = True
        if sync is not None:
            (sync / f"ready.{name}").touch()
            timed_alone = wait_for_siblings(sync, expected, deadline)
        lock = open(sync / "lock", "w") if sync is not None else None  # noqa: SIM115 - held across the timing
        try:
            if lock is not None:
                fcntl.flock(lock, fcntl.LOCK_EX)
            if cuda:
                torch.cuda.reset_peak_memory_stats()
            row: dict[str, Any] = dict(run(repeats, 1))
            if cuda:
                row["peak_gpu_memory_gib"] = torch.cuda.max_memory_allocated() / 2**30
        finally:
            if lock is not None:
                fcntl.flock(lock, fcntl.LOCK_UN)
                lock.close()
    row.update(
        {
            "compile_and_warmup_s": compile_s,
            "timed_alone": timed_alone,
            "repeats": repeats,
            "frames": frames,
            "guidance_scale": case.guidance,
            "set_attention": list(case.set_attention) or "full at every level",
            "cached_references": case.cached_references,
            "vae_all_views_per_call": case.unchunked,
            "compiled": not args.no_compile,
        }
    )
    return row


def run_worker(args: argparse.Namespace) -> None:
    """One case in this process; its row goes to stdout as one ``RESULT`` JSON line."""
    sync = Path(args.sync) if args.sync else None
    deadline = time.monotonic() + args.barrier_s
    try:
        row = measure_case(args.worker, args, sync, args.expect, deadline)
    except Exception as error:  # the driver records it; the other cases go on
        if sync is not None:
            (sync / f"failed.{args.worker}").touch()
        row = {"failed": f"{type(error).__name__}: {str(error).splitlines()[0] if str(error) else ''}"}
    print(RESULT_PREFIX + json.dumps({"case": args.worker, **row}), flush=True)


def worker_command(args: argparse.Namespace, name: str, sync: Path, expected: int) -> list[str]:
    command = [sys.executable, __file__, "--worker", name, "--sync", str(sync), "--expect", str(expected)]
    command += ["--device", args.device, "--barrier-s", str(args.barrier_s)]
    for flag in ("height", "width", "refs", "targets", "repeats"):
        if getattr(args, flag) is not None:
            command += [f"--{flag}", str(getattr(args, flag))]
    command += ["--no-compile"] if args.no_compile else []
    command += ["--small-config"] if args.small_config else []
    return command


def run_driver(args: argparse.Namespace) -> dict[str, Any]:
    """Start one worker per case, collect their rows (a case that dies or outlives ``--timeout-s`` is recorded
    as failed) and write ``results/<out>.json``."""
    names = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        raise SystemExit(f"unknown cases {unknown}; known: {', '.join(CASES)}")
    cuda = args.device == "cuda"
    payload: dict[str, Any] = {
        "benchmark": "compiled_presets",
        "architecture": "test config (tiny)" if args.small_config else "sd-turbo (random weights)",
        "device": args.device,
        "dtype": "bfloat16" if cuda else "float32",
        "height": args.height or (576 if cuda else 64),
        "width": args.width or (1024 if cuda else 128),
        "references": args.refs or (8 if cuda else 2),
        "targets": args.targets or (8 if cuda else 2),
        "compile": "none" if args.no_compile else "torch.compile inductor default (UNet, VAE encode, decode)",
        "machine": machine(),
        "cases": {},
    }
    if cuda:
        payload["machine"]["cuda_version"] = torch.version.cuda
    environment = dict(os.environ)
    environment.setdefault("TORCHINDUCTOR_COMPILE_THREADS", str(max(1, (os.cpu_count() or 1) // len(names))))
    with tempfile.TemporaryDirectory() as scratch:
        sync = Path(scratch)
        processes = {
            name: subprocess.Popen(
                worker_command(args, name, sync, len(names)),
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                env=environment,
            )
            for name in names
        }
        end = time.monotonic() + args.timeout_s
        for name, process in processes.items():
            try:
                output, _ = process.communicate(timeout=max(1.0, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                process.kill()
                output, _ = process.communicate()
                (sync / f"failed.{name}").touch()
                payload["cases"][name] = {"failed": f"not finished within {args.timeout_s:.0f} s"}
                print(f"  {name:<12} not finished within {args.timeout_s:.0f} s", flush=True)
                continue
            rows = [line for line in output.splitlines() if line.startswith(RESULT_PREFIX)]
            if not rows:
                tail = output.strip().splitlines()[-1:] or ["no output"]
                payload["cases"][name] = {"failed": f"exit {process.returncode}: {tail[0]}"}
            else:
                row = json.loads(rows[-1].removeprefix(RESULT_PREFIX))
                row.pop("case")
                payload["cases"][name] = row
            row = payload["cases"][name]
            if "total_ms_per_frame" in row:
                print(
                    f"  {name:<12} {row['total_ms_per_frame']:8.1f} ms/frame ({row['frames_per_second']:.1f} frames/s)"
                    f", peak {row.get('peak_gpu_memory_gib', float('nan')):.1f} GiB, compile {row['compile_and_warmup_s']:.0f} s",
                    flush=True,
                )
            else:
                print(f"  {name:<12} {row['failed']}", flush=True)
            print(f"wrote {write_result(args.out, payload)}", flush=True)
    return payload


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_device_and_size(parser)
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma list of {', '.join(CASES)}")
    parser.add_argument("--barrier-s", type=float, default=300.0, help="longest wait for the other cases")
    parser.add_argument("--timeout-s", type=float, default=540.0, help="the whole run's limit")
    parser.add_argument("--no-compile", action="store_true", help="eager (a CPU check of the orchestration)")
    parser.add_argument("--small-config", action="store_true", help=argparse.SUPPRESS)  # tests: tiny models
    parser.add_argument("--worker", choices=sorted(CASES), help=argparse.SUPPRESS)
    parser.add_argument("--sync", help=argparse.SUPPRESS)
    parser.add_argument("--expect", type=int, default=1, help=argparse.SUPPRESS)
    parser.add_argument("--out", default="compiled_presets", help="results/<out>.json")
    args = parser.parse_args()
    if args.worker:
        run_worker(args)
    else:
        run_driver(args)


if __name__ == "__main__":
    main()
