"""The refit-steps plot: which run is which point of which curve, and the PNG ``leaderboard --plots`` writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.reporting.plots import plot_refit_steps, refit_curves, write_plots


def rows(
    run: str, method: str, psnr: list[float], refit: tuple[float, str, str, str] | None = None
) -> pd.DataFrame:
    """Per-target rows of one run in group lane+2; ``refit``: (steps, refit enhancer, schedule, run enhancer)."""
    frame = pd.DataFrame(
        {
            "run": run,
            "method": method,
            "dataset": "synthetic",
            "split": "test",
            "group": "lane+2",
            "scene": ["a", "b"][: len(psnr)],
            "psnr": psnr,
            "ssim": 0.5,
            "lpips": 0.3,
        }
    )
    if refit is not None:
        frame["refit_steps"], frame["refit_method"], frame["refit_schedule"], frame["run_method"] = refit
        frame["refit_s"] = 10.0
    return frame


def images(*extra: pd.DataFrame) -> pd.DataFrame:
    return pd.concat(
        [
            rows("runs/identity", "identity", [10.0, 12.0]),
            rows("runs/setdiff", "setdiff", [11.0, 13.0]),
            rows(
                "runs/s3d-100", "setdiff-3D-100", [14.0, 14.0], (100.0, "setdiff", "progressive", "identity")
            ),
            rows("runs/s3d", "setdiff-3D", [15.0, 15.0], (300.0, "setdiff", "progressive", "identity")),
            rows("runs/s3d+", "setdiff-3D+", [16.0, 16.0], (300.0, "setdiff", "progressive", "setdiff")),
            *extra,
        ],
        ignore_index=True,
    )


def points(curves: pd.DataFrame) -> set[tuple[str, float, str]]:
    return {(f"{row.enhancer} {row.kind}", row.x, row.run) for row in curves.itertuples()}


def test_each_refit_run_is_a_point_and_the_plain_runs_open_the_curves() -> None:
    assert points(refit_curves(images())) == {
        ("setdiff 3D", 0.0, "runs/identity"),  # a refit of 0 steps is the fit: its render
        ("setdiff 3D", 100.0, "runs/s3d-100"),
        ("setdiff 3D", 300.0, "runs/s3d"),
        ("setdiff 3D+", 0.0, "runs/setdiff"),  # ... and setdiff on it, the post-process row
        ("setdiff 3D+", 300.0, "runs/s3d+"),
    }


def test_two_schedules_are_told_apart_and_plain_runs_alone_make_no_curve() -> None:
    one_shot = rows("runs/s3d-os", "setdiff-os-3D", [15.5, 15.5], (300.0, "setdiff", "one-shot", "identity"))
    curves = points(refit_curves(images(one_shot)))
    assert ("setdiff (one-shot) 3D", 300.0, "runs/s3d-os") in curves
    assert ("setdiff (one-shot) 3D", 0.0, "runs/identity") in curves
    assert ("setdiff (progressive) 3D", 100.0, "runs/s3d-100") in curves
    plain = (
        images()
        .query("run in ['runs/identity', 'runs/setdiff']")
        .drop(columns=["refit_steps", "refit_method", "refit_schedule", "run_method", "refit_s"])
    )
    assert refit_curves(plain).empty
    with pytest.raises(UsageError, match="no run here scores a refit"):
        plot_refit_steps(plain, Path("unused.png"))


def test_leaderboard_plots_include_the_refit_steps_with_the_warp_error(tmp_path: Path) -> None:
    sequences = pd.DataFrame(
        {"run": ["runs/identity", "runs/s3d"], "dataset": "synthetic", "scene": "a", "warp": [900.0, 800.0]}
    )
    written = write_plots("synthetic", images(), tmp_path, sequences=sequences)
    assert [p.name for p in written] == ["synthetic_lane_shift.png", "synthetic_refit_steps.png"]
    png = written[1].read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n"
    import cv2

    picture = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    # 3 metric rows + the warp row of 3.0-inch panels at 120 dpi
    assert picture.shape[0] == 4 * 3 * 120
    without = write_plots("synthetic", images(), tmp_path / "site", refit_steps=False)
    assert [p.name for p in without] == ["synthetic_lane_shift.png"]
