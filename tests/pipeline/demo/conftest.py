"""The tiny demo, run once per session with the shipped models (shared by the driving and sparse tests)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main


def run_tiny_demo(folder: Path, omp_threads: str, *extra: str) -> Path:
    """``setdiff-bench demo --preset tiny [extra]`` from ``folder`` into the default folder (``runs/demo``, relative,
    so that the recorded commands match between folders), under umask 022 and the given ``OMP_NUM_THREADS``
    (which must not matter)."""
    previous_cwd, previous_umask = Path.cwd(), os.umask(0o022)
    previous_omp = os.environ.get("OMP_NUM_THREADS")
    os.environ["OMP_NUM_THREADS"] = omp_threads
    try:
        os.chdir(folder)
        assert main(["demo", "--preset", "tiny", "--no-progress", *extra]) == 0
    finally:
        os.chdir(previous_cwd)
        os.umask(previous_umask)
        if previous_omp is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = previous_omp
    return folder / "runs" / "demo"


@pytest.fixture(scope="session")
def shipped_demo_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The default path: the preset's test scenes and the shipped models."""
    return run_tiny_demo(tmp_path_factory.mktemp("demo_shipped"), "1")
