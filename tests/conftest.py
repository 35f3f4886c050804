"""Shared pytest configuration: deterministic torch, few threads, GPU marker handling."""

from __future__ import annotations

import os

import pytest
import torch

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
