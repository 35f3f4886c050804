"""Paired differences between two methods on the same targets: mean difference, bootstrap interval, scene wins.

A paired comparison looks only at targets both methods were scored on, and at the per-target difference
``a - b`` of each metric.  Its interval is a **percentile bootstrap resampled by scene** (a cluster
bootstrap): each resample draws as many scenes as there are, with replacement, and takes every target of
each drawn scene, so frames of one scene — which share a fit, a street and a light — are never counted as
independent evidence.  The statistic of a resample is the same mean the tables print: the mean of per-target
differences (targets of a scene drawn twice count twice), or, for a ``scene_mean`` profile, the mean over the
drawn scenes of each scene's mean difference.  With ``unit="frame"`` every target is its own cluster (the
plain bootstrap of ``scipy.stats.bootstrap(..., method="percentile")``, which draws the same indices from
the same seed).  Resamples are drawn once per call from ``numpy.random.default_rng(seed)`` and shared by
every metric, so intervals of one table are computed on the same resamples; the number of resamples, the
level and the seed are recorded with every interval (:class:`BootstrapSettings`).

An interval needs at least two clusters: with one scene there is nothing to resample between scenes, and
the interval is ``nan`` (shown as "n/a"), never a width-zero interval that would look certain.

Wins count scenes, not frames: a scene is won by ``a`` when its mean difference favours ``a`` in the
metric's direction (:attr:`~setdiff_bench.metrics.registry.MetricSpec.higher_is_better`), lost when it
favours ``b``, tied when the means are equal.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.io.run_layout import TARGET_COLUMNS
from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.bootstrap import BootstrapSettings


class PairingError(SetDiffBenchError):
    """Two sets of results that cannot be paired (no shared targets, duplicate rows, missing metrics)."""


@dataclass(frozen=True)
class PairedDifference:
    """One metric's paired comparison of ``a`` against ``b``.

    Attributes:
        metric: metric name (a key of :data:`~setdiff_bench.metrics.registry.METRICS`).
        mean_a: ``a``'s mean over the paired targets (the tables' aggregation).
        mean_b: ``b``'s mean over the same targets.
        difference: ``mean_a - mean_b`` in the metric's units (positive: ``a`` higher).
        low: lower end of the interval of ``difference`` (``nan`` with fewer than two clusters).
        high: upper end of the interval.
        targets: paired targets.
        scenes: scenes among them.
        wins: scenes whose mean difference favours ``a`` in the metric's direction.
        losses: scenes that favour ``b``.
        ties: scenes with equal means.
        settings: how the interval was drawn.
    """

    metric: str
    mean_a: float
    mean_b: float
    difference: float
    low: float
    high: float
    targets: int
    scenes: int
    wins: int
    losses: int
    ties: int
    settings: BootstrapSettings

    @property
    def has_interval(self) -> bool:
        return not (math.isnan(self.low) or math.isnan(self.high))

    @property
    def holds(self) -> bool:
        """The interval excludes 0: the difference is beyond what resampling scenes (or targets) explains."""
        return self.has_interval and (self.low > 0.0 or self.high < 0.0)

    @property
    def a_better(self) -> bool:
        """``a`` is better on the mean, in the metric's direction."""
        sign = 1.0 if get_metric(self.metric).higher_is_better else -1.0
        return sign * self.difference > 0.0

    def verdict(self, a: str, b: str) -> str:
        """``"a better"`` / ``"b better"`` when the interval excludes 0, else ``"no difference shown"``."""
        if not self.holds:
            return "no difference shown"
        return f"{a} better" if self.a_better else f"{b} better"

    def format(self, decimals: int | None = None) -> str:
        """``"+1.81 [+1.20, +2.41]"`` (``"+1.81 [n/a]"`` without an interval)."""
        digits = get_metric(self.metric).decimals + 1 if decimals is None else decimals
        if not self.has_interval:
            return f"{self.difference:+.{digits}f} [n/a]"
        return f"{self.difference:+.{digits}f} [{self.low:+.{digits}f}, {self.high:+.{digits}f}]"


#: Below this many scenes a scene bootstrap says little about other scenes, and outputs say so.
FEW_SCENES = 10


def few_scenes_note(scenes: int) -> str | None:
    """A caveat for intervals resampled over fewer than :data:`FEW_SCENES` scenes, else ``None``."""
    if scenes >= FEW_SCENES:
        return None
    return (
        f"Only {scenes} scene(s): an interval resampled by scene is no wider than the spread of the scene "
        "means, so a difference that holds is one with the same sign in every mix of these scenes, "
        "not 95 % confidence about other scenes."
    )


def bootstrap_indices(clusters: int, settings: BootstrapSettings) -> np.ndarray:
    """``(resamples, clusters)`` cluster indices drawn with replacement from ``default_rng(settings.seed)``
    (the same call, hence the same draws, as ``scipy.stats.bootstrap`` with that generator)."""
    rng = np.random.default_rng(settings.seed)
    return rng.integers(0, clusters, size=(settings.resamples, clusters))


def cluster_interval(
    sums: np.ndarray,
    counts: np.ndarray,
    indices: np.ndarray,
    confidence: float,
    *,
    scene_mean: bool = False,
) -> tuple[float, float]:
    """Percentile interval of the resampled statistic, vectorised over resamples and metrics.

    Args:
        sums: ``(clusters, metrics)`` per-cluster sums of the differences.
        counts: ``(clusters,)`` targets per cluster.
        indices: ``(resamples, clusters)`` drawn clusters (:func:`bootstrap_indices`).
        confidence: two-sided level.
        scene_mean: the statistic is the mean of cluster means instead of the mean over targets.

    Returns:
        ``(low, high)`` arrays of shape ``(metrics,)``; ``nan`` with fewer than two clusters.
    """
    metrics = sums.shape[1]
    if sums.shape[0] < 2:
        return np.full(metrics, np.nan), np.full(metrics, np.nan)
    if scene_mean:
        statistic = (sums / counts[:, None])[indices].mean(axis=1)  # (resamples, metrics)
    else:
        statistic = sums[indices].sum(axis=1) / counts[indices].sum(axis=1)[:, None]
    alpha = (1.0 - confidence) / 2.0
    low, high = np.percentile(statistic, [100.0 * alpha, 100.0 * (1.0 - alpha)], axis=0)
    return low, high


def pair_targets(
    a: pd.DataFrame,
    b: pd.DataFrame,
    metrics: Sequence[str],
    keys: Sequence[str] = TARGET_COLUMNS,
    names: tuple[str, str] = ("a", "b"),
) -> pd.DataFrame:
    """The targets both ``a`` and ``b`` have: ``keys`` plus ``<metric>_a`` and ``<metric>_b`` columns.

    Raises:
        PairingError: a metric column is missing, or a frame has duplicate rows on ``keys`` (both name the
            side, as ``names`` calls it).
    """
    for name, frame in zip(names, (a, b)):
        missing = [c for c in (*keys, *metrics) if c not in frame.columns]
        if missing:
            raise PairingError(f"{name} has no column(s) {', '.join(missing)} (scored with other metrics?)")
        if frame.duplicated(list(keys)).any():
            raise PairingError(f"{name} has several rows for one target; pass one run per side")
    left = a[[*keys, *metrics]]
    right = b[[*keys, *metrics]]
    return left.merge(right, on=list(keys), suffixes=("_a", "_b"), how="inner", sort=True)


def paired_differences(
    pairs: pd.DataFrame,
    metrics: Sequence[str],
    settings: BootstrapSettings | None = None,
    *,
    scene_mean: bool = False,
) -> dict[str, PairedDifference]:
    """Metric → :class:`PairedDifference` of ``a`` against ``b`` over the rows of ``pairs``
    (:func:`pair_targets`: a ``scene`` column and ``<metric>_a`` / ``<metric>_b`` per metric), with intervals
    drawn as ``settings`` says (default :class:`BootstrapSettings`).

    Targets where either side is not finite for a metric are left out of that metric.

    Raises:
        PairingError: ``pairs`` is empty.
    """
    if not len(pairs):
        raise PairingError("no shared targets to compare")
    settings = settings or BootstrapSettings()
    scene_codes, _ = pd.factorize(pairs["scene"], sort=True)
    clusters = scene_codes if settings.unit == "scene" else np.arange(len(pairs))
    results: dict[str, PairedDifference] = {}
    for metric in metrics:
        values_a = pairs[f"{metric}_a"].to_numpy(dtype=np.float64)
        values_b = pairs[f"{metric}_b"].to_numpy(dtype=np.float64)
        keep = np.isfinite(values_a) & np.isfinite(values_b)
        results[metric] = _difference(
            metric,
            values_a[keep],
            values_b[keep],
            clusters[keep],
            scene_codes[keep],
            settings,
            scene_mean=scene_mean,
        )
    return results


def _difference(
    metric: str,
    values_a: np.ndarray,
    values_b: np.ndarray,
    clusters: np.ndarray,
    scenes: np.ndarray,
    settings: BootstrapSettings,
    *,
    scene_mean: bool,
) -> PairedDifference:
    differences = values_a - values_b
    _, cluster_codes = np.unique(clusters, return_inverse=True)
    scene_ids, scene_codes = np.unique(scenes, return_inverse=True)
    if scene_mean:
        scene_counts = np.bincount(scene_codes, minlength=len(scene_ids)).astype(np.float64)

        def mean(values: np.ndarray) -> float:
            return float((np.bincount(scene_codes, values, len(scene_ids)) / scene_counts).mean())
    else:

        def mean(values: np.ndarray) -> float:
            return float(values.mean())

    if not len(differences):
        nan = float("nan")
        return PairedDifference(metric, nan, nan, nan, nan, nan, 0, 0, 0, 0, 0, settings)
    count = int(cluster_codes.max()) + 1
    sums = np.bincount(cluster_codes, differences, count)[:, None]
    counts = np.bincount(cluster_codes, minlength=count).astype(np.float64)
    # the statistic's own scene weighting: per-scene means are averaged only when clusters are scenes
    by_cluster_mean = scene_mean and settings.unit == "scene"
    low, high = cluster_interval(
        sums, counts, bootstrap_indices(count, settings), settings.confidence, scene_mean=by_cluster_mean
    )
    wins, losses, ties = scene_wins(differences, scene_codes, metric)
    return PairedDifference(
        metric=metric,
        mean_a=mean(values_a),
        mean_b=mean(values_b),
        difference=mean(differences),
        low=float(low[0]),
        high=float(high[0]),
        targets=len(differences),
        scenes=len(scene_ids),
        wins=wins,
        losses=losses,
        ties=ties,
        settings=settings,
    )


def scene_wins(differences: np.ndarray, scene_codes: np.ndarray, metric: str) -> tuple[int, int, int]:
    """``(wins, losses, ties)`` of ``a`` over scenes: the sign of each scene's mean difference in the metric's
    direction (``scene_codes``: 0-based scene index per target)."""
    count = int(scene_codes.max()) + 1
    means = np.bincount(scene_codes, differences, count) / np.bincount(scene_codes, minlength=count)
    sign = 1.0 if get_metric(metric).higher_is_better else -1.0
    signed = sign * means
    return int((signed > 0).sum()), int((signed < 0).sum()), int((signed == 0).sum())


def difference_records(differences: dict[str, PairedDifference], **labels: object) -> list[dict[str, object]]:
    """One long-table record per metric: ``labels`` (e.g. ``group=``) then every field and the settings."""
    return [
        {
            **labels,
            "metric": d.metric,
            "mean_a": d.mean_a,
            "mean_b": d.mean_b,
            "difference": d.difference,
            "low": d.low,
            "high": d.high,
            "holds": d.holds,
            "targets": d.targets,
            "scenes": d.scenes,
            "wins": d.wins,
            "losses": d.losses,
            "ties": d.ties,
            "unit": d.settings.unit,
            "confidence": d.settings.confidence,
            "resamples": d.settings.resamples,
            "seed": d.settings.seed,
        }
        for d in differences.values()
    ]
