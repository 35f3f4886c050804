"""The capture the training-pair recipe tests share: one street scene of the synthetic layout
(``tests.packets.packet_fixtures``), made once for the package."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import write_scene


@pytest.fixture(scope="package")
def capture(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The dataset root holding ``street_00`` (a single scene: its split is train)."""
    root = tmp_path_factory.mktemp("capture")
    with torch_threads(1):
        write_scene(root / "street_00", 11)
    return root
