"""Issue 57: ``leaderboard --runs`` takes several folders, as ``report --runs`` does (``--runs A B`` and
``--runs A --runs B``), so a user's run need not sit in the baselines' folder; ``compare`` finds runs by name
under them.

Expected tables come from a leaderboard over one folder that holds every run (the single-folder path that the
rest of this folder's tests check against independent references).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

import setdiff_bench as sb
from setdiff_bench.cli.main import main
from setdiff_bench.reporting.leaderboard import find_runs, survey_runs
from tests.evaluation.run.store_fixtures import leaderboard_argv


@pytest.fixture
def split_runs(lb_runs: Path, tmp_path: Path) -> tuple[Path, Path]:
    """``baselines/identity`` and ``mine/reproject``: the two runs in two folders."""
    shutil.copytree(lb_runs / "identity", tmp_path / "baselines" / "identity")
    shutil.copytree(lb_runs / "reproject", tmp_path / "mine" / "reproject")
    return tmp_path / "baselines", tmp_path / "mine"


def table(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "synthetic.parquet")


@pytest.mark.parametrize("spelling", ["repeated", "one flag"])
def test_several_runs_folders_make_one_table(
    lb_runs: Path, split_runs: tuple[Path, Path], tmp_path: Path, spelling: str
) -> None:
    baselines, mine = split_runs
    assert main(leaderboard_argv("synthetic", lb_runs, tmp_path / "one", "--format", "parquet,md")) == 0
    runs = ["--runs", str(baselines), "--runs", str(mine)]
    if spelling == "one flag":
        runs = ["--runs", str(baselines), str(mine)]
    argv = [
        "leaderboard",
        "--dataset",
        "synthetic",
        *runs,
        "--out",
        str(tmp_path / "two"),
        "--format",
        "parquet,md",
    ]
    assert main(argv) == 0
    pd.testing.assert_frame_equal(table(tmp_path / "two"), table(tmp_path / "one"))
    assert sorted(set(table(tmp_path / "two")["label"])) == ["identity", "reproject"]
    # the recorded command names both folders, so it remakes the same table
    assert f"--runs {baselines} {mine} --format" in (tmp_path / "two" / "synthetic.md").read_text()


def test_a_run_reached_through_two_folders_counts_once(split_runs: tuple[Path, Path], tmp_path: Path) -> None:
    baselines, mine = split_runs
    both = [baselines.parent, mine, mine / "reproject"]
    assert find_runs(both) == [baselines / "identity", mine / "reproject"]
    assert survey_runs(both)[1] == []
    argv = ["leaderboard", "--dataset", "synthetic", "--runs", *map(str, both), "--out", str(tmp_path / "t")]
    assert main([*argv, "--format", "parquet"]) == 0  # no "duplicate rows" refusal
    assert sorted(set(table(tmp_path / "t")["label"])) == ["identity", "reproject"]


def test_a_missing_runs_folder_is_named(
    split_runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    baselines, _ = split_runs
    argv = ["leaderboard", "--dataset", "synthetic", "--runs", str(baselines), str(tmp_path / "nowhere")]
    assert main([*argv, "--out", str(tmp_path / "t")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"setdiff-bench leaderboard: error: {tmp_path / 'nowhere'}: runs folder not found"]
    assert not (tmp_path / "t").exists()


def test_compare_takes_runs_by_name_under_several_folders(
    split_runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    baselines, mine = split_runs
    out = tmp_path / "cmp"
    by_folder = ["compare", str(mine / "reproject"), str(baselines / "identity"), "--resamples", "50"]
    assert main([*by_folder, "--out", str(tmp_path / "by_folder")]) == 0
    expected = capsys.readouterr().out.splitlines()[:-2]  # the verdicts, without the two file lines
    argv = ["compare", "reproject", "identity", "--runs", str(baselines), "--runs", str(mine)]
    assert main([*argv, "--resamples", "50", "--out", str(out)]) == 0
    assert capsys.readouterr().out.splitlines()[:-2] == expected
    frame = pd.read_parquet(out / "compare_reproject_vs_identity.parquet")
    pd.testing.assert_frame_equal(
        frame, pd.read_parquet(tmp_path / "by_folder" / "compare_reproject_vs_identity.parquet")
    )
    # a name two runs carry, and a name no run carries, are refused in one line
    shutil.copytree(mine / "reproject", tmp_path / "again" / "reproject")
    for extra, fragment in (
        (["--runs", str(tmp_path / "again")], "2 runs are called 'reproject'"),
        ([], "no run folder or run of that name"),
    ):
        name = "reproject" if extra else "nothing"
        code = main(
            ["compare", name, "identity", "--runs", str(baselines), str(mine), *extra, "--out", str(out)]
        )
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and err[0].startswith(f"setdiff-bench compare: error: {name}: ")
        assert fragment in err[0], err


def test_the_python_leaderboard_takes_several_folders_too(
    lb_runs: Path, split_runs: tuple[Path, Path], tmp_path: Path
) -> None:
    baselines, mine = split_runs
    one = sb.leaderboard_frame(sb.leaderboard(lb_runs, "synthetic"))
    pd.testing.assert_frame_equal(sb.leaderboard_frame(sb.leaderboard([baselines, mine], "synthetic")), one)
    # run folders themselves, as before, and a run reached twice
    both = [baselines / "identity", mine / "reproject", mine]
    pd.testing.assert_frame_equal(sb.leaderboard_frame(sb.leaderboard(both, "synthetic")), one)


def test_the_default_output_is_outside_the_tracked_tree(
    split_runs: tuple[Path, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    baselines, mine = split_runs
    monkeypatch.chdir(tmp_path)
    argv = ["leaderboard", "--dataset", "synthetic", "--runs", str(baselines), str(mine), "--format", "md"]
    assert main(argv) == 0
    assert [p.name for p in (tmp_path / "runs" / "leaderboards").iterdir()] == ["synthetic.md"]
    assert not (tmp_path / "results").exists()
