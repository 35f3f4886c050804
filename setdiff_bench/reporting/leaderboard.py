"""Leaderboards: per-group means of per-image metrics per method → Parquet, LaTeX (booktabs), Markdown.

Inputs are finished runs (``metrics.parquet`` of :mod:`setdiff_bench.evaluation.run`, found recursively under
``--runs``) and, only when asked (``with_reported``), the SetDiff paper's reported numbers from
``protocols/reported/*.csv`` — always marked: a ``source`` column (``measured`` / ``reported``), a
"(paper)" suffix in Markdown and a dagger in LaTeX.

Aggregation (the nerfbaselines convention, docs/metrics.md, "Evaluation and aggregation"): a cell is the **mean of
per-image values** over the block's targets (not a metric of pooled errors, not a mean of scene means);
the pooled "All" block averages every image of every group.  Warp error is a per-sequence value; its
cell is the mean over sequences.  A method whose rows in a block miss targets that another method has
is refused with an error naming the method, the block and the missing frames — a mean over a subset
is never shown.  A method with no rows at all in a block shows "–".

Best per column: bold, decided on the values as displayed (measured values at their metric's
``decimals``, e.g. PSNR 2, SSIM/LPIPS 3, warp 1; reported numbers at their printed precision), so ties
share the bold.  Column headers, decimals and direction (``higher_is_better``, shown as ↑/↓) are read
from the metric's :class:`~setdiff_bench.metrics.registry.MetricSpec`; nothing here repeats them.

The writers (:func:`render_markdown`, :func:`render_latex`, :func:`to_frame`) take any
:class:`Leaderboard`; :func:`pooled_table` builds a one-block table of labelled rows, which is how the
ablation tables (:mod:`setdiff_bench.reporting.ablation`) are written.

Table shapes follow the paper: EUVS Settings 1–3 (Table 1), Para-Lane single/double lane shift
(Table 2), nuScenes one pooled block with warp error (Table 3 + supplement), DL3DV 3/6/9 views
(Table 4); they are declared once, in the ``[leaderboard]`` table of the dataset's default protocol
(``protocols/<dataset>.toml``, :func:`dataset_layout`); other datasets get one block per group found.
"""

from __future__ import annotations

import json
import math
import warnings
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.errors import SetDiffBenchError, UsageError
from setdiff_bench.evaluation.profiles import DEFAULT_PROFILE, PROFILE_COLUMN, get_profile
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.io.images import image_size
from setdiff_bench.io.run_layout import MANIFEST_FILE, METRICS_FILE, RUN_FILE, SEQUENCES_FILE
from setdiff_bench.loaders import DATASETS
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.metrics.registry import METRICS, get_metric
from setdiff_bench.protocols import POOLED, Block, Layout, list_protocols, load_protocol
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.paired import (
    TARGET_COLUMNS,
    PairedDifference,
    few_scenes_note,
    pair_targets,
    paired_differences,
)

FORMATS = ("parquet", "latex", "md")
ALL = POOLED  # block key of the pooled block (every group)


class LeaderboardError(SetDiffBenchError):
    """Runs that cannot be put in one table (missing rows, duplicates, no data)."""


SECTIONS = ("reconstruction", "enhancer", "ablation", "measured")


def dataset_layout(dataset: str) -> Layout:
    """The table shape of ``dataset``: the ``[leaderboard]`` table of its default protocol
    (``protocols/<dataset>.toml``); one block per group found when it has none (or no packaged protocol).

    Raises:
        ProtocolError: the default protocol file is invalid.
    """
    if dataset not in list_protocols():
        return Layout(None)
    layout = load_protocol(dataset).leaderboard
    return layout if layout is not None else Layout(None)


#: Block key of the cost columns (``cost=True``): what enhancing took, beside what it scored.
COST = "cost"


@dataclass(frozen=True)
class CostColumn:
    """A column of the cost block, read from every run's per-target timing columns (lower is better).

    Attributes:
        label: column header; decimals: digits printed; aggregate: how a method's targets reduce to one
            value (``median``: robust to the first packet's warm-up; ``max``: the peak).
    """

    label: str
    decimals: int
    aggregate: str


#: The cost block: ms per target frame (median over the method's targets, warm) and peak memory (CUDA max
#: allocated or peak resident memory, the largest over its packets), as ``run`` records them.
COST_COLUMNS: dict[str, CostColumn] = {
    "ms_per_frame": CostColumn("ms/frame", 0, "median"),
    "peak_memory_mb": CostColumn("peak MiB", 0, "max"),
}


def metric_header(name: str) -> str:
    """The column header of metric ``name`` (``MetricSpec.label``: ``psnr_euvs`` → ``PSNR``)."""
    return COST_COLUMNS[name].label if name in COST_COLUMNS else get_metric(name).label


def metric_decimals(name: str) -> int:
    """Digits after the point that tables print for metric ``name`` (``MetricSpec.decimals``)."""
    return COST_COLUMNS[name].decimals if name in COST_COLUMNS else get_metric(name).decimals


def higher_is_better(name: str) -> bool:
    """Ranking direction of metric ``name`` (``MetricSpec.higher_is_better``; costs: lower is better)."""
    return False if name in COST_COLUMNS else get_metric(name).higher_is_better


# ---------------------------------------------------------------------- inputs
class UnfinishedRunWarning(UserWarning):
    """A run folder left out of a table because its run has not finished (shown as one line by the CLI)."""


@dataclass(frozen=True)
class UnfinishedRun:
    """A folder claimed by ``run`` (``run.json``) whose ``manifest.json`` is not written yet: the run is still
    going, was killed, or its shards are unfinished or not merged (``merge_run`` writes the manifest last)."""

    folder: Path
    method: str | None  # from run.json; None when it cannot be read

    def problem(self) -> str:
        """What is wrong and what to do (the folder is named beside it)."""
        method = f" (method {self.method})" if self.method else ""
        return (
            f"run incomplete{method}: no {MANIFEST_FILE} yet (still running, killed, or shards unfinished or "
            "not merged); finish it, or run the same `setdiff-bench run` command with --merge"
        )


def survey_runs(runs: str | Path) -> tuple[list[Path], list[UnfinishedRun]]:
    """The finished run folders under ``runs`` and the unfinished ones, each sorted.

    A folder with ``metrics.parquet`` is a finished run unless ``run`` claimed it (``run.json``) and has not
    written its ``manifest.json`` (the last file a run writes, atomically); a claimed folder without the
    manifest is unfinished.  Folders of other writers (evaluation profiles, tables made by hand) have no
    ``run.json`` and count when their ``metrics.parquet`` exists.

    Raises:
        UsageError: ``runs`` is not a folder.
    """
    root = Path(runs)
    if not root.is_dir():
        raise UsageError("runs folder not found", root)
    unfinished = []
    for claimed in sorted(root.rglob(RUN_FILE)):
        folder = claimed.parent
        if not (folder / MANIFEST_FILE).is_file() or not (folder / METRICS_FILE).is_file():
            unfinished.append(UnfinishedRun(folder, _claimed_method(claimed)))
    skipped = {run.folder for run in unfinished}  # with the profile tables inside them
    finished = sorted(p.parent for p in root.rglob(METRICS_FILE) if skipped.isdisjoint(p.parents))
    return finished, unfinished


def _claimed_method(run_file: Path) -> str | None:
    """The method ``run.json`` names, or ``None`` when it cannot be read (being written, damaged)."""
    try:
        method = json.loads(run_file.read_text(encoding="utf-8")).get("method")
    except (OSError, ValueError, AttributeError):
        return None
    return method if isinstance(method, str) else None


def find_runs(runs: str | Path) -> list[Path]:
    """Every finished run folder (holding ``metrics.parquet``) under ``runs``, sorted.

    Unfinished runs (:func:`survey_runs`) are left out, each with an :class:`UnfinishedRunWarning` naming it.

    Raises:
        UsageError: ``runs`` is not a folder.
        LeaderboardError: every run under ``runs`` is unfinished (a table of none would say less).
    """
    finished, unfinished = survey_runs(runs)
    require_finished(finished, unfinished)
    warn_unfinished(unfinished)
    return finished


def require_finished(finished: Sequence[Path], unfinished: Sequence[UnfinishedRun]) -> None:
    """Refuse a runs folder whose every run is unfinished, naming the first.

    Raises:
        LeaderboardError: no finished run and at least one unfinished one.
    """
    if unfinished and not finished:
        first = unfinished[0]
        raise LeaderboardError(first.problem() + _more(len(unfinished) - 1, "unfinished run"), first.folder)


def warn_unfinished(unfinished: Sequence[UnfinishedRun]) -> None:
    """One :class:`UnfinishedRunWarning` per run left out (the CLI prints each as one line)."""
    for run in unfinished:
        warnings.warn(f"{run.folder}: left out, {run.problem()}", UnfinishedRunWarning, stacklevel=3)


def _more(count: int, what: str) -> str:
    return f" (and {count} more {what}{'s' if count > 1 else ''})" if count else ""


def load_runs(runs: str | Path | Sequence[Path]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per-target rows and per-sequence rows of every run (a ``run`` column names the folder)."""
    folders = find_runs(runs) if isinstance(runs, str | Path) else [Path(p) for p in runs]
    images, sequences = [], []
    for folder in folders:
        try:
            images.append(pd.read_parquet(folder / METRICS_FILE).assign(run=str(folder)))
            if (folder / SEQUENCES_FILE).is_file():
                sequences.append(pd.read_parquet(folder / SEQUENCES_FILE).assign(run=str(folder)))
        except (OSError, pa.ArrowException) as error:
            raise LeaderboardError(f"unreadable run results ({type(error).__name__})", folder) from None
    image_frame = pd.concat(images, ignore_index=True) if images else pd.DataFrame()
    sequence_frame = pd.concat(sequences, ignore_index=True) if sequences else pd.DataFrame()
    return image_frame, sequence_frame


def load_reported(dataset: str | None = None, tables: Iterable[str] | None = None) -> pd.DataFrame:
    """The paper's numbers from ``protocols/reported/*.csv`` (long format).

    Columns: ``table, dataset, section, setting, group, method, method_id, metric, value`` (float),
    ``printed`` (the text as typeset), ``decimals``, ``bold`` (bold in the paper), ``source``
    (``"reported"``).  ``group`` is the protocol group the setting corresponds to (``""`` = all).
    """
    folder = resources.files("setdiff_bench.protocols") / "reported"
    frames = []
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".csv"):
            with entry.open() as handle:
                frames.append(pd.read_csv(handle, dtype=str, keep_default_na=False))
    frame = pd.concat(frames, ignore_index=True)
    if dataset is not None:
        frame = frame[frame["dataset"] == dataset]
    if tables is not None:
        frame = frame[frame["table"].isin(list(tables))]
    frame = frame.rename(columns={"value": "printed"}).reset_index(drop=True)
    frame["value"] = frame["printed"].astype(float)
    frame["decimals"] = frame["printed"].map(lambda text: len(text.split(".")[1]) if "." in text else 0)
    frame["bold"] = frame["bold"] == "1"
    frame["source"] = "reported"
    return frame


# ---------------------------------------------------------------------- the table
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


def _present(what: str, names: Sequence[str]) -> str:
    """``"; <what>: a, b"`` for an error message, or nothing when ``names`` is empty."""
    return f"; {what}: {', '.join(names)}" if len(names) else ""


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

    Raises:
        LeaderboardError: no rows, a metric column missing, duplicate rows, or a method missing rows.
        UsageError: ``against`` is not a measured method of the table.
    """
    layout = layout or dataset_layout(dataset)
    metric_names = tuple(metrics or layout.metrics)
    frame = images if len(images) else pd.DataFrame(columns=["dataset"])
    present = sorted(set(frame["dataset"]))
    no_reported = reported is None or not len(reported)
    if dataset not in present and dataset not in DATASETS and no_reported:
        raise UsageError(
            f"unknown dataset {dataset!r}; choose from {', '.join(DATASETS)}"
            + _present("runs found for", present),
            "--dataset",
        )
    frame = frame[frame["dataset"] == dataset]
    spec = get_profile(profile)
    frame = profile_rows(frame, profile, dataset if no_reported else None)
    if (
        metrics is None and profile != DEFAULT_PROFILE
    ):  # the profile's metrics (+ the DINOv2 columns when scored)
        metric_names = spec.metrics + tuple(
            m
            for m, s in METRICS.items()
            if s.scope == "profile" and m in frame.columns and frame[m].notna().any()
        )
    unknown_metrics = [m for m in metric_names if m not in METRICS]
    if unknown_metrics:
        raise UsageError(
            f"unknown metric(s) {', '.join(unknown_metrics)}; known: {', '.join(METRICS)}", "--metrics"
        )
    if profile != DEFAULT_PROFILE and reported is not None and len(reported):
        raise LeaderboardError(
            f"the paper's reported numbers use the {DEFAULT_PROFILE} profile; they cannot share "
            f"a table with profile {profile} (drop --with-reported)"
        )
    if split is not None and len(frame) and spec.scenes == "split":  # "all": the profile averages every scene
        splits = sorted(set(frame["split"]))
        frame = frame[frame["split"] == split]
        if not len(frame) and no_reported:
            raise LeaderboardError(
                f"no {dataset} results of split {split!r}" + _present("splits with results", splits)
            )
    if methods is not None and len(frame):
        unknown = sorted(set(methods) - set(frame["method"]))
        if unknown:
            raise LeaderboardError(
                f"no {dataset} runs of method(s) {', '.join(unknown)}"
                + _present("methods with runs", sorted(set(frame["method"])))
            )
        frame = frame[frame["method"].isin(list(methods))]
    if not len(frame) and no_reported:
        raise LeaderboardError(
            f"no {dataset} results{f' of split {split}' if split else ''} to tabulate"
            + _present("runs found for", present)
        )
    missing_columns = [m for m in metric_names if len(frame) and m not in frame.columns]
    if missing_columns:
        raise LeaderboardError(
            f"runs have no column(s) {', '.join(missing_columns)} "
            f"(they were scored with other metrics; pass --metrics)"
        )
    _check_duplicates(frame)
    groups = sorted(frame["group"].unique(), key=natural_key) if len(frame) else []
    blocks = list(layout.blocks) if layout.blocks is not None else [Block(g, g) for g in groups]
    if layout.blocks is not None and groups:
        unknown = [g for g in groups if g not in {b.key for b in blocks}]
        if unknown and not any(b.key == ALL for b in blocks):
            blocks += [Block(g, g) for g in unknown]
    seq = sequences if sequences is not None and len(sequences) else None
    if seq is not None:
        seq = seq[(seq["dataset"] == dataset) & seq["method"].isin(frame["method"].unique())]
    seq_names = tuple(
        m
        for m in layout.sequence_metrics
        if (seq is not None and m in seq.columns and len(seq))
        or (reported is not None and len(reported) and m in set(reported["metric"]))
    )
    columns = [(b, metric_names + (seq_names if b.key == ALL else ())) for b in blocks]
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
                frame,
                seq,
                blocks,
                metric_names,
                seq_names,
                scene_mean=spec.aggregation == "scene_mean",
            )
        )
    _check_complete(frame, blocks)
    if cost:
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
        columns.append((Block(COST, "Cost"), recorded))
    settings = bootstrap or BootstrapSettings()
    if against is not None:
        if against not in order:
            raise UsageError(
                f"no {dataset} runs of method {against!r} in the table"
                + _present("methods in the table", list(order)),
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
                    spec.aggregation,
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
    board.best = _best(board)
    board.notes = _notes(board, frame, seq)
    if spec.aggregation == "scene_mean":
        board.notes[0] = board.notes[0].replace(
            "Cells are means of per-image values over each block's targets",
            "Cells are means over scenes of each scene's mean over its targets",
        )
    return board


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


def profile_rows(frame: pd.DataFrame, profile: str, dataset: str | None = None) -> pd.DataFrame:
    """The rows scored under ``profile``: plain run rows are ``paper``; a ``paper`` table written by
    ``setdiff-bench evaluate`` is used only where no plain run rows exist (they hold the same numbers).

    Raises:
        LeaderboardError: (only when ``dataset`` is given) ``frame`` holds rows of ``dataset`` but none were
            scored under ``profile`` — the runs need ``setdiff-bench evaluate`` first.
    """
    if PROFILE_COLUMN not in frame.columns:
        chosen = frame if profile == DEFAULT_PROFILE else frame.iloc[0:0]
    else:
        plain = frame[PROFILE_COLUMN].isna()
        if profile == DEFAULT_PROFILE and plain.any():
            chosen = frame[plain]
        else:
            chosen = frame[frame[PROFILE_COLUMN].fillna(DEFAULT_PROFILE) == profile]
    mine = frame["dataset"] == dataset if dataset is not None and "dataset" in frame.columns else None
    if mine is not None and mine.any() and not (chosen["dataset"] == dataset).any():
        raise LeaderboardError(
            f"no {dataset} results scored under profile {profile!r}: score the runs with "
            f"`setdiff-bench evaluate RUN --profile {profile}` first"
        )
    return chosen


def _check_duplicates(frame: pd.DataFrame) -> None:
    if not len(frame):
        return
    keys = ["method", *TARGET_COLUMNS]
    duplicated = frame[frame.duplicated(keys, keep=False)]
    if len(duplicated):
        first = duplicated.iloc[0]
        runs = sorted(duplicated[(duplicated[keys] == first[keys]).all(axis=1)]["run"].unique())
        raise LeaderboardError(
            f"method {first['method']!r} has {len(duplicated)} duplicate rows, e.g. "
            f"{first['scene']}/{first['frame']} ({first['group']}) in runs {', '.join(runs)}; "
            "keep one run per method"
        )


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
    board.best = _best(board) if best is None else best
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


def _best(board: Leaderboard) -> dict[tuple[str, str], set[int]]:
    best: dict[tuple[str, str], set[int]] = {}
    for cell in board.cells():
        shown = {i: board.display(row, cell) for i, row in enumerate(board.rows)}
        numbers = {i: float(text) for i, text in shown.items() if text is not None}
        if not numbers:
            continue
        target = max(numbers.values()) if higher_is_better(cell[1]) else min(numbers.values())
        best[cell] = {i for i, value in numbers.items() if value == target}
    return best


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


# ---------------------------------------------------------------------- writers
def to_frame(board: Leaderboard) -> pd.DataFrame:
    """Long table: one row per (row, block, metric) with value, count, best flag and source."""
    records = []
    for index, row in enumerate(board.rows):
        for block, metrics in board.columns:
            for metric in metrics:
                cell = (block.key, metric)
                if cell not in row.values:
                    continue
                records.append(
                    {
                        "dataset": board.dataset,
                        "profile": board.profile,
                        "row_order": index,
                        "source": row.source,
                        "section": row.section,
                        "method": row.method,
                        "label": row.label,
                        "block": block.key,
                        "block_label": block.label,
                        "metric": metric,
                        "value": row.values[cell],
                        "decimals": row.decimals.get(cell, metric_decimals(metric)),
                        "count": row.counts.get(cell),
                        "best": index in board.best.get(cell, set()),
                        **_difference_fields(row.differences.get(cell)),
                    }
                )
    paired = list(_difference_fields(None)) if board.against is not None else []
    frame = pd.DataFrame.from_records(
        records,
        columns=[
            "dataset",
            "row_order",
            "source",
            "section",
            "method",
            "label",
            "block",
            "block_label",
            "metric",
            "value",
            "decimals",
            "count",
            "best",
            *paired,
        ],
    )
    for column in ("wins", "losses", "ties", "scenes", "resamples", "bootstrap_seed"):
        if column in frame.columns:
            frame[column] = frame[column].astype("Int64")
    return frame


def _difference_fields(difference: PairedDifference | None) -> dict[str, object]:
    """The Parquet columns of a cell's paired difference (``None``: no difference there)."""
    if difference is None:
        nan = float("nan")
        return dict.fromkeys(("difference", "low", "high"), nan) | {
            "holds": False,
            "wins": None,
            "losses": None,
            "ties": None,
            "scenes": None,
            "resamples": None,
            "bootstrap_seed": None,
        }
    return {
        "difference": difference.difference,
        "low": difference.low,
        "high": difference.high,
        "holds": difference.holds,
        "wins": difference.wins,
        "losses": difference.losses,
        "ties": difference.ties,
        "scenes": difference.scenes,
        "resamples": difference.settings.resamples,
        "bootstrap_seed": difference.settings.seed,
    }


LATEX_SPECIALS = {
    "\\": r"\textbackslash{}",
    "&": r"\&",
    "%": r"\%",
    "$": r"\$",
    "#": r"\#",
    "_": r"\_",
    "{": r"\{",
    "}": r"\}",
    "~": r"\textasciitilde{}",
    "^": r"\textasciicircum{}",
}


def latex_escape(text: str) -> str:
    """Escape LaTeX's special characters in plain text."""
    return "".join(LATEX_SPECIALS.get(char, char) for char in text)


def metric_arrow(metric: str, latex: bool) -> str:
    """The metric's direction arrow (``MetricSpec.arrow``), in LaTeX math where asked."""
    if metric in COST_COLUMNS:
        return r"$\downarrow$" if latex else "↓"
    spec = get_metric(metric)
    if latex:
        return r"$\uparrow$" if spec.higher_is_better else r"$\downarrow$"
    return spec.arrow


def render_latex(board: Leaderboard, command: str | None = None) -> str:
    """A booktabs ``tabular`` in the paper's shape (needs ``\\usepackage{booktabs}``)."""
    spec = "l" + "|".join("c" * len(metrics) for _, metrics in board.columns)
    lines = [f"% {latex_escape(board.title)}"]
    if command:
        lines.append(f"% generated by: {command}")
    lines += [f"% {note}" for note in board.notes]
    lines += [r"% requires \usepackage{booktabs}", rf"\begin{{tabular}}{{{spec}}}", r"\toprule"]
    if len(board.columns) > 1 or board.columns[0][0].key != ALL:
        heads, rules, start = [""], [], 2
        for block, metrics in board.columns:
            heads.append(rf"\multicolumn{{{len(metrics)}}}{{c}}{{\textbf{{{latex_escape(block.label)}}}}}")
            rules.append(rf"\cmidrule(lr){{{start}-{start + len(metrics) - 1}}}")
            start += len(metrics)
        lines.append(" & ".join(heads) + r" \\")
        lines.append(" ".join(rules))
    header = [rf"\textbf{{{latex_escape(board.row_header)}}}"]
    header += [
        rf"\textbf{{{latex_escape(metric_header(m))}}}{metric_arrow(m, True)}"
        for _, metrics in board.columns
        for m in metrics
    ]
    lines += [" & ".join(header) + r" \\", r"\midrule"]
    previous = None
    for index, row in enumerate(board.rows):
        group = (row.source, row.section)
        if previous is not None and group != previous:
            lines.append(r"\midrule")
        previous = group
        label = latex_escape(row.label) + (r"$^\dagger$" if row.source == "reported" else "")
        cells = [label]
        for cell in board.cells():
            text = board.display(row, cell)
            if text is None:
                cells.append("--")
            elif index in board.best.get(cell, set()):
                cells.append(rf"\textbf{{{text}}}" + _difference_suffix(board, row, cell, r"$^\ast$"))
            else:
                cells.append(text + _difference_suffix(board, row, cell, r"$^\ast$"))
        lines.append(" & ".join(cells) + r" \\")
    lines += [r"\bottomrule", r"\end{tabular}"]
    lines += [f"% {latex_escape(line)}" for line in _interval_lines(board)]
    return "\n".join(lines) + "\n"


def _difference_suffix(board: Leaderboard, row: Row, cell: tuple[str, str], mark: str) -> str:
    """`` (+1.81*)``: the cell's paired difference at the cell's decimals, marked when its interval excludes
    0; empty where the row has none (the ``against`` row, reported rows, warp error, tables without one)."""
    difference = row.differences.get(cell)
    if difference is None or math.isnan(difference.difference):
        return ""
    decimals = row.decimals.get(cell, metric_decimals(cell[1]))
    return f" ({difference.difference:+.{decimals}f}{mark if difference.holds else ''})"


def _interval_lines(board: Leaderboard) -> list[str]:
    """One line per measured row and block: each metric's difference, interval and scenes won."""
    if board.against is None:
        return []
    labels = {block.key: block.label for block, _ in board.columns}
    lines = []
    for row in board.rows:
        for block, metrics in board.columns:
            parts = [
                f"{metric_header(m)} {d.format()} won {d.wins} of {d.scenes}"
                for m in metrics
                if (d := row.differences.get((block.key, m))) is not None
            ]
            if parts:
                lines.append(f"{row.label} vs {board.against}, {labels[block.key]}: {'; '.join(parts)}")
    return lines


def md_escape(text: str) -> str:
    """Text safe inside a Markdown table cell (``|`` escaped)."""
    return text.replace("|", r"\|")


def render_markdown(board: Leaderboard, command: str | None = None) -> str:
    """A GitHub Markdown table: one column per (block, metric), best in bold, paper rows suffixed."""
    multi = len(board.columns) > 1 or board.columns[0][0].key != ALL
    header = [board.row_header] + [
        (f"{block.label} " if multi else "") + metric_header(m) + metric_arrow(m, False)
        for block, metrics in board.columns
        for m in metrics
    ]
    lines = [
        f"**{md_escape(board.title)}**",
        "",
        "| " + " | ".join(md_escape(h) for h in header) + " |",
        "|" + "---|" + "---:|" * (len(header) - 1),
    ]
    for index, row in enumerate(board.rows):
        label = row.label + (" (paper)" if row.source == "reported" else "")
        cells = [md_escape(label)]
        for cell in board.cells():
            text = board.display(row, cell)
            cells.append(
                "–"
                if text is None
                else (f"**{text}**" if index in board.best.get(cell, set()) else text)
                + _difference_suffix(board, row, cell, r"\*")
            )
        lines.append("| " + " | ".join(cells) + " |")
    lines.append("")
    lines += [md_escape(note) for note in board.notes]
    lines += _interval_markdown(board)
    if command:
        lines.append(f"Generated by `{command}`.")
    return "\n".join(lines) + "\n"


def _interval_markdown(board: Leaderboard) -> list[str]:
    """The paired differences of a table with ``against`` as a Markdown table: one row per measured method
    and block, one column per metric holding ``difference [low, high]`` and the scenes it wins."""
    if board.against is None:
        return []
    metrics = list(dict.fromkeys(m for _, ms in board.columns for m in ms))
    records = []
    for row in board.rows:
        for block, _ in board.columns:
            found = {m: row.differences.get((block.key, m)) for m in metrics}
            if any(d is not None for d in found.values()):
                cells = [
                    "–"
                    if d is None
                    else d.format() + (r" \*" if d.holds else "") + f", won {d.wins} of {d.scenes}"
                    for d in found.values()
                ]
                records.append([md_escape(row.label), md_escape(block.label), *cells])
    if not records:
        return []
    confidence = (board.bootstrap or BootstrapSettings()).confidence
    header = [board.row_header, "Block", *(metric_header(m) + metric_arrow(m, False) for m in metrics)]
    lines = [
        "",
        f"**Paired differences to {md_escape(board.against)}: row − {md_escape(board.against)} "
        f"[{confidence * 100:g} % interval], scenes won of scenes**",
        "",
        "| " + " | ".join(header) + " |",
        "|---|---|" + "---:|" * len(metrics),
    ]
    lines += ["| " + " | ".join(record) + " |" for record in records]
    lines.append("")
    return lines


def write_leaderboard(
    board: Leaderboard, out: str | Path, formats: Sequence[str] = FORMATS, command: str | None = None
) -> dict[str, Path]:
    """Write ``<out>/<stem>.{parquet,tex,md}`` atomically (:attr:`Leaderboard.stem`); returns format → path."""
    unknown = [f for f in formats if f not in FORMATS]
    if unknown:
        raise UsageError(
            f"unknown format(s) {', '.join(unknown)}; choose from {', '.join(FORMATS)}", "--format"
        )
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    if "parquet" in formats:
        path = out / f"{board.stem}.parquet"
        table = pa.Table.from_pandas(to_frame(board), preserve_index=False)
        with atomic_path(path) as tmp:
            pq.write_table(table, tmp, compression="zstd")
        written["parquet"] = path
    if "latex" in formats:
        written["latex"] = out / f"{board.stem}.tex"
        write_text_atomic(written["latex"], render_latex(board, command))
    if "md" in formats:
        written["md"] = out / f"{board.stem}.md"
        write_text_atomic(written["md"], render_markdown(board, command))
    return written


def reported_for(dataset: str, layout: Layout | None = None) -> pd.DataFrame:
    """The reported rows the dataset's layout mixes in (empty when the paper has none)."""
    layout = layout or dataset_layout(dataset)
    if not layout.reported_tables:
        return load_reported(dataset).iloc[0:0]
    return load_reported(dataset, layout.reported_tables)
