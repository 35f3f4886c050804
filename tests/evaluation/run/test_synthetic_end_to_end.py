"""The whole chain on the embedded synthetic benchmark: generate (tiny) → prepare with a 3DGS fit → run
identity, reproject and precomputed (on a copy of identity's images) → leaderboard.

Slow (minutes: the 3DGS fit dominates); the analytic-store tests in this folder cover the same run and
leaderboard code in the default suite.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.evaluation.run import RunSettings, comparable_metrics, run_method
from setdiff_bench.io.run_layout import IMAGES_DIR, METRICS_FILE
from setdiff_bench.reporting.leaderboard import build_leaderboard, load_runs, write_leaderboard
from setdiff_bench.runtime.threads import torch_threads


@pytest.mark.slow
def test_synthetic_packets_end_to_end(tmp_path: Path) -> None:
    from setdiff_bench.packets.prepare import prepare
    from setdiff_bench.synthetic.generate import generate_scene
    from setdiff_bench.synthetic.presets import get_preset

    with torch_threads(1):
        generate_scene(tmp_path / "data", get_preset("tiny"), seed=0, index=0)
        prepare(
            "synthetic", tmp_path / "data", tmp_path / "packets", fit=True, fit_iterations=60, progress=False
        )
        runs = tmp_path / "runs"
        for method in ("identity", "reproject"):
            run_method(tmp_path / "packets", runs / method, RunSettings(method, split=None), progress=False)
        external = tmp_path / "external"
        shutil.copytree(runs / "identity" / IMAGES_DIR, external)
        run_method(
            tmp_path / "packets",
            runs / "precomputed",
            RunSettings("precomputed", {"source": str(external)}, split=None),
            progress=False,
        )
    identity = comparable_metrics(runs / "identity" / METRICS_FILE)
    copied = comparable_metrics(runs / "precomputed" / METRICS_FILE).assign(method="identity")
    pd.testing.assert_frame_equal(identity, copied)
    images, sequences = load_runs(runs)
    board = build_leaderboard("synthetic", images, sequences, split=None)
    paths = write_leaderboard(board, tmp_path / "leaderboards")
    assert sorted(p.name for p in paths.values()) == ["synthetic.md", "synthetic.parquet", "synthetic.tex"]
    assert {row.label for row in board.rows} == {"identity", "precomputed", "reproject"}
    assert {block.key for block, _ in board.columns} >= {"lane+1", "lane+2"}
