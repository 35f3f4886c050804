"""Ablations: seed spread (max − min, sd), beyond-spread verdicts and the paired gain over targets."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.reporting import ablation


def run_means(psnr: list[float], lpips: float = 0.2) -> ablation.RunMeans:
    """A run of four targets (two scenes, two frames each) with these PSNRs."""
    rows = pd.DataFrame(
        {
            "protocol": "synthetic",
            "group": "lane+1",
            "scene": ["s0", "s0", "s1", "s1"],
            "frame": ["f0", "f1", "f0", "f1"],
            "psnr": psnr,
            "ssim": 0.8,
            "lpips": lpips,
        }
    )
    means = {"psnr": sum(psnr) / 4, "ssim": 0.8, "lpips": lpips, "targets": 4.0}
    return ablation.RunMeans(means, rows)


def test_paired_gain_over_targets_is_averaged_over_models() -> None:
    # model 0: Both − None = +1 on every target; model 1: +0.5 on s0's targets, +1.5 on s1's.
    # Averaged over models per target: s0 +0.75, s1 +1.25 -> mean +1.0, interval [0.75, 1.25] (two scenes)
    seed0 = {"none": run_means([20, 20, 20, 20]), "both": run_means([21, 21, 21, 21], lpips=0.19)}
    seed1 = {"none": run_means([22, 22, 22, 22]), "both": run_means([22.5, 22.5, 23.5, 23.5], lpips=0.19)}
    found = ablation.paired_over_targets([seed0, seed1], "both", "none")
    assert found is not None
    psnr = found["psnr"]
    assert psnr.difference == pytest.approx(1.0) and psnr.targets == 4 and psnr.scenes == 2
    assert (psnr.low, psnr.high) == (pytest.approx(0.75), pytest.approx(1.25)) and psnr.holds
    frame = ablation.geometry_frame(ablation.mean_over_models([seed0, seed1]))
    ordering = ablation.ordering_geometry(frame, [seed0, seed1])
    # spreads: None 22 − 20 = 2, Both 23 − 21 = 2 -> the +1 dB mean gain is within them, but holds over targets
    assert (
        "gain per model +1.0000, +1.0000, better in 2 of 2, mean gain within the seed spread (2.0000); "
        "paired gain over 4 targets +1.0000 [+0.7500, +1.2500] (holds), better in 2 of 2 scenes; paper: better"
    ) in ordering[3]
    # LPIPS −0.01 everywhere is a gain of +0.01 (lower is better), the interval flipped to match
    assert "paired gain over 4 targets +0.0100 [+0.0100, +0.0100] (holds)" in ordering[5]
    assert ordering[6].startswith("Paired gains over targets: each target's gain averaged over the 2 models,")
    assert ordering[7].startswith("Only 2 scene(s)")


def test_results_without_rows_have_no_interval_and_one_model_still_does() -> None:
    plain = [
        {
            "none": {"psnr": 20.0, "ssim": 0.8, "lpips": 0.2, "targets": 4.0},
            "both": {"psnr": 21.0, "ssim": 0.8, "lpips": 0.2, "targets": 4.0},
        }
    ]
    assert ablation.paired_over_targets(plain, "both", "none") is None
    one = [{(1, 1): run_means([20, 20, 21, 21]), (3, 1): run_means([20.5, 20.5, 21.1, 21.1])}]
    notes = ablation.ordering_setsize(ablation.mean_over_models(one), one)
    assert (
        "paired gain over 4 targets +0.3000 [+0.1000, +0.5000] (holds), better in 2 of 2 scenes" in notes[0]
    )
    assert "gain per model" not in notes[0]  # one model: no per-model list, no spread


def test_pooled_means_keeps_the_per_target_rows(tmp_path: Path) -> None:
    rows = run_means([20, 21, 22, 23]).rows.assign(split=["test", "test", "test", "train"])
    rows.to_parquet(tmp_path / "metrics.parquet", index=False)
    means = ablation.pooled_means(tmp_path / "metrics.parquet")
    assert means["psnr"] == pytest.approx(21.0) and means["targets"] == 3.0
    assert means.rows is not None and means.rows["frame"].tolist() == ["f0", "f1", "f0"]
