"""Group rules on datasets written in their official layouts and read by the loaders."""

from __future__ import annotations

import numpy as np
import pytest

from setdiff_bench.errors import ProtocolError
from setdiff_bench.loaders import load_scenes
from setdiff_bench.packets.packing import applicable_groups
from setdiff_bench.protocols import load_protocol
from setdiff_bench.protocols.rules import sparse_view_indices, uniform_indices
from tests.protocols.protocol_fixtures import (
    T0_US,
    paralane_scene,
    write_dl3dv_scene,
    write_euvs_scene,
    write_nuscenes,
)

KEYFRAMES_S = [0.0, 5.0, 9.999999, 10.0, 10.5, 11.0, 11.999999, 12.0, 13.0, 14.0, 14.999999, 15.0, 16.0]
SWEEPS_S = [9.5, 10.2]


def offsets(frames) -> list[float]:
    return sorted({round((f.timestamp_us - T0_US) / 1e6, 6) for f in frames})


def test_nuscenes_buckets_split_exactly_at_whole_seconds(tmp_path):
    write_nuscenes(tmp_path, KEYFRAMES_S, SWEEPS_S)
    protocol = load_protocol("nuscenes")
    [scene] = load_scenes("nuscenes", tmp_path, **protocol.loader_options)
    expected = {
        "10-11s": [10.0, 10.5],
        "11-12s": [11.0, 11.999999],
        "12-13s": [12.0],
        "13-14s": [13.0],
        "14-15s": [14.0, 14.999999],
    }
    assert [g.name for g in protocol.groups] == list(expected)
    for group in protocol.groups:
        frames = group.select(scene)
        assert (
            offsets(frames.targets) == expected[group.name]
        )  # keyframes only: the 10.2 s sweep is not a target
        assert {f.sensor for f in frames.targets} == {"CAM_FRONT", "CAM_BACK"}
        assert offsets(frames.fit) == [0.0, 5.0, 9.5, 9.999999]  # [0, 10) s, sweeps included
        assert group.fit_key == "first_10s"
    every = {t for g in protocol.groups for t in offsets(g.select(scene).targets)}
    assert 15.0 not in every and 16.0 not in every


def test_dl3dv_sparse_views_follow_the_3dgs_enhancer_gap_rule(tmp_path):
    test_hash = "0a78c25f77c1ba1d1a3f07c18c9735ae1254a9a71290734b8836eefbefaadbc7"
    write_dl3dv_scene(tmp_path / "1K" / test_hash, 300)
    protocol = load_protocol("dl3dv")
    [scene] = load_scenes("dl3dv", tmp_path, **protocol.loader_options)
    assert protocol.split.assign([test_hash, "f" * 64]) == {test_hash: "test", "f" * 64: "train"}
    names = list(scene.frame_names)
    assert names[0] == "frame_00001.png" and len(names) == 300
    picked = {g.name: g.select(scene) for g in protocol.groups}
    assert [names.index(f.name) for f in picked["n3"].fit] == [0, 50, 100]
    assert [names.index(f.name) for f in picked["n6"].fit] == [0, 50, 100, 150, 200, 250]
    assert [names.index(f.name) for f in picked["n9"].fit] == list(range(0, 201, 25))  # 9·50 > 300 → gap 25
    # targets: every frame strictly between the first and last training view that is not one
    assert [names.index(f.name) for f in picked["n3"].targets] == [i for i in range(1, 100) if i != 50]
    assert len(picked["n9"].targets) == 200 - 1 - 7


@pytest.mark.parametrize(
    ("frames", "views", "expected"),
    [
        (300, 3, [0, 50, 100]),
        (300, 9, [0, 25, 50, 75, 100, 125, 150, 175, 200]),
        (150, 3, [0, 50, 100]),
        (149, 3, [0, 25, 50]),
        (100, 6, [0, 16, 32, 48, 64, 80]),
        (74, 3, [0, 24, 48]),
    ],
)
def test_sparse_view_gap_cases(frames, views, expected):
    assert sparse_view_indices(frames, views) == expected


def test_euvs_targets_are_test_set_txt_and_fit_is_every_other_model_image(tmp_path):
    rng = np.random.default_rng(5)
    fixture = write_euvs_scene(tmp_path / "Level 2" / "nuplan_vegas_location_1", rng)
    protocol = load_protocol("euvs")
    [scene] = load_scenes("euvs", tmp_path, **protocol.loader_options)
    [group] = applicable_groups(protocol, scene)
    assert group.name == "level2" and group.fit_key == "level2"
    frames = group.select(scene)
    listed = (tmp_path / "Level 2" / "nuplan_vegas_location_1" / "test_set.txt").read_text().split()
    assert sorted(f.name for f in frames.targets) == sorted(listed) == sorted(fixture.test)
    assert sorted(f.name for f in frames.fit) == sorted(set(fixture.views) - set(listed))


def test_euvs_scene_without_level_matches_no_group(tmp_path):
    write_euvs_scene(tmp_path / "somewhere", np.random.default_rng(6))
    protocol = load_protocol("euvs")
    [scene] = load_scenes("euvs", tmp_path, **protocol.loader_options)
    with pytest.raises(ProtocolError, match="matches no group") as error:
        applicable_groups(protocol, scene)
    assert str(protocol.path) in str(error.value) and "somewhere" in str(error.value)


def test_paralane_lane_shifts_sample_uniformly():
    assert uniform_indices(10, 4) == [0, 3, 6, 9]
    assert uniform_indices(5, 25) == [0, 1, 2, 3, 4]
    assert uniform_indices(26, 25) == [
        *range(0, 13),
        *range(14, 26),
    ]  # k·25/24 at k = 12 is 12.5 → 12 (half to even)
    scene = paralane_scene({0: 250, 1: 31, 2: 20})
    protocol = load_protocol("paralane")
    single, double = protocol.group("single").select(scene), protocol.group("double").select(scene)
    lane0 = [f for f in scene.frames if f.metadata["lane"] == 0]
    lane1 = [f for f in scene.frames if f.metadata["lane"] == 1]
    assert len(single.fit) == 200 and single.fit[0] is lane0[0] and single.fit[-1] is lane0[-1]
    steps = np.diff([lane0.index(f) for f in single.fit])
    assert set(steps) == {1, 2}  # 250 frames → 200 picks: spacing 249/199 ≈ 1.25
    assert [lane1.index(f) for f in single.targets] == [
        0,
        1,
        2,
        4,
        5,
        6,
        8,
        9,
        10,
        11,
        12,
        14,
        15,
        16,
        18,
        19,
        20,
        21,
        22,
        24,
        25,
        26,
        28,
        29,
        30,
    ]  # 1.25·k, halves to even
    assert {f.traversal for f in double.targets} == {"clip_2"} and len(double.targets) == 20
    assert single.fit == double.fit and protocol.group("single").fit_key == "clip_0"


def test_holdout_every_takes_every_8th_frame_as_target():
    """Generic captures: indices 0, 8, 16, … are held out (Mip-NeRF 360 / 3DGS), the rest are fitted."""
    from types import SimpleNamespace

    from setdiff_bench.protocols.rules import RULES

    frames = tuple(SimpleNamespace(name=f"{i:04d}.jpg") for i in range(20))
    chosen = RULES["holdout_every"].select(SimpleNamespace(frames=frames), {"every": 8})
    assert [f.name for f in chosen.targets] == ["0000.jpg", "0008.jpg", "0016.jpg"]
    assert len(chosen.fit) == 17 and not {f.name for f in chosen.fit} & {f.name for f in chosen.targets}
    group = load_protocol("nerfstudio").groups[0]
    assert (group.name, group.rule, group.params) == ("holdout8", "holdout_every", {"every": 8})
