"""A folder of fitted scenes, as the sensorsim service serves them.

Layout: ``<scenes>/<scene_id>/`` is a scene folder in any layout the dataset loaders recognise by its files
(synthetic, EUVS, COLMAP, nerfstudio: :func:`setdiff_bench.loaders.detect_dataset`) holding its fitted 3DGS
as ``scene.ply`` (or ``fits/lane0.ply``, where the synthetic benchmark writes it).  The folder name is the
scene id (``get_available_scenes``).

* **Recorded frames** (the enhancer's references, chosen per tick by Eq. 2): the scene's frames that are
  not in its test split.
* **Cameras** (``get_available_cameras``): one per sensor of the recorded frames (``Frame.sensor``; a scene
  of one unnamed sensor has one camera ``camera``), with the intrinsics of its first recorded frame and its
  pose in the rig.  The rig frame is the first sensor's first recorded frame turned to x forward, y left,
  z up (AlpaSim's vehicle axes, from the camera's OpenCV axes); another sensor's pose in it comes from its
  recorded frame of the same timestamp (a sensor with none is left out, with a log line).
"""

from __future__ import annotations

import collections
import threading
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.evaluation.stream import StreamInputError
from setdiff_bench.serve.rpc_errors import LOG

#: Where a scene's fitted PLY may be, in order.
SCENE_PLY_NAMES = ("scene.ply", "fits/lane0.ply")
#: The logical id of the camera of a scene whose frames name no sensor.
UNNAMED_SENSOR = "camera"
#: Longest scene id accepted (characters).
MAX_SCENE_ID_CHARS = 128
#: The rig's axes (x forward, y left, z up) in OpenCV camera coordinates (x right, y down, z forward), as columns:
#: ``rig_to_world = camera_to_world @ RIG_AXES_IN_CAMERA``.
RIG_AXES_IN_CAMERA = np.array(
    [[0.0, -1.0, 0.0, 0.0], [0.0, 0.0, -1.0, 0.0], [1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]]
)


@dataclass(frozen=True)
class SceneCamera:
    """A camera of a scene: its logical id, the recorded camera (world frame) and its pose in the rig
    (``camera_to_rig``, ``(4, 4)``: AlpaSim's ``rig_to_camera`` field)."""

    logical_id: str
    camera: Camera
    camera_to_rig: np.ndarray


@dataclass
class FittedScene:
    """One loaded scene: its id, folder, PLY, Gaussians, recorded frames and cameras."""

    scene_id: str
    folder: Path
    ply: Path
    gaussians: Any  # GaussianModel
    recorded: list[Any]  # Frame
    cameras: list[SceneCamera]

    @property
    def ply_bytes(self) -> int:
        return self.ply.stat().st_size

    def recorded_views(
        self, height: int, width: int, count: int
    ) -> tuple[np.ndarray, list[Camera], list[str]]:
        """``count`` recorded frames evenly spaced over the recording, at ``height × width``.

        Returns:
            ``(count, H, W, 3)`` uint8 images (resized with area averaging where the size differs), their
            cameras scaled to the size, and their frame names.
        """
        from setdiff_bench.io.images import quantize_uint8, read_rgb

        picks = np.unique(np.linspace(0, len(self.recorded) - 1, max(1, count)).round().astype(int))
        images, cameras, names = [], [], []
        for index in picks:
            frame = self.recorded[int(index)]
            pixels = read_rgb(frame.image_path)
            camera = frame.camera
            if (camera.height, camera.width) != (height, width):
                pixels = cv2.resize(pixels, (width, height), interpolation=cv2.INTER_AREA)
                camera = scaled_camera(camera, height, width)
            images.append(quantize_uint8(pixels))
            cameras.append(camera)
            names.append(frame.name)
        return np.stack(images), cameras, names


def scaled_camera(camera: Camera, height: int, width: int) -> Camera:
    """``camera`` with its intrinsics scaled per axis to ``height × width`` (pixel centres at +0.5)."""
    K = camera.K.copy()
    K[0] *= width / camera.width
    K[1] *= height / camera.height
    K[2] = [0.0, 0.0, 1.0]
    return Camera(K, camera.w2c, width, height, camera.distortion, camera.source)


def _scene_cameras(frames: list[Any]) -> list[SceneCamera]:
    by_sensor: dict[str, list[Any]] = collections.defaultdict(list)
    for frame in frames:
        by_sensor[frame.sensor or UNNAMED_SENSOR].append(frame)
    first_sensor = next(iter(by_sensor))
    anchor = by_sensor[first_sensor][0]
    rig_to_world = anchor.camera.c2w @ RIG_AXES_IN_CAMERA
    world_to_rig = np.linalg.inv(rig_to_world)
    cameras = []
    for sensor, sensor_frames in by_sensor.items():
        same_time = [
            f
            for f in sensor_frames
            if f.timestamp_us == anchor.timestamp_us and f.traversal == anchor.traversal
        ]
        if sensor != first_sensor and not same_time:
            LOG.info("camera %r left out: no frame recorded at the rig's reference time", sensor)
            continue
        frame = anchor if sensor == first_sensor else same_time[0]
        cameras.append(SceneCamera(sensor, sensor_frames[0].camera, world_to_rig @ frame.camera.c2w))
    return cameras


class SceneLibrary:
    """The scenes of a folder, loaded when first asked for and kept (at most ``max_loaded``, least recently
    used dropped first).

    Scene ids are only ever matched against the folder's listing, so no request names a path.
    """

    def __init__(self, root: Path, max_loaded: int = 8) -> None:
        self.root = Path(root)
        self.max_loaded = max_loaded
        self._loaded: collections.OrderedDict[str, FittedScene] = collections.OrderedDict()
        self._lock = threading.Lock()
        self._loading: dict[str, threading.Lock] = collections.defaultdict(threading.Lock)

    def scene_ids(self) -> list[str]:
        """Sub-folders with a fitted PLY and a recognised layout, sorted."""
        from setdiff_bench.loaders import detect_dataset

        ids = []
        for folder in sorted(p for p in self.root.iterdir() if p.is_dir()):
            if self._ply(folder) is not None and detect_dataset(folder) is not None:
                ids.append(folder.name)
        return ids

    @staticmethod
    def _ply(folder: Path) -> Path | None:
        for name in SCENE_PLY_NAMES:
            if (folder / name).is_file():
                return folder / name
        return None

    def get(self, scene_id: str) -> FittedScene:
        """The loaded scene ``scene_id``.

        Raises:
            StreamInputError: not a scene of the folder (the message lists a few), or a scene without
                recorded frames.
        """
        with self._lock:
            if scene_id in self._loaded:
                self._loaded.move_to_end(scene_id)
                return self._loaded[scene_id]
        if not 0 < len(scene_id) <= MAX_SCENE_ID_CHARS or not scene_id.isprintable():
            raise StreamInputError(f"not a scene id ({len(scene_id)} characters)", "scene_id")
        available = self.scene_ids()
        if scene_id not in available:
            shown = ", ".join(available[:5]) + (", ..." if len(available) > 5 else "")
            raise StreamInputError(
                f"unknown scene {scene_id!r}; this server has {len(available)}: {shown or 'none'}", "scene_id"
            )
        with self._loading[scene_id]:  # one load per scene, however many rollouts ask at once
            with self._lock:
                if scene_id in self._loaded:
                    return self._loaded[scene_id]
            scene = self._load(scene_id)
            with self._lock:
                self._loaded[scene_id] = scene
                while len(self._loaded) > self.max_loaded:
                    dropped, _ = self._loaded.popitem(last=False)
                    LOG.info("scene %s unloaded (at most %d loaded)", dropped, self.max_loaded)
        return scene

    def _load(self, scene_id: str) -> FittedScene:
        from setdiff_bench.gaussians.ply import read_ply
        from setdiff_bench.loaders import detect_dataset, load_scenes

        folder = self.root / scene_id
        dataset = detect_dataset(folder)
        ply = self._ply(folder)
        assert dataset is not None and ply is not None  # scene_ids() checked both
        [scene] = load_scenes(dataset, folder)
        recorded = [frame for frame in scene.frames if frame.split != "test"]
        if not recorded:
            raise StreamInputError(f"scene {scene_id!r} has no recorded (non-test) frames", "scene_id")
        LOG.info("scene %s loaded: %d recorded frames, %s", scene_id, len(recorded), ply)
        return FittedScene(scene_id, folder, ply, read_ply(ply), recorded, _scene_cameras(recorded))
