"""``setdiff-bench demo``: the embedded synthetic benchmark end to end (see :mod:`setdiff_bench.pipeline.demo`).

    setdiff-bench demo [--benchmark driving|sparse] [--preset tiny|default|full] [--out runs/demo]
                       [--train [--ablations] | --refit]

The outputs go to a scratch folder of the benchmark's own (default ``runs/demo`` for driving,
``runs/demo_sparse`` for sparse; git-ignored); ``setdiff-bench publish`` copies a finished run over the
published results on purpose.  The demo ends by printing its leaderboard and one line saying whether it
equals the published table (:mod:`setdiff_bench.pipeline.reproduction`).
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

from setdiff_bench.cli import add_device_argument, add_progress_argument

VERB = "demo"
HELP = "the embedded benchmark end to end: synthetic scenes, 3DGS fits, packets, SetDiff vs baselines, leaderboard"
DESCRIPTION = (
    "Generate the synthetic benchmark's test scenes, fit their 3DGS, build packets, run identity, "
    "reproject and the shipped DiFix and SetDiff models (tiny_difix, tiny_setdiff; trained on other "
    "scenes), and write the leaderboard, plots and grids into a scratch folder (default runs/demo, runs/demo_sparse for sparse, "
    "git-ignored; `setdiff-bench publish` copies a finished run to results/). --train makes every scene "
    "and trains SetDiff and DiFix first. Every stage resumes. --benchmark sparse runs the sparse-view "
    "benchmark instead (DL3DV-style walks, 3DGS on 3/6/9 views, shipped tiny_setdiff_sparse and "
    "tiny_difix_sparse, the leaderboard in Table 4's layout beside the paper's rows). --refit also distils "
    "every enhancer's novel views back into the test scenes' 3DGS and scores the rows X, X-3D and X-3D+ "
    "(docs/refit.md; default out runs/demo_refit, runs/demo_sparse_refit).\n\n"
    "Examples:\n\n    setdiff-bench demo\n    setdiff-bench demo --preset tiny --out runs/smoke\n"
    "    setdiff-bench demo --benchmark sparse\n"
    "    setdiff-bench demo --refit\n"
    "    setdiff-bench demo --train --setdiff-steps 1000 --difix-steps 1000\n"
    "    setdiff-bench demo --train --setdiff-steps 1000 --difix-steps 1000 --ablations"
)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from setdiff_bench.pipeline.presets import DEFAULT_BENCHMARK, DEMO_BENCHMARKS

    parser.add_argument(
        "--benchmark",
        default=DEFAULT_BENCHMARK,
        choices=tuple(DEMO_BENCHMARKS),
        help="; ".join(f"{b.name}: {b.description}" for b in DEMO_BENCHMARKS.values())
        + f" (default {DEFAULT_BENCHMARK})",
    )
    presets = DEMO_BENCHMARKS[DEFAULT_BENCHMARK].presets
    parser.add_argument(
        "--preset",
        default="default",
        choices=tuple(presets),
        help="; ".join(f"{p.name}: {p.description}" for p in presets.values())
        + " (the sparse benchmark's presets of the same names run its walks: "
        + "; ".join(f"{p.name}: {p.description}" for p in DEMO_BENCHMARKS["sparse"].presets.values())
        + ")",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default: "
        + ", ".join(f"{b.default_out} for {name}" for name, b in DEMO_BENCHMARKS.items())
        + "; git-ignored scratch folders, one per benchmark)",
    )
    parser.add_argument("--work", type=Path, default=None, help="intermediate data (default: <out>/work)")
    parser.add_argument("--seed", type=int, default=0, help="scene and training seed")
    parser.add_argument(
        "--jobs", type=int, default=2, help="processes for scene generation and packet rendering"
    )
    add_device_argument(parser, "device of every stage")
    parser.add_argument(
        "--train",
        action="store_true",
        help="make every scene and train SetDiff and DiFix on the training scenes instead of "
        "evaluating the shipped models",
    )
    parser.add_argument("--setdiff-steps", type=int, default=None, help="override the preset's SetDiff steps")
    parser.add_argument("--difix-steps", type=int, default=None, help="override the preset's DiFix steps")
    parser.add_argument(
        "--ablations",
        action="store_true",
        help="with --train: also run the geometry and set-size ablations (four more trainings)",
    )
    parser.add_argument(
        "--refit",
        action="store_true",
        help="also refit each test scene's 3DGS on every enhancer's novel views (progressive schedule, with "
        "snapshots) and score X, X-3D and X-3D+ with paired comparisons and a refit-steps plot (shipped models; "
        "default out "
        + ", ".join(f"{b.refit.default_out} for {name}" for name, b in DEMO_BENCHMARKS.items())
        + ")",
    )
    add_progress_argument(parser)


def invocation(args: argparse.Namespace) -> str:
    """The command line that reproduces this demo, from the parsed arguments."""
    parts = ["demo"]
    parts += (
        ["--benchmark", args.benchmark] if args.benchmark != "driving" else []
    )  # the default: not repeated
    parts += ["--preset", args.preset, "--out", str(args.out), "--seed", str(args.seed)]
    device = None if args.device == "auto" else args.device  # auto is the default: not repeated
    for flag, value in (
        ("--work", args.work),
        ("--device", device),
        ("--setdiff-steps", args.setdiff_steps),
        ("--difix-steps", args.difix_steps),
    ):
        if value is not None:
            parts += [flag, str(value)]
    parts += ["--train"] if args.train else []
    if args.ablations:
        parts.append("--ablations")
    if args.refit:
        parts.append("--refit")
    return "setdiff-bench " + shlex.join(parts)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import UsageError
    from setdiff_bench.pipeline.demo import DemoPaths, run_demo
    from setdiff_bench.pipeline.presets import get_benchmark, get_demo_preset
    from setdiff_bench.pipeline.reproduction import Reproduction
    from setdiff_bench.pipeline.stages import StageFailed
    from setdiff_bench.runtime.devices import resolve_device

    if args.jobs < 1:
        raise UsageError(f"--jobs must be >= 1, got {args.jobs}", "--jobs")
    resolve_device(
        args.device
    )  # checked here; passed on as given (auto: not at all), so the stages resolve it
    preset = get_demo_preset(args.preset, args.benchmark)
    benchmark = get_benchmark(args.benchmark)
    default_out = benchmark.refit.default_out if args.refit else benchmark.default_out
    args.out = args.out if args.out is not None else Path(default_out)
    paths = DemoPaths(out=args.out, work=args.work or args.out / "work")
    device = None if args.device == "auto" else args.device  # the stages' own default is auto
    try:
        summary = run_demo(
            preset,
            paths,
            seed=args.seed,
            jobs=args.jobs,
            device=device,
            train=args.train,
            setdiff_steps=args.setdiff_steps,
            difix_steps=args.difix_steps,
            ablations=args.ablations,
            refit=args.refit,
            progress=not args.no_progress,
            invocation=invocation(args),
        )
    except StageFailed as failure:
        return failure.code
    this_run = summary["this_run_seconds"]
    board = args.out / f"{benchmark.leaderboard}.md"
    if board.is_file():
        print(board.read_text(encoding="utf-8").strip() + "\n")
    print(Reproduction.from_json(summary["reproduction"]).line())
    print(
        f"demo finished: {summary['total_seconds'] / 60:.1f} min of stage work, {this_run / 60:.1f} min in this run: "
        f"{args.out / 'README.md'}"
    )
    return 0
