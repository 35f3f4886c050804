"""Fixtures of the refit tests: one street scene of the synthetic layout with its fit (seconds to write)."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import write_scene


@pytest.fixture(scope="package")
def street_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A dataset root holding ``street_00`` with its fit at ``street_00/fits/lane0.ply``."""
    with torch_threads(1):
        root = tmp_path_factory.mktemp("street")
        write_scene(root / "street_00", 11)
        return root
