"""The report site's targets: one :class:`TargetRecord` per target (packet id and view) with every method's
metric values, and a method's gain over the baseline on a target (positive helps, negative damages,
whatever the metric's direction)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from setdiff_bench.loaders.common import natural_key
from setdiff_bench.metrics.registry import METRICS
from setdiff_bench.reporting.gains import gain
from setdiff_bench.reporting.site._video import slug
from setdiff_bench.reporting.targets import TargetKey

#: The columns naming one target in the runs' per-image rows.
TARGET_KEY = ["packet_id", "view"]


def image_metrics(frame: pd.DataFrame) -> list[str]:
    """The per-image metric columns of ``frame``, in the registry's order."""
    return [
        name
        for name, spec in METRICS.items()
        if spec.scope in ("image", "profile") and name in frame.columns and frame[name].notna().any()
    ]


@dataclass(frozen=True)
class TargetRecord:
    """One target's identity and every method's metric values."""

    key: TargetKey
    dataset: str
    scene: str
    group: str
    frame: str
    slug: str
    values: dict[str, dict[str, float]]  # method label → metric → value


def target_records(
    frame: pd.DataFrame, labels: Mapping[str, Path], metrics: Sequence[str]
) -> list[TargetRecord]:
    """The targets of ``frame`` (per-image rows of the runs, one split and profile), in natural order."""
    by_run = {str(folder): label for label, folder in labels.items()}
    records = []
    ordered = frame.sort_values(["dataset", "scene", "group", "packet_id", "view"], kind="stable")
    for (packet_id, view), rows in ordered.groupby(TARGET_KEY, sort=False):
        first = rows.iloc[0]
        values = {
            by_run[str(row["run"])]: {m: float(row[m]) for m in metrics if pd.notna(row[m])}
            for _, row in rows.iterrows()
            if str(row["run"]) in by_run
        }
        name = f"{packet_id}__{int(view)}"  # packet ids are unique in a store (they name the protocol)
        records.append(
            TargetRecord(
                TargetKey(str(packet_id), int(view)),
                str(first["dataset"]),
                str(first["scene"]),
                str(first["group"]),
                str(first["frame"]),
                slug(name),
                values,
            )
        )
    return sorted(
        records, key=lambda r: (r.dataset, natural_key(r.scene), natural_key(r.group), natural_key(r.frame))
    )


def target_gain(record: TargetRecord, method: str, metric: str, baseline: str) -> float:
    """``method``'s gain over ``baseline`` on ``metric`` for this target (NaN when either is missing)."""
    mine = record.values.get(method, {}).get(metric)
    base = record.values.get(baseline, {}).get(metric)
    if mine is None or base is None:
        return float("nan")
    return gain(metric, mine, base)
