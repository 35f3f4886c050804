"""FID / KID in the leaderboard (issue 41): runs scored with ``--inception`` on a store mixing protocol packets
(ground truth) and lane-shift packets (none) give a table whose shift blocks show FID / KID only, their image
metrics "–" (never NaN), and whose protocol blocks show PSNR / SSIM / LPIPS beside FID / KID for the same
targets; the caption names the reference set and the network's SHA-256.

Independent references: the FID / KID cells are compared with ``distribution.parquet`` read here, the image
metric cells with means of ``metrics.parquet`` taken here, the SHA-256 with :mod:`hashlib` on the file.
"""

from __future__ import annotations

import hashlib
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.protocols import POOLED, Block, Layout
from setdiff_bench.reporting.leaderboard import (
    build_leaderboard,
    load_distribution,
    load_runs,
    render_markdown,
    to_frame,
)
from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import StreetScene
from tests.packets.trajectory.conftest import GROUPS, SHIFTS

METHODS = ("identity", "difix")
PAIRED = ("psnr", "ssim", "lpips")


@pytest.fixture(scope="module")
def mixed_runs(
    street: tuple[Path, StreetScene], inception_file: Path, tmp_path_factory: pytest.TempPathFactory
) -> tuple[Path, Path]:
    """``(store, runs)``: the scene's protocol packets and its shift:-3 / shift:-6 packets in one store, and
    ``runs/identity`` and ``runs/difix`` (tiny_difix) on it, both scored with ``--inception``."""
    root, _ = street
    base = tmp_path_factory.mktemp("mixed_leaderboard")
    store, runs = base / "store", base / "runs"
    with torch_threads(1):
        prepare("synthetic", root, store, fits=root, progress=False)
        prepare("synthetic", root, store, fits=root, progress=False, trajectories=SHIFTS)
        for method in METHODS:
            extra = ["--checkpoint", "tiny_difix"] if method == "difix" else []
            argv = ["run", "--method", method, "--packets", str(store), "--out", str(runs / method)]
            argv += ["--split", "all", "--warp-cache", "none", "--no-progress", *extra]
            assert main([*argv, "--inception", str(inception_file)]) == 0
    return store, runs


def _table(runs: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[str, str, pd.DataFrame]:
    argv = ["leaderboard", "--dataset", "synthetic", "--runs", str(runs), "--out", str(out)]
    assert main([*argv, "--split", "all", "--methods", ",".join(METHODS)]) == 0
    capsys.readouterr()
    md = (out / "synthetic.md").read_text()
    tex = (out / "synthetic.tex").read_text()
    return md, tex, pd.read_parquet(out / "synthetic.parquet")


def test_fid_kid_columns_hold_the_distribution_values(
    mixed_runs: tuple[Path, Path], inception_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, runs = mixed_runs
    md, tex, frame = _table(runs, tmp_path / "tables", capsys)
    assert not frame["value"].isna().any()  # "not computed" is an absent cell, never NaN
    protocol_groups: set[str] = set()
    small: set[str] = set()
    for method in METHODS:
        dist = pd.read_parquet(runs / method / "distribution.parquet")
        metrics = pd.read_parquet(runs / method / "metrics.parquet")
        assert set(GROUPS) <= set(dist["group"])
        own = frame[frame["method"] == method]
        for record in dist.to_dict("records"):
            cells = own[own["block"] == record["group"]].set_index("metric")
            if pd.isna(record["fid"]):  # too few images for FID / KID: no cell ("–"), no NaN
                assert record["enhanced"] < 2 and not {"fid", "kid"} & set(cells.index)
                small.add(record["group"])
                continue
            for metric in ("fid", "kid"):
                assert math.isfinite(record[metric])
                assert cells.loc[metric, "value"] == record[metric]  # the same float, not a recomputation
                assert cells.loc[metric, "count"] == record["enhanced"]
            rows = metrics[metrics["group"] == record["group"]]
            if record["group"] in GROUPS:  # no ground truth: FID / KID only
                assert rows[list(PAIRED)].isna().all().all()
                assert set(cells.index) == {"fid", "kid"}
            else:  # ground truth: the image metrics beside FID / KID, over the same targets
                protocol_groups.add(record["group"])
                assert set(cells.index) == {*PAIRED, "fid", "kid"}
                for metric in PAIRED:
                    expected = float(np.mean(rows[metric].to_numpy(dtype=np.float64)))
                    assert cells.loc[metric, "value"] == pytest.approx(expected, rel=1e-12)
                    assert cells.loc[metric, "count"] == len(rows) == record["enhanced"]
    assert protocol_groups  # both kinds of block are in the table
    assert small == {"interp"}  # the scene's one held-out frame: its block shows no FID / KID column

    header = next(line for line in md.splitlines() if line.startswith("| Method"))
    for group in GROUPS:
        assert f"{group} PSNR↑ | {group} SSIM↑ | {group} LPIPS↓ | {group} FID↓ | {group} KID↓" in header
    columns = [c.strip() for c in header.strip("|").split("|")]
    # interp is labelled "Held-out" by the synthetic layout
    assert "Held-out PSNR↑" in columns and not any(c.startswith("Held-out") and "ID" in c for c in columns)
    for method in METHODS:
        line = next(line for line in md.splitlines() if line.startswith(f"| {method} |"))
        cells = dict(zip(columns, (c.strip() for c in line.strip("|").split("|")), strict=True))
        dist = pd.read_parquet(runs / method / "distribution.parquet").set_index("group")
        for group in GROUPS:
            assert [cells[f"{group} {m}"] for m in ("PSNR↑", "SSIM↑", "LPIPS↓")] == ["–"] * 3
            shown = cells[f"{group} FID↓"].strip("*")
            assert shown == f"{dist.loc[group, 'fid']:.2f}"
            assert cells[f"{group} KID↓"].strip("*") == f"{dist.loc[group, 'kid']:.4f}"
        assert "nan" not in line.lower()
    sha = hashlib.sha256(inception_file.read_bytes()).hexdigest()
    caption = next(line for line in md.splitlines() if line.startswith("FID / KID:"))
    assert "recorded frames its packets carry as references" in caption and f"SHA-256 {sha[:12]}" in caption
    assert "–: not computed. The targets of shift-3m, shift-6m have no ground truth" in md
    assert r"\textbf{FID}$\downarrow$" in tex and "nan" not in tex.lower()
    assert "% FID / KID: each block's enhanced targets" in tex


def test_runs_without_distribution_files_keep_their_table(
    mixed_runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The same runs without ``distribution.parquet``: no FID / KID column or caption line, and every image
    metric cell as in the table with them."""
    _, runs = mixed_runs
    plain = tmp_path / "runs"
    for method in METHODS:
        shutil.copytree(runs / method, plain / method)
        (plain / method / "distribution.parquet").unlink()
        (plain / method / "distribution.json").unlink()
    md, _, frame = _table(plain, tmp_path / "plain", capsys)
    _, _, with_fid = _table(runs, tmp_path / "fid", capsys)
    assert not {"fid", "kid"} & set(frame["metric"]) and "FID↓" not in md and "FID / KID:" not in md
    assert not set(GROUPS) & set(frame["block"])
    assert "Not in the table: shift-3m, shift-6m, whose targets have no ground truth" in md
    keys = ["method", "block", "metric"]
    same = with_fid[with_fid["metric"].isin(PAIRED)].sort_values(keys).reset_index(drop=True)
    plain_cells = frame.sort_values(keys).reset_index(drop=True)
    pd.testing.assert_frame_equal(
        plain_cells.drop(columns=["row_order", "best"]), same.drop(columns=["row_order", "best"])
    )


def test_a_pooled_layout_gives_each_shift_its_own_block(mixed_runs: tuple[Path, Path]) -> None:
    """A layout that pools every group (nuScenes' shape): the shift groups still get blocks of their own, and
    the pooled means are over the targets with ground truth only."""
    _, runs = mixed_runs
    images, _ = load_runs(runs)
    dist = load_distribution([runs / m for m in METHODS])
    board = build_leaderboard(
        "synthetic",
        images,
        split=None,
        layout=Layout((Block(POOLED, "All"),), title="pooled"),
        distribution=dist,
    )
    assert [block.key for block, _ in board.columns] == [POOLED, *GROUPS]
    assert board.columns[0][1] == PAIRED  # no FID / KID for the pooled set
    frame = to_frame(board)
    for method in METHODS:
        rows = images[(images["method"] == method) & ~images["group"].isin(GROUPS)]
        cell = frame[(frame["method"] == method) & (frame["block"] == POOLED) & (frame["metric"] == "psnr")]
        assert cell["value"].item() == pytest.approx(float(rows["psnr"].mean()), rel=1e-12)
        assert cell["count"].item() == len(rows)
    assert "the pooled block leaves them out" in render_markdown(board)


def test_fid_from_different_networks_is_refused(
    mixed_runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _, runs = mixed_runs
    copied = tmp_path / "runs"
    for method in METHODS:
        shutil.copytree(runs / method, copied / method)
    info = copied / "difix" / "distribution.json"
    info.write_text(info.read_text().replace('"inception_sha256": "', '"inception_sha256": "0'))
    out = tmp_path / "tables"
    argv = [
        "leaderboard",
        "--dataset",
        "synthetic",
        "--runs",
        str(copied),
        "--out",
        str(out),
        "--split",
        "all",
    ]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "different Inception weights" in err[0]
    assert not out.exists()


def test_a_shift_block_with_ground_truth_shows_both(
    mixed_runs: tuple[Path, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Where the shifted frames have ground truth (the synthetic world renders any pose, as
    benchmarks/trajectory_ranking.py does), the same shift block shows PSNR / SSIM / LPIPS beside FID / KID
    over the same targets: here the run's null image metrics are filled with known values."""
    _, runs = mixed_runs
    copied = tmp_path / "runs"
    filled: dict[str, pd.DataFrame] = {}
    for offset, method in enumerate(METHODS):
        shutil.copytree(runs / method, copied / method)
        path = copied / method / "metrics.parquet"
        metrics = pd.read_parquet(path)
        shifted = metrics["group"].isin(GROUPS)
        values = np.arange(shifted.sum(), dtype=np.float64)
        metrics.loc[shifted, "psnr"] = 20.0 + offset + values
        metrics.loc[shifted, "ssim"] = 0.5 + 0.01 * values
        metrics.loc[shifted, "lpips"] = 0.1 + 0.001 * values
        metrics.to_parquet(path, index=False)
        filled[method] = metrics
    md, _, frame = _table(copied, tmp_path / "tables", capsys)
    assert "–: not computed" not in md and not frame["value"].isna().any()
    for method in METHODS:
        dist = pd.read_parquet(copied / method / "distribution.parquet").set_index("group")
        for group in GROUPS:
            cells = frame[(frame["method"] == method) & (frame["block"] == group)].set_index("metric")
            assert set(cells.index) == {*PAIRED, "fid", "kid"}
            rows = filled[method][filled[method]["group"] == group]
            for metric in PAIRED:
                assert cells.loc[metric, "value"] == pytest.approx(float(rows[metric].mean()), rel=1e-12)
            assert cells.loc["fid", "value"] == dist.loc[group, "fid"]
            assert cells.loc["psnr", "count"] == cells.loc["fid", "count"] == len(rows)
