"""Aggregation: finished-run rows (and the paper's, when asked) of one dataset into a
:class:`~setdiff_bench.reporting.leaderboard.table.Leaderboard` (:func:`build_leaderboard`): rows chosen and
checked, blocks, one measured row per method (means of per-image values), the cost block, paired differences,
best cells and notes.

The cells come from :mod:`.cells` (measured, reported, cost, paired differences) and :mod:`.distribution`
(FID / KID, groups without ground truth); this module lays out the blocks, puts the table together and
writes its caption and notes."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from setdiff_bench.io.images import image_size
from setdiff_bench.io.run_layout import TARGET_COLUMNS
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.protocols import Block, Layout
from setdiff_bench.protocols.profiles import DEFAULT_PROFILE, get_profile
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.leaderboard.cells import (
    add_differences,
    check_complete,
    cost_column,
    measured_row,
    reported_rows,
)
from setdiff_bench.reporting.leaderboard.columns import ALL, COST, LeaderboardError, dataset_layout
from setdiff_bench.reporting.leaderboard.distribution import (
    DISTRIBUTION_METRICS,
    distribution_cells,
    distribution_notes,
    groups_without_ground_truth,
    select_distribution,
)
from setdiff_bench.reporting.leaderboard.selection import select_rows
from setdiff_bench.reporting.leaderboard.table import Leaderboard, best_cells
from setdiff_bench.reporting.paired import few_scenes_note

__all__ = ["build_leaderboard", "scored_size"]


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
        profile: the evaluation profile tabulated (:mod:`setdiff_bench.protocols.profiles`): rows of plain runs are
            ``paper``; ``setdiff-bench evaluate`` tables carry their profile.  The caption names it, and the
            profile's averaging is used (``scene_mean``: the mean of per-scene means).
        against: a measured method shown in the table: every other measured cell gets its paired difference
            to it (:mod:`setdiff_bench.reporting.paired`; image metrics only, warp error is per sequence), which
            the writers show as a gain, positive = better (:mod:`setdiff_bench.reporting.gains`).
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
    blind = groups_without_ground_truth(frame, metric_names)
    paired = frame[~frame["group"].isin(blind)] if blind else frame  # the rows image metrics average
    blocks = _blocks(layout, frame, blind)
    dist = select_distribution(distribution, dataset, frame, split if spec.scenes == "split" else None)
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
    # trajectory groups with render-flow warp error (sequences.parquet's flow_source) show it in their block
    render_groups = (
        set(seq.loc[seq["flow_source"] == "render", "group"])
        if seq is not None and "flow_source" in seq.columns
        else set()
    )
    columns = [
        (
            b,
            metric_names
            + (seq_names if b.key == ALL or b.key in render_groups else ())
            + (DISTRIBUTION_METRICS if b.key != ALL and b.key in dist_groups else ()),
        )
        for b in blocks
    ]
    rows = (
        reported_rows(reported, blocks, layout.reported_tables)
        if reported is not None and len(reported)
        else []
    )
    order = list(methods) if methods is not None else sorted(frame["method"].unique()) if len(frame) else []
    for method in order:
        rows.append(
            measured_row(
                method,
                paired,
                seq,
                blocks,
                metric_names,
                seq_names,
                scene_mean=spec.aggregation == "scene_mean",
                group_sequences=True,
            )
        )
        if dist is not None:
            distribution_cells(rows[-1], dist, blocks)
    check_complete(frame, blocks)
    if cost:
        columns.append(cost_column(rows, frame))
    settings = bootstrap or BootstrapSettings()
    if against is not None:
        add_differences(
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
        title += f"; paired gains over {against} (positive = better): {settings.describe()}"
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
    board.notes += distribution_notes(board, dist, blind)
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


def _notes(board: Leaderboard, frame: pd.DataFrame, seq: pd.DataFrame | None) -> list[str]:
    notes = [
        "Cells are means of per-image values over each block's targets; best per column in bold "
        "(ties share it, compared as displayed)."
    ]
    if len(frame):
        targets = frame.drop_duplicates(list(TARGET_COLUMNS))
        counts = targets.groupby("group")["frame"].count()
        notes.append(
            "Targets per block: "
            + ", ".join(f"{g}: {int(counts[g])}" for g in sorted(counts.index, key=natural_key))
            + "."
        )
    if seq is not None and len(seq):
        notes.append("Warp error: mean over per-camera sequences (MSE on the 0-255 scale).")
        if "flow_source" in seq.columns and (seq["flow_source"] == "render").any():
            notes.append(
                "Warp error of a trajectory block (no ground truth): flow and occlusion from the 3DGS renders of "
                "its targets, one sequence per camera and group; compare it within the block only."
            )
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
            + (
                " refit s/scene: the wall time of the refit each scene's render came from (`run --refit`: "
                "steps, updates and the enhancer inside them; mean over the row's scenes)."
                if any((COST, "refit_s") in row.values for row in board.rows)
                else ""
            )
        )
    if board.against is not None:
        notes.append(
            f"(±x): paired gain over {board.against} on the same targets, positive = the row is better (row − "
            f"{board.against} where higher is better, {board.against} − row where lower is); a star marks one "
            "whose interval excludes 0. Scenes won: scenes whose mean difference favours the row in the metric's "
            "direction. Warp error is per sequence and has no paired difference."
        )
        scenes = [d.scenes for row in board.rows for d in row.differences.values()]
        caveat = few_scenes_note(min(scenes)) if scenes else None
        if caveat:
            notes.append(caveat)
    return notes
