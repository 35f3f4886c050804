"""COLMAP models through pycolmap: binary, text, legacy; PINHOLE / SIMPLE_PINHOLE / OPENCV; policies."""

from __future__ import annotations

import numpy as np
import pytest

from setdiff_bench.errors import CameraError, DatasetError, ImageError
from setdiff_bench.loaders import load_scenes
from setdiff_bench.loaders.colmap import read_colmap_model
from tests.loaders.loader_fixtures import (
    assert_projects,
    intrinsics,
    random_view,
    write_colmap,
    write_colmap_text_by_hand,
    write_image,
)

DIST = np.array([0.05, -0.02, 0.001, -0.0015])


def _views(rng, model: str, n: int = 3):
    K = intrinsics(fx=29.0, fy=29.0) if model == "SIMPLE_PINHOLE" else intrinsics()
    dist = DIST if model == "OPENCV" else None
    return {f"img_{i:02d}.png": random_view(rng, K, dist=dist) for i in range(n)}


@pytest.mark.parametrize("fmt", ["binary", "text"])
@pytest.mark.parametrize("model", ["PINHOLE", "SIMPLE_PINHOLE", "OPENCV"])
def test_model_projects_known_points(tmp_path, fmt, model):
    rng = np.random.default_rng(7)
    views = _views(rng, model)
    points = np.concatenate([v.points for v in views.values()])
    write_colmap(tmp_path, views, model=model, fmt=fmt, shared_camera=False, points=points)
    loaded = read_colmap_model(tmp_path)
    assert sorted(loaded.cameras) == sorted(views)
    for name, view in views.items():
        camera = loaded.cameras[name]
        assert (camera.width, camera.height) == (view.width, view.height)
        assert_projects(camera, view.points, view.expected_pixels())
        if model == "OPENCV":
            assert camera.distortion is not None and np.allclose(camera.distortion.params, DIST)
        else:
            assert camera.distortion is None
    np.testing.assert_allclose(loaded.points3d, points, atol=1e-12)
    assert loaded.points_rgb.tolist()[0] == [10, 20, 30]


def test_legacy_binary_model_without_rigs_and_frames(tmp_path):
    rng = np.random.default_rng(1)
    views = _views(rng, "PINHOLE")
    write_colmap(tmp_path, views)
    (tmp_path / "rigs.bin").unlink()
    (tmp_path / "frames.bin").unlink()
    loaded = read_colmap_model(tmp_path)
    for name, view in views.items():
        assert_projects(loaded.cameras[name], view.points, view.expected_pixels())


def test_hand_written_text_model_without_points3d(tmp_path):
    rng = np.random.default_rng(2)
    views = _views(rng, "PINHOLE")
    write_colmap_text_by_hand(tmp_path, views)
    loaded = read_colmap_model(tmp_path)
    assert len(loaded.points3d) == 0
    for name, view in views.items():
        assert_projects(loaded.cameras[name], view.points, view.expected_pixels())


def test_text_model_missing_points2d_lines_is_refused(tmp_path):
    views = _views(np.random.default_rng(3), "PINHOLE")
    write_colmap_text_by_hand(tmp_path, views, points2d=False)
    with pytest.raises(DatasetError, match="POINTS2D") as info:
        read_colmap_model(tmp_path)
    assert "images.txt" in str(info.value)


def test_distortion_policies(tmp_path):
    views = _views(np.random.default_rng(4), "OPENCV", n=1)
    write_colmap(tmp_path, views, model="OPENCV")
    ignored = read_colmap_model(tmp_path, distortion="ignore")
    view = next(iter(views.values()))
    assert ignored.cameras["img_00.png"].distortion is None
    # Ignoring distortion equals projecting with zero coefficients.
    view.dist = np.zeros(4)
    assert_projects(ignored.cameras["img_00.png"], view.points, view.expected_pixels())
    with pytest.raises(DatasetError, match="non-zero distortion") as info:
        read_colmap_model(tmp_path, distortion="error")
    assert "-o distortion=ignore" in str(info.value)  # the CLI's syntax, not only Python's


def test_quaternion_norm_off_is_refused(tmp_path):
    views = _views(np.random.default_rng(5), "PINHOLE", n=2)
    write_colmap_text_by_hand(tmp_path, views)
    text = (tmp_path / "images.txt").read_text().splitlines()
    fields = text[1].split()
    fields[1:5] = [repr(float(v) * 1.01) for v in fields[1:5]]
    text[1] = " ".join(fields)
    (tmp_path / "images.txt").write_text("\n".join(text) + "\n")
    with pytest.raises(CameraError, match="norm") as info:
        read_colmap_model(tmp_path)
    assert "images.txt" in str(info.value)


def test_missing_model_file(tmp_path):
    views = _views(np.random.default_rng(6), "PINHOLE", n=1)
    write_colmap(tmp_path, views)
    (tmp_path / "images.bin").unlink()
    with pytest.raises(DatasetError, match="missing COLMAP file images"):
        read_colmap_model(tmp_path)


def test_generic_dataset_rescales_a_downscaled_image_folder(tmp_path):
    rng = np.random.default_rng(8)
    K = intrinsics(fx=120.0, fy=112.0, cx=61.2, cy=50.4)
    views = {f"f{i}.png": random_view(rng, K, width=128, height=96) for i in range(2)}
    write_colmap(tmp_path / "room" / "sparse" / "0", views)
    for name in views:
        write_image(tmp_path / "room" / "images" / name, 128, 96)
        write_image(tmp_path / "room" / "images_4" / name, 32, 24)
    full = load_scenes("colmap", tmp_path)[0]
    quarter = load_scenes("colmap", tmp_path, images_dir="images_4")[0]
    assert full.name == "room" and full.frame_names == ("f0.png", "f1.png")
    scale = np.diag([0.25, 0.25, 1.0])
    for frame_full, frame_quarter in zip(full.frames, quarter.frames):
        view = views[frame_full.name]
        assert_projects(frame_full.camera, view.points, view.expected_pixels())
        assert (frame_quarter.camera.width, frame_quarter.camera.height) == (32, 24)
        assert_projects(frame_quarter.camera, view.points, view.expected_pixels(scale @ K))
    # The full-resolution folder must match the model exactly.
    write_image(tmp_path / "room" / "images" / "f1.png", 64, 48)
    with pytest.raises(ImageError, match="64x48"):
        load_scenes("colmap", tmp_path)
