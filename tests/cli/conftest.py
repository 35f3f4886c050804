"""Fixtures of the issue-45 CLI tests."""

from __future__ import annotations

import sys
import types
from pathlib import Path

import pytest

from tests.models.setdiff_fixtures import FakeStore


class IndexedFakeStore(FakeStore):
    """:class:`~tests.models.test_cli_train.FakeStore` whose index also has the columns the training
    manifest reads besides hashes and scenes (dataset, image size), as ``prepare`` writes them."""

    def __init__(self, root: Path) -> None:
        super().__init__(root)
        rows = len(self.index)
        self.index = self.index.assign(dataset=["synthetic"] * rows, height=[16] * rows, width=[16] * rows)


@pytest.fixture
def train_store(monkeypatch: pytest.MonkeyPatch) -> type[IndexedFakeStore]:
    """``setdiff_bench.packets.store.PacketStore`` replaced by :class:`IndexedFakeStore` for ``train``."""
    module = types.ModuleType("setdiff_bench.packets.store")
    module.PacketStore = IndexedFakeStore  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "setdiff_bench.packets.store", module)
    IndexedFakeStore.calls = []
    return IndexedFakeStore
