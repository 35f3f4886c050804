"""A tiny store with timestamped camera sequences in two scenes, an identity run and a reproject run, and
the report site built from them (once per package: ~5 s)."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store

#: two scenes, two groups of one packet with four targets each: four camera sequences of four frames (two
#: scenes, so the per-scene breakdown has an interval over scenes)
SPEC = StoreSpec(scenes=("scene_a", "scene_b"), targets=4, timestamps=True)


@pytest.fixture(scope="package")
def store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with torch_threads(1):
        return build_store(tmp_path_factory.mktemp("store"), SPEC)


@pytest.fixture(scope="package")
def runs(store: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A folder holding ``identity/`` and ``reproject/`` runs on :func:`store`."""
    folder = tmp_path_factory.mktemp("runs")
    with torch_threads(1):
        for method in ("identity", "reproject"):
            run_method(store, folder / method, RunSettings(method), progress=False)
    return folder


@pytest.fixture(scope="package")
def site(store: Path, runs: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The report site of :func:`runs`, built through the CLI."""
    from setdiff_bench.cli.main import main

    out = tmp_path_factory.mktemp("report") / "site"
    assert main(["report", "--runs", str(runs), "--packets", str(store), "--out", str(out)]) == 0
    return out
