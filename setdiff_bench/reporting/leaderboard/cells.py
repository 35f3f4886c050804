"""A leaderboard's rows and cells: one measured row per method (means of per-image values per block, or of
per-scene means), the paper's reported rows, the cost block, the paired differences to ``--against``, and
the refusal of a mean over a subset of a block's targets."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.run_layout import TARGET_COLUMNS
from setdiff_bench.protocols import Block
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.leaderboard.columns import (
    ALL,
    COST,
    COST_COLUMNS,
    LeaderboardError,
    metric_decimals,
)
from setdiff_bench.reporting.leaderboard.selection import name_list
from setdiff_bench.reporting.leaderboard.table import SECTIONS, Row
from setdiff_bench.reporting.paired import PairedDifference, pair_targets, paired_differences


def cost_column(rows: Sequence[Row], frame: pd.DataFrame) -> tuple[Block, tuple[str, ...]]:
    """Fill each measured row's cost cells (:data:`COST_COLUMNS` its runs recorded); the cost block's column."""
    recorded = tuple(name for name in COST_COLUMNS if name in frame.columns)
    for row in rows:
        if row.source == "measured":
            own = frame[frame["method"] == row.method]
            for name in recorded:
                aggregate = COST_COLUMNS[name].aggregate
                per = own.groupby("scene")[name].first() if aggregate == "scene_mean" else own[name]
                values = per.to_numpy(dtype=np.float64)
                values = values[~np.isnan(values)]
                if len(values):
                    reduce = {"median": np.median, "max": np.max, "scene_mean": np.mean}[aggregate]
                    row.values[(COST, name)] = float(reduce(values))
                    row.decimals[(COST, name)] = COST_COLUMNS[name].decimals
                    row.counts[(COST, name)] = len(values)
    return (Block(COST, "Cost"), recorded)


def add_differences(
    rows: Sequence[Row],
    frame: pd.DataFrame,
    dataset: str,
    against: str,
    order: Sequence[str],
    blocks: Sequence[Block],
    metric_names: Sequence[str],
    settings: BootstrapSettings,
    aggregation: str,
) -> None:
    """Give every measured row but ``against``'s its paired differences to ``against``.

    Raises:
        UsageError: ``against`` is not a measured method of the table.
    """
    if against not in order:
        raise UsageError(
            f"no {dataset} runs of method {against!r} in the table"
            + name_list("methods in the table", list(order)),
            "--against",
        )
    for row in rows:
        if row.source == "measured" and row.method != against:
            row.differences = _paired_cells(
                frame,
                row.method,
                against,
                blocks,
                metric_names,
                settings,
                aggregation,
            )


def _block_rows(frame: pd.DataFrame, block: Block) -> pd.DataFrame:
    return frame if block.key == ALL else frame[frame["group"] == block.key]


def check_complete(frame: pd.DataFrame, blocks: Sequence[Block]) -> None:
    """Refuse a mean over a subset: every method present in a block must have every target of it."""
    keys = list(TARGET_COLUMNS)
    if not len(frame):
        return
    for block in blocks:
        rows = _block_rows(frame, block)
        if not len(rows):
            continue
        universe = set(map(tuple, rows[keys].drop_duplicates().to_numpy().tolist()))
        for method, own in rows.groupby("method", sort=True):
            have = set(map(tuple, own[keys].to_numpy().tolist()))
            missing = sorted(universe - have)
            if missing:
                shown = ", ".join(f"{scene}/{name} ({group})" for _, group, scene, name in missing[:5])
                raise LeaderboardError(
                    f"method {method!r} lacks {len(missing)} of {len(universe)} targets of block "
                    f"{block.label!r} that other runs have ({shown}{', ...' if len(missing) > 5 else ''}); "
                    "refusing to average it over a subset — finish or rerun it"
                )


def measured_row(
    method: str,
    frame: pd.DataFrame,
    seq: pd.DataFrame | None,
    blocks: Sequence[Block],
    metric_names: Sequence[str],
    seq_names: Sequence[str],
    *,
    scene_mean: bool = False,
    group_sequences: bool = False,
) -> Row:
    """One measured method's cells: image metric means per block, and sequence metric means (warp error).

    The pooled block's sequence cells average the method's ground-truth-flow sequences (every sequence of a
    ``sequences.parquet`` without a ``flow_source`` column, as written before render flow existed).  With
    ``group_sequences``, a group block gets the mean of that group's render-flow sequences (novel
    trajectories, whose image metrics are not in ``frame``) where it has any; the caller must then give such
    blocks the sequence metrics' columns.
    """
    row = Row(label=method, method=method, source="measured", section="measured")
    own = frame[frame["method"] == method]
    mine = seq[seq["method"] == method] if seq is not None else None
    for block in blocks:
        rows = _block_rows(own, block)
        if len(rows):
            for metric in metric_names:
                values = rows[metric].to_numpy(dtype=np.float64)
                mean = rows.groupby("scene")[metric].mean().mean() if scene_mean else values.mean()
                row.values[(block.key, metric)] = float(mean)
                row.decimals[(block.key, metric)] = metric_decimals(metric)
                row.counts[(block.key, metric)] = len(values)
        if mine is None or (block.key == ALL and not len(rows)) or (block.key != ALL and not group_sequences):
            continue
        sequences = _block_sequences(mine, block)
        for metric in seq_names:
            if metric in sequences.columns and len(sequences):
                row.values[(block.key, metric)] = float(sequences[metric].to_numpy(dtype=np.float64).mean())
                row.decimals[(block.key, metric)] = metric_decimals(metric)
                row.counts[(block.key, metric)] = len(sequences)
    return row


def _block_sequences(seq: pd.DataFrame, block: Block) -> pd.DataFrame:
    """The sequence rows a block's sequence cells average: ground-truth flow for the pooled block, the
    group's render-flow sequences for a group block (none in files without ``flow_source``)."""
    if "flow_source" not in seq.columns:
        return seq if block.key == ALL else seq.iloc[:0]
    if block.key == ALL:
        return seq[seq["flow_source"] != "render"]
    return seq[(seq["flow_source"] == "render") & (seq["group"] == block.key)]


def _paired_cells(
    frame: pd.DataFrame,
    method: str,
    against: str,
    blocks: Sequence[Block],
    metric_names: Sequence[str],
    settings: BootstrapSettings,
    aggregation: str,
) -> dict[tuple[str, str], PairedDifference]:
    """(block key, metric) → paired difference of ``method`` to ``against`` over the block's targets."""
    cells: dict[tuple[str, str], PairedDifference] = {}
    for block in blocks:
        rows = _block_rows(frame, block)
        mine, theirs = rows[rows["method"] == method], rows[rows["method"] == against]
        if not len(mine) or not len(theirs):
            continue
        pairs = pair_targets(mine, theirs, metric_names)
        found = paired_differences(pairs, metric_names, settings, scene_mean=aggregation == "scene_mean")
        cells.update({(block.key, metric): difference for metric, difference in found.items()})
    return cells


def reported_rows(reported: pd.DataFrame, blocks: Sequence[Block], tables: Sequence[str]) -> list[Row]:
    """Paper rows keyed by (section, method id), tables in layout order then CSV order.

    Settings map to blocks by their ``group``; the same method in two tables (nuScenes Table 3 and the
    consistency table) becomes one row labelled as in the first table.
    """
    rows: dict[tuple[str, str], Row] = {}
    keys = {b.key for b in blocks}
    rank = {table: i for i, table in enumerate(tables)}
    ordered_records = reported.assign(_rank=reported["table"].map(lambda t: rank.get(t, len(rank))))
    for record in ordered_records.sort_values("_rank", kind="stable").itertuples():
        if record.group not in keys:
            continue
        key = (record.section, record.method_id)
        if key not in rows:
            rows[key] = Row(
                label=record.method, method=record.method_id, source="reported", section=record.section
            )
        cell = (record.group, record.metric)
        rows[key].values[cell] = float(record.value)
        rows[key].decimals[cell] = int(record.decimals)
    ordered = sorted(rows.values(), key=lambda r: SECTIONS.index(r.section) if r.section in SECTIONS else 99)
    # a paper table may repeat a row in two sections (EUVS Table 1: "3DGS" is the first reconstruction row
    # and the base of the enhancer section, with the same numbers): one row in ours
    unique: list[Row] = []
    for row in ordered:
        if not any(r.label == row.label and r.values == row.values for r in unique):
            unique.append(row)
    return unique
