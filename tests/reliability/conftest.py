"""Session inputs of the reliability tests, and one torch thread (tiny images on a shared 2-core machine)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from setdiff_bench.threads import torch_threads
from tests.reliability.world import World


@pytest.fixture(autouse=True)
def _single_torch_thread() -> Iterator[None]:
    with torch_threads(1):
        yield


@pytest.fixture(scope="session")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    """Pristine inputs, each built on first use (see :mod:`tests.reliability.world`)."""
    return World(tmp_path_factory.mktemp("world"))
