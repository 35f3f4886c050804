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
"""

from __future__ import annotations

import statistics
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
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.leaderboard import (
    Leaderboard,
    load_reported,
    pooled_row,
    pooled_table,
    render_latex,
    render_markdown,
)
from setdiff_bench.reporting.paired import (
    TARGET_COLUMNS,
    PairedDifference,
    few_scenes_note,
    pair_targets,
    paired_differences,
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


class RunMeans(dict[str, float]):
    """One run's pooled means (metric → mean, plus ``targets``) that also carries the per-target rows they
    average (:attr:`rows`: :data:`~setdiff_bench.reporting.paired.TARGET_COLUMNS` and the metrics), so that
    two rows of an ablation can be compared target by target."""

    def __init__(self, means: Mapping[str, float], rows: pd.DataFrame | None = None) -> None:
        super().__init__(means)
        self.rows = rows


def pooled_means(metrics_file: Path, split: str = "test") -> RunMeans:
    """Mean of each metric over the targets of ``split`` in one run's ``metrics.parquet`` (with the rows)."""
    if not metrics_file.is_file():
        raise SetDiffBenchError("run has no metrics.parquet (did the run finish?)", metrics_file.parent)
    frame = pd.read_parquet(metrics_file)
    frame = frame[frame["split"] == split]
    if not len(frame):
        raise SetDiffBenchError(f"no {split} targets in the run", metrics_file)
    means = {m: float(frame[m].mean()) for m in METRICS} | {"targets": float(len(frame))}
    return RunMeans(means, frame[[*TARGET_COLUMNS, *METRICS]].reset_index(drop=True))


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
    """One line per metric: the seed spread of each row's value, max − min and (``sd``) the standard
    deviation over models (n − 1); none for one model."""
    if len(per_model) < 2:
        return []
    notes = [f"Each cell is the mean over {len(per_model)} trained models ({', '.join(models)})."]
    for metric in METRICS:
        spec = get_metric(metric)
        cells = []
        for key, text in label.items():
            values = [model[key][metric] for model in per_model if key in model]
            sd = statistics.stdev(values) if len(values) > 1 else 0.0
            digits = spec.decimals + 1
            cells.append(f"{text} {max(values) - min(values):.{digits}f} (sd {sd:.{digits}f})")
        notes.append(f"{spec.label} spread (max − min over models): {', '.join(cells)}.")
    return notes


def seed_spread(per_model: Sequence[Mapping[Key, Mapping[str, float]]], key: Key, metric: str) -> float:
    """Max − min over models of row ``key``'s value (0 with one model)."""
    values = [model[key][metric] for model in per_model if key in model]
    return max(values) - min(values) if values else 0.0


def paired_over_targets(
    per_model: Sequence[Mapping[Key, Mapping[str, float]]],
    new: Key,
    old: Key,
    settings: BootstrapSettings | None = None,
) -> dict[str, PairedDifference] | None:
    """``new`` against ``old`` target by target: each target's difference averaged over the models, its mean
    and bootstrap interval (resampled by scene) and the scenes won, per metric.

    Only targets that every model scored in both rows count.  ``None`` when a model's rows do not carry their
    per-target values (:class:`RunMeans`), or no target is shared.
    """
    paired = []
    for model in per_model:
        if new not in model or old not in model:
            continue
        rows_new, rows_old = getattr(model[new], "rows", None), getattr(model[old], "rows", None)
        if rows_new is None or rows_old is None:
            return None
        paired.append(pair_targets(rows_new, rows_old, METRICS))
    if not paired:
        return None
    grouped = pd.concat(paired, ignore_index=True).groupby(list(TARGET_COLUMNS), sort=True)
    every_model = grouped.size() == len(paired)
    pairs = grouped.mean(numeric_only=True)[every_model].reset_index()
    if not len(pairs):
        return None
    return paired_differences(pairs, METRICS, settings)


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
    frame: pd.DataFrame,
    per_model: Sequence[Mapping[str, Mapping[str, float]]] = (),
    settings: BootstrapSettings | None = None,
) -> list[str]:
    """Plain-language comparison with the paper's Table 5 ordering (None worst, Both best).  With both
    rows present, each metric also compares Both with None; with two or more ``per_model`` results
    (``variant key`` → metric → value, one mapping per training seed) that line gives every model's own
    paired gain, in how many models Both is better and whether the mean gain is beyond the seed spreads;
    when the results carry their per-target rows (:class:`RunMeans`) it also gives the paired interval over
    targets (:func:`paired_over_targets`, drawn as ``settings`` says)."""
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
    over_targets = paired_over_targets(per_model, "both", "none", settings)
    for metric in METRICS:
        spec = get_metric(metric)
        sign = 1.0 if spec.higher_is_better else -1.0
        both, none = float(by.loc["both", metric]), float(by.loc["none", metric])
        per_seed = _paired_gains(per_model, "both", "none", metric, sign)
        per_seed += _target_gain(over_targets, metric)
        notes.append(
            f"{spec.label}: Both vs None {'better' if sign * (both - none) > 0 else 'not better'} "
            f"({both:.4f} vs {none:.4f}{per_seed}; paper: better)"
        )
    return notes + _interval_notes([over_targets], len(per_model), settings)


def ordering_setsize(
    results: Mapping[tuple[int, int], Mapping[str, float]],
    per_model: Sequence[Mapping[tuple[int, int], Mapping[str, float]]] = (),
    settings: BootstrapSettings | None = None,
) -> list[str]:
    """Whether more references / more targets help, as in the paper's Table 6.  ``results`` holds the means;
    with two or more ``per_model`` results each comparison also gives every model's own (paired) gain, in
    how many models the larger set is better and whether the mean gain is beyond the seed spreads; results
    that carry their per-target rows (:class:`RunMeans`) add the paired interval over targets."""
    comparisons = (  # (larger set, smaller set, what the paper found)
        ((3, 1), (1, 1), "better"),
        ((3, 6), (3, 1), "better for PSNR/SSIM, LPIPS within 0.001"),
    )
    over_targets = {
        (new, old): paired_over_targets(per_model, new, old, settings)
        for new, old, _ in comparisons
        if new in results and old in results
    }
    notes = []
    for metric in METRICS:
        label = get_metric(metric).label
        sign = 1.0 if get_metric(metric).higher_is_better else -1.0
        for new_size, old_size, paper in comparisons:
            new, old = results.get(new_size), results.get(old_size)
            if new and old:
                gain = sign * (new[metric] - old[metric])
                per_seed = _paired_gains(per_model, new_size, old_size, metric, sign)
                per_seed += _target_gain(over_targets[(new_size, old_size)], metric)
                notes.append(
                    f"{label}: {new_size[0]}+{new_size[1]} vs {old_size[0]}+{old_size[1]} "
                    f"{'better' if gain > 0 else 'not better'} "
                    f"({new[metric]:.4f} vs {old[metric]:.4f}{per_seed}; paper: {paper})"
                )
    return notes + _interval_notes(list(over_targets.values()), len(per_model), settings)


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
    mean_gain = sum(paired) / len(paired)
    spreads = [seed_spread(per_model, new, metric), seed_spread(per_model, old, metric)]
    beyond = (
        f"mean gain beyond both seed spreads ({spreads[0]:.4f}, {spreads[1]:.4f})"
        if abs(mean_gain) > max(spreads)
        else f"mean gain within the seed spread ({max(spreads):.4f})"
    )
    return (
        f"; gain per model {', '.join(f'{g:+.4f}' for g in paired)}, "
        f"better in {sum(g > 0 for g in paired)} of {len(paired)}, {beyond}"
    )


def _target_gain(over_targets: Mapping[str, PairedDifference] | None, metric: str) -> str:
    """``"; over 252 targets +0.3450 [+0.2900, +0.4000] (holds), better in 3 of 3 scenes"``: the paired gain
    over targets (positive = better, whatever the metric's direction) and its interval; empty without one."""
    if over_targets is None:
        return ""
    d = over_targets[metric]
    sign = 1.0 if get_metric(metric).higher_is_better else -1.0
    low, high = sorted((sign * d.low, sign * d.high))
    interval = f"[{low:+.4f}, {high:+.4f}]" if d.has_interval else "[n/a]"
    return (
        f"; paired gain over {d.targets} targets {sign * d.difference:+.4f} {interval} "
        f"({'holds' if d.holds else 'interval includes 0'}), better in {d.wins} of {d.scenes} scenes"
    )


def _interval_notes(
    found: Sequence[Mapping[str, PairedDifference] | None], models: int, settings: BootstrapSettings | None
) -> list[str]:
    """How the paired gains over targets were computed, and the few-scenes caveat; none without any."""
    present = [d for d in found if d is not None]
    if not present:
        return []
    averaged = f"each target's gain averaged over the {models} models, " if models > 1 else ""
    notes = [f"Paired gains over targets: {averaged}{(settings or BootstrapSettings()).describe()}."]
    caveat = few_scenes_note(min(d.scenes for found_ in present for d in found_.values()))
    return notes + ([caveat] if caveat else [])


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
