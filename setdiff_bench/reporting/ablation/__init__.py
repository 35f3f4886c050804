"""The paper's two ablations on any packet store: geometric grounding (Table 5) and set size (Table 6).

* **Geometry** trains one SetDiff per variant — no geometry, C-maps only, camera poses (Plücker rays)
  only, both — from the same config, seed and step count (``ModelConfig.use_geometry`` /
  ``geometry_inputs``), runs each on the test packets and tabulates the pooled means.
* **Set size** runs one trained SetDiff with N references + M targets per set for
  N + M ∈ {1+1, 2+1, 3+1, 3+2, 3+4, 3+6} (``-o max_references=N -o targets_per_set=M``): the same
  targets are scored at every size, so columns differ only in how much each target sees.

Each cell is the mean of per-target values over the whole test split (all groups pooled), like
the paper's tables.  Several trained models (training seeds: ``ablate geometry --seed 0 --seed 1``,
``ablate setsize --checkpoint A --checkpoint B``) make each cell the mean over models; the spread
(max − min and standard deviation over models) is printed under the table, every comparison gives each
model's own paired gain, whether the mean gain is beyond both rows' seed spreads, and — computed by the tool,
not by hand — its paired interval over the test targets (the per-target differences averaged over models,
bootstrap resampled by scene, :mod:`setdiff_bench.reporting.paired`) with the scenes it wins; every model's
values go to ``<stem>_per_model.parquet`` (one row per model, row and metric).  The Markdown and LaTeX (booktabs) tables are written by the leaderboard's writers
(:func:`setdiff_bench.reporting.leaderboard.pooled_table`), so cells, bold and headers follow the metric specs
exactly as in the leaderboards; the Markdown adds the paper's numbers (DL3DV) below for orientation —
never mixed into our rows — and the exact commands that produced them.  The set-size table has one row
per set size (the paper prints Table 6 transposed, one row per metric); its Parquet keeps the paper's
shape.

The concepts live in private modules of their own, one each; this face exports them: what an ablation varies
(:mod:`~setdiff_bench.reporting.ablation._design`), its numbers over runs and trained models
(:mod:`~setdiff_bench.reporting.ablation._results`), the comparison with the paper's ordering
(:mod:`~setdiff_bench.reporting.ablation._ordering`) and its tables (:mod:`~setdiff_bench.reporting.ablation._tables`).
"""

from __future__ import annotations

from setdiff_bench.reporting.ablation._design import (
    GEOMETRY_VARIANTS,
    METRICS,
    SET_SIZES,
    GeometryVariant,
    parse_sizes,
    parse_variants,
    size_label,
)
from setdiff_bench.reporting.ablation._ordering import ordering_geometry, ordering_setsize
from setdiff_bench.reporting.ablation._results import (
    Key,
    ModelResults,
    RunMeans,
    mean_over_models,
    paired_over_targets,
    per_model_frame,
    pooled_means,
    seed_spread,
    spread_notes,
)
from setdiff_bench.reporting.ablation._tables import (
    GEOMETRY_HEADER,
    SETSIZE_HEADER,
    geometry_board,
    geometry_frame,
    geometry_latex,
    geometry_markdown,
    paper_board,
    setsize_board,
    setsize_frame,
    setsize_latex,
    setsize_markdown,
    write_tables,
)

__all__ = [
    "GEOMETRY_HEADER",
    "GEOMETRY_VARIANTS",
    "METRICS",
    "SETSIZE_HEADER",
    "SET_SIZES",
    "GeometryVariant",
    "Key",
    "ModelResults",
    "RunMeans",
    "geometry_board",
    "geometry_frame",
    "geometry_latex",
    "geometry_markdown",
    "mean_over_models",
    "ordering_geometry",
    "ordering_setsize",
    "paired_over_targets",
    "paper_board",
    "parse_sizes",
    "parse_variants",
    "per_model_frame",
    "pooled_means",
    "seed_spread",
    "setsize_board",
    "setsize_frame",
    "setsize_latex",
    "setsize_markdown",
    "size_label",
    "spread_notes",
    "write_tables",
]
