"""Session fixtures of the packet tests: a three-scene street dataset and one prepared store."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.packets.prepare import PrepareSummary, prepare
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import StreetScene, write_dataset


@pytest.fixture(scope="session")
def street(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, StreetScene]]:
    """``(root, scenes)``: street_00, street_01 (train) and street_02 (test under the 60/40 rule)."""
    with torch_threads(1):
        root = tmp_path_factory.mktemp("street")
        return root, write_dataset(root)


@pytest.fixture(scope="session")
def prepared(street, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, PrepareSummary, PacketStore]:
    """The whole dataset prepared in-process with the fits found under ``<scene>/fits/``."""
    root, _ = street
    out = tmp_path_factory.mktemp("store")
    with torch_threads(1):
        summary = prepare("synthetic", root, out, fits=root, progress=False)
    return out, summary, PacketStore(out)
