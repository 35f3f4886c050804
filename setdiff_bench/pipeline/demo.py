"""The embedded benchmark end to end: synthetic test scenes → 3DGS fits → packets → ``identity``,
``reproject``, ``difix``, ``setdiff`` → leaderboard, plots, grids.

By default the demo evaluates the models shipped in the package (``tiny_setdiff``, ``tiny_difix``:
:mod:`setdiff_bench.models.setdiff.packaged`), trained with the toolkit's own commands on synthetic
scenes whose generator seeds are disjoint from the demo's test scenes (checked before any work).  It
generates and fits only the preset's **test** scenes (the synthetic protocol's scene split over the
preset's scene list), declares them the test split of the packet store (``prepare --test-scene``),
runs the four methods and writes the leaderboard.  ``--train`` keeps the whole path instead: every
scene, SetDiff and DiFix trained on the training scenes, then the same evaluation (and, on request,
the two ablations, which need training).

Every stage is an ordinary ``setdiff-bench`` command run in its own process
(:mod:`setdiff_bench.pipeline.stages`); the demo records each command and its wall time in
``<out>/README.md`` and ``<out>/demo.json``.  Bulky intermediate data (scenes, packets,
checkpoints, runs) goes to ``<out>/work``; tables, plots and the report sit in ``<out>``, by default
the scratch folder ``runs/demo`` (git-ignored).  The project's published results are replaced only
on purpose, by ``setdiff-bench publish`` (:mod:`setdiff_bench.pipeline.publish`).  Every stage resumes, so an
interrupted demo continues where it stopped; a stage finished by an earlier run keeps its original
time in the report, marked resumed (``<work>/stages.json``).

``demo.json`` is written last (and removed when a run starts), so its presence means the outputs
beside it are complete and from one run; it records the provenance (git revision, command, seed,
torch thread count, package versions) and the SHA-256 of every output.

Presets (``--preset``):

* ``tiny``: tiny scenes (80×48) — a smoke test (CI runs it with and without ``--train``).  Its
  numbers mean nothing.
* ``default``: the ``default`` synthetic preset's 2 test scenes at 256×144 with the shipped models
  (about 5 minutes on 2 CPU cores, measured in README.md); with ``--train``, all 6 scenes and short CPU
  training.
* ``full``: the ``large`` synthetic preset (8 scenes at 512×288); meant for ``--train`` on a GPU.

``--benchmark sparse`` runs the same stages on the sparse-view benchmark
(:data:`setdiff_bench.pipeline.presets.DEMO_BENCHMARKS`): the ``sparse*`` synthetic presets' walks in
DL3DV's layout, prepared with the packaged ``dl3dv_sparse_synthetic`` protocol (its listed test scenes
``sparse_0000_00`` and ``sparse_0000_01``, so seed 0), the shipped ``tiny_setdiff_sparse`` and
``tiny_difix_sparse``, and the leaderboard in Table 4's layout beside the paper's reported DL3DV rows,
with the metrics-against-view-count plot.

Modules, in the order a demo uses them: :mod:`.demo_layout` (its folders and files), :mod:`.demo_scenes`
(the test scenes and the shipped models' unseen check), :mod:`.demo_stages` (every stage's command, as
data), this module (:func:`run_demo`, which runs them), :mod:`.demo_summary` (``demo.json``) and
:mod:`.demo_report` (``README.md``).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file, write_text_atomic
from setdiff_bench.pipeline.demo_layout import BENCHMARK_FILE, REPORT_FILE, SUMMARY_FILE, DemoPaths
from setdiff_bench.pipeline.demo_report import report_markdown
from setdiff_bench.pipeline.demo_scenes import (
    SHIPPED_MODELS,
    check_unseen,
    evaluation_scene_indices,
    scene_count,
    scene_namer,
)
from setdiff_bench.pipeline.demo_stages import METHODS, DemoPlan, DemoStage, DemoStages, demo_stages
from setdiff_bench.pipeline.demo_summary import (
    VERDICT_METRICS,
    better,
    lane_shift_verdict,
    run_provenance,
    summarize,
)
from setdiff_bench.pipeline.presets import (
    DEMO_PRESETS,
    DemoBenchmark,
    DemoPreset,
    get_benchmark,
    get_demo_preset,
)
from setdiff_bench.pipeline.reproduction import check_reproduction
from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline
from setdiff_bench.runtime.devices import resolve_device

__all__ = [
    "DEMO_PRESETS",
    "METHODS",
    "REPORT_FILE",
    "SHIPPED_MODELS",
    "SUMMARY_FILE",
    "VERDICT_METRICS",
    "DemoBenchmark",
    "DemoPaths",
    "DemoPlan",
    "DemoPreset",
    "DemoStage",
    "DemoStages",
    "Pipeline",
    "better",
    "check_folder",
    "check_unseen",
    "demo_stages",
    "evaluation_scene_indices",
    "get_benchmark",
    "get_demo_preset",
    "lane_shift_verdict",
    "report_markdown",
    "run_demo",
    "run_provenance",
    "scene_count",
    "scene_namer",
    "summarize",
]


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


def check_folder(paths: DemoPaths, benchmark: DemoBenchmark) -> None:
    """Refuse, before any work, a folder that holds another benchmark's outputs (its store and runs stay
    untouched); :class:`UsageError` naming the option to pass."""
    other = folder_benchmark(paths)
    if other is not None and other != benchmark.name:
        raise UsageError(
            f"{paths.out} holds the {other} demo's outputs; pass --out for the {benchmark.name} benchmark "
            f"(its default is {benchmark.default_out})",
            "--out",
        )


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
    progress: bool = True,
    invocation: str = "",
) -> dict[str, Any]:
    """Run every stage of the demo; returns the summary also written to ``<out>/demo.json``.

    Args:
        train: train SetDiff and DiFix on the preset's training scenes (else evaluate the shipped models
            on its test scenes only).
        setdiff_steps, difix_steps, ablations: with ``train`` only.

    Raises:
        UsageError: training options without ``train``; a shipped model trained on a test scene.
        StageFailed: a stage exited non-zero (it printed its own error line).
    """
    if not train and (setdiff_steps or difix_steps or ablations):
        raise UsageError(
            "--setdiff-steps, --difix-steps and --ablations train models: add --train", "--train"
        )
    benchmark = get_benchmark(preset.benchmark)
    check_folder(paths, benchmark)
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
    write_text_atomic(paths.work / BENCHMARK_FILE, benchmark.name + "\n")
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
    pipeline.run(*stages.leaderboard)
    for stage in stages.ablations:
        pipeline.run(*stage)
    steps, configs, checkpoints = plan.steps, plan.configs, plan.checkpoints
    summary = summarize(paths, preset, steps if train else {}, pipeline, invocation)
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
    summary["reproduction"] = check_reproduction(benchmark, preset.name, seed, paths.out).as_json()
    write_text_atomic(paths.out / REPORT_FILE, report_markdown(summary, paths))
    summary["files"] = {
        p.name: sha256_file(p)
        for p in sorted(paths.out.iterdir())
        if p.is_file() and not p.name.startswith(".") and p.name != SUMMARY_FILE
    }
    write_text_atomic(paths.out / SUMMARY_FILE, json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return summary
