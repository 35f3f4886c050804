"""nuScenes camera frames read straight from the JSON tables (no devkit).

Dataset facts: docs/datasets.md, "nuScenes tables and frame order".

Layout: ``<dataroot>/v1.0-{mini,trainval,test}/*.json`` (one list of records per table, keyed by
``token``) and the images at ``<dataroot>/<sample_data.filename>`` (``samples/`` keyframes,
``sweeps/`` non-keyframes).  ``version`` picks the folder; when omitted the only one present is used.
``root`` may also be the version folder itself.

Frames of a scene: every camera ``sample_data`` (``calibrated_sensor → sensor.modality == "camera"``;
the channel comes from ``sensor.channel`` because the devkit-added ``channel`` field is not in the
JSON), keyframes and sweeps.  Per channel the records are walked through their ``next`` links from
the earliest one of the scene (rewinding ``prev`` defensively), and every record of the scene must
lie on that chain.  ``sweeps=False`` keeps keyframes only.

Camera: ``camera-to-world = T(ego_pose) · T(calibrated_sensor)`` with ``T(r) = [R(r.rotation) r.translation; 0 1]``
and scalar-first quaternions; the camera frame is already OpenCV (x right, y down, z forward);
``K = calibrated_sensor.camera_intrinsic``; no distortion (images are rectified).  The world is the
map frame of the log (metres).  ``timestamp_us`` is the integer ``sample_data.timestamp``; a float
timestamp (tables written by other tools: mmdetection3d's Lyft tables store ``1556675185903083.2``) is
rounded to the nearest microsecond (Python's ``round``, halves to even), with one warning per table
giving how many were rounded; NaN, infinities and strings are refused.

Frame name: ``sample_data.filename`` (unique).  Frame order: timestamp, then channel in the schema's
listing order ``CAM_FRONT, CAM_FRONT_LEFT, CAM_FRONT_RIGHT, CAM_BACK, CAM_BACK_LEFT, CAM_BACK_RIGHT``
(other channels after, by name), then token.

The tables are parsed with the standard ``json`` module (the devkit does the same; it is not a
dependency here).  ``v1.0-trainval``'s ``sample_data.json`` is large: loading it takes several GB.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from setdiff_bench.camera_values import numeric_array
from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError, ImageError
from setdiff_bench.io.paths import resolve_inside
from setdiff_bench.rotations import rigid_from_quaternion
from setdiff_bench.types import Frame, Scene

from .common import dataset_root, frames_by_key, image_size, natural_key, select_scenes
from .nuscenes_tables import Table, load_table

__all__ = ["list_scenes", "load_scenes", "locate"]

VERSIONS = ("v1.0-mini", "v1.0-trainval", "v1.0-test")
REQUIRED_TABLES = ("scene", "sample", "sample_data", "calibrated_sensor", "sensor", "ego_pose")
CAMERA_CHANNELS = (
    "CAM_FRONT",
    "CAM_FRONT_LEFT",
    "CAM_FRONT_RIGHT",
    "CAM_BACK",
    "CAM_BACK_LEFT",
    "CAM_BACK_RIGHT",
)

Record = Mapping[str, Any]


def locate(root: str | os.PathLike[str], version: str | None = None) -> tuple[Path, Path]:
    """``(dataroot, table folder)`` for ``root`` and an optional ``version`` name."""
    base = dataset_root(root)
    if _is_table_folder(base):
        if version is not None and base.name != version:
            raise DatasetError(f"root is the table folder {base.name!r}, not {version!r}", base)
        return base.parent, base
    if version is not None:
        tables = base / version
        if not tables.is_dir():
            raise DatasetError(f"nuScenes version folder {version!r} not found", tables)
        return base, tables
    present = sorted(p.name for p in base.iterdir() if p.is_dir() and _is_table_folder(p))
    if not present:
        raise DatasetError(
            f"not a nuScenes folder: no table folder here ({' or '.join(VERSIONS)} with scene.json)",
            base,
        )
    if len(present) > 1:
        raise DatasetError(
            f"several nuScenes versions ({', '.join(present)}); choose one with version=<name>", base
        )
    return base, base / present[0]


def _is_table_folder(folder: Path) -> bool:
    """Whether ``folder`` looks like a nuScenes table folder: a ``scene.json`` and a version name
    (``v1.0-mini``) or a ``sample.json`` (a synthetic or EUVS scene folder has a ``scene.json`` too)."""
    named = folder.name in VERSIONS or folder.name.startswith("v1.")
    return (folder / "scene.json").is_file() and (named or (folder / "sample.json").is_file())


def list_scenes(root: str | os.PathLike[str], *, version: str | None = None) -> list[str]:
    """Scene names (``scene-0061`` ...) of the version, in natural order; reads only ``scene.json``."""
    _, tables = locate(root, version)
    names = [str(r.get("name")) for r in load_table(tables, "scene")]
    duplicates = {n for n in names if names.count(n) > 1}
    if duplicates:
        raise DatasetError(f"duplicate scene name {sorted(duplicates)[0]!r}", tables / "scene.json")
    return sorted(names, key=natural_key)


def load_scenes(
    root: str | os.PathLike[str],
    scenes: Iterable[str] | None = None,
    *,
    version: str | None = None,
    channels: Sequence[str] | None = None,
    sweeps: bool = True,
    check_images: bool = True,
) -> list[Scene]:
    """Load nuScenes scenes by name (rules in the module docstring).

    Args:
        root: the nuScenes dataroot (or a version folder).
        scenes: scene names (``"scene-0061"``); ``None`` = all scenes of the version.
        version: ``v1.0-mini``, ``v1.0-trainval`` or ``v1.0-test``; ``None`` = the only one present.
        channels: camera channels to keep (default all ``CAM_*`` of the scene).
        sweeps: include non-keyframe images (12 Hz instead of 2 Hz).
        check_images: read each image header and require it to exist with ``sample_data`` width × height.
    """
    dataroot, tables = locate(root, version)
    t = {name: Table.load(tables, name) for name in REQUIRED_TABLES}
    logs = Table.load(tables, "log") if (tables / "log.json").is_file() else None
    by_name = {str(r.get("name")): r for r in t["scene"].rows.values()}
    chosen = select_scenes(sorted(by_name, key=natural_key), scenes, tables, "nuscenes")

    camera_records = _camera_records(t)
    if channels is not None:
        known = {channel for _, channel in camera_records.values()}
        unknown = sorted(set(channels) - known)
        if unknown:
            raise DatasetError(
                f"unknown camera channel {unknown[0]!r}; available: {', '.join(sorted(known))}",
                t["sensor"].path,
            )
    by_sample: dict[str, list[str]] = {}
    for token, (record, _) in camera_records.items():
        by_sample.setdefault(record.get("sample_token"), []).append(token)

    out = []
    for name in chosen:
        scene = by_name[name]
        sample_tokens = _sample_chain(scene, t)
        in_scene = [token for s in sample_tokens for token in by_sample.get(s, [])]
        per_channel: dict[str, list[str]] = {}
        for token in in_scene:
            per_channel.setdefault(camera_records[token][1], []).append(token)
        frames: list[tuple[tuple, Frame]] = []
        for channel, tokens in per_channel.items():
            if channels is not None and channel not in channels:
                continue
            for token in _channel_chain(tokens, t, camera_records, name, channel):
                record = camera_records[token][0]
                if not sweeps and not record.get("is_key_frame"):
                    continue
                frame = _frame(record, channel, t, dataroot, check_images)
                order = CAMERA_CHANNELS.index(channel) if channel in CAMERA_CHANNELS else len(CAMERA_CHANNELS)
                frames.append(((frame.timestamp_us, order, channel, token), frame))
        log = logs.rows.get(scene.get("log_token")) if logs else None
        out.append(
            Scene(
                dataset="nuscenes",
                name=name,
                root=dataroot,
                frames=frames_by_key(frames),
                metadata={
                    "version": tables.name,
                    "scene_token": scene["token"],
                    "description": scene.get("description", ""),
                    "location": log.get("location") if log else None,
                    "logfile": log.get("logfile") if log else None,
                    "num_samples": len(sample_tokens),
                    "sweeps": sweeps,
                },
            )
        )
    return out


def _camera_records(t: Mapping[str, Table]) -> dict[str, tuple[dict[str, Any], str]]:
    """Camera ``sample_data`` token → (record, channel)."""
    out = {}
    for token, record in t["sample_data"].rows.items():
        calib = t["calibrated_sensor"].get(
            record.get("calibrated_sensor_token"), t["sample_data"], token, "calibrated_sensor_token"
        )
        sensor = t["sensor"].get(
            calib.get("sensor_token"), t["calibrated_sensor"], calib["token"], "sensor_token"
        )
        if sensor.get("modality") == "camera":
            out[token] = (record, str(sensor.get("channel")))
    return out


def _sample_chain(scene: Record, t: Mapping[str, Table]) -> list[str]:
    """Sample tokens of a scene from ``first_sample_token`` through ``next``."""
    tokens: list[str] = []
    token = scene.get("first_sample_token")
    referrer, ref_token, field = t["scene"], scene["token"], "first_sample_token"
    while token:
        if token in tokens:
            raise DatasetError(
                f"sample {token!r} repeats in the next chain of scene {scene.get('name')!r}", t["sample"].path
            )
        sample = t["sample"].get(token, referrer, ref_token, field)
        if sample.get("scene_token") != scene["token"]:
            raise DatasetError(
                f"sample {token!r} on the chain of scene {scene.get('name')!r} belongs to scene "
                f"{sample.get('scene_token')!r}",
                t["sample"].path,
            )
        tokens.append(token)
        referrer, ref_token, field = t["sample"], token, "next"
        token = sample.get("next")
    if not tokens:
        raise DatasetError(f"scene {scene.get('name')!r} has no samples", t["scene"].path)
    return tokens


def _channel_chain(
    tokens: list[str],
    t: Mapping[str, Table],
    camera_records: Mapping[str, tuple],
    scene_name: str,
    channel: str,
) -> list[str]:
    """The channel's records in ``next`` order; every record of the scene must be on the chain."""
    members = set(tokens)
    sample_data = t["sample_data"]
    head = min(tokens, key=lambda tok: (int(camera_records[tok][0].get("timestamp", 0)), tok))
    while True:  # defensive rewind: the schema says prev == "" at scene start
        previous = camera_records[head][0].get("prev")
        if not previous or previous not in members:
            if previous:
                sample_data.get(previous, sample_data, head, "prev")
            break
        head = previous
    chain: list[str] = []
    token = head
    while token and token in members and token not in chain:
        chain.append(token)
        token = camera_records[token][0].get("next")
        if token:
            sample_data.get(token, sample_data, chain[-1], "next")
    if len(chain) != len(members):
        stray = sorted(members - set(chain))[0]
        raise DatasetError(
            f"{channel} sample_data {stray!r} of {scene_name} is not on the next chain that starts "
            f"at {head!r}",
            sample_data.path,
        )
    return chain


def _frame(record: Record, channel: str, t: Mapping[str, Table], dataroot: Path, check_images: bool) -> Frame:
    token = record["token"]
    calib = t["calibrated_sensor"].rows[record["calibrated_sensor_token"]]
    ego = t["ego_pose"].get(record.get("ego_pose_token"), t["sample_data"], token, "ego_pose_token")
    ego_from_camera = rigid_from_quaternion(
        calib.get("rotation", ()),
        calib.get("translation", ()),
        order="wxyz",
        source=f"{t['calibrated_sensor'].path} (token {calib['token']!r})",
    )
    world_from_ego = rigid_from_quaternion(
        ego.get("rotation", ()),
        ego.get("translation", ()),
        order="wxyz",
        source=f"{t['ego_pose'].path} (token {ego['token']!r})",
    )
    K = numeric_array(
        calib.get("camera_intrinsic") or [],
        "camera_intrinsic",
        f"{t['calibrated_sensor'].path} (token {calib['token']!r})",
    )
    if K.shape != (3, 3):
        raise DatasetError(
            f"calibrated_sensor {calib['token']!r} of camera {channel} has no 3x3 camera_intrinsic",
            t["calibrated_sensor"].path,
        )
    filename = record.get("filename")
    image_path = resolve_inside(dataroot, filename, source=t["sample_data"].path)
    width, height = record.get("width"), record.get("height")
    if check_images:
        if not image_path.is_file():
            hint = (
                "" if record.get("is_key_frame") else " (a sweep: download the sweeps or pass sweeps=false)"
            )
            raise ImageError(f"image of sample_data {token!r} not found{hint}", image_path)
        actual = image_size(image_path)
        if width and height and actual != (int(width), int(height)):
            raise ImageError(
                f"image is {actual[0]}x{actual[1]} (WxH) but sample_data {token!r} says {width}x{height}",
                image_path,
            )
        width, height = actual
    if not width or not height:
        raise DatasetError(f"sample_data {token!r} has no width/height", t["sample_data"].path)
    camera = Camera.from_c2w(
        world_from_ego @ ego_from_camera,
        K,
        int(width),
        int(height),
        source=f"{t['sample_data'].path} (token {token!r})",
    )
    timestamp = record.get("timestamp")
    if isinstance(timestamp, bool) or not isinstance(timestamp, int):
        raise DatasetError(
            f"sample_data {token!r} timestamp must be integer microseconds, got {timestamp!r}",
            t["sample_data"].path,
        )
    return Frame(
        name=str(filename),
        image_path=image_path,
        camera=camera,
        timestamp_us=timestamp,
        sensor=channel,
        metadata={
            "sample_data_token": token,
            "sample_token": record.get("sample_token"),
            "is_key_frame": bool(record.get("is_key_frame")),
            "ego_pose_token": ego["token"],
            "calibrated_sensor_token": calib["token"],
        },
    )
