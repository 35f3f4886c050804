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
