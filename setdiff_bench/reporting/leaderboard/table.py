"""The table model: :class:`Row` and :class:`Leaderboard` (what the writers take), the best cells as displayed,
and :func:`pooled_table` / :func:`pooled_row` for one-block tables of labelled rows (the ablation tables)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from setdiff_bench.protocols import Block
from setdiff_bench.protocols.profiles import DEFAULT_PROFILE
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.leaderboard.columns import ALL, higher_is_better, metric_decimals
from setdiff_bench.reporting.paired import PairedDifference

SECTIONS = ("reconstruction", "enhancer", "ablation", "measured")


@dataclass
class Row:
    """One table row: a method (measured) or a paper row (reported)."""

    label: str
    method: str
    source: str  # "measured" | "reported"
    section: str
    values: dict[tuple[str, str], float] = field(default_factory=dict)  # (block key, metric) → value
    decimals: dict[tuple[str, str], int] = field(default_factory=dict)
    counts: dict[tuple[str, str], int] = field(default_factory=dict)  # images or sequences averaged
    #: (block key, metric) → paired difference to the table's ``against`` method (empty without one)
    differences: dict[tuple[str, str], PairedDifference] = field(default_factory=dict)


@dataclass
class Leaderboard:
    """A finished table.

    Attributes:
        dataset: dataset key.
        columns: ``(block, metrics)`` in display order.
        rows: rows in display order (reported sections first, then measured methods).
        best: ``(block key, metric)`` → row indices holding the best displayed value.
        title: caption text.
        notes: footnotes (aggregation, marks).
        profile: the evaluation profile tabulated.
        row_header: header of the label column.
        against: the method every measured row is compared with (paired differences), or ``None``.
        bootstrap: how the intervals of those differences were drawn.
    """

    dataset: str
    columns: list[tuple[Block, tuple[str, ...]]]
    rows: list[Row]
    best: dict[tuple[str, str], set[int]]
    title: str
    notes: list[str]
    profile: str = DEFAULT_PROFILE
    row_header: str = "Method"
    against: str | None = None
    bootstrap: BootstrapSettings | None = None

    @property
    def stem(self) -> str:
        """Output file stem: ``<dataset>``, or ``<dataset>.<profile>`` for a profile other than ``paper``;
        ``.vs_<method>`` appended for a table with paired differences, so it never replaces the plain one."""
        stem = self.dataset if self.profile == DEFAULT_PROFILE else f"{self.dataset}.{self.profile}"
        return stem if self.against is None else f"{stem}.vs_{self.against}"

    def cells(self) -> list[tuple[str, str]]:
        return [(block.key, metric) for block, metrics in self.columns for metric in metrics]

    def display(self, row: Row, cell: tuple[str, str]) -> str | None:
        """The value as printed (``None`` when the row has no value there)."""
        value = row.values.get(cell)
        if value is None or math.isnan(value):
            return None
        return f"{value:.{row.decimals.get(cell, metric_decimals(cell[1]))}f}"


def pooled_table(
    title: str,
    rows: Sequence[Row],
    metrics: Sequence[str],
    *,
    row_header: str = "Method",
    notes: Sequence[str] = (),
    best: dict[tuple[str, str], set[int]] | None = None,
) -> Leaderboard:
    """A one-block table for the writers: ``rows`` hold their values under ``(ALL, metric)``, one column per
    metric, no block header.

    Args:
        title: caption.
        rows: rows in display order (:func:`pooled_row`).
        metrics: metric names, in column order.
        row_header: header of the label column.
        notes: lines printed under the table (LaTeX: comments).
        best: ``(ALL, metric)`` → bold row indices; default: the best displayed value per column.
    """
    board = Leaderboard(
        "", [(Block(ALL, "All"), tuple(metrics))], list(rows), {}, title, list(notes), row_header=row_header
    )
    board.best = best_cells(board) if best is None else best
    return board


def pooled_row(
    label: str,
    values: Mapping[str, float],
    *,
    source: str = "measured",
    decimals: Mapping[str, int] | None = None,
) -> Row:
    """A row of :func:`pooled_table`: metric → value; decimals are the metric's unless given (the printed
    precision of reported numbers); ``source="reported"`` marks it as the paper's."""
    decimals = decimals or {}
    return Row(
        label=label,
        method=label,
        source=source,
        section=source,
        values={(ALL, metric): float(value) for metric, value in values.items()},
        decimals={(ALL, metric): decimals.get(metric, metric_decimals(metric)) for metric in values},
    )


def best_cells(board: Leaderboard) -> dict[tuple[str, str], set[int]]:
    best: dict[tuple[str, str], set[int]] = {}
    for cell in board.cells():
        shown = {i: board.display(row, cell) for i, row in enumerate(board.rows)}
        numbers = {i: float(text) for i, text in shown.items() if text is not None}
        if not numbers:
            continue
        target = max(numbers.values()) if higher_is_better(cell[1]) else min(numbers.values())
        best[cell] = {i for i, value in numbers.items() if value == target}
    return best
