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
(max − min over models) and, for set sizes, each model's own paired gain are printed under the table,
and every model's values go to ``<stem>_per_model.parquet`` (one row per model, row and metric).  The Markdown and LaTeX (booktabs) tables are written by the leaderboard's writers
(:func:`setdiff_bench.reporting.leaderboard.pooled_table`), so cells, bold and headers follow the metric specs
exactly as in the leaderboards; the Markdown adds the paper's numbers (DL3DV) below for orientation —
never mixed into our rows — and the exact commands that produced them.  The set-size table has one row
per set size (the paper prints Table 6 transposed, one row per metric); its Parquet keeps the paper's
shape.
"""

from __future__ import annotations

from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Generic, TypeVar

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.errors import SetDiffBenchError, UsageError
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.leaderboard import (
    Leaderboard,
    load_reported,
    pooled_row,
    pooled_table,
    render_latex,
    render_markdown,
)

METRICS = ("psnr", "ssim", "lpips")
GEOMETRY_HEADER = "Geometric grounding"
SETSIZE_HEADER = "References + targets"


@dataclass(frozen=True)
class GeometryVariant:
    """One row of Table 5: its key (folder names), label, and the [model] overrides that make it."""

    key: str
    label: str
    overrides: Mapping[str, object]


# The C-map attention bias (``attention_bias = "cmap_distance"``, beyond the paper) is C-map geometry too:
# the rows without C-maps switch it off, the rows with C-maps keep the config's setting.
GEOMETRY_VARIANTS: tuple[GeometryVariant, ...] = (
    GeometryVariant("none", "None", {"use_geometry": False, "attention_bias": "none"}),
    GeometryVariant("cmap", "Coordinate maps", {"use_geometry": True, "geometry_inputs": ["cmap"]}),
    GeometryVariant(
        "pose",
        "Camera poses",
        {"use_geometry": True, "geometry_inputs": ["plucker"], "attention_bias": "none"},
    ),
    GeometryVariant("both", "Both", {"use_geometry": True, "geometry_inputs": ["cmap", "plucker"]}),
)

Key = TypeVar("Key", bound=Hashable)

SET_SIZES: tuple[tuple[int, int], ...] = ((1, 1), (2, 1), (3, 1), (3, 2), (3, 4), (3, 6))


def parse_variants(text: str | None) -> tuple[GeometryVariant, ...]:
    """``"none,both"`` → those variants of :data:`GEOMETRY_VARIANTS`, in the paper's row order; ``None``:
    all four."""
    if text is None:
        return GEOMETRY_VARIANTS
    known = {variant.key: variant for variant in GEOMETRY_VARIANTS}
    wanted = [part.strip() for part in text.split(",") if part.strip()]
    unknown = [key for key in wanted if key not in known]
    if unknown or not wanted:
        raise UsageError(
            f"geometry variant {unknown[0]!r} is unknown (choose from {', '.join(known)})"
            if unknown
            else f"no geometry variant given (choose from {', '.join(known)})",
            "--variants",
        )
    return tuple(variant for variant in GEOMETRY_VARIANTS if variant.key in wanted)


def parse_sizes(text: str) -> tuple[tuple[int, int], ...]:
    """``"1+1,3+6"`` → ``((1, 1), (3, 6))``."""
    sizes = []
    for part in text.split(","):
        refs, sep, targets = part.strip().partition("+")
        if not sep or not refs.isdigit() or not targets.isdigit() or int(targets) < 1:
            raise UsageError(
                f"set size {part.strip()!r} is not N+M (N >= 0 references, M >= 1 targets)", "--sizes"
            )
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


def mean_over_models(per_model: Sequence[Mapping[Key, Mapping[str, float]]]) -> dict[Key, dict[str, float]]:
    """Row key → metric → mean over the models (training seeds) that have the row; ``targets`` is kept."""
    keys = list(dict.fromkeys(key for model in per_model for key in model))
    means = {}
    for key in keys:
        own = [model[key] for model in per_model if key in model]
        means[key] = {m: sum(r[m] for r in own) / len(own) for m in METRICS} | {"targets": own[0]["targets"]}
    return means


def spread_notes(
    per_model: Sequence[Mapping[Key, Mapping[str, float]]], label: Mapping[Key, str], models: Sequence[str]
) -> list[str]:
    """One line per metric: the spread (max − min over models) of each row's value; none for one model."""
    if len(per_model) < 2:
        return []
    notes = [f"Each cell is the mean over {len(per_model)} trained models ({', '.join(models)})."]
    for metric in METRICS:
        spec = get_metric(metric)
        cells = []
        for key, text in label.items():
            values = [model[key][metric] for model in per_model if key in model]
            cells.append(f"{text} {max(values) - min(values):.{spec.decimals + 1}f}")
        notes.append(f"{spec.label} spread (max − min over models): {', '.join(cells)}.")
    return notes


def per_model_frame(
    per_model: Sequence[Mapping[Key, Mapping[str, float]]], label: Mapping[Key, str], models: Sequence[str]
) -> pd.DataFrame:
    """Long table of every model's pooled means: columns ``model``, ``row``, ``metric``, ``value``."""
    rows = [
        {"model": name, "row": label[key], "metric": get_metric(metric).label, "value": float(values[metric])}
        for name, model in zip(models, per_model)
        for key, values in model.items()
        for metric in METRICS
    ]
    return pd.DataFrame(rows, columns=["model", "row", "metric", "value"])


@dataclass(frozen=True)
class ModelResults(Generic[Key]):
    """One study's pooled means for each trained model (training seed).

    Attributes:
        per_model: ``per_model[i][row]`` → metric → value (plus ``targets``), one mapping per model.
        labels: row key → its label in the tables (e.g. ``(3, 1)`` → ``"3 + 1"``).
        models: one name per model (a seed, a checkpoint path).
    """

    per_model: Sequence[Mapping[Key, Mapping[str, float]]]
    labels: Mapping[Key, str]
    models: Sequence[str]

    def means(self) -> dict[Key, dict[str, float]]:
        return mean_over_models(self.per_model)

    def spread_notes(self) -> list[str]:
        return spread_notes(self.per_model, self.labels, self.models)

    def frame(self) -> pd.DataFrame:
        return per_model_frame(self.per_model, self.labels, self.models)


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


def ordering_geometry(
    frame: pd.DataFrame, per_model: Sequence[Mapping[str, Mapping[str, float]]] = ()
) -> list[str]:
    """Plain-language comparison with the paper's Table 5 ordering (None worst, Both best).  With both
    rows present, each metric also compares Both with None; with two or more ``per_model`` results
    (``variant key`` → metric → value, one mapping per training seed) that line gives every model's own
    paired gain and in how many models Both is better."""
    notes = []
    by = frame.set_index("variant")
    for metric in METRICS:
        values, spec = by[metric], get_metric(metric)
        better = values.idxmax() if spec.higher_is_better else values.idxmin()
        worse = values.idxmin() if spec.higher_is_better else values.idxmax()
        notes.append(
            f"{spec.label}: best {by.loc[better, 'grounding']}, worst {by.loc[worse, 'grounding']} "
            f"(paper: best Both, worst None)"
        )
    if not {"both", "none"} <= set(by.index):
        return notes
    for metric in METRICS:
        spec = get_metric(metric)
        sign = 1.0 if spec.higher_is_better else -1.0
        both, none = float(by.loc["both", metric]), float(by.loc["none", metric])
        per_seed = _paired_gains(per_model, "both", "none", metric, sign)
        notes.append(
            f"{spec.label}: Both vs None {'better' if sign * (both - none) > 0 else 'not better'} "
            f"({both:.4f} vs {none:.4f}{per_seed}; paper: better)"
        )
    return notes


def ordering_setsize(
    results: Mapping[tuple[int, int], Mapping[str, float]],
    per_model: Sequence[Mapping[tuple[int, int], Mapping[str, float]]] = (),
) -> list[str]:
    """Whether more references / more targets help, as in the paper's Table 6.  ``results`` holds the means;
    with two or more ``per_model`` results each comparison also gives every model's own (paired) gain and
    in how many models the larger set is better."""
    comparisons = (  # (larger set, smaller set, what the paper found)
        ((3, 1), (1, 1), "better"),
        ((3, 6), (3, 1), "better for PSNR/SSIM, LPIPS within 0.001"),
    )
    notes = []
    for metric in METRICS:
        label = get_metric(metric).label
        sign = 1.0 if get_metric(metric).higher_is_better else -1.0
        for new_size, old_size, paper in comparisons:
            new, old = results.get(new_size), results.get(old_size)
            if new and old:
                gain = sign * (new[metric] - old[metric])
                per_seed = _paired_gains(per_model, new_size, old_size, metric, sign)
                notes.append(
                    f"{label}: {new_size[0]}+{new_size[1]} vs {old_size[0]}+{old_size[1]} "
                    f"{'better' if gain > 0 else 'not better'} "
                    f"({new[metric]:.4f} vs {old[metric]:.4f}{per_seed}; paper: {paper})"
                )
    return notes


def _paired_gains(
    per_model: Sequence[Mapping[Key, Mapping[str, float]]], new: Key, old: Key, metric: str, sign: float
) -> str:
    """``"; gain per model +0.1000, -0.0200, better in 1 of 2"``: each model's own ``new`` − ``old`` gain
    (``sign`` −1 for lower-is-better metrics) and in how many models ``new`` is better; empty for one model."""
    paired = [
        sign * (model[new][metric] - model[old][metric])
        for model in per_model
        if new in model and old in model
    ]
    if len(paired) < 2:
        return ""
    return (
        f"; gain per model {', '.join(f'{g:+.4f}' for g in paired)}, "
        f"better in {sum(g > 0 for g in paired)} of {len(paired)}"
    )


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
