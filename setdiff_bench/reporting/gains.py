"""Gains: the one sign convention of every comparison of two methods that the tools print — positive is better.

A method's **gain** over another on a metric is ``method − other`` where higher is better (PSNR, SSIM) and
``other − method`` where lower is (LPIPS, warp error), in the metric's units; so a positive gain helps and a
negative one damages in every column, whatever the metric's direction.  ``compare``, ``leaderboard --against``
and the report all show gains; each output states the convention (:data:`GAIN_CONVENTION`).

A paired difference (:class:`~setdiff_bench.reporting.paired.PairedDifference`, ``a − b`` as computed) becomes a
:class:`PairedGain` with :meth:`PairedGain.of`: the mean and both ends of the interval take the metric's sign
(the interval's ends swap for a lower-is-better metric); whether the interval excludes 0, and the scenes won,
do not depend on the sign and are kept.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from setdiff_bench.metrics.registry import get_metric
from setdiff_bench.reporting.paired import PairedDifference

#: How every output that shows gains states them (one sentence, no method names).
GAIN_CONVENTION = (
    "gains: A − B where higher is better (PSNR, SSIM), B − A where lower is better (LPIPS, warp error), "
    "so a positive gain means A is better in every column"
)


def metric_sign(metric: str) -> float:
    """``+1.0`` for a metric where higher is better, ``-1.0`` where lower is (``MetricSpec.higher_is_better``)."""
    return 1.0 if get_metric(metric).higher_is_better else -1.0


def gain(metric: str, value: float, baseline: float) -> float:
    """``value``'s gain over ``baseline`` on ``metric`` (positive: ``value`` is better)."""
    return metric_sign(metric) * (value - baseline) + 0.0


@dataclass(frozen=True)
class PairedGain:
    """A paired difference of ``a`` against ``b`` read as ``a``'s gain (positive: ``a`` better).

    Attributes:
        metric: metric name.
        value: mean gain over the paired targets, in the metric's units.
        low: lower end of the gain's interval (``nan`` without one).
        high: upper end.
        holds: the interval excludes 0.
        difference: the paired difference it was made from (wins, counts, bootstrap settings).
    """

    metric: str
    value: float
    low: float
    high: float
    holds: bool
    difference: PairedDifference

    @classmethod
    def of(cls, difference: PairedDifference) -> PairedGain:
        sign = metric_sign(difference.metric)
        low, high = (difference.low, difference.high) if sign > 0 else (-difference.high, -difference.low)
        value = sign * difference.difference
        # + 0.0: a zero gain of a lower-is-better metric prints "+0.000", not "-0.000"
        return cls(difference.metric, value + 0.0, low + 0.0, high + 0.0, difference.holds, difference)

    def format(self, decimals: int | None = None) -> str:
        """``"+1.81 [+1.20, +2.41]"`` (``"+1.81 [n/a]"`` without an interval); default decimals: the metric's
        plus one."""
        digits = get_metric(self.metric).decimals + 1 if decimals is None else decimals
        if math.isnan(self.low) or math.isnan(self.high):
            return f"{self.value:+.{digits}f} [n/a]"
        return f"{self.value:+.{digits}f} [{self.low:+.{digits}f}, {self.high:+.{digits}f}]"
