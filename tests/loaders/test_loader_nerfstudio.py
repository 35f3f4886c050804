"""nerfstudio transforms.json: OpenGL c2w → OpenCV w2c, applied_transform, rescaled intrinsics, bad input."""

from __future__ import annotations

import json

import numpy as np
import pytest

from setdiff_bench.errors import DatasetError, ImageError
from setdiff_bench.loaders import load_scenes
from setdiff_bench.loaders.nerfstudio import read_transforms
from tests.loaders.loader_fixtures import (
    NERFSTUDIO_APPLIED,
    assert_projects,
    intrinsics,
    random_view,
    write_image,
    write_transforms,
)

FULL = (128, 96)
QUARTER = np.diag([0.25, 0.25, 1.0])
DIST = np.array([0.04, -0.01, 0.002, 0.001])


def _scene(folder, seed: int, *, applied: bool, downscaled: bool):
    rng = np.random.default_rng(seed)
    K = intrinsics(fx=118.0, fy=121.0, cx=63.1, cy=47.7)
    views = {
        f"frame_{i:05d}.png": random_view(rng, K, width=FULL[0], height=FULL[1], dist=DIST) for i in (3, 1, 2)
    }
    write_transforms(folder, views, full_size=FULL, applied=applied)
    for name in views:
        if downscaled:
            write_image(folder / "images_4" / name, FULL[0] // 4, FULL[1] // 4)
        else:
            write_image(folder / "images" / name, *FULL)
    return views


@pytest.mark.parametrize("applied", [False, True])
def test_full_resolution_projects_known_points(tmp_path, applied):
    views = _scene(tmp_path / "garden", 21, applied=applied, downscaled=False)
    [scene] = load_scenes("nerfstudio", tmp_path)
    assert scene.name == "garden"
    assert scene.frame_names == ("images/frame_00001.png", "images/frame_00002.png", "images/frame_00003.png")
    for frame in scene.frames:
        view = views[frame.name.split("/")[-1]]
        assert frame.camera.distortion is not None
        assert_projects(frame.camera, view.points, view.expected_pixels())


@pytest.mark.parametrize("applied", [False, True])
def test_downscaled_folder_rescales_intrinsics(tmp_path, applied):
    views = _scene(tmp_path, 22, applied=applied, downscaled=True)
    frames = read_transforms(tmp_path / "transforms.json", images_dir="images_4")
    assert [f.name for f in frames] == [
        "images_4/frame_00003.png",
        "images_4/frame_00001.png",
        "images_4/frame_00002.png",
    ]
    for frame in frames:
        view = views[frame.image_path.name]
        assert (frame.camera.width, frame.camera.height) == (32, 24)
        assert_projects(frame.camera, view.points, view.expected_pixels(QUARTER @ view.K))
        assert frame.colmap_im_id in (1, 2, 3)


def test_file_world_keeps_the_applied_transform(tmp_path):
    views = _scene(tmp_path, 23, applied=True, downscaled=False)
    frames = read_transforms(tmp_path / "transforms.json", world="file")
    for frame in frames:
        view = views[frame.image_path.name]
        file_points = (NERFSTUDIO_APPLIED[:3, :3] @ view.points.T).T + NERFSTUDIO_APPLIED[:3, 3]
        assert_projects(frame.camera, file_points, view.expected_pixels())


def test_scaled_applied_transform_is_undone(tmp_path):
    views = _scene(tmp_path, 24, applied=False, downscaled=False)
    meta = json.loads((tmp_path / "transforms.json").read_text())
    A = np.eye(4)
    A[:3, :3] = 3.0 * np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    A[:3, 3] = [5.0, -2.0, 1.0]
    for entry in meta["frames"]:
        c2w = np.asarray(entry["transform_matrix"])
        moved = np.eye(4)
        moved[:3, :3] = A[:3, :3] / 3.0 @ c2w[:3, :3]
        moved[:3, 3] = A[:3, :3] @ c2w[:3, 3] + A[:3, 3]
        entry["transform_matrix"] = moved.tolist()
    meta["applied_transform"] = A[:3].tolist()
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    for frame in read_transforms(tmp_path / "transforms.json"):
        view = views[frame.image_path.name]
        assert_projects(frame.camera, view.points, view.expected_pixels())


def test_duplicate_frame_names(tmp_path):
    _scene(tmp_path, 25, applied=False, downscaled=False)
    meta = json.loads((tmp_path / "transforms.json").read_text())
    meta["frames"].append(dict(meta["frames"][0]))
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match=r"duplicate frame name .images/frame_00003\.png.") as info:
        read_transforms(tmp_path / "transforms.json")
    assert str(tmp_path / "transforms.json") in str(info.value)


def test_path_escaping_the_scene(tmp_path):
    _scene(tmp_path / "scene", 26, applied=False, downscaled=False)
    meta = json.loads((tmp_path / "scene" / "transforms.json").read_text())
    meta["frames"][1]["file_path"] = "../../outside.png"
    (tmp_path / "scene" / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="escapes the dataset root") as info:
        load_scenes("nerfstudio", tmp_path)
    assert str(tmp_path / "scene" / "transforms.json") in str(info.value)


def test_image_not_a_uniform_downscale(tmp_path):
    _scene(tmp_path, 27, applied=False, downscaled=True)
    bad = write_image(tmp_path / "images_4" / "frame_00002.png", 32, 30)
    with pytest.raises(ImageError, match="not a uniform rescale") as info:
        read_transforms(tmp_path / "transforms.json", images_dir="images_4")
    assert str(bad) in str(info.value)


def test_missing_intrinsic(tmp_path):
    _scene(tmp_path, 28, applied=False, downscaled=False)
    meta = json.loads((tmp_path / "transforms.json").read_text())
    del meta["fl_x"]
    (tmp_path / "transforms.json").write_text(json.dumps(meta))
    with pytest.raises(DatasetError, match="missing intrinsic 'fl_x'"):
        read_transforms(tmp_path / "transforms.json")


def test_frames_without_an_image_error_or_skip(tmp_path):
    """Regression: an instant-ngp capture (fox: 67 frames, 50 photos) was refused at the first absent
    image with no way to skip such frames."""
    _scene(tmp_path, 31, applied=False, downscaled=False)
    (tmp_path / "images" / "frame_00002.png").unlink()
    transforms = tmp_path / "transforms.json"
    with pytest.raises(DatasetError) as info:
        read_transforms(transforms)
    message = str(info.value)
    assert message.startswith(f"{transforms}: 1 of 3 frames name an image that does not exist")
    assert "frame_00002.png" in message and "-o missing=skip" in message
    with pytest.warns(
        UserWarning, match="1 of 3 frames name an image that does not exist; skipped"
    ) as caught:
        [scene] = load_scenes("nerfstudio", tmp_path, missing="skip")
    assert len(caught) == 1
    assert [f.name for f in scene.frames] == ["images/frame_00001.png", "images/frame_00003.png"]
    with pytest.raises(DatasetError, match="unknown missing-image policy 'drop'"):
        read_transforms(transforms, missing="drop")
