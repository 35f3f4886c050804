"""``timestamp_or_none``: the one reader of ``timestamp_us`` cells (packet views and run metrics)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from setdiff_bench.packets.store import timestamp_or_none


def test_missing_is_none_else_int() -> None:
    assert timestamp_or_none(None) is None
    assert timestamp_or_none(math.nan) is None
    assert timestamp_or_none(pd.NA) is None
    assert timestamp_or_none(np.int64(1_532_402_927_647_951)) == 1_532_402_927_647_951
    assert timestamp_or_none(12.0) == 12 and isinstance(timestamp_or_none(12.0), int)


def test_run_uses_the_same_function() -> None:
    from setdiff_bench.evaluation.run import _packet  # where a run writes a target's timestamp_us

    assert _packet.timestamp_or_none is timestamp_or_none
    assert not hasattr(_packet, "_timestamp")
