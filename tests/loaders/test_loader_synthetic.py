"""Synthetic scenes: the EUVS layout + scene.json (traversal, camera, timestamps, lane offsets, split)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from setdiff_bench.errors import DatasetError
from setdiff_bench.loaders import list_scenes, load_scenes
from tests.loaders.loader_fixtures import SYN_CAMERAS, SYN_TRAVERSALS, assert_projects, write_synthetic_scene


@pytest.fixture
def synthetic_root(tmp_path):
    views = write_synthetic_scene(tmp_path / "scene_0000_00", np.random.default_rng(61))
    return tmp_path, views


def test_frames_annotated_from_scene_json(synthetic_root):
    root, views = synthetic_root
    assert list_scenes("synthetic", root) == ["scene_0000_00"]
    [scene] = load_scenes("synthetic", root)
    assert scene.dataset == "synthetic"
    expected_order = [
        f"{t}_{c}_{i:03d}.png" for t, _, _ in SYN_TRAVERSALS for c, _ in SYN_CAMERAS for i in range(3)
    ]
    assert list(scene.frame_names) == expected_order
    offsets = {name: offset for name, _, offset in SYN_TRAVERSALS}
    for frame in scene.frames:
        traversal, rest = frame.name.split("_", 1)
        camera, index = rest.rsplit("_", 1)
        assert (frame.traversal, frame.sensor) == (traversal, camera)
        assert frame.timestamp_us == int(index[:3]) * 100000
        assert frame.metadata["lane_offset"] == offsets[traversal]
        assert frame.split == (
            "train" if (traversal, camera) == ("lane0", "front") and index[:3] != "001" else "test"
        )
        assert frame.mask_path is not None and frame.mask_path.name == frame.name
        assert_projects(frame.camera, views[frame.name].points, views[frame.name].expected_pixels())
    assert scene.traversals == ("lane0", "lane1", "turn")
    assert scene.metadata["lane_width_m"] == 3.5


def test_split_disagreeing_with_set_files(synthetic_root):
    root, _ = synthetic_root
    path = root / "scene_0000_00" / "scene.json"
    meta = json.loads(path.read_text())
    meta["frames"][0]["split"] = "test" if meta["frames"][0]["split"] == "train" else "train"
    path.write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="disagrees with the set files") as info:
        load_scenes("synthetic", root)
    assert str(path) in str(info.value)


def test_frame_missing_from_scene_json(synthetic_root):
    root, _ = synthetic_root
    path = root / "scene_0000_00" / "scene.json"
    meta = json.loads(path.read_text())
    removed = meta["frames"].pop(3)["name"]
    path.write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match=f"no entry for frame '{removed}'"):
        load_scenes("synthetic", root)
