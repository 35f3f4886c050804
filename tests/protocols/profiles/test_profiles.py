"""Evaluation profiles: each official rule reproduced on small fixtures with hand-computed values."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.profile_scoring import profile_pair
from setdiff_bench.protocols.profiles import (
    PROFILES,
    aggregate,
    centre_crop_box,
    get_profile,
    nearest_resize_mask,
    pil_resize,
    render_size,
)


def test_render_size_caps_width_at_1600_as_3dgs():
    assert render_size(1920, 1080) == (1600, 900)  # nuPlan-level EUVS images
    assert render_size(1921, 1080) == (1600, 899)  # 1080 / 1.200625 = 899.53 -> truncated
    assert render_size(4000, 3000) == (1600, 1200)
    assert render_size(1600, 900) == (1600, 900)  # at the cap: unchanged
    assert render_size(960, 540) == (960, 540)


def test_centre_crop_box_is_pil_rounding():
    assert centre_crop_box(960, 540, 960, 512) == (0, 14, 960, 526)  # DL3DV images_4 -> 960x512
    # 961 wide: left 0.5 -> 0, right 960.5 -> 960 (half to even): still 960 columns
    assert centre_crop_box(961, 540, 960, 512) == (0, 14, 960, 526)
    # 1024x576 render: left 32, top 32
    assert centre_crop_box(1024, 576, 960, 512) == (32, 32, 992, 544)


def test_pil_resize_bicubic_matches_pillow_and_mask_nearest_matches_floor_rule():
    from PIL import Image

    rng = np.random.default_rng(0)
    image = rng.integers(0, 256, (9, 16, 3), dtype=np.uint8)
    expected = np.asarray(Image.fromarray(image).resize((10, 6), Image.Resampling.BICUBIC))
    assert np.array_equal(pil_resize(image, (10, 6)), expected)
    mask = np.zeros((4, 4), bool)
    mask[:, 3] = True
    # nearest 4 -> 2 columns takes source columns floor(0*2)=0 and floor(1*2)=2: column 3 is never sampled
    assert not nearest_resize_mask(mask, (2, 4)).any()
    # 4 -> 8 columns: source floor(j/2): destination columns 6, 7 come from column 3
    out = nearest_resize_mask(mask, (8, 4))
    assert out[:, 6:].all() and not out[:, :6].any()


def test_scene_means_differ_from_pooled_means_on_a_hand_case():
    # scene A: three images 10, 20, 30 (mean 20); scene B: one image 40.
    frame = pd.DataFrame(
        {
            "method": ["m"] * 4,
            "group": ["g"] * 4,
            "scene": ["A", "A", "A", "B"],
            "frame": ["a1", "a2", "a3", "b1"],
            "psnr": [10.0, 20.0, 30.0, 40.0],
        }
    )
    pooled, _ = aggregate(frame, ["psnr"], "pooled")
    scene_mean, scenes = aggregate(frame, ["psnr"], "scene_mean")
    assert pooled["psnr"].item() == pytest.approx(25.0)  # (10+20+30+40)/4
    assert scene_mean["psnr"].item() == pytest.approx(30.0)  # (20+40)/2
    assert scenes.set_index("scene")["psnr"].to_dict() == {"A": 20.0, "B": 40.0}
    assert scenes.set_index("scene")["images"].to_dict() == {"A": 3, "B": 1}
    assert (scene_mean["scenes"].item(), scene_mean["images"].item()) == (2, 4)


def test_profiles_are_declared_and_unknown_names_are_refused():
    assert set(PROFILES) >= {"paper", "euvs_official", "dl3dv_3dgs_enhancer"}
    euvs = get_profile("euvs_official")
    assert (euvs.size, euvs.max_width, euvs.aggregation, euvs.scenes) == (
        "render_capped",
        1600,
        "scene_mean",
        "all",
    )
    dl3dv = get_profile("dl3dv_3dgs_enhancer")
    assert (dl3dv.metrics, dl3dv.crop, dl3dv.aggregation) == (("psnr",), (512, 960), "scene_mean")
    with pytest.raises(UsageError, match="known: paper"):
        get_profile("nope")


def test_euvs_pair_is_scored_at_1600x900_and_dl3dv_pair_at_960x512():
    rng = np.random.default_rng(1)
    prediction = rng.integers(0, 256, (576, 1024, 3), dtype=np.uint8)
    original = rng.integers(0, 256, (1080, 1920, 3), dtype=np.uint8)
    mask = np.ones((1080, 1920), bool)
    mask[:540] = False
    pair = profile_pair(get_profile("euvs_official"), prediction, original, mask, (0, 0, 1920, 1080))
    assert pair.ground_truth.shape == (900, 1600, 3) and pair.prediction.shape == (900, 1600, 3)
    assert pair.mask.shape == (900, 1600) and pair.mask[:450].sum() == 0 and pair.mask[450:].all()
    from PIL import Image

    expected = np.asarray(Image.fromarray(original).resize((1600, 900), Image.Resampling.BICUBIC))
    assert np.array_equal(pair.ground_truth, expected)
    small = rng.integers(0, 256, (540, 960, 3), dtype=np.uint8)
    pair = profile_pair(
        get_profile("dl3dv_3dgs_enhancer"), prediction, small, np.ones((540, 960), bool), (0, 0, 960, 540)
    )
    assert pair.ground_truth.shape == (512, 960, 3) and pair.prediction.shape == (512, 960, 3)
    assert np.array_equal(pair.ground_truth, small[14:526])  # native size: GT untouched, rows 14..525


def test_leaderboard_of_euvs_official_uses_every_scene_scene_means_and_its_metrics():
    from setdiff_bench.reporting.leaderboard import build_leaderboard, render_markdown

    # level1: scene A (test split) images 10 and 20 dB, scene B (train split) one image 40 dB
    frame = pd.DataFrame(
        {
            "dataset": "euvs",
            "protocol": "euvs",
            "group": "level1",
            "method": "identity",
            "run": "r",
            "profile": "euvs_official",
            "scene": ["A", "A", "B"],
            "frame": ["a1", "a2", "b1"],
            "split": ["test", "test", "train"],
            "psnr_euvs": [10.0, 20.0, 40.0],
            "ssim_euvs": [0.5, 0.7, 0.9],
            "lpips_euvs": [0.3, 0.1, 0.2],
            "cos_dinov2": [0.8, 0.6, 1.0],
            "final_score": [1.0, 2.0, 3.0],
        }
    )
    board = build_leaderboard("euvs", frame, profile="euvs_official")
    values = board.rows[0].values
    assert values[("level1", "psnr_euvs")] == pytest.approx(
        (15.0 + 40.0) / 2
    )  # not 23.33 pooled, not 15 test-only
    assert values[("level1", "cos_dinov2")] == pytest.approx((0.7 + 1.0) / 2)
    assert values[("level1", "final_score")] == pytest.approx((1.5 + 3.0) / 2)
    assert "evaluation profile: euvs_official" in render_markdown(board)
