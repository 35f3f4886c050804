"""EUVS layout: geometry, split files, masks paired by name, GT poses, level inference, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.errors import CameraError, DatasetError, ImageError, SetDiffBenchError
from setdiff_bench.loaders import list_scenes, load_scenes
from tests.loaders.loader_fixtures import MARS_NAMES, assert_projects, write_euvs_scene, write_image


@pytest.fixture
def euvs_root(tmp_path):
    rng = np.random.default_rng(11)
    scene = write_euvs_scene(tmp_path / "Level 3" / "MARS_location_62_scene_03", rng)
    return tmp_path, scene


def test_frames_cameras_split_and_masks(euvs_root):
    root, fixture = euvs_root
    assert list_scenes("euvs", root) == ["Level 3/MARS_location_62_scene_03"]
    [scene] = load_scenes("euvs", root)
    # natural order: traversal 6 before 11, then channel, then index
    assert scene.frame_names == (
        "trav_6_channel_1_img_001.jpg",
        "trav_6_channel_1_img_002.jpg",
        "trav_6_channel_2_img_001.jpg",
        "trav_11_channel_1_img_001.jpg",
        "trav_11_channel_1_img_002.jpg",
    )
    for frame in scene.frames:
        view = fixture.views[frame.name]
        assert_projects(frame.camera, view.points, view.expected_pixels())
        assert (frame.camera.width, frame.camera.height) == (32, 24)
        assert frame.split == ("test" if frame.name in fixture.test else "train")
        assert frame.mask_path is not None
        assert frame.mask_path.name == Path(frame.name).stem + ".png"  # paired by name, never by order
        assert frame.image_path == (fixture.folder / "images" / frame.name).resolve()
        assert frame.timestamp_us is None
    first = scene.frames[0]
    assert (first.traversal, first.sensor) == ("trav_6", "CAM_FRONT_CENTER")
    assert scene.frames[2].sensor == "CAM_FRONT_LEFT"
    assert scene.traversals == ("trav_6", "trav_11")
    assert scene.metadata["level"] == 3 and scene.metadata["level_source"] == "folder"
    assert scene.points3d is not None and scene.points3d.shape == (30, 3)


def test_ground_truth_poses(euvs_root):
    root, fixture = euvs_root
    [sfm] = load_scenes("euvs", root)
    [gt] = load_scenes("euvs", root, poses="gt")
    assert gt.points3d is None  # SfM points are in the other world
    for frame_sfm, frame_gt in zip(sfm.frames, gt.frames):
        gt_view = fixture.gt_views[frame_gt.name]
        assert_projects(frame_gt.camera, gt_view.points, gt_view.expected_pixels())
        np.testing.assert_allclose(frame_sfm.metadata["gt_w2c"], frame_gt.camera.w2c, atol=1e-12)
        expected_center = -gt_view.R.T @ gt_view.t
        np.testing.assert_allclose(frame_gt.camera.center, expected_center, atol=1e-9)


def test_level_given_inferred_from_name_or_unknown(tmp_path):
    rng = np.random.default_rng(12)
    write_euvs_scene(tmp_path / "MARS_location_15_scene_02", rng, gt_poses=False)
    write_euvs_scene(tmp_path / "level_2" / "nuplan_vegas_location_8", rng, gt_poses=False)
    write_euvs_scene(
        tmp_path / "nuplan_boston_location_3", rng, gt_poses=False, train_file="training_set.txt"
    )
    scenes = {s.name: s for s in load_scenes("euvs", tmp_path)}
    # natural order, case-sensitive (upper case first)
    assert list(scenes) == [
        "MARS_location_15_scene_02",
        "level_2/nuplan_vegas_location_8",
        "nuplan_boston_location_3",
    ]
    assert (
        scenes["MARS_location_15_scene_02"].metadata["level"],
        scenes["MARS_location_15_scene_02"].metadata["level_source"],
    ) == (3, "name")
    assert scenes["level_2/nuplan_vegas_location_8"].metadata["level"] == 2
    assert scenes["nuplan_boston_location_3"].metadata["level"] is None
    assert scenes["nuplan_boston_location_3"].metadata["train_set"] == "training_set.txt"
    [alone] = load_scenes("euvs", tmp_path / "level_2" / "nuplan_vegas_location_8")  # root = the scene
    assert (alone.name, alone.metadata["level"]) == ("nuplan_vegas_location_8", 2)
    [given] = load_scenes("euvs", tmp_path, ["nuplan_boston_location_3"], level=1)
    assert (given.metadata["level"], given.metadata["level_source"]) == (1, "given")


def test_frames_outside_set_files_train_and_mask_optional(tmp_path):
    rng = np.random.default_rng(13)
    fixture = write_euvs_scene(tmp_path / "s", rng, train_file=None)
    for name in MARS_NAMES:  # only test frames keep their masks
        if name not in fixture.test:
            (tmp_path / "s" / "dynamic_masks" / (Path(name).stem + ".png")).unlink()
    [scene] = load_scenes("euvs", tmp_path)
    for frame in scene.frames:
        assert frame.split == ("test" if frame.name in fixture.test else "train")
        assert (frame.mask_path is None) == (frame.split == "train")


# ---------------------------------------------------------------------- bad input, one test per case
def _rejected(root: Path, error: type[SetDiffBenchError], path: Path, problem: str, **options: str) -> None:
    """Loading ``root`` raises ``error``: one line naming ``path`` and ``problem``."""
    with pytest.raises(error) as info:
        load_scenes("euvs", root, **options)
    text = str(info.value)
    assert "\n" not in text
    assert str(path) in text, text
    assert problem in text, text


@pytest.mark.parametrize(
    ("text", "problem"),
    [("\n\n", "empty"), ("trav_99_channel_1_img_001.jpg\n", "no pose")],
    ids=["empty", "name_without_pose"],
)
def test_bad_test_set(euvs_root, text, problem):
    root, fixture = euvs_root
    (fixture.folder / "test_set.txt").write_text(text)
    _rejected(root, DatasetError, fixture.folder / "test_set.txt", problem)


def test_duplicate_frame_name_in_test_set(euvs_root):
    root, fixture = euvs_root
    (fixture.folder / "test_set.txt").write_text("\n".join([*fixture.test, fixture.test[0]]) + "\n")
    _rejected(root, DatasetError, fixture.folder / "test_set.txt", "duplicate frame name")


def test_test_image_without_mask(euvs_root):
    root, fixture = euvs_root
    (fixture.folder / "dynamic_masks" / "trav_11_channel_1_img_002.png").unlink()
    _rejected(
        root,
        DatasetError,
        fixture.folder / "dynamic_masks",
        "has no dynamic mask 'trav_11_channel_1_img_002.png'",
    )
    load_scenes("euvs", root, masks="optional")  # explicitly optional: accepted


def test_image_size_differs_from_camera(euvs_root):
    root, fixture = euvs_root
    bad = write_image(fixture.folder / "images" / "trav_6_channel_1_img_002.jpg", 33, 24)
    _rejected(root, ImageError, bad, "33x24")


def test_missing_image_file(euvs_root):
    root, fixture = euvs_root
    missing = fixture.folder / "images" / "trav_6_channel_2_img_001.jpg"
    missing.unlink()
    _rejected(root, ImageError, missing, "not found")


def test_gt_pose_quaternion_norm_off(euvs_root):
    root, fixture = euvs_root
    path = fixture.folder / "poses" / "images.txt"
    lines = path.read_text().split("\n")
    fields = lines[0].split()
    fields[1:5] = [repr(float(v) * 1.002) for v in fields[1:5]]
    lines[0] = " ".join(fields)
    path.write_text("\n".join(lines))
    _rejected(root, CameraError, path, "norm")


def test_image_name_escaping_the_dataset(tmp_path):
    rng = np.random.default_rng(14)
    names = ("a.jpg", "../escape.jpg")
    write_euvs_scene(tmp_path / "s", rng, names=names, test=("a.jpg",), masks=False, gt_poses=False)
    _rejected(
        tmp_path,
        DatasetError,
        tmp_path / "s" / "sparse" / "0" / "images.bin",
        "escapes the dataset root",
        masks="none",
    )
