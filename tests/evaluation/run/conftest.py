"""Stores and finished runs shared by the run tests (built once per module: each build costs ~1 s)."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store


@pytest.fixture(scope="package")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two groups × two scenes × one packet of three targets (one partly masked), split test."""
    with torch_threads(1):
        return build_store(tmp_path_factory.mktemp("store"), StoreSpec(scenes=("scene_a", "scene_b")))


@pytest.fixture(scope="package")
def identity_run(store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "identity"
    with torch_threads(1):
        run_method(store, out, RunSettings("identity"), progress=False)
    return out
