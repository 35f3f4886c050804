"""What a run did: :class:`RunResult`, and the paired metrics it skipped for targets without ground truth."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.run._settings import RunSettings
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.metrics.registry import MetricSpec
from setdiff_bench.packets.store import PacketStore, target_has_ground_truth


@dataclass(frozen=True)
class SkippedMetrics:
    """Metrics a run could not compute for some targets because they have no ground truth.

    Attributes:
        metrics: metric names skipped: the run's image metrics.  Never ``warp``: with warp error on, the
            targets without ground truth get it from their renders' flow
            (:mod:`setdiff_bench.evaluation.run._sequences`, ``flow_source = "render"``).
        targets: how many selected targets have no ground truth.
        groups: the groups those targets are in, sorted.
    """

    metrics: tuple[str, ...]
    targets: int
    groups: tuple[str, ...]

    def line(self, distribution: bool = False) -> str:
        """The one line ``run`` prints; ``distribution``: FID / KID are being computed (``--inception``)."""
        how = "FID / KID below" if distribution else "FID / KID (--inception FILE)"
        return (
            f"skipped {', '.join(self.metrics)} for {self.targets} target(s) without ground truth "
            f"(groups {', '.join(self.groups)}): novel-trajectory views are scored by {how}"
        )

    def record(self) -> dict[str, Any]:
        """The manifest's ``skipped`` entry."""
        return {
            "metrics": list(self.metrics),
            "targets": self.targets,
            "groups": list(self.groups),
            "reason": "no ground truth (novel-trajectory targets); their metric columns are null",
        }


def skipped_metrics(
    store: PacketStore, selection: Sequence[str], settings: RunSettings, specs: Sequence[MetricSpec]
) -> SkippedMetrics | None:
    """What a run over ``selection`` skips for lack of ground truth (``None`` when every target has it).

    ``settings`` does not change the answer any more (warp error is never skipped for lack of ground
    truth); it stays in the signature for the callers.
    """
    rows = pd.DataFrame(target_rows(store, selection))
    if rows.empty:
        return None
    without = rows[~target_has_ground_truth(rows)]
    if without.empty:
        return None
    metrics = tuple(spec.name for spec in specs)  # warp error is computed for them, from the renders' flow
    return SkippedMetrics(metrics, len(without), tuple(sorted(without["group"].unique())))


@dataclass
class RunResult:
    """What one call of :func:`run_method` did.

    Attributes:
        out: the run folder.
        enhanced: packets enhanced by this call.
        skipped: packets of this shard already done.
        remaining: packets of the whole selection still without a fragment (other shards).
        merged: whether ``metrics.parquet`` is complete (written now or already up to date).
        skipped_metrics: the paired metrics not computed for the selection's targets without ground
            truth (``None``: every target has it).
    """

    out: Path
    enhanced: int
    skipped: int
    remaining: int
    merged: bool
    skipped_metrics: SkippedMetrics | None = None

    @property
    def metrics(self) -> pd.DataFrame:
        """The merged per-target table (raises if the run is not merged yet)."""
        if not self.merged:
            raise UsageError(f"run not complete: {self.remaining} packets remain", self.out)
        return pd.read_parquet(self.out / METRICS_FILE)


def target_rows(store: PacketStore, selection: Sequence[str]) -> list[dict[str, Any]]:
    index = store.index
    rows = index[(index["role"] == "target") & index["packet_id"].isin(list(selection))]
    return rows.sort_values(["packet_id", "view"]).to_dict("records")
