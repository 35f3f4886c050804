"""Serve benchmark: the stream API in-process against the gRPC round trip on 127.0.0.1, same run.

Latency per tick (p50 / p99, ms) and frames per second for a 3-camera rig driven along a synthetic
recorded trajectory (``tests/stream/stream_fixtures``), for

* ``in_process``: :class:`setdiff_bench.evaluation.stream.StreamSession` called directly (uint8 in, uint8 out);
* ``grpc``: ``setdiff-bench serve`` in its own process, called through
  :class:`setdiff_bench.serve.client.EnhancerClient` (request encoding, transport, decoding included);
* ``in_process_cached``: the same with the reference-latent cache on.

Goal: the service adds <= 20 % over in-process (``overhead_ratio = grpc p50 / in_process p50``) at
256x144 on the CPU.  Both run with one torch thread.  ``--memory N`` instead sends N small requests to
a served process and samples its resident memory every N/10 requests (flat-memory check).

The model is a tiny random SetDiff (``--checkpoint`` to use a trained one): the enhancer's own cost
is small, which makes the overhead ratio a conservative (large) estimate.

    python benchmarks/serve.py [--height 144 --width 256] [--ticks 40] [--checkpoint CKPT]
    python benchmarks/serve.py --memory 10000 --height 32 --width 48
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks.common import machine, write_result
from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.serve.client import EnhancerClient
from tests.stream.stream_fixtures import recorded_references, save_tiny_checkpoint, serve_argv, tick_frames

ROOT = Path(__file__).resolve().parents[1]


def percentiles(samples: list[float], frames_per_tick: int) -> dict[str, float]:
    ms = np.asarray(samples) * 1000.0
    return {
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "mean_ms": float(ms.mean()),
        "ticks": len(ms),
        "frames_per_s": float(frames_per_tick * len(ms) / (ms.sum() / 1000.0)),
    }


def in_process(
    checkpoint: Path, size: tuple[int, int], ticks: int, cache: bool, device: str
) -> dict[str, float]:
    session = StreamSession(
        load_enhancer("setdiff", str(checkpoint), device=device),
        recorded_references(size),
        cache_reference_latents=cache,
    )
    frames = [tick_frames(t, size) for t in range(ticks)]
    session.enhance(frames[0])  # warm-up
    samples = []
    for tick in frames:
        start = time.perf_counter()
        out = session.enhance(tick)
        torch.round(out * 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()
        samples.append(time.perf_counter() - start)
    return percentiles(samples, 3)


def start_served(checkpoint: Path, *extra: str, device: str = "cpu") -> tuple[subprocess.Popen[str], int]:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import torch, sys; torch.set_num_threads(1); "
            "from setdiff_bench.cli.main import main; sys.exit(main(sys.argv[1:]))",
            *serve_argv(checkpoint, *extra, device=device),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    line = process.stdout.readline()
    return process, int(line.split(":")[1].split()[0])


def stop_served(process: subprocess.Popen[str]) -> None:
    process.terminate()
    process.wait(timeout=60)


def over_grpc(checkpoint: Path, size: tuple[int, int], ticks: int, device: str) -> dict[str, float]:
    process, port = start_served(checkpoint, device=device)
    try:
        with EnhancerClient(f"127.0.0.1:{port}") as client:
            session = client.start_session(recorded_references(size))
            frames = [tick_frames(t, size) for t in range(ticks)]
            client.enhance(session, frames[0])
            samples = []
            for tick in frames:
                start = time.perf_counter()
                client.enhance(session, tick)  # request built and reply decoded inside the timing
                samples.append(time.perf_counter() - start)
            client.close_session(session)
    finally:
        stop_served(process)
    return percentiles(samples, 3)


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS")


def memory(checkpoint: Path, size: tuple[int, int], requests: int) -> dict[str, Any]:
    process, port = start_served(checkpoint)
    samples = []
    try:
        with EnhancerClient(f"127.0.0.1:{port}") as client:
            session = client.start_session(recorded_references(size))
            requests_built = [client.enhance_request(session, tick_frames(t, size)) for t in range(50)]
            every = max(1, requests // 10)
            start = time.perf_counter()
            for i in range(requests):
                client.enhance(session, requests_built[i % len(requests_built)])
                if i % every == 0 or i == requests - 1:
                    samples.append({"requests": i + 1, "rss_mib": rss_mib(process.pid)})
            seconds = time.perf_counter() - start
            client.close_session(session)
    finally:
        stop_served(process)
    after_warmup = [s["rss_mib"] for s in samples[1:]]
    return {
        "requests": requests,
        "seconds": seconds,
        "samples": samples,
        "growth_after_first_sample_mib": max(after_warmup) - after_warmup[0] if after_warmup else 0.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--height", type=int, default=144)
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--ticks", type=int, default=40)
    parser.add_argument("--checkpoint", type=Path, default=None)
    parser.add_argument(
        "--device", default="cpu", help="cpu, or cuda (e.g. --height 576 --width 1024 on a GPU)"
    )
    parser.add_argument(
        "--memory", type=int, default=0, help="instead: N requests, served process RSS sampled"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    size = (args.height, args.width)
    with tempfile.TemporaryDirectory() as folder:
        checkpoint = args.checkpoint or save_tiny_checkpoint(Path(folder) / "tiny_setdiff")
        if args.memory:
            result = memory(checkpoint, size, args.memory)
            path = write_result(
                "serve_memory",
                {
                    "machine": machine(),
                    "size": list(size),
                    "memory": result,
                    "checkpoint": "tiny random" if args.checkpoint is None else str(args.checkpoint),
                },
            )
            print(
                f"{args.memory} requests in {result['seconds']:.0f} s; RSS "
                f"{[round(s['rss_mib'], 1) for s in result['samples']]} MiB; "
                f"growth after first sample {result['growth_after_first_sample_mib']:.1f} MiB → {path}"
            )
            return
        runs = {
            "in_process": in_process(checkpoint, size, args.ticks, False, args.device),
            "grpc": over_grpc(checkpoint, size, args.ticks, args.device),
            "in_process_cached": in_process(checkpoint, size, args.ticks, True, args.device),
        }
    payload = {
        "machine": machine(),
        "size": list(size),
        "device": args.device,
        "cameras_per_tick": 3,
        "references_per_tick": 3,
        "checkpoint": "tiny random" if args.checkpoint is None else str(args.checkpoint),
        "runs": runs,
        "overhead_ratio_p50": runs["grpc"]["p50_ms"] / runs["in_process"]["p50_ms"],
        "overhead_ratio_p99": runs["grpc"]["p99_ms"] / runs["in_process"]["p99_ms"],
        "cache_saving_p50": 1.0 - runs["in_process_cached"]["p50_ms"] / runs["in_process"]["p50_ms"],
        "goal": "grpc p50 <= 1.2 x in-process p50",
    }
    path = write_result(f"serve_{args.device}_{args.height}x{args.width}", payload)
    for name, run in runs.items():
        print(
            f"{name:18s} p50 {run['p50_ms']:7.1f} ms  p99 {run['p99_ms']:7.1f} ms  {run['frames_per_s']:6.2f} frames/s"
        )
    print(
        f"overhead ratio (p50) {payload['overhead_ratio_p50']:.3f}; cache saves {payload['cache_saving_p50']:.1%} "
        f"of a tick → {path}"
    )


if __name__ == "__main__":
    main()
