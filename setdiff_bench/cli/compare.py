"""``setdiff-bench compare``: two runs on the targets they share — paired differences per group and per scene,
bootstrap intervals resampled by scene, and the scenes each run wins; Markdown and Parquet.

A difference "holds" when its interval excludes 0.  Intervals of the pooled and per-group rows resample
scenes (frames of one scene are not independent); per-scene rows resample the scene's frames.  Runs that share
no target are refused, naming how many targets each has.  See :mod:`setdiff_bench.reporting.compare`.

Examples::

    setdiff-bench compare runs/demo/work/runs/setdiff runs/demo/work/runs/difix --out runs/demo
    setdiff-bench compare runs/demo/work/runs/setdiff runs/demo/work/runs/identity --metrics psnr --resamples 2000
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path
from typing import TYPE_CHECKING

from setdiff_bench.cli.leaderboard import add_bootstrap_arguments, bootstrap_settings, parse_formats

if TYPE_CHECKING:
    import pandas as pd

VERB = "compare"
HELP = "paired differences of two runs on their shared targets: intervals (bootstrap by scene) and scene wins"
DESCRIPTION = __doc__
FORMATS = ("md", "parquet")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "run_a", type=Path, metavar="RUN_A", help="a finished run folder (holds metrics.parquet)"
    )
    parser.add_argument("run_b", type=Path, metavar="RUN_B", help="the run it is compared with (A − B)")
    parser.add_argument("--out", type=Path, default=Path("results/compare"), help="output folder")
    parser.add_argument("--format", default=",".join(FORMATS), help=f"comma list of {', '.join(FORMATS)}")
    parser.add_argument("--split", default="test", help="split of the targets to compare (train, test, all)")
    parser.add_argument(
        "--metrics", default=None, help="comma list of metric columns (default: the dataset's table metrics)"
    )
    add_bootstrap_arguments(parser)


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces the comparison (recorded in the Markdown)."""
    parts = ["setdiff-bench", "compare", str(args.run_a), str(args.run_b), "--out", str(args.out)]
    parts += ["--format", args.format, "--split", args.split]
    if args.metrics:
        parts += ["--metrics", args.metrics]
    parts += ["--resamples", str(args.resamples), "--bootstrap-seed", str(args.bootstrap_seed)]
    return " ".join(shlex.quote(part) for part in parts)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import UsageError
    from setdiff_bench.evaluation.profiles import DEFAULT_PROFILE
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.metrics.registry import METRICS
    from setdiff_bench.reporting.compare import compare_frames, write_comparison
    from setdiff_bench.reporting.leaderboard import load_runs, profile_rows
    from setdiff_bench.reporting.paired import PairingError

    settings = bootstrap_settings(args)
    formats = parse_formats(args.format, FORMATS)
    metrics = [m.strip() for m in args.metrics.split(",") if m.strip()] if args.metrics else None
    if metrics is not None:
        bad = [m for m in metrics if m not in METRICS]
        if bad or not metrics:
            raise UsageError(f"unknown metric(s) {', '.join(bad)}; known: {', '.join(METRICS)}", "--metrics")
    frames = []
    for folder in (args.run_a, args.run_b):
        if not (folder / METRICS_FILE).is_file():
            raise UsageError(f"not a finished run (no {METRICS_FILE})", folder)
        rows, _ = load_runs([folder])
        rows = profile_rows(rows, DEFAULT_PROFILE)
        if args.split != "all":
            rows = rows[rows["split"] == args.split]
            if not len(rows):
                raise UsageError(f"no targets of split {args.split!r} (pass --split all?)", folder)
        frames.append(rows)
    names = _names(args.run_a, args.run_b, frames[0], frames[1])
    try:
        comparison = compare_frames(
            frames[0],
            frames[1],
            names,
            metrics=metrics,
            settings=settings,
            runs=(str(args.run_a), str(args.run_b)),
        )
    except PairingError as error:
        raise UsageError(error.problem, args.run_b) from None
    for line in comparison.verdicts():
        print(line)
    for fmt, path in write_comparison(comparison, args.out, formats, _command(args)).items():
        print(f"{fmt}: {path}")
    return 0


def _names(run_a: Path, run_b: Path, a: pd.DataFrame, b: pd.DataFrame) -> tuple[str, str]:
    """The runs' methods, or their folder names when both runs are of one method (two seeds)."""
    methods = [", ".join(sorted(set(frame["method"]))) for frame in (a, b)]
    if methods[0] != methods[1]:
        return methods[0], methods[1]
    if run_a.name != run_b.name:
        return run_a.name, run_b.name
    return str(run_a), str(run_b)
