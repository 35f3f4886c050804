"""``setdiff-bench leaderboard``: tables (Parquet, LaTeX, Markdown), plots and image grids from finished runs.

Examples::

    setdiff-bench leaderboard --dataset synthetic --runs runs/demo/work/runs --out runs/tables --plots
    setdiff-bench leaderboard --dataset euvs --with-reported --format latex,md --runs runs/demo/work/runs --out runs/tables
    setdiff-bench leaderboard --dataset synthetic --runs runs/demo/work/runs --out runs/tables --grids 6 \\
        --packets runs/demo/work/packets
    setdiff-bench leaderboard --dataset synthetic --runs runs/demo/work/runs --out runs/tables --against difix
    setdiff-bench leaderboard --dataset synthetic --runs runs/demo/work/runs --out runs/tables_cost --cost

See :mod:`setdiff_bench.reporting.leaderboard` for the aggregation rules (means of per-image values; a method
missing rows in a block is refused) and how reported paper rows are marked.  ``--against METHOD`` writes
``<dataset>.vs_<METHOD>.*`` beside the plain table (both are written): each cell also gets the paired gain over
METHOD on the same targets (positive = better in every column: row − METHOD where higher is better, METHOD − row
where lower is, as the report shows), starred when its bootstrap interval (resampled by scene, :mod:`setdiff_bench.reporting.paired`)
excludes 0, and the Markdown lists every interval and the scenes each method wins.  Every argument is checked
before anything is written.  A run still being written under ``--runs`` (``run.json`` but no ``manifest.json``
yet) is left out with one warning line naming its folder; it is refused when ``--methods`` names its method
and no finished run has it, or when every run is unfinished.

Runs scored with ``--inception`` (``run`` / ``evaluate``) add ``fid`` / ``kid`` columns to the blocks their
``distribution.parquet`` has; novel-trajectory blocks (``prepare --trajectory``: no ground truth) show FID / KID
only, their PSNR / SSIM / LPIPS "–" (not computed).  Tables of other runs are unchanged.
"""

from __future__ import annotations

import argparse
import functools
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path

from setdiff_bench.cli.declared import declared_value
from setdiff_bench.reporting.bootstrap import BootstrapSettings

VERB = "leaderboard"
#: Where ``--runs`` looks when it is not given (``run``'s default ``--out`` is under it).
DEFAULT_RUNS = Path("results/runs")
#: Where the tables go without ``--out``: outside the tracked tree (results/ holds what is published).
DEFAULT_OUT = Path("runs/leaderboards")
HELP = "tabulate finished runs per method and group: Parquet, LaTeX (booktabs), Markdown; plots and grids"
DESCRIPTION = __doc__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--dataset", required=True, help="dataset key (euvs, paralane, nuscenes, dl3dv, synthetic, ...)"
    )
    add_runs_argument(
        parser,
        f"folders searched for runs (several: --runs A B or --runs A --runs B; default {DEFAULT_RUNS})",
    )
    formats = declared_value("setdiff_bench.reporting.leaderboard.render", "FORMATS")
    parser.add_argument("--format", default=",".join(formats), help=f"comma list of {', '.join(formats)}")
    parser.add_argument(
        "--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default {DEFAULT_OUT}, ignored by git)"
    )
    parser.add_argument(
        "--with-reported",
        action="store_true",
        help="add the paper's reported rows (marked '(paper)' / dagger, source=reported)",
    )
    parser.add_argument("--split", default="test", help="split of the targets to tabulate (train, test, all)")
    parser.add_argument("--methods", default=None, help="comma list of methods, in row order (default all)")
    parser.add_argument(
        "--metrics",
        default=None,
        help="comma list of metric columns (default psnr,ssim,lpips; e.g. psnr_euvs,ssim_euvs,lpips_euvs)",
    )
    parser.add_argument(
        "--profile",
        default=declared_value("setdiff_bench.protocols.profiles", "DEFAULT_PROFILE"),
        help="evaluation profile to tabulate (paper = plain runs; others come from "
        "`setdiff-bench evaluate`); named in every caption",
    )
    parser.add_argument(
        "--plots",
        action="store_true",
        help="also write the dataset's metric plots (PNG), and metrics vs refit steps when runs score refits",
    )
    parser.add_argument(
        "--grids",
        type=int,
        default=0,
        metavar="K",
        help="also write a qualitative grid of K targets (needs --packets)",
    )
    parser.add_argument(
        "--packets", type=Path, default=None, help="packet store the runs were made on (for --grids)"
    )
    add_bootstrap_arguments(parser)
    parser.add_argument(
        "--against",
        default=None,
        metavar="METHOD",
        help="also write <dataset>.vs_<METHOD>.* beside the plain table: each cell with its paired gain over "
        "METHOD (a method in the table; positive = better), starred when its interval excludes 0",
    )
    parser.add_argument(
        "--cost",
        action="store_true",
        help="add a Cost block: each method's ms per frame (median) and peak memory, as `run` recorded them",
    )


def add_runs_argument(parser: argparse.ArgumentParser, help: str) -> None:
    """``--runs FOLDER...``, repeatable: ``--runs A B`` and ``--runs A --runs B`` both give ``[A, B]`` (as
    ``report --runs``); not given: ``None`` (the verb picks its default, :func:`runs_folders`)."""
    parser.add_argument(
        "--runs", type=Path, nargs="+", action="extend", default=None, metavar="FOLDER", help=help
    )


def runs_folders(args: argparse.Namespace) -> list[Path]:
    """The folders ``--runs`` named, in order and each once, or ``[DEFAULT_RUNS]``."""
    return list(dict.fromkeys(args.runs)) if args.runs else [DEFAULT_RUNS]


def add_bootstrap_arguments(parser: argparse.ArgumentParser) -> None:
    """``--resamples`` and ``--bootstrap-seed``, with :class:`BootstrapSettings`' defaults (also used by
    ``compare``)."""
    defaults = BootstrapSettings()
    parser.add_argument(
        "--resamples",
        type=int,
        default=defaults.resamples,
        help=f"bootstrap resamples of the paired intervals (default {defaults.resamples})",
    )
    parser.add_argument(
        "--bootstrap-seed",
        type=int,
        default=defaults.seed,
        help=f"seed of the bootstrap resamples (default {defaults.seed})",
    )


def parse_formats(text: str, known: Sequence[str]) -> list[str]:
    """``--format``'s comma list, each one of ``known``.

    Raises:
        UsageError: (naming ``--format``) an unknown format, or none.
    """
    from setdiff_bench.errors import UsageError

    formats = [f.strip() for f in text.split(",") if f.strip()]
    unknown = [f for f in formats if f not in known]
    if unknown or not formats:
        raise UsageError(
            f"unknown format(s) {', '.join(unknown) or '(none given)'}; choose from {', '.join(known)}",
            "--format",
        )
    return formats


def bootstrap_settings(args: argparse.Namespace) -> BootstrapSettings:
    """The settings the options ask for.

    Raises:
        UsageError: ``--resamples`` below 1.
    """
    from setdiff_bench.errors import UsageError

    if args.resamples < 1:
        raise UsageError(f"needs at least 1 resample, got {args.resamples}", "--resamples")
    return BootstrapSettings(resamples=args.resamples, seed=args.bootstrap_seed)


def _command(args: argparse.Namespace) -> str:
    """The command line that reproduces this table (recorded in the outputs)."""
    parts = [
        "setdiff-bench",
        "leaderboard",
        "--dataset",
        args.dataset,
        "--runs",
        *map(str, runs_folders(args)),
        "--format",
        args.format,
        "--out",
        str(args.out),
        "--split",
        args.split,
        "--profile",
        args.profile,
    ]
    for flag, value in (("--methods", args.methods), ("--metrics", args.metrics)):
        if value:
            parts += [flag, value]
    if args.with_reported:
        parts.append("--with-reported")
    if args.cost:
        parts.append("--cost")
    if args.against:
        parts += ["--against", args.against, "--resamples", str(args.resamples)]
        parts += ["--bootstrap-seed", str(args.bootstrap_seed)]
    return " ".join(shlex.quote(part) for part in parts)


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import UsageError
    from setdiff_bench.reporting.leaderboard import (
        FORMATS,
        LeaderboardError,
        build_leaderboard,
        load_distribution,
        load_runs,
        profile_rows,
        reported_for,
        require_finished,
        survey_runs,
        warn_unfinished,
        write_leaderboard,
    )

    if args.grids and args.packets is None:  # every argument is checked before anything is written
        raise UsageError("--grids needs --packets (the store the runs were made on)", "--grids")
    if args.grids < 0:
        raise UsageError(f"needs K >= 0 targets, got {args.grids}", "--grids")
    settings = bootstrap_settings(args)
    formats = parse_formats(args.format, FORMATS)
    split = None if args.split == "all" else args.split
    methods = [m.strip() for m in args.methods.split(",")] if args.methods else None
    metrics = [m.strip() for m in args.metrics.split(",")] if args.metrics else None
    folders = runs_folders(args)
    finished, unfinished = survey_runs(folders)
    require_finished(finished, unfinished)
    images, sequences = load_runs(finished)
    measured = set(images["method"]) if len(images) else set()
    # a method asked for by name whose only run is unfinished is refused, not left out
    for waiting in unfinished:
        if methods and waiting.method in methods and waiting.method not in measured:
            raise LeaderboardError(f"--methods names {waiting.method}: {waiting.problem()}", waiting.folder)
    warn_unfinished(unfinished)  # one line each: left out of the table
    if len(images):
        # plots and grids see the tabulated profile's rows only
        images = profile_rows(images, args.profile, None if args.with_reported else args.dataset)
    reported = None
    if args.with_reported:
        reported = reported_for(args.dataset)
        if reported.empty:
            print(f"note: the paper reports no numbers for dataset {args.dataset!r}", file=sys.stderr)
    build = functools.partial(
        build_leaderboard,
        args.dataset,
        images,
        sequences,
        split=split,
        reported=reported,
        metrics=metrics,
        methods=methods,
        profile=args.profile,
        bootstrap=settings,
        cost=args.cost,
        distribution=load_distribution(finished),
    )
    board = build()
    # --against: the plain table and, beside it, the one with every cell's paired gain over METHOD
    boards = [board, build(against=args.against)] if args.against else [board]
    if args.with_reported and not any(row.source == "measured" for row in board.rows):
        found = sorted(set(images["dataset"])) if len(images) else []
        print(
            f"note: no measured {args.dataset} runs under {', '.join(map(str, folders))}"
            + (f" (runs found for: {', '.join(found)})" if found else "")
            + "; the table holds the paper's rows only",
            file=sys.stderr,
        )
    grid = None
    if args.grids:  # open the store and choose the frames before writing anything
        from setdiff_bench.packets.store import PacketStore
        from setdiff_bench.reporting.grids import pick_frames

        store = PacketStore(args.packets)
        chosen = images[(images["dataset"] == args.dataset) & ((images["split"] == split) if split else True)]
        folders = {
            m: Path(r) for m, r in chosen.drop_duplicates("method")[["method", "run"]].itertuples(index=False)
        }
        order = methods or sorted(folders)
        frames = pick_frames(store.index[store.index["dataset"] == args.dataset], args.grids, split=split)
        grid = (store, {m: folders[m] for m in order if m in folders}, frames)
    command = _command(args)
    for written in boards:
        for fmt, path in write_leaderboard(written, args.out, formats, command).items():
            print(f"{fmt}: {path}")
    if args.plots and len(images):
        from setdiff_bench.reporting.plots import write_plots

        for path in write_plots(args.dataset, images, args.out, split=split, sequences=sequences):
            print(f"plot: {path}")
    if grid is not None:
        from setdiff_bench.reporting.grids import qualitative_grid

        path = qualitative_grid(*grid, args.out / f"{args.dataset}_grid.png")
        print(f"grid: {path}")
    return 0
