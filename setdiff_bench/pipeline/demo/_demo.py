"""``run_demo``: an embedded benchmark end to end, stage by stage (the package's docstring says what it does)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file, write_text_atomic
from setdiff_bench.pipeline.demo._layout import BENCHMARK_FILE, REPORT_FILE, SUMMARY_FILE, DemoPaths
from setdiff_bench.pipeline.demo._report import report_markdown
from setdiff_bench.pipeline.demo._scenes import (
    check_unseen,
    evaluation_scene_indices,
    scene_namer,
)
from setdiff_bench.pipeline.demo._stages import DemoPlan, DemoStages, demo_stages, refit_rows
from setdiff_bench.pipeline.demo._summary import (
    run_provenance,
    summarize,
)
from setdiff_bench.pipeline.presets import (
    DemoBenchmark,
    DemoPreset,
    get_benchmark,
)
from setdiff_bench.pipeline.reproduction import check_reproduction
from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline
from setdiff_bench.runtime.devices import resolve_device


def folder_benchmark(paths: DemoPaths) -> str | None:
    """Which benchmark's outputs ``paths`` already hold (``None``: none).

    The demo records it in ``<work>/benchmark``; a folder made before that record existed is known by its
    finished run's ``demo.json`` (whose preset names its benchmark, ``driving`` when it predates the key).
    """
    marker = paths.work / BENCHMARK_FILE
    if marker.is_file():
        return marker.read_text(encoding="utf-8").strip()
    summary = paths.out / SUMMARY_FILE
    if summary.is_file():
        try:
            return json.loads(summary.read_text(encoding="utf-8"))["preset"].get("benchmark", "driving")
        except (ValueError, KeyError, TypeError, AttributeError):
            return None
    return None


def folder_kind(benchmark: DemoBenchmark, refit: bool) -> str:
    """What a demo folder holds, as ``<work>/benchmark`` records it: the benchmark's name, ``+refit`` for
    ``demo --refit`` (its store holds fewer groups and its runs more rows)."""
    return f"{benchmark.name}+refit" if refit else benchmark.name


def check_folder(paths: DemoPaths, benchmark: DemoBenchmark, refit: bool = False) -> None:
    """Refuse, before any work, a folder that holds another benchmark's outputs, or the other kind of demo's
    (with or without ``--refit``): its store and runs stay untouched; :class:`UsageError` naming the option."""
    other, kind = folder_benchmark(paths), folder_kind(benchmark, refit)
    if other is not None and other != kind:
        default = benchmark.refit.default_out if refit else benchmark.default_out
        raise UsageError(
            f"{paths.out} holds the {other} demo's outputs; pass --out for the {kind} demo (its default is "
            f"{default})",
            "--out",
        )


def _run_refits(pipeline: Pipeline, stages: DemoStages, *, parallel: bool) -> None:
    """The refits and their scoring (each enhancer's refits before its scoring); on a CPU with two jobs in two
    lanes of whole enhancers: SetDiff and ``identity`` in one, DiFix and ``reproject`` in the other."""
    first = ("setdiff", "identity")
    lanes = [
        [s for m in first for s in stages.refits[m]],
        [s for m, own in stages.refits.items() if m not in first for s in own],
    ]
    if parallel:
        pipeline.run_concurrently(lanes)
    else:
        for stage in lanes[0] + lanes[1]:
            pipeline.run(*stage)


def run_demo(
    preset: DemoPreset,
    paths: DemoPaths,
    *,
    seed: int = 0,
    jobs: int = 2,
    device: str | None = None,
    train: bool = False,
    setdiff_steps: int | None = None,
    difix_steps: int | None = None,
    ablations: bool = False,
    refit: bool = False,
    progress: bool = True,
    invocation: str = "",
) -> dict[str, Any]:
    """Run every stage of the demo; returns the summary also written to ``<out>/demo.json``.

    Args:
        train: train SetDiff and DiFix on the preset's training scenes (else evaluate the shipped models
            on its test scenes only).
        setdiff_steps, difix_steps, ablations: with ``train`` only.
        refit: score every enhancer also distilled into the test scenes' 3DGS (``X 3D``, ``X 3D+``; the
            benchmark's :class:`~setdiff_bench.pipeline.presets.RefitDemo`), with the shipped models.

    Raises:
        UsageError: training options without ``train``; a shipped model trained on a test scene.
        StageFailed: a stage exited non-zero (it printed its own error line).
    """
    if not train and (setdiff_steps or difix_steps or ablations):
        raise UsageError(
            "--setdiff-steps, --difix-steps and --ablations train models: add --train", "--train"
        )
    if refit and train:
        raise UsageError(
            "--refit scores the shipped models (a refit per enhancer and test scene); run it without --train",
            "--refit",
        )
    benchmark = get_benchmark(preset.benchmark)
    check_folder(paths, benchmark, refit)
    scene_name = scene_namer(preset)
    test_indices = evaluation_scene_indices(preset, seed)
    shipped = (
        {}
        if train
        else check_unseen([(seed, index) for index in test_indices], benchmark.shipped, scene_name)
    )
    base = Path.cwd()
    (paths.out / SUMMARY_FILE).unlink(missing_ok=True)  # until this run completes, the folder is not a run
    paths.work.mkdir(parents=True, exist_ok=True)
    write_text_atomic(paths.work / BENCHMARK_FILE, folder_kind(benchmark, refit) + "\n")
    pipeline = Pipeline(cwd=base, quiet=not progress, ledger=paths.work / LEDGER_FILE)
    plan = DemoPlan(
        preset,
        benchmark,
        paths,
        base,
        seed,
        jobs,
        device,
        train,
        progress,
        test_indices,
        scene_name,
        steps={"setdiff": setdiff_steps or preset.setdiff_steps, "difix": difix_steps or preset.difix_steps},
        configs={"setdiff": preset.setdiff_config, "difix": preset.difix_config},
        refit=refit,
    )
    stages = demo_stages(plan, ablations=ablations)
    for stage in stages.setup:
        pipeline.run(*stage)
    if jobs >= 2 and resolve_device(device) == "cpu":
        # SetDiff alone takes about as long as the other three together: two lanes, one CPU share each.
        alone = [stage for stage in stages.runs if stage.name == "run setdiff"]
        pipeline.run_concurrently([[stage for stage in stages.runs if stage not in alone], alone])
    else:
        for stage in stages.runs:
            pipeline.run(*stage)
    if refit:
        _run_refits(pipeline, stages, parallel=jobs >= 2 and resolve_device(device) == "cpu")
    pipeline.run(*stages.leaderboard)
    for stage in [*stages.ablations, *stages.compares]:
        pipeline.run(*stage)
    steps, configs, checkpoints = plan.steps, plan.configs, plan.checkpoints
    summary = summarize(
        paths, preset, steps if train else {}, pipeline, invocation, refit_rows(plan) if refit else None
    )
    summary["models"] = (
        {method: {"checkpoint": checkpoints[method]} for method in configs}
        if train
        else {
            method: {
                "shipped": benchmark.shipped[method],
                "files": m["files"],
                "trained_on": m["data"]["scenes"],
                "training_seeds": m["data"].get("synthetic_seeds", []),
            }
            for method, m in shipped.items()
        }
    )
    summary["test_scenes"] = [scene_name(seed, index) for index in test_indices]
    summary["provenance"] = run_provenance(seed)
    summary["provenance"]["tolerance"] = dict(benchmark.tolerance)
    summary["reproduction"] = check_reproduction(
        benchmark, preset.name, seed, paths.out, refit=refit
    ).as_json()
    write_text_atomic(paths.out / REPORT_FILE, report_markdown(summary, paths))
    summary["files"] = {
        p.name: sha256_file(p)
        for p in sorted(paths.out.iterdir())
        if p.is_file() and not p.name.startswith(".") and p.name != SUMMARY_FILE
    }
    write_text_atomic(paths.out / SUMMARY_FILE, json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return summary
