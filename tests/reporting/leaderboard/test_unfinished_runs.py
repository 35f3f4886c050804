"""Issue 45 (found on the fox capture): ``leaderboard`` over a runs folder that also holds a run still being
written leaves that run out with one warning line naming it, instead of failing (or counting it).

A run is unfinished while its folder has ``run.json`` but no ``manifest.json`` (``run`` writes the manifest
last).  The two states a user meets are made from a finished run's folder: packets done but not merged
(fragments only) and merged but the manifest not yet written (``metrics.parquet`` present).  Expected tables
come from a leaderboard over a folder that holds only the finished runs.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.io.run_layout import MANIFEST_FILE, METRICS_FILE
from setdiff_bench.reporting.leaderboard import UnfinishedRunWarning, find_runs, survey_runs
from tests.evaluation.run.store_fixtures import leaderboard_argv

#: The words every warning about an unfinished run ends with (after the folder and the method).
PROBLEM = (
    f"no {MANIFEST_FILE} yet (still running, killed, or shards unfinished or not merged); finish it, or run "
    "the same `setdiff-bench run` command with --merge"
)


def unfinished_copy(run: Path, folder: Path, merged: bool) -> Path:
    """A copy of the finished ``run`` at ``folder`` as it is before its manifest: not merged (fragments
    only) or, with ``merged``, between ``metrics.parquet`` and ``manifest.json``."""
    shutil.copytree(run, folder)
    (folder / MANIFEST_FILE).unlink()
    if not merged:
        (folder / METRICS_FILE).unlink()
    return folder


@pytest.fixture
def runs(lb_runs: Path, tmp_path: Path) -> Path:
    """The finished ``identity`` and ``reproject`` runs plus two unfinished reproject runs
    (``partial`` not merged, ``merging`` merged without its manifest)."""
    folder = tmp_path / "runs"
    shutil.copytree(lb_runs, folder)
    unfinished_copy(lb_runs / "reproject", folder / "partial", merged=False)
    unfinished_copy(lb_runs / "reproject", folder / "merging", merged=True)
    return folder


def board(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "synthetic.parquet")


def test_survey_tells_finished_from_unfinished(runs: Path) -> None:
    finished, unfinished = survey_runs(runs)
    assert finished == [runs / "identity", runs / "reproject"]
    assert [(run.folder, run.method) for run in unfinished] == [
        (runs / "merging", "reproject"),
        (runs / "partial", "reproject"),
    ]
    with pytest.warns(UnfinishedRunWarning) as caught:
        assert find_runs(runs) == finished
    assert [str(w.message) for w in caught] == [
        f"{runs / name}: left out, run incomplete (method reproject): {PROBLEM}"
        for name in ("merging", "partial")
    ]


@pytest.mark.parametrize("methods", [(), ("--methods", "identity,reproject"), ("--methods", "identity")])
def test_unfinished_runs_are_left_out_with_one_line_each(
    runs: Path, lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], methods: tuple[str, ...]
) -> None:
    expected_out, out = tmp_path / "expected", tmp_path / "out"
    assert main(leaderboard_argv("synthetic", lb_runs, expected_out, "--format", "parquet", *methods)) == 0
    capsys.readouterr()
    assert main(leaderboard_argv("synthetic", runs, out, "--format", "parquet", *methods)) == 0
    assert capsys.readouterr().err.splitlines() == [
        f"setdiff-bench leaderboard: warning: {runs / name}: left out, run incomplete (method reproject): "
        f"{PROBLEM}"
        for name in ("merging", "partial")
    ]
    pd.testing.assert_frame_equal(board(out), board(expected_out))


def test_a_method_asked_for_whose_only_run_is_unfinished_is_refused(
    lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    runs = tmp_path / "runs"
    shutil.copytree(lb_runs / "identity", runs / "identity")
    unfinished_copy(lb_runs / "reproject", runs / "reproject", merged=False)
    out = tmp_path / "out"
    assert main(leaderboard_argv("synthetic", runs, out, "--methods", "identity,reproject")) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"setdiff-bench leaderboard: error: {runs / 'reproject'}: --methods names reproject: run incomplete "
        f"(method reproject): {PROBLEM}"
    ]
    assert not out.exists()
    assert main(leaderboard_argv("synthetic", runs, out, "--methods", "identity")) == 0  # not asked: left out
    assert len(capsys.readouterr().err.splitlines()) == 1


def test_a_folder_of_unfinished_runs_only_is_refused_in_one_line(
    lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    runs = tmp_path / "runs"
    unfinished_copy(lb_runs / "identity", runs / "identity", merged=True)
    unfinished_copy(lb_runs / "reproject", runs / "reproject", merged=False)
    out = tmp_path / "out"
    assert main(leaderboard_argv("synthetic", runs, out)) == 2
    assert capsys.readouterr().err.splitlines() == [
        f"setdiff-bench leaderboard: error: {runs / 'identity'}: run incomplete (method identity): {PROBLEM} "
        "(and 1 more unfinished run)"
    ]
    assert not out.exists()
