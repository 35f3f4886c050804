"""The paper's two ablations on any packet store: geometric grounding (Table 5) and set size (Table 6).

* **Geometry** trains one SetDiff per variant — no geometry, C-maps only, camera poses (Plücker rays)
  only, both — from the same config, seed and step count (``ModelConfig.use_geometry`` /
  ``geometry_inputs``), runs each on the test packets and tabulates the pooled means.
* **Set size** runs one trained SetDiff with N references + M targets per set for
  N + M ∈ {1+1, 2+1, 3+1, 3+2, 3+4, 3+6} (``-o max_references=N -o targets_per_set=M``): the same
  targets are scored at every size, so columns differ only in how much each target sees.

Each cell is the mean of per-target values over the whole test split (all groups pooled), like
the paper's tables.  The tables are written as Markdown, LaTeX (booktabs) and Parquet, with the
paper's numbers (DL3DV) printed below for orientation — never mixed into our rows — and the exact
commands that produced them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.errors import SetDiffBenchError, UsageError
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.metrics.registry import METRICS as METRIC_SPECS
from setdiff_bench.reporting.leaderboard import load_reported

METRICS = ("psnr", "ssim", "lpips")
HEADERS = {"psnr": "PSNR", "ssim": "SSIM", "lpips": "LPIPS"}
DECIMALS = {"psnr": 2, "ssim": 3, "lpips": 3}


def _higher(metric: str) -> bool:
    """Ranking direction of ``metric``, from the metric registry (``MetricSpec.higher_is_better``)."""
    return METRIC_SPECS[metric].higher_is_better


@dataclass(frozen=True)
class GeometryVariant:
    """One row of Table 5: its key (folder names), label, and the [model] overrides that make it."""

    key: str
    label: str
    overrides: Mapping[str, object]


GEOMETRY_VARIANTS: tuple[GeometryVariant, ...] = (
    GeometryVariant("none", "None", {"use_geometry": False}),
    GeometryVariant("cmap", "Coordinate maps", {"use_geometry": True, "geometry_inputs": ["cmap"]}),
    GeometryVariant("pose", "Camera poses", {"use_geometry": True, "geometry_inputs": ["plucker"]}),
    GeometryVariant("both", "Both", {"use_geometry": True, "geometry_inputs": ["cmap", "plucker"]}),
)

SET_SIZES: tuple[tuple[int, int], ...] = ((1, 1), (2, 1), (3, 1), (3, 2), (3, 4), (3, 6))


def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``"1+1,3+6"`` → ``((1, 1), (3, 6))``."""
    sizes = []
    for part in text.split(","):
        refs, sep, targets = part.strip().partition("+")
        if not sep or not refs.isdigit() or not targets.isdigit() or int(targets) < 1:
            raise UsageError(f"set size {part.strip()!r} is not N+M (N >= 0 references, M >= 1 targets)", "--sizes")
        sizes.append((int(refs), int(targets)))
    return tuple(sizes)


def size_label(size: tuple[int, int]) -> str:
    return f"{size[0]} + {size[1]}"


def pooled_means(metrics_file: Path, split: str = "test") -> dict[str, float]:
    """Mean of each metric over the targets of ``split`` in one run's ``metrics.parquet``."""
    if not metrics_file.is_file():
        raise SetDiffBenchError("run has no metrics.parquet (did the run finish?)", metrics_file.parent)
    frame = pd.read_parquet(metrics_file)
    frame = frame[frame["split"] == split]
    if not len(frame):
        raise SetDiffBenchError(f"no {split} targets in the run", metrics_file)
    return {m: float(frame[m].mean()) for m in METRICS} | {"targets": float(len(frame))}


def geometry_frame(results: Mapping[str, Mapping[str, float]]) -> pd.DataFrame:
    """Table 5 shape: one row per variant (paper order), columns PSNR, SSIM, LPIPS."""
    rows = [{"grounding": v.label, "variant": v.key, **{m: results[v.key][m] for m in METRICS},
             "targets": int(results[v.key]["targets"])} for v in GEOMETRY_VARIANTS if v.key in results]
    return pd.DataFrame(rows)


def setsize_frame(results: Mapping[tuple[int, int], Mapping[str, float]]) -> pd.DataFrame:
    """Table 6 shape: one row per metric, one column per set size ``N + M``."""
    rows = []
    for metric in METRICS:
        rows.append({"metric": HEADERS[metric], **{size_label(size): results[size][metric] for size in results}})
    return pd.DataFrame(rows)


def ordering_geometry(frame: pd.DataFrame) -> list[str]:
    """Plain-language comparison with the paper's Table 5 ordering (None worst, Both best)."""
    notes = []
    by = frame.set_index("variant")
    for metric in METRICS:
        values = by[metric]
        better = values.idxmax() if _higher(metric) else values.idxmin()
        worse = values.idxmin() if _higher(metric) else values.idxmax()
        notes.append(f"{HEADERS[metric]}: best {by.loc[better, 'grounding']}, worst {by.loc[worse, 'grounding']} "
                     f"(paper: best Both, worst None)")
    return notes


def ordering_setsize(results: Mapping[tuple[int, int], Mapping[str, float]]) -> list[str]:
    """Whether more references / more targets help, as in the paper's Table 6."""
    notes = []
    for metric in METRICS:
        sign = 1.0 if _higher(metric) else -1.0
        one, three = results.get((1, 1)), results.get((3, 1))
        if one and three:
            gain = sign * (three[metric] - one[metric])
            notes.append(f"{HEADERS[metric]}: 3+1 vs 1+1 {'better' if gain > 0 else 'not better'} "
                         f"({three[metric]:.4f} vs {one[metric]:.4f}; paper: better)")
        small, large = results.get((3, 1)), results.get((3, 6))
        if small and large:
            gain = sign * (large[metric] - small[metric])
            notes.append(f"{HEADERS[metric]}: 3+6 vs 3+1 {'better' if gain > 0 else 'not better'} "
                         f"({large[metric]:.4f} vs {small[metric]:.4f}; paper: better for PSNR/SSIM, "
                         f"LPIPS within 0.001)")
    return notes


def reported_frame(table: str) -> pd.DataFrame:
    """The paper's numbers for ``table`` (``table5_geometry_ablation`` or ``table6_setsize_ablation``)."""
    rows = load_reported(None, [table])
    return rows.pivot_table(index="setting" if table.startswith("table6") else "method", columns="metric",
                            values="value", sort=False).reset_index()


def format_cell(value: float, metric: str) -> str:
    return "–" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{DECIMALS[metric]}f}"


def best_index(values: Sequence[float], metric: str) -> set[int]:
    """Positions of the best value at display precision (ties share it)."""
    rounded = [round(v, DECIMALS[metric]) for v in values]
    target = max(rounded) if _higher(metric) else min(rounded)
    return {i for i, v in enumerate(rounded) if v == target}


def geometry_markdown(frame: pd.DataFrame, notes: Sequence[str], commands: str, caption: str) -> str:
    best = {m: best_index(list(frame[m]), m) for m in METRICS}
    lines = [f"# {caption}", "", "| Geometric grounding | PSNR ↑ | SSIM ↑ | LPIPS ↓ |", "|---|---:|---:|---:|"]
    for i, row in frame.iterrows():
        cells = [f"**{format_cell(row[m], m)}**" if i in best[m] else format_cell(row[m], m) for m in METRICS]
        lines.append(f"| {row['grounding']} | " + " | ".join(cells) + " |")
    lines += ["", f"Pooled over {int(frame['targets'].iloc[0])} test targets per variant.", ""]
    lines += ["Ordering against the paper:", *[f"- {n}" for n in notes], ""]
    paper = reported_frame("table5_geometry_ablation")
    lines += ["Paper, Table 5 (DL3DV; for orientation, not comparable numbers):", "",
              "| Geometric grounding | PSNR | SSIM | LPIPS |", "|---|---:|---:|---:|"]
    lines += [f"| {r['method']} | {r['psnr']:.2f} | {r['ssim']:.3f} | {r['lpips']:.3f} |" for _, r in paper.iterrows()]
    lines += ["", "Produced by:", "", commands]
    return "\n".join(lines)


def geometry_latex(frame: pd.DataFrame, caption: str) -> str:
    best = {m: best_index(list(frame[m]), m) for m in METRICS}
    lines = ["\\begin{table}[t]", "\\centering", f"\\caption{{{caption}}}", "\\begin{tabular}{lccc}", "\\toprule",
             "\\textbf{Geometric Grounding} & \\textbf{PSNR} & \\textbf{SSIM} & \\textbf{LPIPS} \\\\", "\\midrule"]
    for i, row in frame.iterrows():
        cells = [f"\\textbf{{{format_cell(row[m], m)}}}" if i in best[m] else format_cell(row[m], m) for m in METRICS]
        lines.append(f"{row['grounding']} & " + " & ".join(cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    return "\n".join(lines)


def setsize_markdown(frame: pd.DataFrame, notes: Sequence[str], commands: str, caption: str, targets: int) -> str:
    sizes = [c for c in frame.columns if c != "metric"]
    lines = [f"# {caption}", "", "| I^r + I^t | " + " | ".join(sizes) + " |", "|---|" + "---:|" * len(sizes)]
    for metric, (_, row) in zip(METRICS, frame.iterrows()):
        values = [row[s] for s in sizes]
        best = best_index(values, metric)
        cells = [f"**{format_cell(v, metric)}**" if i in best else format_cell(v, metric) for i, v in enumerate(values)]
        lines.append(f"| {HEADERS[metric]} {'↑' if _higher(metric) else '↓'} | " + " | ".join(cells) + " |")
    lines += ["", f"Each column scores the same {targets} test targets.", ""]
    lines += ["Ordering against the paper:", *[f"- {n}" for n in notes], ""]
    paper = reported_frame("table6_setsize_ablation")
    lines += ["Paper, Table 6 (DL3DV; for orientation, not comparable numbers):", "",
              "| I^r + I^t | PSNR | SSIM | LPIPS |", "|---|---:|---:|---:|"]
    lines += [f"| {r['setting']} | {r['psnr']:.2f} | {r['ssim']:.3f} | {r['lpips']:.3f} |" for _, r in paper.iterrows()]
    lines += ["", "Produced by:", "", commands]
    return "\n".join(lines)


def setsize_latex(frame: pd.DataFrame, caption: str) -> str:
    sizes = [c for c in frame.columns if c != "metric"]
    lines = ["\\begin{table}[t]", "\\centering", f"\\caption{{{caption}}}", "\\begin{tabular}{l" + "c" * len(sizes) + "}",
             "\\toprule", "$\\mathcal{I}^r + \\mathcal{I}^t$ & " + " & ".join(f"\\textbf{{{s}}}" for s in sizes) + " \\\\",
             "\\midrule"]
    for metric, (_, row) in zip(METRICS, frame.iterrows()):
        values = [row[s] for s in sizes]
        best = best_index(values, metric)
        cells = [f"\\textbf{{{format_cell(v, metric)}}}" if i in best else format_cell(v, metric)
                 for i, v in enumerate(values)]
        lines.append(f"\\textbf{{{HEADERS[metric]}}} & " + " & ".join(cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    return "\n".join(lines)


def write_tables(out: Path, stem: str, frame: pd.DataFrame, markdown: str, latex: str) -> dict[str, Path]:
    """``<out>/<stem>.{md,tex,parquet}``, each written atomically."""
    out.mkdir(parents=True, exist_ok=True)
    paths = {"md": out / f"{stem}.md", "latex": out / f"{stem}.tex", "parquet": out / f"{stem}.parquet"}
    write_text_atomic(paths["md"], markdown)
    write_text_atomic(paths["latex"], latex)
    with atomic_path(paths["parquet"]) as tmp:
        pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), tmp)
    return paths
