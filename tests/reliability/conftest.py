"""Session inputs of the reliability tests, and one torch thread (tiny images on a shared 2-core machine)."""

from __future__ import annotations

import pytest

from tests.reliability.world import World


@pytest.fixture(scope="session")
def world(tmp_path_factory: pytest.TempPathFactory) -> World:
    """Pristine inputs, each built on first use (see :mod:`tests.reliability.world`)."""
    return World(tmp_path_factory.mktemp("world"))
