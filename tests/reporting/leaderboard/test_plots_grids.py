"""Plots (metric vs time bucket / lane shift) and qualitative grids."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.reporting.grids import BAND, GAP, GridFrame, pick_frames, qualitative_grid
from setdiff_bench.reporting.plots import (
    error_bar_caption,
    group_summary,
    lane_shift,
    plot_lane_shift,
    plot_time_buckets,
    time_bucket,
)


def per_image(method: str, group: str, psnr: list[float]) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "dataset": "nuscenes",
            "split": "test",
            "method": method,
            "group": group,
            "psnr": psnr,
            "ssim": 0.5,
            "lpips": 0.3,
            "frame": [f"f{i}" for i in range(len(psnr))],
        }
    )


def test_group_positions() -> None:
    assert time_bucket("10-11s") == (10.0, "10–11 s") and time_bucket("14-15s") == (14.0, "14–15 s")
    assert lane_shift("single") == (1.0, "+1") and lane_shift("double") == (2.0, "+2")
    assert lane_shift("lane+2") == (2.0, "+2") and lane_shift("interp") == (0.0, "0")
    assert time_bucket("level1") is None and lane_shift("side") is None


def test_group_summary_is_mean_and_standard_error() -> None:
    frame = pd.concat(
        [
            per_image("a", "10-11s", [20.0, 22.0, 24.0]),
            per_image("a", "11-12s", [18.0]),
            per_image("a", "level1", [1.0]),
        ]
    )
    summary = group_summary(frame, "psnr", time_bucket).set_index("group")
    assert list(summary.index) == ["10-11s", "11-12s"]
    assert summary.loc["10-11s", "mean"] == pytest.approx(22.0)
    assert summary.loc["10-11s", "sem"] == pytest.approx(2.0 / np.sqrt(3))
    assert summary.loc["11-12s", "sem"] == 0.0 and summary.loc["11-12s", "count"] == 1


def test_plot_caption_says_what_the_error_bars_are() -> None:
    summary = group_summary(
        pd.concat(
            [
                per_image("identity", "lane+1", [20.0, 22.0, 21.0]),
                per_image("identity", "lane+2", [18.0, 19.0]),
            ]
        ),
        "psnr",
        lane_shift,
    )
    caption = error_bar_caption(summary)
    assert "±1 standard error of the mean" in caption and "n = 2–3" in caption


def test_plots_are_written(tmp_path: Path) -> None:
    frame = pd.concat(
        [
            per_image(m, g, [20.0 + i + j, 21.0 + i])
            for i, m in enumerate(("identity", "setdiff"))
            for j, g in enumerate(("10-11s", "11-12s", "12-13s"))
        ]
    )
    path = plot_time_buckets(frame, tmp_path / "plots" / "buckets.png")
    image = cv2.imread(str(path))
    assert image is not None and image.shape[1] > image.shape[0] > 200
    with pytest.raises(UsageError, match="no group of these runs has a position on the 'lane shift' axis"):
        plot_lane_shift(frame, tmp_path / "lanes.png")


def test_pick_frames_round_robin_from_the_middle(lb_store: Path) -> None:
    index = PacketStore(lb_store).index
    frames = pick_frames(index, 3)
    targets = index[index["role"] == "target"].set_index(["packet_id", "view"])
    picked = [
        (targets.loc[(f.packet_id, f.view), "group"], targets.loc[(f.packet_id, f.view), "frame"])
        for f in frames
    ]
    # lane+1 holds front/000000..000003, lane+2 front/000004..000007 (two packets of two targets each)
    assert picked == [
        ("lane+1", "front/000001.jpg"),
        ("lane+2", "front/000005.jpg"),
        ("lane+1", "front/000002.jpg"),
    ]


def test_grid_layout_and_cells(lb_store: Path, lb_runs: Path, tmp_path: Path) -> None:
    store = PacketStore(lb_store)
    frames = [
        GridFrame("synthetic__scene-a__lane+2__0001", 1),
        GridFrame("synthetic__scene-a__lane+1__0000", 0),
    ]
    runs = {"identity": lb_runs / "identity", "reproject": lb_runs / "reproject"}
    path = qualitative_grid(store, runs, frames, tmp_path / "grid.png", cell_width=96)
    grid = cv2.imread(str(path))[:, :, ::-1]
    cell_h = 32 * 96 // 48
    # identity's images are the render: one column "identity = 3DGS render", then reproject, ground truth
    assert grid.shape == (BAND + 2 * (cell_h + BAND + GAP), 150 + 3 * (96 + GAP), 3)
    rows = store.index[store.index["role"] == "target"].set_index(["packet_id", "view"])
    for r, frame in enumerate(frames):
        top = BAND + r * (cell_h + BAND + GAP)
        record = rows.loc[(frame.packet_id, frame.view)]
        for c, source in enumerate(
            (
                lb_runs
                / "identity"
                / pd.read_parquet(lb_runs / "identity" / METRICS_FILE)
                .set_index(["packet_id", "view"])
                .loc[(frame.packet_id, frame.view), "image"],
                None,
                lb_store / record["gt"],
            )
        ):
            if source is None:
                continue
            expected = cv2.resize(
                cv2.imread(str(source))[:, :, ::-1], (96, cell_h), interpolation=cv2.INTER_NEAREST
            )
            left = 150 + c * (96 + GAP)
            np.testing.assert_array_equal(grid[top : top + cell_h, left : left + 96], expected)
        first = cv2.resize(
            cv2.imread(str(lb_store / record["image"]))[:, :, ::-1],
            (96, cell_h),
            interpolation=cv2.INTER_NEAREST,
        )
        np.testing.assert_array_equal(grid[top : top + cell_h, 150 : 150 + 96], first)  # = the 3DGS render
    without_identity = cv2.imread(
        str(
            qualitative_grid(
                store, {"reproject": lb_runs / "reproject"}, frames, tmp_path / "grid2.png", cell_width=96
            )
        )
    )
    assert without_identity.shape[1] == 150 + 3 * (96 + GAP)  # render | reproject | ground truth
    with pytest.raises(UsageError, match="no frames chosen"):
        qualitative_grid(store, runs, [], tmp_path / "empty.png")
