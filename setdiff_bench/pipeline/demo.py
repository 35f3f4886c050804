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
on purpose, by ``setdiff-bench publish`` (:mod:`setdiff_bench.reporting.publish`).  Every stage resumes, so an
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
"""

from __future__ import annotations

import json
import os
import platform
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file, write_text_atomic
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.models.setdiff.packaged import packaged_models
from setdiff_bench.pipeline.presets import (  # noqa: F401 (DEFAULT_OUT, DEMO_PRESETS: re-exported)
    DEFAULT_OUT,
    DEMO_PRESETS,
    DemoBenchmark,
    DemoPreset,
    get_benchmark,
    get_demo_preset,
)
from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline, relative
from setdiff_bench.protocols import load_protocol
from setdiff_bench.runtime.devices import resolve_device
from setdiff_bench.runtime.provenance import git_revision, package_versions
from setdiff_bench.runtime.threads import compute_threads

METHODS = ("identity", "reproject", "difix", "setdiff")
VERDICT_METRICS = ("psnr", "ssim", "lpips")  # the verdict's metrics, in table order
#: The learned methods and the shipped models the driving demo evaluates unless ``--train``.
SHIPPED_MODELS = get_benchmark("driving").shipped
#: The demo's summary in ``<out>``; written last, so a folder with it holds one complete run.
SUMMARY_FILE = "demo.json"
REPORT_FILE = "README.md"


@dataclass(frozen=True)
class DemoPaths:
    """Where the demo reads and writes (all under ``out``)."""

    out: Path
    work: Path

    @property
    def scenes(self) -> Path:
        return self.work / "scenes"

    @property
    def packets(self) -> Path:
        return self.work / "packets"

    def checkpoints(self, method: str) -> Path:
        return self.work / "checkpoints" / method

    @property
    def runs(self) -> Path:
        return self.work / "runs"


def scene_namer(preset: DemoPreset) -> Any:
    """``(seed, index) → scene name`` as ``synth`` names the preset's scenes."""
    # lazy: the CLI imports this module at startup (demo presets); the generator pulls in the 3DGS fitting code
    if get_benchmark(preset.benchmark).dataset == "synthetic":
        from setdiff_bench.synthetic.generate import scene_name

        return scene_name
    from setdiff_bench.synthetic.sparse import sparse_scene_name

    return sparse_scene_name


def scene_count(preset: DemoPreset) -> int:
    """How many scenes (indices ``0 … count - 1``) the preset's benchmark holds."""
    if preset.scenes:
        return preset.scenes
    if get_benchmark(preset.benchmark).dataset == "synthetic":
        from setdiff_bench.synthetic.presets import get_preset

        return get_preset(preset.synth_preset).num_scenes
    from setdiff_bench.synthetic.sparse import get_sparse_preset

    return get_sparse_preset(preset.synth_preset).num_scenes


def evaluation_scene_indices(preset: DemoPreset, seed: int) -> list[int]:
    """The generator indices of the preset's test scenes: the benchmark protocol's scene split over the
    scene names ``synth`` gives the preset's scenes.

    Raises:
        UsageError: no scene of ``seed`` is a test scene (the sparse protocol lists seed 0's).
    """
    benchmark = get_benchmark(preset.benchmark)
    name = scene_namer(preset)
    names = [name(seed, index) for index in range(scene_count(preset))]
    assignment = load_protocol(benchmark.protocol or benchmark.dataset).split.assign(names)
    indices = [index for index, name in enumerate(names) if assignment[name] == "test"]
    if not indices:
        raise UsageError(
            f"the {benchmark.name} benchmark's protocol has no test scene among seed {seed}'s scenes "
            f"({names[0]} …); its test scenes are listed in protocol {benchmark.protocol}",
            "--seed",
        )
    return indices


def check_unseen(
    test_scenes: list[tuple[int, int]],
    shipped_models: dict[str, str] | None = None,
    scene_name: Any = None,
) -> dict[str, dict[str, Any]]:
    """The shipped models' manifests, after checking that none was trained on a demo test scene.

    Args:
        test_scenes: ``(seed, index)`` of each test scene.
        shipped_models: ``{method: packaged model}`` (default: the driving benchmark's).
        scene_name: ``(seed, index) → scene name`` of the benchmark's scenes (default: the driving
            benchmark's, :func:`setdiff_bench.synthetic.generate.scene_name`); compared with the training
            scene names in each manifest (``data.scenes``), so a driving scene and a sparse walk of the same
            ``(seed, index)`` are different scenes.

    Raises:
        UsageError: a shipped model is missing, or its training scenes include a test scene.
    """
    if scene_name is None:
        from setdiff_bench.synthetic.generate import scene_name
    tested = {scene_name(seed, index) for seed, index in test_scenes}
    shipped = packaged_models()
    manifests = {}
    for method, name in (SHIPPED_MODELS if shipped_models is None else shipped_models).items():
        if name not in shipped:
            raise UsageError(
                f"the shipped model {name!r} is not in this installation; run the demo with --train",
                "--train",
            )
        manifest = shipped[name].manifest
        seen = tested & {str(scene).rsplit("/", 1)[-1] for scene in manifest["data"]["scenes"]}
        if seen:
            raise UsageError(
                f"shipped model {name!r} was trained on scene {sorted(seen)[0]}, one of "
                "this demo's test scenes: pick another --seed or use --train",
                "--seed",
            )
        manifests[method] = manifest
    return manifests


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
    scene_name = scene_namer(preset)
    test_indices = evaluation_scene_indices(preset, seed)
    shipped = (
        {}
        if train
        else check_unseen([(seed, index) for index in test_indices], benchmark.shipped, scene_name)
    )
    base = Path.cwd()
    (paths.out / SUMMARY_FILE).unlink(missing_ok=True)  # until this run completes, the folder is not a run
    pipeline = Pipeline(cwd=base, quiet=not progress, ledger=paths.work / LEDGER_FILE)
    rel = lambda p: relative(p, base)  # noqa: E731 - commands read better with short relative paths
    quiet = [] if progress else ["--no-progress"]
    steps = {"setdiff": setdiff_steps or preset.setdiff_steps, "difix": difix_steps or preset.difix_steps}
    configs = {"setdiff": preset.setdiff_config, "difix": preset.difix_config}

    synth = [
        "synth",
        "--out",
        rel(paths.scenes),
        "--preset",
        preset.synth_preset,
        "--seed",
        seed,
        "--jobs",
        jobs,
    ]
    if train:
        synth += ["--scenes", preset.scenes] if preset.scenes else []
    else:
        synth += ["--indices", ",".join(str(i) for i in test_indices)]
    synth += ["--device", device] if device else []
    pipeline.run("synth", synth + quiet)
    prepare = [
        "prepare",
        benchmark.dataset,
        *(["--protocol", benchmark.protocol] if benchmark.protocol else []),
        "--root",
        rel(paths.scenes),
        "--fits",
        rel(paths.scenes),
        "--out",
        rel(paths.packets),
        "--split",
        "all" if train else "test",
        "--workers",
        jobs,
    ]
    if not train and benchmark.protocol is None:
        # only the test scenes exist here: the synthetic protocol's interleaved split over them would differ
        prepare += [part for index in test_indices for part in ("--test-scene", scene_name(seed, index))]
    pipeline.run("prepare", prepare + quiet)
    checkpoints = (
        {method: rel(paths.checkpoints(method)) for method in configs} if train else dict(benchmark.shipped)
    )
    for method in configs if train else ():
        command = [
            "train",
            "--config",
            configs[method],
            "--packets",
            rel(paths.packets),
            "--out",
            checkpoints[method],
            "--steps",
            steps[method],
            "--seed",
            seed,
        ]
        command += ["--device", "cpu"] if device == "cpu" else []
        pipeline.run(f"train {method}", command + quiet)
    runs = []
    for method in METHODS:
        run = [
            "run",
            "--method",
            method,
            "--packets",
            rel(paths.packets),
            "--split",
            "test",
            "--out",
            rel(paths.runs / method),
        ]
        run += ["--checkpoint", checkpoints[method]] if method in checkpoints else []
        run += ["--device", device] if device else []
        runs.append((f"run {method}", run + quiet))
    if jobs >= 2 and resolve_device(device) == "cpu":
        # SetDiff alone takes about as long as the other three together: two lanes, one CPU share each.
        alone = [stage for stage in runs if stage[0] == "run setdiff"]
        pipeline.run_concurrently([[stage for stage in runs if stage not in alone], alone])
    else:
        for name, run in runs:
            pipeline.run(name, run)
    pipeline.run(
        "leaderboard",
        [
            "leaderboard",
            "--dataset",
            benchmark.leaderboard,
            "--runs",
            rel(paths.runs),
            "--out",
            rel(paths.out),
            "--methods",
            ",".join(METHODS),
            "--plots",
            "--grids",
            preset.grid_frames,
            "--packets",
            rel(paths.packets),
            *(["--with-reported"] if benchmark.with_reported else []),
        ],
    )
    if ablations:
        ablate_common = [
            "--packets",
            rel(paths.packets),
            "--out",
            rel(paths.out),
            "--work",
            rel(paths.work),
            *quiet,
        ]
        ablate_common += ["--device", device] if device else []
        pipeline.run(
            "ablate geometry",
            [
                "ablate",
                "geometry",
                "--config",
                configs["setdiff"],
                "--steps",
                steps["setdiff"],
                *ablate_common,
            ],
        )
        pipeline.run(
            "ablate setsize",
            ["ablate", "setsize", "--checkpoint", rel(paths.checkpoints("setdiff")), *ablate_common],
        )
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
    write_text_atomic(paths.out / REPORT_FILE, report_markdown(summary, paths))
    summary["files"] = {
        p.name: sha256_file(p)
        for p in sorted(paths.out.iterdir())
        if p.is_file() and not p.name.startswith(".") and p.name != SUMMARY_FILE
    }
    write_text_atomic(paths.out / SUMMARY_FILE, json.dumps(summary, indent=2, sort_keys=True) + "\n")
    return summary


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


def lane_shift_verdict(metrics: pd.DataFrame, group: str = "lane+2") -> dict[str, Any]:
    """SetDiff against ``identity`` and ``difix`` on one group (the benchmark's verdict group: +2 lanes,
    3 views): means and who wins each metric.

    Args:
        metrics: per-target rows of the four runs (``metrics.parquet`` concatenated).
    """
    rows = metrics[metrics["group"] == group]
    means = rows.groupby("method")[list(VERDICT_METRICS)].mean()
    verdict: dict[str, Any] = {
        "group": group,
        "targets": int((rows["method"] == "setdiff").sum()),
        "means": {m: {k: float(v) for k, v in means.loc[m].items()} for m in means.index},
    }
    if "setdiff" in means.index:
        for other in ("identity", "difix"):
            if other in means.index:
                verdict[f"setdiff_beats_{other}"] = {
                    name: bool(better(name, means.loc["setdiff", name], means.loc[other, name]))
                    for name in VERDICT_METRICS
                }
    return verdict


def summarize(
    paths: DemoPaths, preset: DemoPreset, steps: dict[str, int], pipeline: Pipeline, invocation: str
) -> dict[str, Any]:
    """The demo's machine-readable summary: preset, stage commands and times, the verdict on the benchmark's
    verdict group (under its ``verdict_key``: ``lane_plus_2``, ``views_3``)."""
    benchmark = get_benchmark(preset.benchmark)
    frames = [
        pd.read_parquet(paths.runs / m / METRICS_FILE)
        for m in METHODS
        if (paths.runs / m / METRICS_FILE).is_file()
    ]
    metrics = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    return {
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


def report_markdown(summary: dict[str, Any], paths: DemoPaths) -> str:
    """``<out>/README.md``: what ran, how long, the leaderboard, the verdict and the files."""
    benchmark = get_benchmark(summary["preset"].get("benchmark", "driving"))
    lines = [f"# {benchmark.title}", ""]
    lines += [
        f"Produced by `{summary['invocation']}` (preset `{summary['preset']['name']}`: "
        f"{summary['preset']['description']}); total stage time {summary['total_seconds'] / 60:.1f} min.",
        "",
    ]
    provenance = summary.get("provenance") or {}
    if provenance:
        git = provenance["git"]
        revision = (git["revision"] or "unknown")[:12] + (" with uncommitted changes" if git["dirty"] else "")
        lines += [
            f"Code revision {revision}; seed {provenance['seed']}; {provenance['torch_threads']} torch "
            f"threads on {provenance['machine']['cpu']} (set `SETDIFF_THREADS` to repeat it elsewhere).",
            "",
        ]
    models = summary.get("models") or {}
    for method, model in models.items():
        if "shipped" in model:
            lines.append(
                f"- `{method}`: the shipped model `{model['shipped']}`, trained on "
                f"{', '.join(model['trained_on'])} (none of them a test scene here)."
            )
        else:
            lines.append(f"- `{method}`: trained by this demo ({summary['training_steps'][method]} steps).")
    if models:
        lines.append(f"- Test scenes: {', '.join(summary.get('test_scenes', []))}.")
        lines.append("")
    board = paths.out / f"{benchmark.leaderboard}.md"
    if board.is_file():
        lines += ["## Leaderboard (test scenes)", "", board.read_text(encoding="utf-8").strip(), ""]
        lines += [benchmark.note, ""] if benchmark.note else []
    verdict = summary.get(benchmark.verdict_key) or {}
    if verdict.get("means"):
        specs = [get_metric(name) for name in VERDICT_METRICS]
        lines += [
            f"## {benchmark.verdict_title} ({verdict['targets']} targets)",
            "",
            "| method | " + " | ".join(f"{spec.label} {spec.arrow}" for spec in specs) + " |",
            "|---|" + "---:|" * len(specs),
        ]
        for method in METHODS:
            if method in verdict["means"]:
                m = verdict["means"][method]
                lines.append(
                    f"| {method} | "
                    + " | ".join(f"{m[spec.name]:.{spec.decimals}f}" for spec in specs)
                    + " |"
                )
        for other in ("identity", "difix"):
            wins = verdict.get(f"setdiff_beats_{other}")
            if wins:
                said = ", ".join(f"{k.upper()} {'yes' if v else 'no'}" for k, v in wins.items())
                lines.append(f"\nSetDiff beats `{other}` {benchmark.verdict_title.lower()}: {said}.")
        lines.append("")
    for name, title in (
        ("ablation_geometry.md", "Geometry ablation"),
        ("ablation_setsize.md", "Set-size ablation"),
    ):
        if (paths.out / name).is_file():
            lines += [f"- {title}: [{name}]({name})"]
    lines += ["", "## Commands, in order", ""]
    for stage in summary["stages"]:
        timing = f"{stage['seconds']:.0f} s"
        if stage.get("resumed"):
            timing += f", resumed: work done by an earlier run; this run {stage['rerun_seconds']:.0f} s"
        if stage.get("concurrent_group") is not None:
            timing += f", concurrent group {stage['concurrent_group']} lane {stage['lane']}"
        lines.append(f"1. `{stage['command']}` ({stage['name']}, {timing})")
    lines += ["", "## Files", ""]
    lines += [f"- `{name}`" for name in summary["outputs"]]
    lines += [
        "",
        f"Intermediate data (scenes, packets, checkpoints, runs): `{paths.work}` (not versioned).",
        "",
    ]
    return "\n".join(lines)
