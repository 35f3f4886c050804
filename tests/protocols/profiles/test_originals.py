"""Profiles that score the original captures read them (and their masks) from the dataset layout."""

from __future__ import annotations

import numpy as np

from setdiff_bench.evaluation.profile_scoring import _Originals, profile_pair
from setdiff_bench.protocols.profiles import get_profile
from tests.loaders.loader_fixtures import HEIGHT, MARS_TEST, WIDTH, write_euvs_scene, write_mask


def test_euvs_original_capture_mask_and_crop_window(tmp_path):
    scene = "MARS_location_62_scene_03"
    write_euvs_scene(tmp_path / "Level 3" / scene, np.random.default_rng(3))
    frame = MARS_TEST[0]
    mask_path = tmp_path / "Level 3" / scene / "dynamic_masks" / (frame.removesuffix(".jpg") + ".png")
    write_mask(mask_path, keep=False)  # 0 everywhere: nothing evaluated
    row = {"dataset": "euvs", "protocol": "euvs", "scene": scene, "frame": frame}
    original, mask, window = _Originals(tmp_path).target(row)
    assert original.shape == (HEIGHT, WIDTH, 3) and original.dtype == np.uint8
    assert mask.shape == (HEIGHT, WIDTH) and not mask.any()
    # 32x24 is 4:3; the working 576x1024 is 16:9: full width, height round(32*9/16) = 18, top (24-18)//2 = 3
    assert window == (0, 3, 32, 18)
    pair = profile_pair(
        get_profile("euvs_official"), np.zeros((576, 1024, 3), np.uint8), original, mask, window
    )
    assert pair.ground_truth.shape == (18, 32, 3) and pair.prediction.shape == (18, 32, 3)
    assert np.array_equal(pair.ground_truth, original[3:21])
