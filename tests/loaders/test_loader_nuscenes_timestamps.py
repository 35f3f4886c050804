"""Issue 41: nuScenes-schema tables with fractional-microsecond timestamps (mmdetection3d's Lyft tables).

A generated table (``build_nuscenes``) whose camera timestamps are moved by quarter microseconds —
exact in float64 at 1.5e15, whose spacing is 0.25 — so the rounded values are known by hand.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.errors import DatasetError
from setdiff_bench.loaders import load_scenes
from tests.loaders.loader_fixtures import build_nuscenes

#: offset in microseconds → what rounding to the nearest microsecond adds to the integer stamp
OFFSETS = {0.25: 0, 0.75: 1, -0.25: 0, -0.75: -1}


@pytest.fixture
def nu(tmp_path: Path):
    fixture = build_nuscenes(tmp_path, np.random.default_rng(41))
    fixture.write()
    return fixture


def test_fractional_timestamps_round_with_one_warning(nu) -> None:
    expected: dict[str, int] = {}
    offsets = list(OFFSETS.items())
    cameras = [r for r in nu.tables["sample_data"] if r["token"].startswith("scene0_CAM")]
    for i, record in enumerate(cameras):
        offset, added = offsets[i % len(offsets)]
        expected[record["token"]] = record["timestamp"] + added
        record["timestamp"] = record["timestamp"] + offset  # a float, e.g. 1532402927600000.25
        assert not float(record["timestamp"]).is_integer()
    nu.write()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        [scene] = load_scenes("nuscenes", nu.root, ["scene-0061"])
    lines = [str(w.message) for w in caught if "fractional microseconds" in str(w.message)]
    assert lines == [
        f"{nu.root / 'v1.0-mini' / 'sample_data.json'}: {len(cameras)} sample_data timestamp values are "
        "fractional microseconds; rounded to the nearest microsecond"
    ]
    assert len(scene.frames) == len(cameras)
    for frame in scene.frames:
        assert isinstance(frame.timestamp_us, int)
        assert frame.timestamp_us == expected[frame.metadata["sample_data_token"]]
    stamps = [f.timestamp_us for f in scene.frames]
    assert stamps == sorted(stamps)


def test_the_lyft_value_rounds_down(nu) -> None:
    """``1556675185903083.2`` (float64: ...083.25) → 1556675185903083 µs, as the issue quotes it."""
    record = nu.record("sample_data", "scene1_CAM_BACK_0")
    record["timestamp"] = 1556675185903083.2
    nu.write()
    with pytest.warns(UserWarning, match="1 sample_data timestamp values are fractional"):
        [scene] = load_scenes("nuscenes", nu.root, ["scene-0103"], channels=["CAM_BACK"])
    [frame] = [f for f in scene.frames if f.metadata["sample_data_token"] == "scene1_CAM_BACK_0"]
    assert frame.timestamp_us == 1556675185903083


def test_integral_tables_give_no_warning(nu) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_scenes("nuscenes", nu.root, ["scene-0061"])


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "1532402927600000", True])
def test_nan_infinity_and_strings_are_still_refused(nu, bad) -> None:
    record = nu.record("sample_data", "scene0_CAM_FRONT_LEFT_2")
    record["timestamp"] = bad
    nu.write()
    with pytest.raises(DatasetError) as info:
        load_scenes("nuscenes", nu.root, ["scene-0061"])
    message = str(info.value)
    assert message.startswith(f"{nu.root / 'v1.0-mini' / 'sample_data.json'}: ")
    assert "sample_data 'scene0_CAM_FRONT_LEFT_2' field 'timestamp' must be a JSON int" in message
    assert "\n" not in message
