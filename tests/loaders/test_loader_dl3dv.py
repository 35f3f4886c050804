"""DL3DV: batch/hash folders, images_4 + COLMAP (full-res intrinsics) or transforms.json, HF sample layout."""

from __future__ import annotations

import numpy as np
import pytest

from setdiff_bench.errors import DatasetError
from setdiff_bench.loaders import list_scenes, load_scenes
from tests.loaders.loader_fixtures import (
    assert_projects,
    intrinsics,
    random_view,
    write_colmap,
    write_image,
    write_transforms,
)

HASH_A = "0a78c25f77c1ba1d1a3f07c18c9735ae1254a9a71290734b8836eefbefaadbc7"
HASH_B = "03f5c560f5725ad6ca55fd7e6c0af4c4c7a7ca94c444a584f2a9f316d3b35ea2"
HASH_C = "6a4a6c547d4a904697b5be22ce7fbacbeeca85de99badf7f2715aee3fd471a66"
FULL = (128, 72)
QUARTER = np.diag([0.25, 0.25, 1.0])
DIST = np.array([0.03, -0.01, 0.0005, -0.001])


def _views(seed: int):
    rng = np.random.default_rng(seed)
    K = intrinsics(fx=100.0, fy=101.0, cx=64.3, cy=35.9)
    return {
        f"frame_{i:05d}.png": random_view(rng, K, width=FULL[0], height=FULL[1], dist=DIST)
        for i in (10, 2, 1)
    }


def _images(folder, views):
    for name in views:
        write_image(folder / "images_4" / name, FULL[0] // 4, FULL[1] // 4)


@pytest.fixture
def dl3dv_root(tmp_path):
    views = {}
    scene_a = tmp_path / "1K" / HASH_A  # 960P / 3DGS-Enhancer: images_4 + colmap/sparse/0
    views[HASH_A] = _views(31)
    write_colmap(scene_a / "colmap" / "sparse" / "0", views[HASH_A], model="OPENCV")
    _images(scene_a, views[HASH_A])
    scene_b = tmp_path / "1K" / HASH_B  # images_4 + transforms.json only (nerfstudio world)
    views[HASH_B] = _views(32)
    write_transforms(scene_b, views[HASH_B], full_size=FULL, applied=True)
    _images(scene_b, views[HASH_B])
    scene_c = (
        tmp_path / "2K" / HASH_C / "colmap"
    )  # HF sample: colmap/{images_4, colmap/sparse/0, transforms.json}
    views[HASH_C] = _views(33)
    write_colmap(scene_c / "colmap" / "sparse" / "0", views[HASH_C], model="OPENCV")
    write_transforms(scene_c, views[HASH_C], full_size=FULL, applied=True)
    _images(scene_c, views[HASH_C])
    (tmp_path / "1K" / "not_a_scene").mkdir()
    return tmp_path, views


def test_scenes_project_known_points(dl3dv_root):
    root, views = dl3dv_root
    assert list_scenes("dl3dv", root) == [HASH_B, HASH_A, HASH_C]  # natural order of the hash
    scenes = {s.name: s for s in load_scenes("dl3dv", root)}
    assert scenes[HASH_A].metadata["batch"] == "1K" and scenes[HASH_C].metadata["batch"] == "2K"
    assert scenes[HASH_A].metadata["poses"] == "colmap" and scenes[HASH_B].metadata["poses"] == "transforms"
    for name, scene in scenes.items():
        assert scene.frame_names == ("frame_00001.png", "frame_00002.png", "frame_00010.png")
        for frame in scene.frames:
            view = views[name][frame.name]
            assert (frame.camera.width, frame.camera.height) == (32, 18)
            assert_projects(frame.camera, view.points, view.expected_pixels(QUARTER @ view.K))


def test_transforms_and_colmap_agree_and_policy_ignore(dl3dv_root):
    root, _ = dl3dv_root
    [from_colmap] = load_scenes("dl3dv", root, [HASH_C], poses="colmap")
    [from_json] = load_scenes("dl3dv", root, [HASH_C], poses="transforms")
    for a, b in zip(from_colmap.frames, from_json.frames):
        np.testing.assert_allclose(a.camera.w2c, b.camera.w2c, atol=1e-9)
        np.testing.assert_allclose(a.camera.K, b.camera.K, atol=1e-12)
    [pinhole] = load_scenes("dl3dv", root, [HASH_A], distortion="ignore")
    assert all(frame.camera.distortion is None for frame in pinhole.frames)


def test_batch_folder_as_root_and_unknown_scene(dl3dv_root):
    root, _ = dl3dv_root
    assert list_scenes("dl3dv", root / "1K") == [HASH_B, HASH_A]
    with pytest.raises(DatasetError, match="no dl3dv scene 'deadbeef'"):
        load_scenes("dl3dv", root, ["deadbeef"])
