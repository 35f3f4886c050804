"""Notebook verbs that the library otherwise spells in several calls (re-exported by ``setdiff_bench``).

``import setdiff_bench as sb`` gives the rest directly from the modules that define it; this module holds
only what has no single home there: :func:`leaderboard` (find runs → aggregate → optionally write).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from setdiff_bench.reporting.leaderboard import Leaderboard


def leaderboard(
    runs: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    dataset: str,
    *,
    split: str | None = "test",
    methods: Sequence[str] | None = None,
    metrics: Sequence[str] | None = None,
    profile: str = "paper",
    against: str | None = None,
    with_reported: bool = False,
    out: str | os.PathLike[str] | None = None,
    formats: Sequence[str] = ("parquet", "latex", "md"),
) -> Leaderboard:
    """The leaderboard of finished runs, as ``setdiff-bench leaderboard`` builds it.

    Args:
        runs: a folder searched for run folders (each holds ``metrics.parquet``), or several (run folders or
            folders of runs, as ``leaderboard --runs A B``); a run reached twice counts once.
        dataset: dataset key (``synthetic``, ``euvs``, ...): selects the table layout and the rows.
        split: targets of this split (``None``: all).
        methods: measured methods to show, in this order (default: all, sorted).
        metrics: image metric columns (default: the layout's).
        profile: the evaluation profile tabulated (``paper`` for plain runs).
        against: add every cell's paired gain over this method (positive = better in every column,
            :mod:`setdiff_bench.reporting.gains`; bootstrap by scene).
        with_reported: add the paper's reported rows, marked "(paper)".
        out: when given, write the tables there (``formats`` of parquet, latex, md).
        formats: what to write with ``out``.

    Returns:
        The :class:`~setdiff_bench.reporting.leaderboard.Leaderboard`; ``render_markdown(board)`` and
        ``leaderboard_frame(board)`` (both re-exported by ``setdiff_bench``) turn it into text or a table.

    Raises:
        SetDiffBenchError: no runs, a run of another dataset or split only, an unknown method or metric.
    """
    from setdiff_bench.reporting.leaderboard import (
        build_leaderboard,
        find_runs,
        load_runs,
        reported_for,
        write_leaderboard,
    )

    roots = [Path(runs)] if isinstance(runs, str | os.PathLike) else [Path(run) for run in runs]
    images, sequences = load_runs(find_runs(roots))
    board = build_leaderboard(
        dataset,
        images,
        sequences,
        split=split,
        reported=reported_for(dataset) if with_reported else None,
        metrics=metrics,
        methods=methods,
        profile=profile,
        against=against,
    )
    if out is not None:
        write_leaderboard(board, out, formats)
    return board
