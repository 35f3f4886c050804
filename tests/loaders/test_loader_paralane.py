"""Para-Lane: scene_i/clip_{0,1,2} as lanes, COLMAP text, timestamp folders, lidar poses (x,y,z,w), masks."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from setdiff_bench.errors import CameraError
from setdiff_bench.loaders import list_scenes, load_scenes
from tests.loaders.loader_fixtures import (
    assert_projects,
    intrinsics,
    random_view,
    write_colmap_text_by_hand,
    write_image,
    write_mask,
)

T0 = 1718346704099615
LANE_WIDTH = 3.5
MASK_FOLDERS = {"clip_0": "foreground_mask", "clip_1": "foreground_masks", "clip_2": "foreground_labels"}


def _write_clip(clip_dir, lane: int, rng):
    """Four frames 10 Hz apart; NAME styles differ per clip (full path, stem, unrelated → order fallback)."""
    stamps = [T0 + 100_000 * i + 7 * lane for i in range(4)]
    views, expected_lidar, names = {}, {}, {}
    lidar_lines = []
    for i, stamp in enumerate(stamps):
        center = np.array([2.0 * i, LANE_WIDTH * lane, 1.5])
        name = {0: f"{stamp}/CAMERA_FRONT.png", 1: f"{stamp}.png", 2: f"img_{i:04d}.png"}[lane]
        views[name] = random_view(rng, intrinsics(), center=center)
        names[stamp] = name
        write_image(clip_dir / "images" / str(stamp) / "CAMERA_FRONT.png")
        write_mask(clip_dir / MASK_FOLDERS[clip_dir.name] / str(stamp) / "CAMERA_FRONT.png", keep=False)
        q_xyzw = Rotation.random(random_state=int(rng.integers(1 << 31))).as_quat()
        position = center + np.array([0.0, 0.0, 0.3])
        lidar_lines.append(f"{stamp}.ply {' '.join(repr(float(v)) for v in (*q_xyzw, *position))}")
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat(q_xyzw).as_matrix()  # scipy's order is x, y, z, w
        pose[:3, 3] = position
        expected_lidar[str(stamp)] = pose
    # images.txt lists them out of time order on purpose
    ordered = dict(reversed(list(views.items())))
    write_colmap_text_by_hand(clip_dir / "sparse" / "0", ordered)
    (clip_dir / "sparse" / "0" / "lidar_poses.txt").write_text("\n".join(lidar_lines) + "\n")
    return stamps, views, names, expected_lidar


@pytest.fixture
def paralane_root(tmp_path):
    rng = np.random.default_rng(41)
    clips = {}
    for lane in range(3):
        clips[f"clip_{lane}"] = _write_clip(tmp_path / "scene_0" / f"clip_{lane}", lane, rng)
    return tmp_path, clips


def test_lanes_frames_geometry_and_lidar(paralane_root):
    root, clips = paralane_root
    assert list_scenes("paralane", root) == ["scene_0"]
    with pytest.warns(UserWarning, match="pairing the 4 images with the timestamp folders by sorted order"):
        [scene] = load_scenes("paralane", root)
    assert scene.traversals == ("clip_0", "clip_1", "clip_2")
    assert scene.sensors == ("CAMERA_FRONT",)
    assert len(scene.frames) == 12
    keys = [(f.metadata["lane"], f.timestamp_us) for f in scene.frames]
    assert keys == sorted(keys)
    for frame in scene.frames:
        stamps, views, names, lidar = clips[frame.traversal]
        assert isinstance(frame.timestamp_us, int) and frame.timestamp_us in stamps
        assert frame.name == f"{frame.traversal}/{frame.timestamp_us}/CAMERA_FRONT.png"
        view = views[names[frame.timestamp_us]]
        assert_projects(frame.camera, view.points, view.expected_pixels())
        assert frame.metadata["lane"] == int(frame.traversal[-1])
        np.testing.assert_allclose(
            frame.metadata["lidar_to_world"], lidar[str(frame.timestamp_us)], atol=1e-12
        )
        assert frame.mask_path is None  # foreground masks: 255 = moving, not the keep convention
        assert frame.metadata["foreground_mask_path"].parts[-3] == MASK_FOLDERS[frame.traversal]
    # cameras of neighbouring lanes sit one lane width apart at equal times
    first = {f.traversal: f for f in scene.frames if f.timestamp_us - 7 * f.metadata["lane"] == T0}
    offset = first["clip_1"].camera.center - first["clip_0"].camera.center
    np.testing.assert_allclose(offset, [0.0, LANE_WIDTH, 0.0], atol=1e-9)
    assert scene.metadata["lanes"] == {"clip_0": 0, "clip_1": 1, "clip_2": 2}


def test_mask_polarity_keep_and_lane_override(paralane_root):
    root, _ = paralane_root
    with pytest.warns(UserWarning):
        [scene] = load_scenes(
            "paralane", root, mask_polarity="keep", lane_of_clip={"clip_0": 2, "clip_1": 1, "clip_2": 0}
        )
    assert all(frame.mask_path is not None and frame.mask_path.is_file() for frame in scene.frames)
    assert scene.traversals == ("clip_2", "clip_1", "clip_0")


def test_lidar_quaternion_norm_off(paralane_root):
    root, _ = paralane_root
    path = root / "scene_0" / "clip_0" / "sparse" / "0" / "lidar_poses.txt"
    lines = path.read_text().splitlines()
    fields = lines[2].split()
    fields[1:5] = [repr(float(v) * 0.995) for v in fields[1:5]]
    lines[2] = " ".join(fields)
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(CameraError, match=r"quaternion \(xyzw\) has norm 0\.995") as info:
        load_scenes("paralane", root, ["scene_0"])
    assert f"{path} (line 3)" in str(info.value)
