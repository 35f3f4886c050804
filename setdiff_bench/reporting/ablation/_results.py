"""An ablation's numbers: each run's pooled means and, over trained models (training seeds), their mean,
seed spread and paired comparison over the test targets.

``per_model[i][row]`` → metric → value (plus ``targets``), one mapping per model; a row key is a geometry
variant's key or a set size ``(N, M)``.
"""

from __future__ import annotations

import statistics
from collections.abc import Hashable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Generic, TypeVar

import pandas as pd

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.io.run_layout import TARGET_COLUMNS
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.ablation._design import METRICS
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.paired import PairedDifference, pair_targets, paired_differences

Key = TypeVar("Key", bound=Hashable)


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
