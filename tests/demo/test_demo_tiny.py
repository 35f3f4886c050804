"""CI smoke test: ``setdiff-bench demo --preset tiny`` runs end to end and writes well-formed outputs."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.demo import METHODS
from setdiff_bench.io.images import read_image_raw


@pytest.fixture(scope="module")
def demo_out(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("demo") / "synthetic"
    assert main(["demo", "--preset", "tiny", "--out", str(out), "--no-progress"]) == 0
    return out


def test_demo_writes_leaderboard_with_every_method_and_group(demo_out: Path) -> None:
    board = pd.read_parquet(demo_out / "synthetic.parquet")
    assert {"dataset", "method", "block", "metric", "value", "count", "best", "source"} <= set(board.columns)
    assert set(board["method"]) == set(METHODS) and set(board["source"]) == {"measured"}
    assert {"lane+1", "lane+2", "side", "turn"} <= set(board["block"])
    assert set(board["metric"]) == {"psnr", "ssim", "lpips"}
    assert board["value"].notna().all() and (board["count"] > 0).all()
    # exactly the best value per block and metric is flagged (ties may share it)
    for (_, metric), cell in board.groupby(["block", "metric"]):
        best = cell["value"].max() if metric != "lpips" else cell["value"].min()
        flagged = cell[cell["best"]]["value"]
        assert len(flagged) >= 1 and (flagged.round(cell["decimals"].iloc[0]) == round(best, int(cell["decimals"].iloc[0]))).all()
    markdown = (demo_out / "synthetic.md").read_text()
    latex = (demo_out / "synthetic.tex").read_text()
    for method in METHODS:
        assert method in markdown and method in latex
    assert "\\toprule" in latex and "\\bottomrule" in latex


def test_demo_summary_records_commands_and_verdict(demo_out: Path) -> None:
    summary = json.loads((demo_out / "demo.json").read_text())
    names = [stage["name"] for stage in summary["stages"]]
    assert names[:2] == ["synth", "prepare"]
    assert {"train setdiff", "train difix", "leaderboard"} <= set(names)
    assert all(stage["command"].startswith("setdiff-bench ") for stage in summary["stages"])
    verdict = summary["lane_plus_2"]
    assert verdict["group"] == "lane+2" and verdict["targets"] > 0
    assert set(verdict["means"]) == set(METHODS)
    for method in METHODS:
        assert set(verdict["means"][method]) == {"psnr", "ssim", "lpips"}
    assert set(verdict["setdiff_beats_identity"]) == {"psnr", "ssim", "lpips"}
    readme = (demo_out / "README.md").read_text()
    assert summary["invocation"] in readme and "## Commands, in order" in readme


def test_demo_per_target_metrics_and_images(demo_out: Path) -> None:
    runs = demo_out / "work" / "runs"
    counts = set()
    for method in METHODS:
        frame = pd.read_parquet(runs / method / "metrics.parquet")
        assert {"dataset", "protocol", "group", "split", "scene", "frame", "method", "psnr", "ssim", "lpips"} <= set(
            frame.columns)
        assert (frame["split"] == "test").all() and (frame["method"] == method).all()
        assert frame[["psnr", "ssim", "lpips"]].notna().all().all()
        counts.add(len(frame))
    assert len(counts) == 1  # every method scored the same targets
    grid = read_image_raw(demo_out / "synthetic_grid.png", "uint8")
    assert grid.ndim == 3 and grid.shape[2] >= 3 and grid.shape[0] > 48
    assert (demo_out / "synthetic_lane_shift.png").is_file()
