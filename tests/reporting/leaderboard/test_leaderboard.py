"""Leaderboards: hand-computed means, bold and ties, refusals, LaTeX/Markdown structure, reported rows, shards."""

from __future__ import annotations

import itertools
import re
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.packets.shards import Shard
from setdiff_bench.reporting.leaderboard import (
    Block,
    Layout,
    LeaderboardError,
    build_leaderboard,
    latex_escape,
    load_reported,
    load_runs,
    render_latex,
    render_markdown,
    reported_for,
    to_frame,
    write_leaderboard,
)
from tests.evaluation.run.store_fixtures import leaderboard_argv
from tests.reporting.leaderboard.leaderboard_fixtures import images, table


def split_cells(line: str) -> list[str]:
    """Cells of a LaTeX table row (``\\&`` is text, not a separator)."""
    return [cell.strip() for cell in re.split(r"(?<!\\)&", line.removesuffix(r"\\").strip())]


def row_width(cells: list[str]) -> int:
    return sum(int(m.group(1)) if (m := re.match(r"\\multicolumn\{(\d+)\}", c)) else 1 for c in cells)


def check_latex_structure(text: str) -> tuple[int, list[list[str]]]:
    """booktabs order, tabular spec, every row's width, cmidrule coverage → (columns, body rows' cells)."""
    lines = [line for line in text.splitlines() if line and not line.startswith("%")]
    assert lines[0].startswith(r"\begin{tabular}{") and lines[-1] == r"\end{tabular}"
    spec = re.match(r"\\begin\{tabular\}\{([lc|]+)\}", lines[0]).group(1)
    columns = sum(ch in "lc" for ch in spec)
    assert lines[1] == r"\toprule" and lines[-2] == r"\bottomrule"
    assert lines.count(r"\toprule") == 1 and lines.count(r"\bottomrule") == 1
    first_mid = lines.index(r"\midrule")
    rows = [line for line in lines if line.endswith(r"\\")]
    for line in rows:
        assert row_width(split_cells(line)) == columns, line
    for line in lines:
        if line.startswith(r"\cmidrule"):
            spans = [tuple(map(int, m)) for m in re.findall(r"\\cmidrule\(lr\)\{(\d+)-(\d+)\}", line)]
            assert spans[0][0] == 2 and spans[-1][1] == columns
            assert all(b[0] == a[1] + 1 for a, b in itertools.pairwise(spans))
    body = [split_cells(line) for line in lines[first_mid + 1 :] if line.endswith(r"\\")]
    return columns, body


# ---------------------------------------------------------------------- aggregation
def test_block_means_are_means_of_per_image_values() -> None:
    board = build_leaderboard("synthetic", table())
    frame = to_frame(board).set_index(["method", "block", "metric"])["value"]
    assert frame[("alpha", "lane+1", "psnr")] == pytest.approx(21.0)
    assert frame[("alpha", "lane+2", "ssim")] == pytest.approx(0.43)
    assert frame[("beta", "lane+2", "lpips")] == pytest.approx(0.355)
    assert frame[("beta", "lane+1", "psnr")] == pytest.approx(21.0)
    assert set(to_frame(board)["count"]) == {2}
    assert [b.label for b, _ in board.columns] == [
        "Lane +1",
        "Lane +2",
    ]  # synthetic blocks without data dropped


def test_bold_goes_to_the_best_displayed_value_and_ties_share_it() -> None:
    board = build_leaderboard("synthetic", table())
    best = to_frame(board).query("best")[["method", "block", "metric"]].apply(tuple, axis=1).tolist()
    assert sorted(best) == sorted(
        [
            ("alpha", "lane+1", "psnr"),
            ("beta", "lane+1", "psnr"),  # 21.00 = 21.00
            ("alpha", "lane+1", "ssim"),
            ("beta", "lane+1", "ssim"),  # 0.600 = 0.600
            ("alpha", "lane+1", "lpips"),
            ("beta", "lane+1", "lpips"),  # 0.200 = 0.200, lower is better
            ("alpha", "lane+2", "psnr"),
            ("beta", "lane+2", "ssim"),
            ("beta", "lane+2", "lpips"),
        ]
    )
    md = render_markdown(board)
    assert "| alpha | **21.00** | **0.600** | **0.200** | **18.50** | 0.430 | 0.390 |" in md
    assert "| beta | **21.00** | **0.600** | **0.200** | 17.25 | **0.450** | **0.355** |" in md


def test_pooled_block_averages_every_image() -> None:
    layout = Layout((Block("", "All"),))
    board = build_leaderboard("synthetic", table(), layout=layout)
    frame = to_frame(board).set_index(["method", "metric"])["value"]
    assert frame[("alpha", "psnr")] == pytest.approx((20 + 22 + 18 + 19) / 4)


def test_a_method_missing_rows_is_refused_and_an_absent_block_is_a_dash() -> None:
    partial = pd.concat([table(), images("gamma", "lane+1", [(25.0, 0.9, 0.1)])], ignore_index=True)
    with pytest.raises(
        LeaderboardError,
        match=r"method 'gamma' lacks 1 of 2 targets of block 'Lane \+1' "
        r"that other runs have \(s/f1 \(lane\+1\)\)",
    ):
        build_leaderboard("synthetic", partial)
    complete = pd.concat(
        [table(), images("gamma", "lane+1", [(25.0, 0.9, 0.1), (25.0, 0.9, 0.1)])], ignore_index=True
    )
    md = render_markdown(build_leaderboard("synthetic", complete))
    assert "| gamma | **25.00** | **0.900** | **0.100** | – | – | – |" in md


def test_duplicate_rows_across_runs_are_refused() -> None:
    doubled = pd.concat(
        [table(), images("alpha", "lane+1", [(1.0, 0.1, 0.9)], run="other")], ignore_index=True
    )
    with pytest.raises(
        LeaderboardError,
        match=r"method 'alpha' has 2 duplicate rows, e.g. s/f0 \(lane\+1\) "
        r"in runs other/alpha, r/alpha",
    ):
        build_leaderboard("synthetic", doubled)


def test_filters_and_missing_inputs() -> None:
    with pytest.raises(LeaderboardError, match="no euvs results of split test"):
        build_leaderboard("euvs", table())
    with pytest.raises(LeaderboardError, match="no synthetic runs of method"):
        build_leaderboard("synthetic", table(), methods=["nope"])
    with pytest.raises(LeaderboardError, match="no column"):
        build_leaderboard("synthetic", table(), metrics=["psnr_euvs"])
    board = build_leaderboard("synthetic", table(), methods=["beta", "alpha"])
    assert [row.label for row in board.rows] == ["beta", "alpha"]


def test_nuscenes_pools_buckets_and_adds_warp_error_per_sequence() -> None:
    frame = pd.concat(
        [
            images("identity", "10-11s", [(16.0, 0.6, 0.5)], dataset="nuscenes", frames=["a"]),
            images("identity", "14-15s", [(14.0, 0.5, 0.6)], dataset="nuscenes", frames=["b"]),
        ],
        ignore_index=True,
    )
    sequences = pd.DataFrame(
        {
            "dataset": "nuscenes",
            "method": "identity",
            "sensor": ["CAM_FRONT", "CAM_BACK"],
            "warp": [100.0, 110.0],
        }
    )
    board = build_leaderboard("nuscenes", frame, sequences)
    md = render_markdown(board)
    assert "| Method | PSNR↑ | SSIM↑ | LPIPS↓ | Warp↓ |" in md
    assert "| identity | **15.00** | **0.550** | **0.550** | **105.0** |" in md
    mixed = render_markdown(
        build_leaderboard("nuscenes", frame, sequences, reported=reported_for("nuscenes"))
    )
    assert "| OmniRe + SetDiff (paper) | **21.58** | **0.716** | **0.303** | 108.9 |" in mixed
    assert "| identity | 15.00 | 0.550 | 0.550 | **105.0** |" in mixed


# ---------------------------------------------------------------------- LaTeX and Markdown
def test_latex_is_booktabs_in_the_papers_shape_with_bold_and_escaping() -> None:
    named = table().replace({"method": {"alpha": "my_method & 50% #1"}})
    text = render_latex(
        build_leaderboard("synthetic", named), command="setdiff-bench leaderboard --dataset synthetic"
    )
    columns, body = check_latex_structure(text)
    assert columns == 1 + 2 * 3
    assert r"\multicolumn{3}{c}{\textbf{Lane +1}} & \multicolumn{3}{c}{\textbf{Lane +2}}" in text
    assert r"\textbf{PSNR}$\uparrow$" in text and r"\textbf{LPIPS}$\downarrow$" in text
    assert body[0][0] == r"beta" and body[1][0] == r"my\_method \& 50\% \#1"
    assert body[1][1:4] == [r"\textbf{21.00}", r"\textbf{0.600}", r"\textbf{0.200}"]
    assert body[0][4] == "17.25" and body[0][5] == r"\textbf{0.450}"
    assert latex_escape(r"a\b~c^d{e}$") == r"a\textbackslash{}b\textasciitilde{}c\textasciicircum{}d\{e\}\$"


@pytest.mark.skipif(shutil.which("pdflatex") is None, reason="pdflatex not installed")
def test_latex_compiles(tmp_path: Path) -> None:
    body = render_latex(build_leaderboard("euvs", pd.DataFrame(), reported=reported_for("euvs")))
    (tmp_path / "t.tex").write_text(
        f"\\documentclass{{article}}\\usepackage{{booktabs}}\\begin{{document}}\n{body}\\end{{document}}\n"
    )
    subprocess.run(
        ["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "t.tex"],
        cwd=tmp_path,
        check=True,
        capture_output=True,
    )


def test_markdown_rows_have_the_header_width() -> None:
    md = render_markdown(build_leaderboard("euvs", pd.DataFrame(), reported=reported_for("euvs")))
    table_lines = [line for line in md.splitlines() if line.startswith("|")]
    widths = {len(re.split(r"(?<!\\)\|", line)) for line in table_lines}
    assert widths == {1 + 1 + 9 + 1}
    assert table_lines[0].startswith("| Method | Setting 1 PSNR↑ | Setting 1 SSIM↑ | Setting 1 LPIPS↓ |")


# ---------------------------------------------------------------------- reported rows
@pytest.mark.parametrize("dataset", ["euvs", "paralane", "nuscenes", "dl3dv"])
def test_reported_only_table_reproduces_the_papers_bold(dataset: str) -> None:
    board = build_leaderboard(dataset, pd.DataFrame(), reported=reported_for(dataset))
    best = {
        (row.section, row.label, cell)
        for cell, rows in board.best.items()
        for i, row in enumerate(board.rows)
        if i in rows
    }
    reported = reported_for(dataset)
    labels = reported.drop_duplicates(["section", "method_id"]).set_index(["section", "method_id"])["method"]
    bold = {
        (r.section, labels[(r.section, r.method_id)], (r.group, r.metric))
        for r in reported.itertuples()
        if r.bold
    }
    assert best == bold


def test_reported_rows_are_marked_and_only_mixed_on_request() -> None:
    measured = pd.concat(
        [images("identity", g, [(15.0, 0.7, 0.3)], dataset="euvs") for g in ("level1", "level3")],
        ignore_index=True,
    )
    plain = build_leaderboard("euvs", measured)
    assert {row.source for row in plain.rows} == {"measured"}
    mixed = build_leaderboard("euvs", measured, reported=reported_for("euvs"))
    frame = to_frame(mixed)
    assert set(frame["source"]) == {"measured", "reported"}
    assert set(frame[frame["source"] == "measured"]["label"]) == {"identity"}
    md, tex = render_markdown(mixed), render_latex(mixed)
    assert (
        "| 3DGS + SetDiff (paper) | 17.84 |" in md
        and "| identity | 15.00 | 0.700 | 0.300 | – | – | – | 15.00 |" in md
    )
    assert r"3DGS + SetDiff$^\dagger$ & 17.84" in tex and "\nidentity & 15.00" in tex
    _, body = check_latex_structure(tex)
    # the paper's Table 1 repeats 3DGS (first reconstruction row, base of the enhancer section): shown once
    assert md.count("| 3DGS (paper) |") == 1 and tex.count("\n3DGS$^\\dagger$ &") == 1
    assert len(body) == 12 + 1
    assert tex.count(r"\midrule") == 3  # header | reconstruction | enhancer (paper) | measured


def test_load_reported_filters() -> None:
    frame = load_reported("nuscenes")
    assert set(frame["table"]) == {"table3_nuscenes", "supp_consistency"}
    assert frame[(frame["metric"] == "warp") & (frame["method_id"] == "setdiff")]["value"].tolist() == [108.9]


# ---------------------------------------------------------------------- real runs, shards, CLI
def test_two_shards_give_the_same_leaderboard_as_one_run(
    lb_store: Path, lb_runs: Path, tmp_path: Path
) -> None:
    sharded = tmp_path / "sharded"
    shutil.copytree(lb_runs / "reproject", sharded / "reproject")
    for index in (1, 0):
        run_method(
            lb_store, sharded / "identity", RunSettings("identity"), shard=Shard(index, 2), progress=False
        )
    outputs = []
    for runs in (lb_runs, sharded):
        found, sequences = load_runs(runs)
        board = build_leaderboard("synthetic", found, sequences)
        paths = write_leaderboard(board, tmp_path / f"lb_{runs.name}")
        outputs.append({fmt: path.read_bytes() for fmt, path in paths.items()})
    assert outputs[0] == outputs[1]


def test_leaderboard_cli(
    lb_store: Path, lb_runs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "lb"
    options = ("--plots", "--grids", "2", "--packets", str(lb_store), "--with-reported")
    assert main(leaderboard_argv("synthetic", lb_runs, out, *options)) == 0
    captured = capsys.readouterr()
    assert "the paper reports no numbers for dataset 'synthetic'" in captured.err
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        "synthetic.md",
        "synthetic.parquet",
        "synthetic.tex",
        "synthetic_grid.png",
        "synthetic_lane_shift.png",
    ]
    md = (out / "synthetic.md").read_text()
    assert "| identity |" in md and "| reproject |" in md and "Generated by `setdiff-bench leaderboard" in md
    frame = pd.read_parquet(out / "synthetic.parquet")
    assert set(frame["method"]) == {"identity", "reproject"} and set(frame["block"]) == {"lane+1", "lane+2"}
    # reproject really repairs the shifted views of the analytic scene
    psnr = frame[frame["metric"] == "psnr"].groupby("method")["value"].mean()
    assert psnr["reproject"] > psnr["identity"] + 3
    for argv, fragment in (
        (["--runs", str(tmp_path / "none")], "runs folder not found"),
        (["--runs", str(lb_runs), "--format", "pdf"], "unknown format(s) pdf"),
        (["--runs", str(lb_runs), "--grids", "2"], "--grids needs --packets"),
    ):
        code = main(["leaderboard", "--dataset", "synthetic", "--out", str(tmp_path / "x"), *argv])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and fragment in err[0], err
