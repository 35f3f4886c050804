"""Paired differences: hand-computed cases, identical runs, scene- against frame-level resampling, scipy."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import scipy.stats

from setdiff_bench.reporting.bootstrap import BootstrapSettings
from setdiff_bench.reporting.paired import PairingError, pair_targets, paired_differences


def pairs_of(scenes: list[str], a: list[float], b: list[float], metric: str = "psnr") -> pd.DataFrame:
    """A :func:`pair_targets`-shaped frame: one row per target with ``<metric>_a`` and ``<metric>_b``."""
    return pd.DataFrame({"scene": scenes, f"{metric}_a": a, f"{metric}_b": b})


def test_a_known_paired_difference_over_two_scenes() -> None:
    # scene s0: differences 1, 1; scene s1: 2, 2.  Mean 1.5.  A resample of two scenes is (s0, s0) -> 1,
    # mixed -> 1.5 or (s1, s1) -> 2, each pure draw with probability 1/4 > 2.5 %: the interval is [1, 2].
    pairs = pairs_of(["s0", "s0", "s1", "s1"], [11.0, 13.0, 16.0, 18.0], [10.0, 12.0, 14.0, 16.0])
    d = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=4000))["psnr"]
    assert d.difference == pytest.approx(1.5) and d.mean_a == 14.5 and d.mean_b == 13.0
    assert (d.low, d.high) == (pytest.approx(1.0), pytest.approx(2.0))
    assert d.holds and d.a_better and (d.wins, d.losses, d.ties) == (2, 0, 0)
    assert (d.targets, d.scenes) == (4, 2)
    assert d.verdict("A", "B") == "A better"
    # LPIPS is lower-is-better: the same numbers are two losses, and B is the better one
    lpips = paired_differences(
        pairs_of(["s0", "s0", "s1", "s1"], [0.3] * 4, [0.1, 0.1, 0.2, 0.2], "lpips"), ["lpips"]
    )
    assert (lpips["lpips"].wins, lpips["lpips"].losses) == (0, 2) and lpips["lpips"].verdict(
        "A", "B"
    ) == "B better"


def test_identical_runs_give_zero_and_an_interval_of_zero() -> None:
    values = [20.0, 21.5, 19.0, 22.0, 18.5, 20.5]
    pairs = pairs_of(["s0", "s0", "s1", "s1", "s2", "s2"], values, values)
    for unit in ("scene", "frame"):
        d = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=500, unit=unit))["psnr"]
        assert (d.difference, d.low, d.high) == (0.0, 0.0, 0.0)
        assert not d.holds and (d.wins, d.losses, d.ties) == (0, 0, 3)
        assert d.verdict("A", "B") == "no difference shown"


def test_scene_resampling_is_wider_than_frame_resampling_on_correlated_frames() -> None:
    # four scenes of ten frames each; the difference is mostly a per-scene offset (frames of one scene agree)
    rng = np.random.default_rng(0)
    offsets = [0.9, -0.4, 0.7, -0.1]
    scenes = [f"s{i}" for i, _ in enumerate(offsets) for _ in range(10)]
    differences = np.array([o for o in offsets for _ in range(10)]) + rng.normal(0, 0.02, 40)
    pairs = pairs_of(scenes, list(20.0 + differences), [20.0] * 40)
    by_scene = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=4000))["psnr"]
    by_frame = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=4000, unit="frame"))["psnr"]
    assert by_scene.difference == pytest.approx(by_frame.difference)
    assert by_frame.holds  # 40 "independent" frames make the mean +0.275 look certain ...
    assert not by_scene.holds  # ... two of four scenes go the other way
    assert (by_scene.high - by_scene.low) > 3 * (by_frame.high - by_frame.low)
    assert (by_scene.wins, by_scene.losses) == (2, 2)


def test_one_scene_has_no_interval_rather_than_a_certain_looking_one() -> None:
    d = paired_differences(pairs_of(["s0"] * 3, [2.0, 3.0, 4.0], [1.0, 1.0, 1.0]), ["psnr"])["psnr"]
    assert d.difference == pytest.approx(2.0) and not d.has_interval and not d.holds
    assert d.format() == "+2.000 [n/a]"


def test_scene_mean_statistic_weights_scenes_equally() -> None:
    # s0: one target, difference 0; s1: three targets, difference 2 -> target mean 1.5, scene mean 1.0
    pairs = pairs_of(["s0", "s1", "s1", "s1"], [5.0, 7.0, 7.0, 7.0], [5.0, 5.0, 5.0, 5.0])
    assert paired_differences(pairs, ["psnr"])["psnr"].difference == pytest.approx(1.5)
    d = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=4000), scene_mean=True)["psnr"]
    assert d.difference == pytest.approx(1.0) and (d.low, d.high) == (pytest.approx(0.0), pytest.approx(2.0))


@pytest.mark.parametrize("unit", ["scene", "frame"])
def test_one_target_per_scene_matches_scipy_bootstrap(unit: str) -> None:
    rng = np.random.default_rng(7)
    a = rng.normal(21.0, 1.0, 15)
    b = a - rng.normal(0.3, 0.5, 15)
    pairs = pairs_of([f"s{i:02d}" for i in range(15)], list(a), list(b))
    settings = BootstrapSettings(resamples=3000, seed=11, unit=unit)
    d = paired_differences(pairs, ["psnr"], settings)["psnr"]
    reference = scipy.stats.bootstrap(
        (a - b,), np.mean, n_resamples=3000, method="percentile", rng=np.random.default_rng(11)
    ).confidence_interval
    assert d.low == pytest.approx(reference.low, rel=1e-9) and d.high == pytest.approx(
        reference.high, rel=1e-9
    )


def test_frame_unit_matches_scipy_on_several_targets_per_scene() -> None:
    rng = np.random.default_rng(3)
    d_true = rng.normal(0.1, 0.4, 24)
    pairs = pairs_of([f"s{i % 3}" for i in range(24)], list(10.0 + d_true), [10.0] * 24)
    d = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=2000, seed=5, unit="frame"))["psnr"]
    reference = scipy.stats.bootstrap(
        (pairs["psnr_a"].to_numpy() - 10.0,),
        np.mean,
        n_resamples=2000,
        method="percentile",
        rng=np.random.default_rng(5),
    ).confidence_interval
    assert (d.low, d.high) == (
        pytest.approx(reference.low, rel=1e-9),
        pytest.approx(reference.high, rel=1e-9),
    )


def test_same_seed_same_interval_and_recorded_settings() -> None:
    pairs = pairs_of(["s0", "s1", "s2", "s0"], [1.0, 2.0, 4.0, 3.0], [0.0, 0.0, 0.0, 0.0])
    first = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=300, seed=2))["psnr"]
    again = paired_differences(pairs, ["psnr"], BootstrapSettings(resamples=300, seed=2))["psnr"]
    assert first == again and first.settings.resamples == 300 and first.settings.seed == 2
    assert "300 resamples, seed 2" in first.settings.describe()


def test_pair_targets_keeps_the_shared_targets_and_refuses_duplicates() -> None:
    def rows(frames: list[str], psnr: float) -> pd.DataFrame:
        return pd.DataFrame(
            {"protocol": "p", "group": "g", "scene": "s", "frame": frames, "psnr": [psnr] * len(frames)}
        )

    pairs = pair_targets(rows(["f0", "f1", "f2"], 2.0), rows(["f1", "f2", "f3"], 1.0), ["psnr"])
    assert pairs["frame"].tolist() == ["f1", "f2"] and pairs["psnr_a"].tolist() == [2.0, 2.0]
    with pytest.raises(PairingError, match="several rows for one target"):
        pair_targets(rows(["f0", "f0"], 2.0), rows(["f0"], 1.0), ["psnr"])
    with pytest.raises(PairingError, match="no column"):
        pair_targets(rows(["f0"], 2.0), rows(["f0"], 1.0), ["ssim"])
    with pytest.raises(PairingError, match="no shared targets"):
        paired_differences(pairs.iloc[0:0], ["psnr"])
