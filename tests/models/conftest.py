"""Shared setup of the SetDiff tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from setdiff_bench.threads import torch_threads


@pytest.fixture(autouse=True)
def _one_intra_op_thread() -> Iterator[None]:
    """Run the tiny networks single-threaded: their ops are too small to gain from threads, and on a
    shared 2-core machine oversubscribed threads made them up to 25× slower (measured).  Restored after."""
    with torch_threads(1):
        yield
