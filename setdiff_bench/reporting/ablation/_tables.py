"""An ablation's tables: the Parquet shapes of Tables 5 and 6, their Markdown and LaTeX (through the
leaderboard's writers, beside the paper's numbers and the commands), and the files written."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.ablation._design import GEOMETRY_VARIANTS, METRICS, size_label
from setdiff_bench.reporting.ablation._results import ModelResults
from setdiff_bench.reporting.leaderboard import (
    Leaderboard,
    load_reported,
    pooled_row,
    pooled_table,
    render_latex,
    render_markdown,
)

GEOMETRY_HEADER = "Geometric grounding"
SETSIZE_HEADER = "References + targets"


def geometry_frame(results: Mapping[str, Mapping[str, float]]) -> pd.DataFrame:
    """Table 5 shape: one row per variant (paper order), columns PSNR, SSIM, LPIPS."""
    rows = [
        {
            "grounding": v.label,
            "variant": v.key,
            **{m: results[v.key][m] for m in METRICS},
            "targets": int(results[v.key]["targets"]),
        }
        for v in GEOMETRY_VARIANTS
        if v.key in results
    ]
    return pd.DataFrame(rows)


def setsize_frame(results: Mapping[tuple[int, int], Mapping[str, float]]) -> pd.DataFrame:
    """Table 6 shape: one row per metric, one column per set size ``N + M``."""
    rows = []
    for metric in METRICS:
        rows.append(
            {
                "metric": get_metric(metric).label,
                **{size_label(size): results[size][metric] for size in results},
            }
        )
    return pd.DataFrame(rows)


def paper_board(table: str, title: str) -> Leaderboard:
    """The paper's numbers for ``table`` (``table5_geometry_ablation`` or ``table6_setsize_ablation``) as a
    table for the writers: one row per variant or set size at the printed precision, the paper's bold."""
    records = load_reported(None, [table])
    key = "setting" if table.startswith("table6") else "method"
    rows, best = [], {}
    for index, (label, own) in enumerate(records.groupby(key, sort=False)):
        rows.append(
            pooled_row(
                str(label),
                dict(zip(own["metric"], own["value"])),
                source="reported",
                decimals=dict(zip(own["metric"], own["decimals"])),
            )
        )
        for cell in rows[-1].values:
            if own.loc[own["metric"] == cell[1], "bold"].any():
                best.setdefault(cell, set()).add(index)
    header = SETSIZE_HEADER if key == "setting" else GEOMETRY_HEADER
    return pooled_table(title, rows, METRICS, row_header=header, best=best)


def geometry_board(frame: pd.DataFrame, caption: str, notes: Sequence[str] = ()) -> Leaderboard:
    """Table 5 for the writers: one row per variant, best per column in bold; ``notes`` go under it."""
    rows = [pooled_row(row["grounding"], {m: row[m] for m in METRICS}) for _, row in frame.iterrows()]
    pooled = [f"Pooled over {int(frame['targets'].iloc[0])} test targets per variant.", *notes]
    return pooled_table(caption, rows, METRICS, row_header=GEOMETRY_HEADER, notes=pooled)


def setsize_board(frame: pd.DataFrame, caption: str, notes: Sequence[str] = ()) -> Leaderboard:
    """Table 6 for the writers, from :func:`setsize_frame`: one row per set size, one column per metric."""
    sizes = [c for c in frame.columns if c != "metric"]
    values = {
        size: {metric: row[size] for metric, (_, row) in zip(METRICS, frame.iterrows())} for size in sizes
    }
    rows = [pooled_row(size, values[size]) for size in sizes]
    return pooled_table(caption, rows, METRICS, row_header=SETSIZE_HEADER, notes=notes)


def _document(board: Leaderboard, ordering: Sequence[str], paper: Leaderboard, commands: str) -> str:
    """Our table, the ordering against the paper, the paper's table and the commands, as Markdown."""
    lines = [
        render_markdown(board),
        "Ordering against the paper:",
        *[f"- {n}" for n in ordering],
        "",
        render_markdown(paper).rstrip("\n"),
        "",
        "Produced by:",
        "",
        commands,
    ]
    return "\n".join(lines)


def geometry_markdown(
    frame: pd.DataFrame, notes: Sequence[str], commands: str, caption: str, spread: Sequence[str] = ()
) -> str:
    """``notes``: the ordering against the paper; ``spread``: :func:`spread_notes` (under the table)."""
    paper = paper_board(
        "table5_geometry_ablation", "Paper, Table 5 (DL3DV; for orientation, not comparable numbers)"
    )
    return _document(geometry_board(frame, caption, spread), notes, paper, commands)


def geometry_latex(frame: pd.DataFrame, caption: str) -> str:
    return render_latex(geometry_board(frame, caption))


def setsize_markdown(
    frame: pd.DataFrame,
    notes: Sequence[str],
    commands: str,
    caption: str,
    targets: int,
    spread: Sequence[str] = (),
) -> str:
    """``notes``: the ordering against the paper; ``spread``: :func:`spread_notes` (under the table)."""
    paper = paper_board(
        "table6_setsize_ablation", "Paper, Table 6 (DL3DV; for orientation, not comparable numbers)"
    )
    board = setsize_board(
        frame, caption, [f"Every set size scores the same {targets} test targets.", *spread]
    )
    return _document(board, notes, paper, commands)


def setsize_latex(frame: pd.DataFrame, caption: str) -> str:
    return render_latex(setsize_board(frame, caption))


def write_tables(
    out: Path, stem: str, frame: pd.DataFrame, markdown: str, latex: str, results: ModelResults
) -> dict[str, Path]:
    """``<out>/<stem>.{md,tex,parquet}`` and every model's values (``results``) in
    ``<out>/<stem>_per_model.parquet``, each written atomically."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "md": out / f"{stem}.md",
        "latex": out / f"{stem}.tex",
        "parquet": out / f"{stem}.parquet",
        "per_model": out / f"{stem}_per_model.parquet",
    }
    write_text_atomic(paths["md"], markdown)
    write_text_atomic(paths["latex"], latex)
    for key, table in (("parquet", frame), ("per_model", results.frame())):
        with atomic_path(paths[key]) as tmp:
            pq.write_table(pa.Table.from_pandas(table, preserve_index=False), tmp)
    return paths
