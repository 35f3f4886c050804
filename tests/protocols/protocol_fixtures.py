"""Tiny datasets in official layouts for the protocol tests: nuScenes tables with chosen timestamps,
a DL3DV scene with N frames, EUVS scenes (through the loader tests' writer), in-memory Para-Lane scenes."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pycolmap
from scipy.spatial.transform import Rotation

from setdiff_bench.cameras import Camera
from setdiff_bench.types import Frame, Scene
from tests.loaders import loader_fixtures  # the loader tests' official-layout writers

T0_US = 1_532_402_927_000_000
EGO_FROM_CAMERA = np.array(
    [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
)  # camera z → ego x (forward)
K = np.array([[10.0, 0.0, 8.0], [0.0, 10.0, 6.0], [0.0, 0.0, 1.0]])


def write_image(path: Path, width: int = 16, height: int = 12) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), np.full((height, width, 3), 90, np.uint8))


def seconds_to_us(seconds: float) -> int:
    return T0_US + round(seconds * 1_000_000)


def write_nuscenes(
    root: Path,
    keyframes_s: list[float],
    sweeps_s: list[float],
    channels: tuple[str, ...] = ("CAM_FRONT", "CAM_BACK"),
) -> Path:
    """One scene ``scene-0001`` whose cameras fire at ``T0 + keyframes_s`` (samples) and ``T0 + sweeps_s``."""
    tables = loader_fixtures.nuscenes_tables("n000-fixture", "n000", "boston-seaport")
    keys = [seconds_to_us(s) for s in keyframes_s]
    samples = [f"sample{i}" for i in range(len(keys))]
    for i, (token, stamp) in enumerate(zip(samples, keys)):
        tables["sample"].append(
            {
                "token": token,
                "timestamp": stamp,
                "scene_token": "scene0",
                "prev": samples[i - 1] if i else "",
                "next": samples[i + 1] if i + 1 < len(keys) else "",
            }
        )
    tables["scene"].append(
        {
            "token": "scene0",
            "name": "scene-0001",
            "description": "fixture",
            "log_token": "log0",
            "nbr_samples": len(samples),
            "first_sample_token": samples[0],
            "last_sample_token": samples[-1],
        }
    )
    for c, channel in enumerate(channels):
        rotation = Rotation.from_euler("z", 180.0 * c, degrees=True).as_matrix() @ EGO_FROM_CAMERA
        tables["sensor"].append({"token": f"sensor_{channel}", "channel": channel, "modality": "camera"})
        tables["calibrated_sensor"].append(
            {
                "token": f"calib_{channel}",
                "sensor_token": f"sensor_{channel}",
                "translation": [1.0, 0.0, 1.5],
                "rotation": Rotation.from_matrix(rotation).as_quat(scalar_first=True).tolist(),
                "camera_intrinsic": K.tolist(),
            }
        )
        records = sorted([(stamp, True) for stamp in keys] + [(seconds_to_us(s), False) for s in sweeps_s])
        tokens = [f"{channel}_{j}" for j in range(len(records))]
        for j, (stamp, is_key) in enumerate(records):
            owner = (
                samples[keys.index(stamp)]
                if is_key
                else samples[next(i for i, k in enumerate(keys) if k > stamp)]
            )
            filename = f"{'samples' if is_key else 'sweeps'}/{channel}/n000-fixture__{channel}__{stamp}.jpg"
            write_image(root / filename)
            tables["ego_pose"].append(
                {
                    "token": f"ego_{tokens[j]}",
                    "timestamp": stamp,
                    "translation": [5.0 * (stamp - T0_US) / 1e6, 0.0, 0.0],
                    "rotation": [1.0, 0.0, 0.0, 0.0],
                }
            )
            tables["sample_data"].append(
                {
                    "token": tokens[j],
                    "sample_token": owner,
                    "ego_pose_token": f"ego_{tokens[j]}",
                    "calibrated_sensor_token": f"calib_{channel}",
                    "timestamp": stamp,
                    "fileformat": "jpg",
                    "is_key_frame": is_key,
                    "height": 12,
                    "width": 16,
                    "filename": filename,
                    "prev": tokens[j - 1] if j else "",
                    "next": tokens[j + 1] if j + 1 < len(records) else "",
                }
            )
    for name, records in tables.items():
        (root / "v1.0-mini").mkdir(parents=True, exist_ok=True)
        (root / "v1.0-mini" / f"{name}.json").write_text(json.dumps(records))
    return root


def write_dl3dv_scene(folder: Path, num_frames: int) -> Path:
    """``<hash>/images_4/frame_00001.png …`` and ``<hash>/colmap/sparse/0`` with cameras along a line."""
    rec = pycolmap.Reconstruction()
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(model="PINHOLE", width=16, height=9, params=[8.0, 8.0, 8.0, 4.5], camera_id=1)
    )
    for i in range(num_frames):
        name = f"frame_{i + 1:05d}.png"
        write_image(folder / "images_4" / name, 16, 9)
        rec.add_image_with_trivial_frame(
            pycolmap.Image(name=name, camera_id=1, image_id=i + 1),
            pycolmap.Rigid3d(
                pycolmap.Rotation3d(np.array([0.0, 0.0, 0.0, 1.0])), np.array([-0.1 * i, 0.0, 0.0])
            ),
        )
    sparse = folder / "colmap" / "sparse" / "0"
    sparse.mkdir(parents=True, exist_ok=True)
    rec.write_binary(str(sparse))
    return folder


def paralane_scene(frames_per_lane: dict[int, int]) -> Scene:
    """An in-memory Para-Lane-like scene: lane k = ``clip_k``, 10 Hz timestamps, cameras 3.5 m apart per lane."""
    frames = []
    for lane, count in frames_per_lane.items():
        for i in range(count):
            w2c = np.eye(4)
            w2c[:3, 3] = [-3.5 * lane, 0.0, -0.5 * i]
            stamp = 1_718_346_704_000_000 + 100_000 * i
            frames.append(
                Frame(
                    name=f"clip_{lane}/{stamp}/CAMERA_FRONT.png",
                    image_path=Path("/nonexistent"),
                    camera=Camera(K, w2c, 16, 12),
                    timestamp_us=stamp,
                    sensor="CAMERA_FRONT",
                    traversal=f"clip_{lane}",
                    metadata={"lane": lane},
                )
            )
    return Scene(dataset="paralane", name="scene_0", root=Path("/nonexistent"), frames=tuple(frames))


write_euvs_scene = loader_fixtures.write_euvs_scene
