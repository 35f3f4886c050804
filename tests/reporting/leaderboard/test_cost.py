"""``leaderboard --cost``: each method's ms per frame (median over its targets) and peak memory (largest),
from the timing columns ``run`` records; lower is better; the default table has no cost block."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.reporting.leaderboard import (
    COST,
    build_leaderboard,
    render_latex,
    render_markdown,
    to_frame,
)
from tests.reporting.leaderboard.leaderboard_fixtures import table


def timed() -> pd.DataFrame:
    frame = table()
    alpha = frame["method"] == "alpha"
    # alpha: 10, 20, 30, 1000 ms (a slow first packet: the median ignores it); beta: 5 ms everywhere
    frame["ms_per_frame"] = 5.0
    frame.loc[alpha, "ms_per_frame"] = [1000.0, 10.0, 20.0, 30.0]
    frame["peak_memory_mb"] = 800.0
    frame.loc[alpha, "peak_memory_mb"] = [900.0, 2500.0, 950.0, 900.0]
    return frame


def test_cost_block_holds_median_time_and_peak_memory() -> None:
    board = build_leaderboard("synthetic", timed(), cost=True)
    values = to_frame(board).set_index(["method", "block", "metric"])["value"]
    assert values[("alpha", COST, "ms_per_frame")] == pytest.approx(25.0)  # median of 10, 20, 30, 1000
    assert values[("alpha", COST, "peak_memory_mb")] == pytest.approx(2500.0)
    assert values[("beta", COST, "ms_per_frame")] == pytest.approx(5.0)
    beta = [row.method for row in board.rows].index("beta")
    assert board.best[(COST, "ms_per_frame")] == {beta} and board.best[(COST, "peak_memory_mb")] == {beta}
    markdown = render_markdown(board)
    assert "Cost ms/frame↓" in markdown and "Cost peak MiB↓" in markdown
    assert "| alpha |" in markdown and "| 25 | 2500 |" in markdown
    assert "Cost: the enhancer's wall time per target frame" in markdown
    assert "Cost" in render_latex(board)


def test_default_table_has_no_cost_block_and_old_runs_show_a_dash() -> None:
    assert all(block.key != COST for block, _ in build_leaderboard("synthetic", timed()).columns)
    old = timed().drop(columns="peak_memory_mb")  # a run made before peak memory was recorded
    board = build_leaderboard("synthetic", old, cost=True)
    assert [metrics for block, metrics in board.columns if block.key == COST] == [("ms_per_frame",)]


def test_a_profile_not_scored_yet_says_to_run_evaluate(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """`leaderboard --profile euvs_official` on plain runs (issue 45): the line says to run `evaluate` first."""
    from setdiff_bench.cli.main import main
    from tests.evaluation.run.store_fixtures import build_store, run_argv

    store = build_store(tmp_path / "packets")
    assert main(run_argv("identity", store, tmp_path / "runs" / "identity")) == 0
    capsys.readouterr()
    argv = [
        "leaderboard",
        "--dataset",
        "synthetic",
        "--runs",
        str(tmp_path / "runs"),
        "--out",
        str(tmp_path / "t"),
    ]
    assert main([*argv, "--profile", "euvs_official"]) == 2
    assert capsys.readouterr().err.strip() == (
        "setdiff-bench leaderboard: error: no synthetic results scored under profile 'euvs_official': score the "
        "runs with `setdiff-bench evaluate RUN --profile euvs_official` first"
    )
    assert not (tmp_path / "t").exists()


def _refit_manifest(wall_s: float, peak_mb: float) -> dict[str, object]:
    """A refit manifest with the fields ``refit`` writes that ``run --refit`` reads (docs/refit.md)."""
    return {
        "format": "setdiff-refit/1",
        "time": {"wall_s": wall_s, "s_per_step": wall_s / 300, "steps_run": 300, "enhance_s": 10.0},
        "peak_memory_mb": peak_mb,
        "enhancer": {"method": "difix"},
        "schedule": {"schedule": "progressive", "steps": 300},
        "ply": {"sha256": "0" * 64},
    }


def test_refit_runs_show_each_scenes_refit_time(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """`run --refit DIR` records each scene's refit cost; `leaderboard --cost` shows its mean over scenes on the
    X 3D row, a dash on the others; the run's identity names the manifests it read."""
    import json

    from setdiff_bench.cli.main import main
    from tests.evaluation.run.store_fixtures import StoreSpec, build_store, leaderboard_argv, run_argv

    store = build_store(tmp_path / "packets", StoreSpec(scenes=("scene_a", "scene_b")))
    refits = tmp_path / "refit"
    for scene, wall_s in (("scene_a", 100.0), ("scene_b", 160.0)):
        (refits / scene).mkdir(parents=True)
        (refits / scene / "lane0.refit.json").write_text(json.dumps(_refit_manifest(wall_s, 900.0)))
    runs = tmp_path / "runs"
    assert main(run_argv("identity", store, runs / "identity")) == 0
    assert (
        main([*run_argv("identity", store, runs / "refit", "--name", "difix_3D"), "--refit", str(refits)])
        == 0
    )
    manifest = json.loads((runs / "refit" / "manifest.json").read_text())
    assert sorted(manifest["refit"]["fits"]) == ["scene_a/lane0", "scene_b/lane0"]
    assert manifest["refit"]["fits"]["scene_b/lane0"]["wall_s"] == 160.0
    assert sorted(json.loads((runs / "refit" / "run.json").read_text())["refit_manifests"]) == [
        "scene_a/lane0",
        "scene_b/lane0",
    ]
    assert "refit_manifests" not in json.loads((runs / "identity" / "run.json").read_text())
    capsys.readouterr()
    assert main(leaderboard_argv("synthetic", runs, tmp_path / "board", "--cost", "--format", "md")) == 0
    markdown = (tmp_path / "board" / "synthetic.md").read_text()
    assert "Cost refit s/scene↓" in markdown
    cells = {
        line.split("|")[1].strip(): [cell.strip(" *") for cell in line.split("|")[2:-1]]
        for line in markdown.splitlines()
        if line.startswith(("| difix_3D |", "| identity |"))
    }
    assert cells["difix_3D"][-1] == "130"  # (100 + 160) / 2, the last cost column
    assert cells["identity"][-1] not in {"", "130"} and not cells["identity"][-1][0].isdigit()  # no refit
    assert "refit s/scene: the wall time of the refit" in markdown


def test_a_refit_folder_without_a_scenes_manifest_is_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One line naming the missing manifest, exit 2, no run folder."""
    from setdiff_bench.cli.main import main
    from tests.evaluation.run.store_fixtures import build_store, run_argv

    store = build_store(tmp_path / "packets")
    (tmp_path / "refit").mkdir()
    assert main([*run_argv("identity", store, tmp_path / "run"), "--refit", str(tmp_path / "refit")]) == 2
    error = capsys.readouterr().err.strip()
    assert len(error.splitlines()) == 1
    assert "scene_a/lane0.refit.json" in error and "no refit manifest for scene 'scene_a'" in error
    assert not (tmp_path / "run").exists()
