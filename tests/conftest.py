"""Shared pytest configuration: deterministic torch, one intra-op thread per test, GPU marker handling."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
import torch

from setdiff_bench.runtime.threads import torch_threads

# Verbs called by the tests (in-process or as subprocesses) run single-threaded unless told otherwise:
# the test data is tiny, and oversubscribed threads on a shared machine only slow it down.  Results do not
# depend on this choice being the same as a user's: each run records its own count.
os.environ.setdefault("SETDIFF_THREADS", "1")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if torch.cuda.is_available():
        return
    skip = pytest.mark.skip(reason="needs CUDA (no GPU on this machine)")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(autouse=True)
def _seed() -> None:
    torch.manual_seed(0)


@pytest.fixture(autouse=True)
def _single_torch_thread() -> Iterator[None]:
    """Every test runs with one torch intra-op thread (restored after): the tensors are tiny, and on a shared
    2-core machine oversubscribed threads made the tiny networks and the tile rasteriser up to 25x slower
    (measured).  Session fixtures that compute pin their own count with :func:`torch_threads`."""
    with torch_threads(1):
        yield
