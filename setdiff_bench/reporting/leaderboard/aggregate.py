"""Aggregation: finished-run rows (and the paper's, when asked) of one dataset into a
:class:`~setdiff_bench.reporting.leaderboard.table.Leaderboard` (:func:`build_leaderboard`): rows chosen and
checked, blocks, one measured row per method (means of per-image values), the cost block, paired differences,
best cells and notes."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.profiles import DEFAULT_PROFILE, get_profile
from setdiff_bench.io.images import image_size
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.protocols import Block, Layout
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.leaderboard.columns import (
    ALL,
    COST,
    COST_COLUMNS,
    LeaderboardError,
    dataset_layout,
    metric_decimals,
)
from setdiff_bench.reporting.leaderboard.selection import name_list, select_rows
from setdiff_bench.reporting.leaderboard.table import SECTIONS, Leaderboard, Row, best_cells
from setdiff_bench.reporting.paired import (
    TARGET_COLUMNS,
    PairedDifference,
    few_scenes_note,
    pair_targets,
    paired_differences,
)


def build_leaderboard(
    dataset: str,
    images: pd.DataFrame,
    sequences: pd.DataFrame | None = None,
    *,
    split: str | None = "test",
    reported: pd.DataFrame | None = None,
    metrics: Sequence[str] | None = None,
    methods: Sequence[str] | None = None,
    layout: Layout | None = None,
    profile: str = DEFAULT_PROFILE,
    against: str | None = None,
    bootstrap: BootstrapSettings | None = None,
    cost: bool = False,
    distribution: pd.DataFrame | None = None,
) -> Leaderboard:
    """Aggregate runs (and optional reported rows) of ``dataset`` into a :class:`Leaderboard`.

    Args:
        dataset: dataset key; selects the layout and filters the rows.
        images: per-target rows (:func:`load_runs`), any datasets.
        sequences: per-sequence rows (warp error), or ``None``.
        split: keep rows of this split (``None``: all).
        reported: rows of :func:`load_reported` to mix in (already chosen by the caller), or ``None``.
        metrics: image metric columns (default: the layout's).
        methods: measured methods to show, in this order (default: all, sorted).
        layout: override the dataset's layout.
        profile: the evaluation profile tabulated (:mod:`setdiff_bench.evaluation.profiles`): rows of plain runs are
            ``paper``; ``setdiff-bench evaluate`` tables carry their profile.  The caption names it, and the
            profile's averaging is used (``scene_mean``: the mean of per-scene means).
        against: a measured method shown in the table: every other measured cell gets its paired difference
            to it (:mod:`setdiff_bench.reporting.paired`; image metrics only, warp error is per sequence).
        bootstrap: how those intervals are drawn (default :class:`BootstrapSettings`).
        cost: add a "Cost" block of :data:`COST_COLUMNS` (ms per frame, peak memory) per measured method.
        distribution: FID / KID rows (:func:`~setdiff_bench.reporting.leaderboard.inputs.load_distribution`),
            or ``None``: every group block a measured method has a row for gets ``fid`` and ``kid`` columns
            after its image metrics (the pooled block none: a set metric of the pooled frames is not a mean of
            the blocks').  A group whose targets have no ground truth (every image metric null: novel
            trajectories) gets a block of its own even where the layout pools every group, shows no image
            metric value ("–", not computed) and is left out of the pooled block's means.

    Raises:
        LeaderboardError: no rows, a metric column missing, duplicate rows, a method missing rows, two FID / KID
            rows for one method and block, or FID / KID computed with different Inception weights.
        UsageError: ``against`` is not a measured method of the table.
    """
    layout = layout or dataset_layout(dataset)
    frame, metric_names = select_rows(
        dataset,
        images,
        reported,
        split=split,
        metrics=metrics,
        methods=methods,
        layout=layout,
        profile=profile,
    )
    spec = get_profile(profile)
    blind = _groups_without_ground_truth(frame, metric_names)
    paired = frame[~frame["group"].isin(blind)] if blind else frame  # the rows image metrics average
    blocks = _blocks(layout, frame, blind)
    dist = _select_distribution(distribution, dataset, frame, split if spec.scenes == "split" else None)
    # a block too small for FID / KID (fewer than 2 images on a side: null in every run) gets no such columns
    valued = dist[dist[list(DISTRIBUTION_METRICS)].notna().any(axis=1)] if dist is not None else None
    dist_groups = set(valued["group"]) if valued is not None else set()
    seq = sequences if sequences is not None and len(sequences) else None
    if seq is not None:
        seq = seq[(seq["dataset"] == dataset) & seq["method"].isin(frame["method"].unique())]
    seq_names = tuple(
        m
        for m in layout.sequence_metrics
        if (seq is not None and m in seq.columns and len(seq))
        or (reported is not None and len(reported) and m in set(reported["metric"]))
    )
    columns = [
        (
            b,
            metric_names
            + (seq_names if b.key == ALL else ())
            + (DISTRIBUTION_METRICS if b.key != ALL and b.key in dist_groups else ()),
        )
        for b in blocks
    ]
    rows = (
        _reported_rows(reported, blocks, layout.reported_tables)
        if reported is not None and len(reported)
        else []
    )
    order = list(methods) if methods is not None else sorted(frame["method"].unique()) if len(frame) else []
    for method in order:
        rows.append(
            _measured_row(
                method,
                paired,
                seq,
                blocks,
                metric_names,
                seq_names,
                scene_mean=spec.aggregation == "scene_mean",
            )
        )
        if dist is not None:
            _distribution_cells(rows[-1], dist, blocks)
    _check_complete(frame, blocks)
    if cost:
        columns.append(_cost_column(rows, frame))
    settings = bootstrap or BootstrapSettings()
    if against is not None:
        _add_differences(
            rows, paired, dataset, against, order, blocks, metric_names, settings, spec.aggregation
        )
    filled = {key for row in rows for key, _ in row.values}
    columns = [(block, metrics) for block, metrics in columns if block.key in filled]
    if not columns:
        raise LeaderboardError(
            f"no {dataset} results fall in the table's blocks ({', '.join(b.label for b in blocks)})"
        )
    title = f"{layout.title or dataset}; {spec.caption(scored_size(frame))}"
    if against is not None:
        title += f"; paired differences to {against}: {settings.describe()}"
    board = Leaderboard(
        dataset,
        columns,
        rows,
        {},
        title,
        [],
        profile,
        against=against,
        bootstrap=settings if against else None,
    )
    board.best = best_cells(board)
    board.notes = _notes(board, frame, seq)
    board.notes += _distribution_notes(board, dist, blind)
    if spec.aggregation == "scene_mean":
        board.notes[0] = board.notes[0].replace(
            "Cells are means of per-image values over each block's targets",
            "Cells are means over scenes of each scene's mean over its targets",
        )
    return board


def _blocks(layout: Layout, frame: pd.DataFrame, blind: frozenset[str] = frozenset()) -> list[Block]:
    """The table's blocks: the layout's (plus one per group it does not name, unless it pools every group), or
    one per group found.  A group without ground truth (``blind``) always gets its own block, named by its
    group (``shift+3m``): the pooled block leaves it out."""
    groups = sorted(frame["group"].unique(), key=natural_key) if len(frame) else []
    blocks = list(layout.blocks) if layout.blocks is not None else [Block(g, g) for g in groups]
    if layout.blocks is not None and groups:
        pools = any(b.key == ALL for b in blocks)
        unknown = [g for g in groups if g not in {b.key for b in blocks} and (not pools or g in blind)]
        blocks += [Block(g, g) for g in unknown]
    return blocks


#: The distribution metrics a block shows when its runs were scored with ``--inception`` (registry names).
DISTRIBUTION_METRICS = ("fid", "kid")


def _groups_without_ground_truth(frame: pd.DataFrame, metric_names: Sequence[str]) -> frozenset[str]:
    """Groups whose every row has every image metric null: targets without ground truth (novel-trajectory
    packets, ``prepare --trajectory``), which ``run`` leaves unscored.  A group with any value is not one."""
    names = [m for m in metric_names if m in frame.columns]
    if not len(frame) or not names:
        return frozenset()
    empty = frame[names].isna().all(axis=1).groupby(frame["group"]).all()
    return frozenset(str(group) for group, blind in empty.items() if blind)


def _select_distribution(
    distribution: pd.DataFrame | None, dataset: str, frame: pd.DataFrame, split: str | None
) -> pd.DataFrame | None:
    """The FID / KID rows of the table's measured methods, dataset and split, one per (method, group); ``None``
    when there are none.

    Raises:
        LeaderboardError: two rows for one method and group (two scored runs of a method), or rows computed
            with different Inception weights (their values cannot share a column).
    """
    if distribution is None or not len(distribution) or not len(frame):
        return None
    dist = distribution[
        (distribution["dataset"] == dataset)
        & distribution["method"].isin(set(frame["method"]))
        & distribution["group"].isin(set(frame["group"]))
    ]
    if split is not None:
        dist = dist[dist["split"] == split]
    if not len(dist):
        return None
    duplicated = dist[dist.duplicated(["method", "group"], keep=False)]
    if len(duplicated):
        first = duplicated.iloc[0]
        runs = sorted(duplicated[duplicated["method"] == first["method"]]["run"].unique())
        raise LeaderboardError(
            f"method {first['method']!r} has FID / KID for block {first['group']!r} in {len(runs)} runs "
            f"({', '.join(runs)}); keep one run per method"
        )
    weights = dist.drop_duplicates("inception_sha256")
    if len(weights) > 1:
        shown = ", ".join(
            f"{str(sha)[:12] if isinstance(sha, str) else 'unrecorded'} ({run})"
            for sha, run in weights[["inception_sha256", "run"]].itertuples(index=False)
        )
        raise LeaderboardError(
            f"runs scored FID / KID with different Inception weights: {shown}; rescore them with one "
            "--inception file (setdiff-bench evaluate RUN --inception FILE)"
        )
    return dist.reset_index(drop=True)


def _distribution_cells(row: Row, dist: pd.DataFrame, blocks: Sequence[Block]) -> None:
    """Fill ``row``'s FID / KID cells from its method's distribution rows (a null value stays out: "–");
    the count is the block's enhanced targets."""
    own = dist[dist["method"] == row.method].set_index("group")
    for block in blocks:
        if block.key == ALL or block.key not in own.index:
            continue
        record = own.loc[block.key]
        for metric in DISTRIBUTION_METRICS:
            value = record[metric]
            if pd.isna(value):
                continue
            row.values[(block.key, metric)] = float(value)
            row.decimals[(block.key, metric)] = metric_decimals(metric)
            row.counts[(block.key, metric)] = int(record["enhanced"])


def _distribution_notes(board: Leaderboard, dist: pd.DataFrame | None, blind: frozenset[str]) -> list[str]:
    """The caption lines of FID / KID (what they compare, with which network) and of blocks without ground
    truth (why their image metrics show "–")."""
    notes = []
    shown = {block.key for block, metrics in board.columns if set(DISTRIBUTION_METRICS) & set(metrics)}
    if dist is not None and shown:
        first = dist.iloc[0]
        sha, name = first["inception_sha256"], first["inception_file"]
        network = (name + ", " if isinstance(name, str) else "") + (
            f"SHA-256 {sha[:12]}…" if isinstance(sha, str) else "weights not recorded"
        )
        notes.append(
            "FID / KID: each block's enhanced targets against the recorded frames its packets carry as "
            "references (each once per scene), pooled over the block's scenes; Inception-v3 pool3 features "
            f"({network}, from distribution.json). They depend on the set sizes: compare them only within a "
            "block."
        )
    shown_blind = sorted(blind & {block.key for block, _ in board.columns}, key=natural_key)
    hidden = sorted(blind - set(shown_blind), key=natural_key)
    if hidden:
        notes.append(
            f"Not in the table: {', '.join(hidden)}, whose targets have no ground truth (novel trajectories); "
            "score the runs with --inception FILE for their FID / KID."
        )
    if shown_blind:
        names = shown_blind
        notes.append(
            f"–: not computed. The targets of {', '.join(names)} have no ground truth (novel trajectories), "
            "so their image metrics are null and those blocks are scored by FID / KID only"
            + (
                ""
                if not any(b.key == ALL for b, _ in board.columns)
                else "; the pooled block leaves them out"
            )
            + "."
        )
    return notes


def _cost_column(rows: Sequence[Row], frame: pd.DataFrame) -> tuple[Block, tuple[str, ...]]:
    """Fill each measured row's cost cells (:data:`COST_COLUMNS` its runs recorded); the cost block's column."""
    recorded = tuple(name for name in COST_COLUMNS if name in frame.columns)
    for row in rows:
        if row.source == "measured":
            own = frame[frame["method"] == row.method]
            for name in recorded:
                values = own[name].to_numpy(dtype=np.float64)
                values = values[~np.isnan(values)]
                if len(values):
                    reduce = np.median if COST_COLUMNS[name].aggregate == "median" else np.max
                    row.values[(COST, name)] = float(reduce(values))
                    row.decimals[(COST, name)] = COST_COLUMNS[name].decimals
                    row.counts[(COST, name)] = len(values)
    return (Block(COST, "Cost"), recorded)


def _add_differences(
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


def scored_size(frame: pd.DataFrame) -> tuple[int, int] | None:
    """``(height, width)`` of the images the rows were scored on, read from each run's first output image,
    when every run shares one (the caption states it); ``None`` otherwise or without run folders."""
    if not len(frame) or "run" not in frame.columns or "image" not in frame.columns:
        return None
    sizes = {
        image_size(Path(run) / str(first))
        for run, first in frame.drop_duplicates("run")[["run", "image"]].itertuples(index=False)
    }
    return sizes.pop() if len(sizes) == 1 else None


def _block_rows(frame: pd.DataFrame, block: Block) -> pd.DataFrame:
    return frame if block.key == ALL else frame[frame["group"] == block.key]


def _check_complete(frame: pd.DataFrame, blocks: Sequence[Block]) -> None:
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


def _measured_row(
    method: str,
    frame: pd.DataFrame,
    seq: pd.DataFrame | None,
    blocks: Sequence[Block],
    metric_names: Sequence[str],
    seq_names: Sequence[str],
    *,
    scene_mean: bool = False,
) -> Row:
    row = Row(label=method, method=method, source="measured", section="measured")
    own = frame[frame["method"] == method]
    for block in blocks:
        rows = _block_rows(own, block)
        if not len(rows):
            continue
        for metric in metric_names:
            values = rows[metric].to_numpy(dtype=np.float64)
            mean = rows.groupby("scene")[metric].mean().mean() if scene_mean else values.mean()
            row.values[(block.key, metric)] = float(mean)
            row.decimals[(block.key, metric)] = metric_decimals(metric)
            row.counts[(block.key, metric)] = len(values)
        if block.key == ALL and seq is not None:
            mine = seq[seq["method"] == method]
            for metric in seq_names:
                if metric in mine.columns and len(mine):
                    row.values[(ALL, metric)] = float(mine[metric].to_numpy(dtype=np.float64).mean())
                    row.decimals[(ALL, metric)] = metric_decimals(metric)
                    row.counts[(ALL, metric)] = len(mine)
    return row


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


def _reported_rows(reported: pd.DataFrame, blocks: Sequence[Block], tables: Sequence[str]) -> list[Row]:
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


def _notes(board: Leaderboard, frame: pd.DataFrame, seq: pd.DataFrame | None) -> list[str]:
    notes = [
        "Cells are means of per-image values over each block's targets; best per column in bold "
        "(ties share it, compared as displayed)."
    ]
    if len(frame):
        targets = frame.drop_duplicates(["protocol", "group", "scene", "frame"])
        counts = targets.groupby("group")["frame"].count()
        notes.append(
            "Targets per block: "
            + ", ".join(f"{g}: {int(counts[g])}" for g in sorted(counts.index, key=natural_key))
            + "."
        )
    if seq is not None and len(seq):
        notes.append("Warp error: mean over per-camera sequences (MSE on the 0-255 scale).")
    if any(row.source == "reported" for row in board.rows):
        notes.append(
            "Rows marked (paper) / † are the numbers reported in the SetDiff paper, not measured here."
        )
    if any(block.key == COST for block, _ in board.columns):
        notes.append(
            "Cost: the enhancer's wall time per target frame (median over the method's targets; no I/O or "
            "scoring) and its peak memory (CUDA: most allocated while enhancing a packet; CPU: the peak "
            "resident memory of the process, model included), as `run` recorded them on its machine: "
            "compare methods run on the same machine."
        )
    if board.against is not None:
        notes.append(
            f"(±x): paired difference to {board.against} (row − {board.against}) over the same targets; "
            "a star marks one whose interval excludes 0. Scenes won: scenes whose mean difference favours the row "
            "in the metric's direction. Warp error is per sequence and has no paired difference."
        )
        scenes = [d.scenes for row in board.rows for d in row.differences.values()]
        caveat = few_scenes_note(min(scenes)) if scenes else None
        if caveat:
            notes.append(caveat)
    return notes
