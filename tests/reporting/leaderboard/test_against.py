"""``leaderboard --against``: paired gains beside each cell (positive = better, LPIPS included: issue 57); the
plain table is unchanged and written too; every argument is checked before anything is written (issue 45,
defect 2); a --with-reported table without measured rows says so."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.leaderboard import (
    build_leaderboard,
    render_latex,
    render_markdown,
    to_frame,
    write_leaderboard,
)
from tests.evaluation.run.store_fixtures import leaderboard_argv


def rows(
    method: str, psnr_by_scene: dict[str, list[float]], group: str = "lane+1", lpips: float = 0.2
) -> pd.DataFrame:
    """Per-target rows of ``method``: PSNR values per scene (frames f0, f1, ...), SSIM 0.8, LPIPS ``lpips``."""
    return pd.DataFrame(
        [
            {
                "dataset": "synthetic",
                "protocol": "synthetic",
                "group": group,
                "split": "test",
                "scene": scene,
                "frame": f"f{i}",
                "method": method,
                "psnr": value,
                "ssim": 0.8,
                "lpips": lpips,
                "run": f"r/{method}",
            }
            for scene, values in psnr_by_scene.items()
            for i, value in enumerate(values)
        ]
    )


def table() -> pd.DataFrame:
    # setdiff − difix: +1 in both scenes (holds); identity − difix: +0.5 in s0, −0.5 in s1 (does not);
    # LPIPS: setdiff 0.15 against difix's 0.2, a gain of +0.05 (lower is better)
    return pd.concat(
        [
            rows("difix", {"s0": [20.0, 21.0], "s1": [22.0, 23.0]}),
            rows("setdiff", {"s0": [21.0, 22.0], "s1": [23.0, 24.0]}, lpips=0.15),
            rows("identity", {"s0": [20.5, 21.5], "s1": [21.5, 22.5]}),
        ],
        ignore_index=True,
    )


def test_against_adds_starred_differences_and_keeps_the_plain_table(tmp_path: Path) -> None:
    plain = build_leaderboard("synthetic", table())
    board = build_leaderboard(
        "synthetic", table(), against="difix", bootstrap=BootstrapSettings(resamples=1000)
    )
    assert board.stem == "synthetic.vs_difix" and plain.stem == "synthetic"
    md = render_markdown(board)
    assert (
        "paired gains over difix (positive = better): paired bootstrap over scenes, 95 % percentile interval, "
        "1000 resamples" in md
    )
    # LPIPS 0.150 against 0.200: shown as a gain of +0.050, not as the raw difference −0.050
    assert "| setdiff | **22.50** (+1.00\\*) | **0.800** (+0.000) | **0.150** (+0.050\\*) |" in md
    assert "| identity | 21.50 (+0.00) |" in md  # +0.5 and −0.5 by scene: no star
    assert "| difix | 21.50 | **0.800** | 0.200 |" in md  # the reference row has no difference
    assert "| setdiff | Lane +1 | +1.000 [+1.000, +1.000] \\*, won 2 of 2 |" in md
    assert "| +0.0500 [+0.0500, +0.0500] \\*, won 2 of 2 |" in md
    assert "| identity | Lane +1 | +0.000 [-0.500, +0.500], won 1 of 2 |" in md
    assert (
        "Paired gains over difix (positive = the row is better" in md and "positive = the row is better" in md
    )
    assert "Only 2 scene(s)" in md
    assert r"\textbf{22.50} (+1.00$^\ast$)" in render_latex(board)
    frame = to_frame(board)
    cell = frame[(frame["method"] == "setdiff") & (frame["metric"] == "psnr")].iloc[0]
    assert (cell["gain"], cell["gain_low"], cell["gain_high"], cell["wins"]) == (1.0, 1.0, 1.0, 2) and cell[
        "holds"
    ]
    lpips = frame[(frame["method"] == "setdiff") & (frame["metric"] == "lpips")].iloc[0]
    assert lpips[["gain", "gain_low", "gain_high"]].tolist() == pytest.approx([0.05, 0.05, 0.05])
    assert frame[frame["method"] == "difix"]["gain"].isna().all()
    # the plain table: no difference anywhere, and the columns of before
    assert "(+" not in render_markdown(plain) and "gain" not in to_frame(plain).columns
    written = write_leaderboard(board, tmp_path, ["md", "parquet"])
    assert sorted(p.name for p in written.values()) == ["synthetic.vs_difix.md", "synthetic.vs_difix.parquet"]


def test_against_a_method_not_in_the_table_is_refused() -> None:
    with pytest.raises(UsageError, match="no synthetic runs of method 'reproject' in the table"):
        build_leaderboard("synthetic", table(), against="reproject")
    with pytest.raises(UsageError, match="methods in the table: setdiff"):
        build_leaderboard("synthetic", table(), methods=["setdiff"], against="difix")


def test_leaderboard_cli_against(lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "lb"
    assert (
        main(leaderboard_argv("synthetic", lb_runs, out, "--against", "identity", "--resamples", "200")) == 0
    )
    # the plain table its help promises, beside the one with gains; the same as without --against
    assert sorted(p.name for p in out.iterdir()) == [
        "synthetic.md",
        "synthetic.parquet",
        "synthetic.tex",
        "synthetic.vs_identity.md",
        "synthetic.vs_identity.parquet",
        "synthetic.vs_identity.tex",
    ]
    assert main(leaderboard_argv("synthetic", lb_runs, tmp_path / "plain")) == 0
    # (the .tex and .md name the command, which differs)
    assert (out / "synthetic.parquet").read_bytes() == (tmp_path / "plain" / "synthetic.parquet").read_bytes()
    md = (out / "synthetic.vs_identity.md").read_text()
    assert "--against identity --resamples 200 --bootstrap-seed 0" in md
    assert "[n/a]" in md  # the fixture store has one scene: no interval, rather than a certain-looking one


def test_every_argument_is_checked_before_anything_is_written(
    lb_store: Path, lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "lb"
    for options, fragment in (
        (["--grids", "2"], "--grids needs --packets"),  # issue 45, defect 2: used to write the tables first
        (["--grids", "2", "--packets", str(tmp_path / "no_store")], "no_store"),
        (["--grids", "-1", "--packets", str(lb_store)], "needs K >= 0"),
        (["--format", "md,pdf"], "unknown format(s) pdf"),
        (["--against", "difix"], "no synthetic runs of method 'difix'"),
        (["--resamples", "0", "--against", "identity"], "needs at least 1 resample"),
    ):
        assert main(leaderboard_argv("synthetic", lb_runs, out, *options)) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and fragment in err[0], err
        assert not out.exists(), options


def test_with_reported_and_no_measured_runs_says_so(
    lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(leaderboard_argv("euvs", lb_runs, tmp_path / "lb", "--with-reported")) == 0
    err = capsys.readouterr().err
    assert f"note: no measured euvs runs under {lb_runs} (runs found for: synthetic)" in err
    assert "the table holds the paper's rows only" in err
