"""nuScenes from the JSON tables: keyframes + sweeps through next chains, ego ∘ sensor poses, bad tables."""

from __future__ import annotations

import numpy as np
import pytest

from setdiff_bench.errors import CameraError, DatasetError, ImageError
from setdiff_bench.loaders import list_scenes, load_scenes
from tests.loaders.loader_fixtures import NU_CAMERAS, assert_projects, build_nuscenes, write_json


@pytest.fixture
def nu(tmp_path):
    fixture = build_nuscenes(tmp_path, np.random.default_rng(51))
    fixture.write()
    return fixture


def test_every_camera_frame_in_time_order_with_known_geometry(nu):
    assert list_scenes("nuscenes", nu.root) == ["scene-0061", "scene-0103"]
    [scene] = load_scenes("nuscenes", nu.root, ["scene-0061"])
    expected = {f.token: f for f in nu.frames["scene-0061"]}
    assert len(scene.frames) == len(expected) == 3 * (3 + 2 * 2)  # 3 cameras × (3 keyframes + 4 sweeps)
    stamps = [f.timestamp_us for f in scene.frames]
    assert stamps == sorted(stamps) and all(isinstance(s, int) for s in stamps)
    assert set(scene.sensors) == set(NU_CAMERAS)
    for frame in scene.frames:
        known = expected[frame.metadata["sample_data_token"]]
        assert (frame.sensor, frame.timestamp_us, frame.metadata["is_key_frame"]) == (
            known.channel,
            known.timestamp,
            known.is_key_frame,
        )
        assert frame.name.startswith("samples/" if known.is_key_frame else "sweeps/")
        assert frame.image_path == (nu.root / frame.name).resolve()
        assert_projects(frame.camera, known.points, known.pixels)
    assert scene.metadata["location"] == "singapore-onenorth"
    assert scene.metadata["version"] == "v1.0-mini"


def test_keyframes_only_and_channel_selection(nu):
    [keyframes] = load_scenes("nuscenes", nu.root, ["scene-0061"], sweeps=False)
    assert len(keyframes.frames) == 9 and all(f.metadata["is_key_frame"] for f in keyframes.frames)
    [back] = load_scenes("nuscenes", nu.root, ["scene-0103"], channels=["CAM_BACK"])
    assert back.sensors == ("CAM_BACK",) and len(back.frames) == 2 + 2
    with pytest.raises(DatasetError, match="unknown camera channel 'CAM_SIDE'"):
        load_scenes("nuscenes", nu.root, channels=["CAM_SIDE"])


def test_version_folder_choice(nu):
    write_json(nu.root / "v1.0-trainval" / "scene.json", [])
    with pytest.raises(DatasetError, match="several nuScenes versions"):
        list_scenes("nuscenes", nu.root)
    assert list_scenes("nuscenes", nu.root, version="v1.0-mini") == ["scene-0061", "scene-0103"]
    assert list_scenes("nuscenes", nu.root / "v1.0-mini") == ["scene-0061", "scene-0103"]


# ---------------------------------------------------------------------- bad input, one test per case
def test_missing_table(nu):
    (nu.root / "v1.0-mini" / "ego_pose.json").unlink()
    with pytest.raises(DatasetError) as info:
        load_scenes("nuscenes", nu.root)
    assert (
        str(info.value) == f"{nu.root / 'v1.0-mini' / 'ego_pose.json'}: missing nuScenes table ego_pose.json"
    )


def test_dangling_token(nu):
    record = nu.record("sample_data", "scene0_CAM_FRONT_LEFT_2")
    record["ego_pose_token"] = "no-such-pose"
    nu.write()
    with pytest.raises(DatasetError) as info:
        load_scenes("nuscenes", nu.root, ["scene-0061"])
    message = str(info.value)
    assert message.startswith(str(nu.root / "v1.0-mini" / "sample_data.json"))
    assert "'no-such-pose', which is not in ego_pose.json" in message


def test_integral_float_timestamp_is_accepted(nu):
    """Regression: nuScenes-format tables from other tools (Lyft via mmdetection3d, KAIST) store
    ``timestamp`` as ``1556675185850000.0``; it was refused as "must be a JSON int"."""
    record = nu.record("sample_data", "scene0_CAM_FRONT_LEFT_2")
    expected = record["timestamp"]
    record["timestamp"] = float(expected)
    nu.write()
    [scene] = load_scenes("nuscenes", nu.root, ["scene-0061"])
    [frame] = [f for f in scene.frames if f.metadata["sample_data_token"] == "scene0_CAM_FRONT_LEFT_2"]
    assert frame.timestamp_us == expected and isinstance(frame.timestamp_us, int)
    # fractional microseconds are rounded since issue 41 (tests/loaders/test_loader_nuscenes_timestamps.py)


def test_missing_field_is_named(nu):
    """Regression: an absent ``ego_pose_token`` was reported as "refers to token None"."""
    del nu.record("sample_data", "scene0_CAM_FRONT_LEFT_2")["ego_pose_token"]
    nu.write()
    with pytest.raises(DatasetError) as info:
        load_scenes("nuscenes", nu.root, ["scene-0061"])
    assert str(info.value) == (
        f"{nu.root / 'v1.0-mini' / 'sample_data.json'}: sample_data "
        "'scene0_CAM_FRONT_LEFT_2': missing field 'ego_pose_token'"
    )


def test_quaternion_norm_off(nu):
    pose = nu.record("ego_pose", "ego_scene0_CAM_BACK_1")
    pose["rotation"] = [v * 1.0015 for v in pose["rotation"]]
    nu.write()
    with pytest.raises(CameraError, match=r"norm 1\.0015") as info:
        load_scenes("nuscenes", nu.root, ["scene-0061"])
    assert str(nu.root / "v1.0-mini" / "ego_pose.json") in str(info.value)


def test_path_escaping_the_dataset_root(nu):
    nu.record("sample_data", "scene0_CAM_FRONT_0")["filename"] = "../../outside/x.jpg"
    nu.write()
    with pytest.raises(DatasetError, match="escapes the dataset root") as info:
        load_scenes("nuscenes", nu.root, ["scene-0061"])
    assert str(nu.root / "v1.0-mini" / "sample_data.json") in str(info.value)


def test_record_off_the_next_chain(nu):
    nu.record("sample_data", "scene0_CAM_FRONT_2")["next"] = ""  # chain cut after the third frame
    nu.write()
    with pytest.raises(DatasetError, match="is not on the next chain"):
        load_scenes("nuscenes", nu.root, ["scene-0061"])


def test_missing_sweep_image(nu):
    sweep = next(f for f in nu.frames["scene-0061"] if not f.is_key_frame)
    path = nu.root / nu.record("sample_data", sweep.token)["filename"]
    path.unlink()
    with pytest.raises(ImageError, match="sweeps=false") as info:
        load_scenes("nuscenes", nu.root, ["scene-0061"])
    assert str(path) in str(info.value)
    [scene] = load_scenes("nuscenes", nu.root, ["scene-0061"], sweeps=False)
    assert len(scene.frames) == 9


def test_image_size_differs_from_sample_data(nu):
    nu.record("sample_data", "scene1_CAM_FRONT_0")["width"] = 40
    nu.write()
    with pytest.raises(ImageError, match="says 40x24"):
        load_scenes("nuscenes", nu.root, ["scene-0103"])
