"""Session inputs of the reliability tests, and one torch thread (tiny images on a shared 2-core machine)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from tests.reliability.world import World
from tests.run.store_fixtures import one_thread


@pytest.fixture(autouse=True)
def _one_thread() -> Iterator[None]:
    with one_thread():
        yield


@pytest.fixture(scope="session")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    """Pristine inputs, each built on first use (see :mod:`tests.reliability.world`)."""
    return World(tmp_path_factory.mktemp("world"))
