"""Novel trajectories (issue 41): spec parsing, shifted / yawed / file cameras, scene bounds, bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import CameraError, UsageError
from setdiff_bench.packets.trajectory import (
    TrajectorySpec,
    check_within_bounds,
    novel_cameras,
    parse_trajectory,
    scene_bounds,
)

K = np.array([[50.0, 0.0, 32.0], [0.0, 50.0, 24.0], [0.0, 0.0, 1.0]])


def driving_camera(x: float) -> Camera:
    """World z up; the camera at (x, 0, 1.5) looks along +x: its right is world -y, its down world -z."""
    c2w = np.eye(4)
    c2w[:3, :3] = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # columns: right, down, fwd
    c2w[:3, 3] = (x, 0.0, 1.5)
    return Camera.from_c2w(c2w, K, 64, 48)


HALF_K = np.array([[25.0, 0.0, 16.0], [0.0, 25.0, 12.0], [0.0, 0.0, 1.0]])
RECORDED = [(f"front_{i}", driving_camera(2.0 * i)) for i in range(3)]


def test_parse_specs() -> None:
    assert parse_trajectory("shift:3") == TrajectorySpec("shift", 3.0)
    assert parse_trajectory("shift:-1.5").label == "shift-1.5m"
    assert parse_trajectory("yaw:10").label == "yaw+10deg"
    for bad in ("shift", "shift:", "shift:abc", "shift:nan", "shift:inf", "roll:3", "lane:3"):
        with pytest.raises(UsageError) as info:
            parse_trajectory(bad)
        assert str(info.value).startswith("--trajectory: ") and "\n" not in str(info.value)
    with pytest.raises(UsageError, match="trajectory file not found"):
        parse_trajectory("/no/such/poses.json")


def test_shift_moves_each_camera_to_its_right_by_hand() -> None:
    moved = novel_cameras(parse_trajectory("shift:3"), RECORDED)
    assert [name for name, _ in moved] == ["front_0@shift+3m", "front_1@shift+3m", "front_2@shift+3m"]
    for (_, before), (_, after) in zip(RECORDED, moved, strict=True):
        # right of a camera looking along +x with z up is world -y: 3 m right = y - 3
        assert np.allclose(after.center, before.center + np.array([0.0, -3.0, 0.0]))
        assert np.allclose(after.R, before.R) and np.array_equal(after.K, before.K)
        assert (after.width, after.height) == (64, 48)


def test_yaw_turns_each_camera_right_about_its_vertical_axis() -> None:
    [(_, turned)] = novel_cameras(parse_trajectory("yaw:90"), RECORDED[:1])
    before = RECORDED[0][1]
    assert np.allclose(turned.center, before.center)
    # forward (camera z) of the turned camera = world direction of the old right: world -y
    assert np.allclose(turned.R[2], [0.0, -1.0, 0.0], atol=1e-12)
    [(_, small)] = novel_cameras(parse_trajectory("yaw:-30"), RECORDED[:1])
    assert float(small.R[2] @ before.R[2]) == pytest.approx(math.cos(math.radians(30)))
    assert float(small.R[2] @ [0.0, 1.0, 0.0]) == pytest.approx(math.sin(math.radians(30)))  # turned left


def _write(tmp_path: Path, poses: object) -> Path:
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(poses, allow_nan=True))
    return path


def test_pose_file_cameras(tmp_path: Path) -> None:
    c2w = np.eye(4)
    c2w[:3, 3] = (1.0, 2.0, 3.0)
    path = _write(
        tmp_path,
        {
            "poses": [
                {"name": "a", "c2w": c2w.tolist()},
                {"c2w": c2w.tolist(), "width": 32, "height": 24, "K": HALF_K.tolist()},
            ]
        },
    )
    cameras = novel_cameras(parse_trajectory(str(path)), RECORDED)
    assert [name for name, _ in cameras] == ["a", "pose_0001"]
    assert np.allclose(cameras[0][1].center, (1.0, 2.0, 3.0)) and np.array_equal(cameras[0][1].K, K)
    assert (cameras[1][1].width, cameras[1][1].height) == (32, 24)


@pytest.mark.parametrize(
    ("pose", "message"),
    [
        ({"c2w": (np.eye(4) * [2.0, 1.0, 1.0, 1.0]).tolist()}, "rotation is not orthonormal"),
        ({"c2w": np.diag([1.0, 1.0, -1.0, 1.0]).tolist()}, "a reflection"),
        ({"c2w": [[math.nan, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]}, "NaN"),
    ],
)
def test_non_rigid_or_nan_pose_is_one_line_naming_the_file(tmp_path: Path, pose: dict, message: str) -> None:
    path = _write(tmp_path, [{"c2w": np.eye(4).tolist()}, pose])
    with pytest.raises(CameraError) as info:
        novel_cameras(parse_trajectory(str(path)), RECORDED)
    text = str(info.value)
    assert text.startswith(f"{path} (pose 1): ") and message in text and "\n" not in text


def test_malformed_pose_files(tmp_path: Path) -> None:
    for content, message in (
        ([], "non-empty JSON list"),
        ([{"name": "x"}], "'c2w' 4x4 matrix"),
        ([{"c2w": np.eye(4).tolist(), "width": 3.5}], "width and height must be integers"),
        (
            [{"name": "x", "c2w": np.eye(4).tolist()}, {"name": "x", "c2w": np.eye(4).tolist()}],
            "duplicate pose name 'x'",
        ),
    ):
        with pytest.raises(UsageError, match=message):
            novel_cameras(parse_trajectory(str(_write(tmp_path, content))), RECORDED)
    (tmp_path / "broken.json").write_text("{")
    with pytest.raises(UsageError, match="unreadable trajectory file"):
        novel_cameras(parse_trajectory(str(tmp_path / "broken.json")), RECORDED)


def test_scene_bounds_and_a_shift_that_leaves_them() -> None:
    rng = np.random.default_rng(0)
    # a street 0..10 m long, -5..5 m wide, 0..4 m high, and two far floaters the percentiles ignore
    points = rng.uniform([0.0, -5.0, 0.0], [10.0, 5.0, 4.0], size=(2000, 3))
    points = np.vstack([points, [[500.0, 500.0, 500.0], [-500.0, 0.0, 0.0]]])
    low, high = scene_bounds(points)
    assert np.allclose(low, [-0.5, -5.5, -0.2], atol=0.2) and np.allclose(high, [10.5, 5.5, 4.2], atol=0.2)
    check_within_bounds(novel_cameras(parse_trajectory("shift:3"), RECORDED), (low, high), "shift:3")
    with pytest.raises(UsageError) as info:
        check_within_bounds(novel_cameras(parse_trajectory("shift:8"), RECORDED), (low, high), "shift:8")
    text = str(info.value)
    assert text.startswith("shift:8: 3 of 3 cameras leave the scene bounds") and "'front_0@shift+8m'" in text
    with pytest.raises(UsageError, match="fewer than 2 Gaussians"):
        scene_bounds(np.zeros((1, 3)))


def test_recorded_cameras_outside_the_gaussians_extend_the_bounds() -> None:
    points = np.random.default_rng(1).uniform([0.0, 0.0, 5.0], [1.0, 1.0, 6.0], size=(500, 3))
    centres = np.array([[0.5, 0.5, 0.0]])  # an object-centric camera in front of the reconstruction
    low, high = scene_bounds(points, centres)
    assert low[2] == pytest.approx(0.0 - 0.05 * (high[2] - low[2]) / 1.1, abs=0.05)
    assert (centres[0] >= low).all() and (centres[0] <= high).all()
