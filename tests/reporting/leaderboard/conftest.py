"""One small real store and finished identity / reproject runs, shared by the leaderboard tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store


@pytest.fixture(scope="package")
def lb_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One scene, groups lane+1 / lane+2, two packets of two targets each per group."""
    with torch_threads(1):
        return build_store(tmp_path_factory.mktemp("lb_store"), StoreSpec(packets_per_group=2, targets=2))


@pytest.fixture(scope="package")
def lb_runs(lb_store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """``runs/identity`` and ``runs/reproject`` on :func:`lb_store`."""
    runs = tmp_path_factory.mktemp("lb_runs")
    with torch_threads(1):
        for method in ("identity", "reproject"):
            run_method(lb_store, runs / method, RunSettings(method), progress=False)
    return runs
