"""The demo's machine-readable summary (``<out>/demo.json``): preset, stage commands and times, the
provenance the numbers depend on, and the verdict on the benchmark's verdict group (SetDiff against
``identity`` and ``difix``, per metric in its direction)."""

from __future__ import annotations

import functools
import os
import platform
from dataclasses import asdict
from pathlib import Path
from typing import Any

import pandas as pd

from setdiff_bench.io.run_layout import METRICS_FILE, SEQUENCES_FILE
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.pipeline.demo._layout import REPORT_FILE, SUMMARY_FILE, DemoPaths
from setdiff_bench.pipeline.demo._stages import METHODS
from setdiff_bench.pipeline.presets import DemoPreset, get_benchmark
from setdiff_bench.pipeline.stages import Pipeline
from setdiff_bench.runtime.provenance import git_revision, package_versions
from setdiff_bench.runtime.threads import compute_threads

VERDICT_METRICS = ("psnr", "ssim", "lpips")  # the verdict's metrics, in table order


def run_provenance(seed: int) -> dict[str, Any]:
    """What the numbers depend on: code revision, seed, torch thread count, versions, CPU.

    On the same machine the same command gives byte-identical scenes, fits, packets, checkpoints and
    leaderboards; another thread count, CPU instruction set, torch build or a GPU changes the last bits
    of every float sum, and training amplifies them (README "Reproducibility").
    """
    return {
        "git": git_revision(),
        "seed": seed,
        "torch_threads": compute_threads(),
        "machine": {
            "cpu": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(),
            "system": platform.system(),
        },
        "versions": package_versions(),
    }


def better(metric: str, value: float, other: float) -> bool:
    """Whether ``value`` is strictly better than ``other`` in ``metric``'s direction (``MetricSpec``)."""
    return value > other if get_metric(metric).higher_is_better else value < other


def _group_means(metrics: pd.DataFrame, group: str, counted: str) -> tuple[pd.DataFrame, dict[str, Any]]:
    """Each run's mean of :data:`VERDICT_METRICS` on ``group``, and the verdict's common fields: the group, its
    number of targets (those of run ``counted``) and the means."""
    rows = metrics[metrics["group"] == group]
    means = rows.groupby("method")[list(VERDICT_METRICS)].mean()
    return means, {
        "group": group,
        "targets": int((rows["method"] == counted).sum()),
        "means": {m: {k: float(v) for k, v in means.loc[m].items()} for m in means.index},
    }


def lane_shift_verdict(metrics: pd.DataFrame, group: str) -> dict[str, Any]:
    """SetDiff against ``identity`` and ``difix`` on one group (the benchmark's verdict group: +2 lanes,
    3 views): means and who wins each metric.

    Args:
        metrics: per-target rows of the four runs (``metrics.parquet`` concatenated).
        group: the benchmark's ``verdict_group`` (:data:`setdiff_bench.pipeline.presets.DEMO_BENCHMARKS`).
    """
    means, verdict = _group_means(metrics, group, counted="setdiff")
    if "setdiff" in means.index:
        for other in ("identity", "difix"):
            if other in means.index:
                verdict[f"setdiff_beats_{other}"] = {
                    name: bool(better(name, means.loc["setdiff", name], means.loc[other, name]))
                    for name in VERDICT_METRICS
                }
    return verdict


def interval_winners(comparisons: pd.DataFrame, group: str, names: list[str], metric: str) -> list[str]:
    """The rows of ``names`` that no other row of ``names`` beats on ``group`` in ``metric`` with a paired
    interval excluding 0 (``compare``'s ``holds``), in ``names``' order: one name is a winner the intervals
    show, several are rows the intervals do not separate.

    Args:
        comparisons: ``compare`` tables (``compare_<a>_vs_<b>.parquet``) concatenated; their group-level rows
            (``level == "group"``, ``key``: the group) are read, ``gain`` > 0 meaning ``a`` is better.
    """
    rows = comparisons[
        (comparisons["level"] == "group") & (comparisons["key"] == group) & (comparisons["metric"] == metric)
    ]
    beaten = {
        r.b if r.gain > 0 else r.a
        for r in rows.itertuples()
        if r.a in names and r.b in names and r.a != r.b and bool(r.holds)
    }
    return [name for name in names if name not in beaten]


def refit_verdict(
    metrics: pd.DataFrame, group: str, comparisons: pd.DataFrame | None = None
) -> dict[str, Any]:
    """``demo --refit``: per enhancer ``X``, the means of ``X``, ``X-3D`` and ``X-3D+`` on ``group``, which of
    them has the best mean in each metric (its direction; ``best``) and, given the demo's paired comparisons,
    which the intervals show winning (``winners``: :func:`interval_winners`), with ``identity`` and
    ``identity-3D`` (the schedule alone).

    Args:
        metrics: per-target rows of the demo's runs (``metrics.parquet`` concatenated; ``method`` holds each
            run's name).
        comparisons: the demo's ``compare`` tables concatenated (``None``: no ``winners``).
    """
    means, verdict = _group_means(metrics, group, counted="identity")
    verdict["best"], verdict["winners"] = {}, {}
    for method in METHODS:
        names = [n for n in (method, f"{method}-3D", f"{method}-3D+") if n in means.index]
        if len(names) < 2:
            continue
        verdict["best"][method] = {
            metric: functools.reduce(
                lambda a, b, m=metric: b if better(m, means.loc[b, m], means.loc[a, m]) else a, names
            )
            for metric in VERDICT_METRICS
        }
        if comparisons is not None and len(comparisons):
            verdict["winners"][method] = {
                metric: interval_winners(comparisons, group, names, metric) for metric in VERDICT_METRICS
            }
    return verdict


def read_comparisons(folder: Path) -> pd.DataFrame:
    """Every ``compare`` table (``compare_*.parquet``) in ``folder``, concatenated (empty when there is none)."""
    tables = [pd.read_parquet(p) for p in sorted(folder.glob("compare_*.parquet"))]
    return pd.concat(tables, ignore_index=True) if tables else pd.DataFrame()


def summarize(
    paths: DemoPaths,
    preset: DemoPreset,
    steps: dict[str, int],
    pipeline: Pipeline,
    invocation: str,
    refit_rows: list[str] | None = None,
) -> dict[str, Any]:
    """The demo's machine-readable summary: preset, stage commands and times, the verdict on the benchmark's
    verdict group (under its ``verdict_key``: ``lane_plus_2``, ``views_3``) and, for ``demo --refit`` (its rows
    ``refit_rows``), ``refit``: the refit verdict on each refitted group (``groups``: :func:`refit_verdict`, with
    the winners the compare tables in ``paths.out`` show) and each row's mean warp error (``warp``)."""
    benchmark = get_benchmark(preset.benchmark)
    runs = refit_rows or list(METHODS)
    frames = [
        pd.read_parquet(paths.runs / m / METRICS_FILE)
        for m in runs
        if (paths.runs / m / METRICS_FILE).is_file()
    ]
    metrics = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    extra = {}
    if refit_rows and len(metrics):
        comparisons = read_comparisons(paths.out)
        extra["refit"] = {
            "groups": [refit_verdict(metrics, group, comparisons) for group in benchmark.refit.groups],
            # mean over each run's camera sequences (every scored group's targets in frame order)
            "warp": {
                name: float(pd.read_parquet(paths.runs / name / SEQUENCES_FILE)["warp"].mean())
                for name in refit_rows
                if (paths.runs / name / SEQUENCES_FILE).is_file()
            },
        }
    return {
        **extra,
        "invocation": invocation,
        "preset": asdict(preset),
        "training_steps": steps,
        "stages": [
            {
                "name": r.name,
                "command": r.command,
                "seconds": round(r.seconds, 1),
                "resumed": r.resumed,
                "rerun_seconds": None if r.rerun_seconds is None else round(r.rerun_seconds, 1),
                "concurrent_group": r.group,
                "lane": r.lane,
                "threads": r.threads,
            }
            for r in pipeline.records
        ],
        "total_seconds": round(pipeline.elapsed_seconds(), 1),
        "this_run_seconds": round(pipeline.elapsed_seconds(this_run=True), 1),
        benchmark.verdict_key: lane_shift_verdict(metrics, benchmark.verdict_group) if len(metrics) else {},
        "outputs": sorted(
            p.name
            for p in paths.out.iterdir()
            if p.is_file() and not p.name.startswith(".") and p.name not in (REPORT_FILE, SUMMARY_FILE)
        )
        if paths.out.is_dir()
        else [],
    }
