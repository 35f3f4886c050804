"""Shared helpers for the benchmark scripts: timing, machine description, JSON output."""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch

RESULTS = Path(__file__).resolve().parent / "results"


def time_call(
    fn: Callable[[], Any], *, repeats: int = 5, warmup: int = 1, cuda: bool = False
) -> dict[str, float]:
    """Run ``fn`` ``warmup`` times, then time ``repeats`` calls; milliseconds (median, min, mean)."""
    for _ in range(warmup):
        fn()
    if cuda:
        torch.cuda.synchronize()
    samples = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        if cuda:
            torch.cuda.synchronize()
        samples.append((time.perf_counter() - start) * 1000.0)
    return {
        "median_ms": statistics.median(samples),
        "min_ms": min(samples),
        "mean_ms": statistics.fmean(samples),
        "repeats": repeats,
    }


def add_device_and_size(parser: argparse.ArgumentParser, *, views: bool = True) -> None:
    """The options every GPU benchmark shares: ``--device`` (CUDA when available), ``--height`` and ``--width``
    (each script's own default when left out), and with ``views`` the set size ``--refs`` / ``--targets``
    with the CFG scale ``--guidance`` and ``--repeats``."""
    parser.add_argument(
        "--device", choices=("cuda", "cpu"), default="cuda" if torch.cuda.is_available() else "cpu"
    )
    parser.add_argument("--height", type=int)
    parser.add_argument("--width", type=int)
    if views:
        parser.add_argument("--refs", type=int)
        parser.add_argument("--targets", type=int)
        parser.add_argument("--guidance", type=float, default=2.0)
        parser.add_argument("--repeats", type=int)


def machine() -> dict[str, Any]:
    """Device, versions and load: what a reader needs to interpret timings."""
    info: dict[str, Any] = {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "cpu": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "load_average_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None,
        "cuda": torch.cuda.is_available(),
    }
    if torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(0)
    return info


def write_result(name: str, payload: dict[str, Any]) -> Path:
    """Write ``benchmarks/results/<name>.json`` (sorted keys, trailing newline) and return its path."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    path.write_text(json.dumps(payload, indent=2, sort_keys=True) + "\n")
    return path
