"""``setdiff-bench compare``: two runs on the targets they share — paired gains of RUN_A over RUN_B per group and
per scene (positive = RUN_A better in every column: ``A − B`` where higher is better, ``B − A`` where lower is,
as the report shows), bootstrap intervals resampled by scene, and the scenes each run wins; Markdown and Parquet.

A difference "holds" when its interval excludes 0.  Intervals of the pooled and per-group rows resample
scenes (frames of one scene are not independent); per-scene rows resample the scene's frames.  Runs that share
no target are refused, naming how many targets each has.  See :mod:`setdiff_bench.reporting.compare`.

``RUN_A`` and ``RUN_B`` are run folders, or the names of runs (the method, or ``run --name``) found under the
``--runs`` folders (several: ``--runs A B`` or ``--runs A --runs B``, as ``leaderboard`` and ``report``).  The
outputs go to ``--out`` (default ``runs/compare``, outside the tracked tree).

Examples::

    setdiff-bench compare runs/demo/work/runs/setdiff runs/demo/work/runs/difix --out runs/demo
    setdiff-bench compare runs/demo/work/runs/setdiff runs/demo/work/runs/identity --metrics psnr --resamples 2000
    setdiff-bench compare mymethod setdiff --runs runs/mine runs/demo/work/runs
"""

from __future__ import annotations

import argparse
import shlex
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from setdiff_bench.cli.leaderboard import (
    add_bootstrap_arguments,
    add_runs_argument,
    bootstrap_settings,
    parse_formats,
)

if TYPE_CHECKING:
    import pandas as pd

VERB = "compare"
HELP = "paired gains of one run over another on shared targets (positive = better): intervals, scene wins"
DESCRIPTION = __doc__
FORMATS = ("md", "parquet")
#: Where the outputs go without ``--out`` (ignored by git, like every ``runs/`` folder).
DEFAULT_OUT = Path("runs/compare")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "run_a",
        metavar="RUN_A",
        help="a finished run folder (holds metrics.parquet), or the name of a run under --runs",
    )
    parser.add_argument("run_b", metavar="RUN_B", help="the run it is compared with (gains of A over B)")
    add_runs_argument(parser, "folders searched for RUN_A / RUN_B given by name (several: --runs A B)")
    parser.add_argument(
        "--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT})"
    )
    parser.add_argument("--format", default=",".join(FORMATS), help=f"comma list of {', '.join(FORMATS)}")
    parser.add_argument("--split", default="test", help="split of the targets to compare (train, test, all)")
    parser.add_argument(
        "--metrics", default=None, help="comma list of metric columns (default: the dataset's table metrics)"
    )
    add_bootstrap_arguments(parser)


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces the comparison (recorded in the Markdown)."""
    parts = ["setdiff-bench", "compare", str(args.run_a), str(args.run_b)]
    if args.runs:
        parts += ["--runs", *map(str, dict.fromkeys(args.runs))]
    parts += ["--out", str(args.out)]
    parts += ["--format", args.format, "--split", args.split]
    if args.metrics:
        parts += ["--metrics", args.metrics]
    parts += ["--resamples", str(args.resamples), "--bootstrap-seed", str(args.bootstrap_seed)]
    return " ".join(shlex.quote(part) for part in parts)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import UsageError
    from setdiff_bench.metrics.registry import METRICS
    from setdiff_bench.protocols.profiles import DEFAULT_PROFILE
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
    folders = [
        resolve_run(text, parameter, list(dict.fromkeys(args.runs or ())))
        for text, parameter in ((args.run_a, "run_a"), (args.run_b, "run_b"))
    ]
    frames = []
    for folder in folders:
        rows, _ = load_runs([folder])
        rows = profile_rows(rows, DEFAULT_PROFILE)
        if args.split != "all":
            rows = rows[rows["split"] == args.split]
            if not len(rows):
                raise UsageError(f"no targets of split {args.split!r} (pass --split all?)", folder)
        frames.append(rows)
    names = _names(folders[0], folders[1], frames[0], frames[1])
    try:
        comparison = compare_frames(
            frames[0],
            frames[1],
            names,
            metrics=metrics,
            settings=settings,
            runs=(str(folders[0]), str(folders[1])),
        )
    except PairingError as error:
        raise UsageError(error.problem, folders[1]) from None
    print(comparison.header())  # which run is A, and the sign of the gains
    for line in comparison.verdicts():
        print(line)
    for fmt, path in write_comparison(comparison, args.out, formats, _command(args)).items():
        print(f"{fmt}: {path}")
    return 0


def resolve_run(text: str, parameter: str, searched: Sequence[Path]) -> Path:
    """The finished run ``text`` names: a run folder, else the one run under ``searched`` whose rows carry that
    name (``metrics.parquet``'s ``method`` column: the method, or the run's ``--name``).

    Raises:
        UsageError: (naming ``parameter``) no such folder or name, a folder that is not a finished run, or a
            name several runs carry (they are listed: pass one folder).
    """
    from setdiff_bench.errors import UsageError
    from setdiff_bench.io.run_layout import METRICS_FILE
    from setdiff_bench.reporting.leaderboard import find_runs, run_names

    folder = Path(text)
    if folder.is_dir():
        if not (folder / METRICS_FILE).is_file():
            raise UsageError(f"not a finished run (no {METRICS_FILE})", text, parameter=parameter)
        return folder
    if not searched:
        raise UsageError(
            "no such run folder (to name a run, pass the folders that hold it with --runs)",
            text,
            parameter=parameter,
        )
    names = run_names(find_runs(searched, profiles=False))
    matches = [run for run, carried in names.items() if text in carried]
    if len(matches) == 1:
        return matches[0]
    if matches:
        raise UsageError(
            f"{len(matches)} runs are called {text!r} ({', '.join(map(str, matches))}); pass one folder",
            text,
            parameter=parameter,
        )
    known = sorted({name for carried in names.values() for name in carried})
    raise UsageError(
        f"no run folder or run of that name under {', '.join(map(str, searched))} "
        f"(runs: {', '.join(known) or 'none'})",
        text,
        parameter=parameter,
    )


def _names(run_a: Path, run_b: Path, a: pd.DataFrame, b: pd.DataFrame) -> tuple[str, str]:
    """The runs' methods, or their folder names when both runs are of one method (two seeds)."""
    methods = [", ".join(sorted(set(frame["method"]))) for frame in (a, b)]
    if methods[0] != methods[1]:
        return methods[0], methods[1]
    if run_a.name != run_b.name:
        return run_a.name, run_b.name
    return str(run_a), str(run_b)
