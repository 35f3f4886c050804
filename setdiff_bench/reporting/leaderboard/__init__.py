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

FID / KID (issue 41): runs scored with ``--inception`` hold ``distribution.parquet`` (one row per block,
:mod:`setdiff_bench.evaluation.distribution_scoring`); their values become ``fid`` / ``kid`` columns of the
group blocks that have them (:func:`load_distribution`, ``build_leaderboard(distribution=)``), with a caption
line naming the reference set and the Inception weights.  A group whose targets have no ground truth
(novel-trajectory packets: every image metric null) is a block of its own showing FID / KID only, its image
metrics "–" (not computed, never NaN: the Parquet has no such cell), and the pooled block leaves it out.
Tables of runs without distribution files are unchanged.

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

Modules, leaves first: :mod:`.columns` (layout, blocks, each metric's header/decimals/direction, the error),
:mod:`.inputs` (finding and reading runs, the reported numbers), :mod:`.table` (the table model),
:mod:`.selection` (which rows a table averages), :mod:`.cells` (measured, reported, cost and paired-difference
cells), :mod:`.distribution` (FID / KID rows and captions), :mod:`.aggregate` (:func:`build_leaderboard`)
and :mod:`.render` (Parquet, LaTeX, Markdown).  Every public name is importable from this package.
"""

from setdiff_bench.protocols import Block, Layout
from setdiff_bench.reporting.leaderboard.aggregate import build_leaderboard, scored_size
from setdiff_bench.reporting.leaderboard.columns import (
    ALL,
    COST,
    COST_COLUMNS,
    CostColumn,
    LeaderboardError,
    dataset_layout,
    higher_is_better,
    metric_arrow,
    metric_decimals,
    metric_header,
)
from setdiff_bench.reporting.leaderboard.distribution import DISTRIBUTION_METRICS
from setdiff_bench.reporting.leaderboard.inputs import (
    UnfinishedRun,
    UnfinishedRunWarning,
    find_runs,
    load_distribution,
    load_reported,
    load_runs,
    reported_for,
    require_finished,
    run_names,
    survey_runs,
    warn_unfinished,
)
from setdiff_bench.reporting.leaderboard.render import (
    FORMATS,
    LATEX_SPECIALS,
    latex_escape,
    md_escape,
    render_latex,
    render_markdown,
    to_frame,
    write_leaderboard,
)
from setdiff_bench.reporting.leaderboard.selection import profile_rows
from setdiff_bench.reporting.leaderboard.table import SECTIONS, Leaderboard, Row, pooled_row, pooled_table

__all__ = [
    "ALL",
    "COST",
    "COST_COLUMNS",
    "DISTRIBUTION_METRICS",
    "FORMATS",
    "LATEX_SPECIALS",
    "SECTIONS",
    "Block",
    "CostColumn",
    "Layout",
    "Leaderboard",
    "LeaderboardError",
    "Row",
    "UnfinishedRun",
    "UnfinishedRunWarning",
    "build_leaderboard",
    "dataset_layout",
    "find_runs",
    "higher_is_better",
    "latex_escape",
    "load_distribution",
    "load_reported",
    "load_runs",
    "md_escape",
    "metric_arrow",
    "metric_decimals",
    "metric_header",
    "pooled_row",
    "pooled_table",
    "profile_rows",
    "render_latex",
    "render_markdown",
    "reported_for",
    "require_finished",
    "run_names",
    "scored_size",
    "survey_runs",
    "to_frame",
    "warn_unfinished",
    "write_leaderboard",
]
