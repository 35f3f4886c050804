"""DL3DV's metric-vs-view-count plot (groups n3/n6/n9 of the sparse-view protocols)."""

from __future__ import annotations

from pathlib import Path

import cv2
import pandas as pd

from setdiff_bench.reporting.plots import group_summary, view_count, write_plots


def rows(method: str, group: str, psnr: list[float]) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "dataset": "dl3dv",
            "split": "test",
            "method": method,
            "group": group,
            "psnr": psnr,
            "ssim": 0.5,
            "lpips": 0.3,
        }
    )


def test_view_count_positions() -> None:
    assert view_count("n3") == (3.0, "3") and view_count("n12") == (12.0, "12")
    assert view_count("lane+2") is None and view_count("n") is None and view_count("dl3dv_n3") is None


def test_view_count_summary_orders_groups_by_views() -> None:
    frame = pd.concat([rows("difix", "n9", [30.0, 32.0]), rows("difix", "n3", [10.0, 14.0, 12.0])])
    summary = group_summary(frame, "psnr", view_count).sort_values("x")
    assert summary["x"].tolist() == [3.0, 9.0]
    assert summary["mean"].tolist() == [12.0, 31.0]
    # standard error by hand: n3 std (ddof 1) = 2, / sqrt(3); n9 std = sqrt(2), / sqrt(2) = 1
    assert abs(summary["sem"].iloc[0] - 2 / 3**0.5) < 1e-12 and abs(summary["sem"].iloc[1] - 1.0) < 1e-12


def test_dl3dv_runs_get_a_view_count_plot(tmp_path: Path) -> None:
    frame = pd.concat(
        [
            rows(m, g, [20.0 + i, 21.0 + i])
            for i, g in enumerate(("n3", "n6", "n9"))
            for m in ("identity", "difix")
        ]
    )
    written = write_plots("dl3dv", frame, tmp_path)
    assert [p.name for p in written] == ["dl3dv_view_count.png"]
    image = cv2.imread(str(written[0]))
    assert image is not None and image.shape[1] > image.shape[0] > 100
