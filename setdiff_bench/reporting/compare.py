"""Compare two runs on the targets they share: per group, pooled and per scene, paired differences with
bootstrap intervals and scenes won (``setdiff-bench compare RUN_A RUN_B``).

Rows (:class:`Comparison`):

* **All** — every shared target of every group, interval resampled by scene;
* **each group** — in the dataset's table order (:func:`~setdiff_bench.reporting.leaderboard.dataset_layout`),
  interval resampled by scene;
* **each scene** — all groups of the scene pooled; with one scene there are no scenes to resample, so its
  interval resamples the scene's targets (frames), which treats correlated frames as independent and is
  narrower than a between-scene interval would be (the ``unit`` column says which).

Every number is a **gain** of A over B (:mod:`setdiff_bench.reporting.gains`: ``A − B`` where higher is
better, ``B − A`` where lower is, so positive means A is better in every column, as the report shows); wins
follow the metric's direction.  Each output states the convention: the printed header line
(:meth:`Comparison.header`), the Markdown caption and notes, and the Parquet's ``gain``, ``gain_low`` and
``gain_high`` columns (beside ``mean_a`` / ``mean_b``, each run's own mean).  The Markdown states the
bootstrap (resamples, level, seed) and the number of shared targets; the Parquet holds one row per (level,
group, scene, metric) with every field of :class:`~setdiff_bench.reporting.paired.PairedDifference` but the
raw difference, which the gain replaces.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.io.run_layout import TARGET_COLUMNS
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.gains import GAIN_CONVENTION, PairedGain
from setdiff_bench.reporting.leaderboard import ALL, dataset_layout, md_escape, metric_arrow, metric_header
from setdiff_bench.reporting.paired import (
    PairedDifference,
    PairingError,
    difference_records,
    few_scenes_note,
    pair_targets,
    paired_differences,
)

#: Columns that pair two runs' rows: the dataset and the target.
PAIR_COLUMNS: tuple[str, ...] = ("dataset", *TARGET_COLUMNS)
#: The levels of a comparison's rows, in display order.
LEVELS = ("all", "group", "scene")


@dataclass
class ComparisonRow:
    """One row of a comparison: a level (``all``, ``group``, ``scene``), its key and label, and its differences."""

    level: str
    key: str
    label: str
    differences: dict[str, PairedDifference] = field(default_factory=dict)


@dataclass
class Comparison:
    """``a`` against ``b`` on their shared targets.

    Attributes:
        a: name of the first run (a method, or the run folder when both runs are of one method).
        b: name of the second run.
        metrics: metric names compared, in column order.
        rows: pooled, per-group and per-scene rows.
        shared: shared targets; ``only_a`` / ``only_b``: targets of one run only (left out).
        settings: the bootstrap of the pooled and per-group intervals.
        runs: the two run folders (recorded in the outputs).
    """

    a: str
    b: str
    metrics: tuple[str, ...]
    rows: list[ComparisonRow]
    shared: int
    only_a: int
    only_b: int
    settings: BootstrapSettings
    runs: tuple[str, str] = ("", "")

    @property
    def stem(self) -> str:
        """Output file stem: ``compare_<a>_vs_<b>``."""
        return f"compare_{_file_part(self.a)}_vs_{_file_part(self.b)}"

    def header(self) -> str:
        """The line that says what the numbers are: which run is A, which B, and the sign convention."""
        return f"A = {self.a}, B = {self.b}; {GAIN_CONVENTION}"

    def verdicts(self) -> list[str]:
        """One plain line per pooled / group row: each metric's gain of A over B, its interval, the verdict and
        the scenes won."""
        lines = []
        for row in self.rows:
            if row.level == "scene":
                continue
            first = next(iter(row.differences.values()))
            parts = [
                f"{get_metric(m).label} {PairedGain.of(d).format()} {d.verdict(self.a, self.b)}, "
                f"won {d.wins} of {d.scenes}"
                for m, d in row.differences.items()
            ]
            lines.append(
                f"{row.label} ({first.targets} targets, {first.scenes} scenes): gain of {self.a} over {self.b}: "
                + "; ".join(parts)
            )
        return lines


def _file_part(name: str) -> str:
    return "".join(char if char.isalnum() or char in "+-." else "_" for char in name) or "_"


def compare_frames(
    a: pd.DataFrame,
    b: pd.DataFrame,
    names: tuple[str, str],
    *,
    metrics: Sequence[str] | None = None,
    settings: BootstrapSettings | None = None,
    runs: tuple[str, str] = ("", ""),
) -> Comparison:
    """Compare the per-target rows ``a`` and ``b`` (one run each: ``metrics.parquet`` rows).

    Args:
        a: rows of the first run.
        b: rows of the second run.
        names: how the two are called in the outputs.
        metrics: metric columns (default: the dataset's table metrics, :func:`dataset_layout`).
        settings: bootstrap settings of the pooled and per-group rows (default :class:`BootstrapSettings`);
            per-scene rows use the same with ``unit="frame"``.
        runs: the run folders, recorded in the outputs.

    Raises:
        PairingError: the runs share no targets (the message says how many each has), a metric is missing,
            or a run has duplicate rows.
    """
    settings = settings or BootstrapSettings()
    datasets = sorted(set(a["dataset"]) & set(b["dataset"])) if len(a) and len(b) else []
    layout = dataset_layout(datasets[0]) if len(datasets) == 1 else dataset_layout("")
    names_metrics = tuple(metrics or layout.metrics)
    pairs = pair_targets(a, b, names_metrics, PAIR_COLUMNS, names)
    if not len(pairs):
        raise PairingError(
            f"{names[0]} and {names[1]} share no targets (they share 0; {names[0]} has {len(a)}, "
            f"{names[1]} has {len(b)}): compare runs made on the same packets"
        )
    labels = {block.key: block.label for block in layout.blocks or ()}
    groups = sorted(pairs["group"].unique(), key=natural_key)
    if layout.blocks is not None:
        rank = {block.key: i for i, block in enumerate(layout.blocks)}
        groups = sorted(groups, key=lambda g: (rank.get(g, len(rank)), natural_key(g)))
    rows = [ComparisonRow("all", ALL, "All", paired_differences(pairs, names_metrics, settings))]
    for group in groups:
        own = pairs[pairs["group"] == group]
        rows.append(
            ComparisonRow(
                "group", group, labels.get(group, group), paired_differences(own, names_metrics, settings)
            )
        )
    by_frame = replace(settings, unit="frame")
    for scene in sorted(pairs["scene"].unique(), key=natural_key):
        own = pairs[pairs["scene"] == scene]
        rows.append(ComparisonRow("scene", scene, scene, paired_differences(own, names_metrics, by_frame)))
    return Comparison(
        a=names[0],
        b=names[1],
        metrics=names_metrics,
        rows=rows,
        shared=len(pairs),
        only_a=len(a) - len(pairs),
        only_b=len(b) - len(pairs),
        settings=settings,
        runs=runs,
    )


def to_frame(comparison: Comparison) -> pd.DataFrame:
    """Long table: one row per (comparison row, metric): the gain of A over B (``gain``, ``gain_low``,
    ``gain_high``: positive = A better) and every other field of the paired difference."""
    records = []
    for order, row in enumerate(comparison.rows):
        labels = {"a": comparison.a, "b": comparison.b, "row_order": order}
        for record in difference_records(
            row.differences, **labels, level=row.level, key=row.key, label=row.label
        ):
            paired = PairedGain.of(row.differences[str(record["metric"])])
            for raw in ("difference", "low", "high"):
                del record[raw]
            records.append(record | {"gain": paired.value, "gain_low": paired.low, "gain_high": paired.high})
    return pd.DataFrame.from_records(records)


def render_markdown(comparison: Comparison, command: str | None = None) -> str:
    """The comparison as Markdown: a caption, the group table, the scene table, the notes and the command."""
    a, b = md_escape(comparison.a), md_escape(comparison.b)
    level = f"{comparison.settings.confidence * 100:g} %"
    lines = [
        f"**Gains of {a} over {b} (positive = {a} better) on {comparison.shared} shared targets; "
        f"{md_escape(comparison.settings.describe())}**",
        "",
    ]
    for title, levels, unit in (
        ("By group (All: every group pooled)", ("all", "group"), "scenes"),
        ("By scene (every group of the scene pooled)", ("scene",), "targets of the scene"),
    ):
        rows = [row for row in comparison.rows if row.level in levels]
        header = ["", "Targets", *(metric_header(m) + metric_arrow(m, False) for m in comparison.metrics)]
        lines += [
            f"{title}: gain of {a} over {b} [{level} interval, resampled over {unit}], \\* when it excludes 0; "
            "scenes won by " + a + " of scenes",
            "",
            "| " + " | ".join(header) + " |",
            "|---|---:|" + "---:|" * len(comparison.metrics),
        ]
        for row in rows:
            first = next(iter(row.differences.values()))
            cells = [
                PairedGain.of(d).format() + (r" \*" if d.holds else "") + f", won {d.wins} of {d.scenes}"
                for d in (row.differences[m] for m in comparison.metrics)
            ]
            lines.append("| " + " | ".join([md_escape(row.label), str(first.targets), *cells]) + " |")
        lines.append("")
    lines += ["Verdicts (an interval that excludes 0 is a difference that holds):", ""]
    lines += [f"- {md_escape(line)}" for line in comparison.verdicts()]
    lines.append("")
    pooled = next(iter(comparison.rows[0].differences.values()))
    notes = [
        few_scenes_note(pooled.scenes) or "",
        f"Runs: {comparison.runs[0]} ({a}) and {comparison.runs[1]} ({b})." if any(comparison.runs) else "",
        f"A = {comparison.a}, B = {comparison.b}; {GAIN_CONVENTION}. Gains are means of per-target gains, in "
        "each metric's units; per-scene intervals resample the scene's targets as if independent, so they are "
        "narrower than a between-scene interval.",
        f"Targets only in {a}: {comparison.only_a}; only in {b}: {comparison.only_b} (left out)."
        if comparison.only_a or comparison.only_b
        else "",
    ]
    lines += [md_escape(note) for note in notes if note]
    if command:
        lines.append(f"Generated by `{command}`.")
    return "\n".join(lines) + "\n"


def write_comparison(
    comparison: Comparison,
    out: str | Path,
    formats: Sequence[str] = ("md", "parquet"),
    command: str | None = None,
) -> dict[str, Path]:
    """Write ``<out>/<stem>.md`` and ``<out>/<stem>.parquet`` atomically; returns format → path."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    if "md" in formats:
        written["md"] = out / f"{comparison.stem}.md"
        write_text_atomic(written["md"], render_markdown(comparison, command))
    if "parquet" in formats:
        written["parquet"] = out / f"{comparison.stem}.parquet"
        with atomic_path(written["parquet"]) as tmp:
            pq.write_table(
                pa.Table.from_pandas(to_frame(comparison), preserve_index=False), tmp, compression="zstd"
            )
    return written


__all__ = [
    "LEVELS",
    "PAIR_COLUMNS",
    "Comparison",
    "ComparisonRow",
    "compare_frames",
    "render_markdown",
    "to_frame",
    "write_comparison",
]
