"""Stores and finished runs shared by the run tests (built once per module: each build costs ~1 s)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from setdiff_bench.run import RunSettings, run_method
from tests.run.store_fixtures import StoreSpec, build_store, one_thread


@pytest.fixture(autouse=True)
def _one_thread() -> Iterator[None]:
    with one_thread():
        yield


@pytest.fixture(scope="package")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two groups × two scenes × one packet of three targets (one partly masked), split test."""
    with one_thread():
        return build_store(tmp_path_factory.mktemp("store"), StoreSpec(scenes=("scene_a", "scene_b")))


@pytest.fixture(scope="package")
def identity_run(store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "identity"
    with one_thread():
        run_method(store, out, RunSettings("identity"), progress=False)
    return out
