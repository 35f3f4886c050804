"""The one sign convention of comparisons (issue 57): a gain is positive when the first method is better, for
metrics where higher is better (PSNR) and where lower is (LPIPS) alike."""

from __future__ import annotations

import math

import pytest

from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.gains import PairedGain, gain
from setdiff_bench.reporting.paired import PairedDifference


def difference(metric: str, value: float, low: float, high: float) -> PairedDifference:
    """A paired difference ``a − b`` as :func:`paired_differences` would hold it (3 of 3 scenes won)."""
    return PairedDifference(metric, 0.0, 0.0, value, low, high, 12, 3, 3, 0, 0, BootstrapSettings())


def test_a_lower_is_better_difference_becomes_a_positive_gain() -> None:
    # LPIPS a − b = −0.05 [−0.07, −0.03]: a is better by 0.05, the interval's ends swap
    paired = PairedGain.of(difference("lpips", -0.05, -0.07, -0.03))
    assert (paired.value, paired.low, paired.high) == pytest.approx((0.05, 0.03, 0.07))
    assert paired.holds and paired.format() == "+0.0500 [+0.0300, +0.0700]"
    # PSNR keeps its sign: a − b is already the gain
    psnr = PairedGain.of(difference("psnr", 1.81, 1.2, 2.41))
    assert (psnr.value, psnr.low, psnr.high) == (1.81, 1.2, 2.41) and psnr.format(2) == "+1.81 [+1.20, +2.41]"


def test_zero_and_missing_intervals_print_plainly() -> None:
    assert PairedGain.of(difference("lpips", 0.0, 0.0, 0.0)).format() == "+0.0000 [+0.0000, +0.0000]"
    nan = float("nan")
    no_interval = PairedGain.of(difference("lpips", 0.01, nan, nan))
    assert no_interval.format() == "-0.0100 [n/a]" and math.isnan(no_interval.low) and not no_interval.holds


def test_gain_of_single_values() -> None:
    assert gain("psnr", 25.0, 24.0) == 1.0 and gain("lpips", 0.1, 0.15) == pytest.approx(0.05)
    assert str(gain("lpips", 0.2, 0.2)) == "0.0"  # not -0.0
