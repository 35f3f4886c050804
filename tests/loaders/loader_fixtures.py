"""Fixture writers for the loader tests: tiny scenes in each dataset's official on-disk layout.

Geometry is built here with plain numpy / scipy / OpenCV, independently of setdiff_bench.cameras:
a camera is chosen first (rotation, centre, K), known 3D points are placed in front of it, and the
pixels where they must appear are computed with ``cv2.projectPoints``.  The pose is then written in
the dataset's own convention (COLMAP w2c wxyz, nerfstudio OpenGL c2w, nuScenes ego ∘ sensor, ...).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import pycolmap
from scipy.spatial.transform import Rotation

WIDTH, HEIGHT = 32, 24
TOLERANCE_PX = 1e-4


@dataclass
class View:
    """A camera built by the test: world-to-camera ``R``, ``t`` (OpenCV axes), ``K``, size, distortion."""

    R: np.ndarray
    t: np.ndarray
    K: np.ndarray
    width: int = WIDTH
    height: int = HEIGHT
    dist: np.ndarray = field(default_factory=lambda: np.zeros(4))
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (P, 3) world

    @property
    def center(self) -> np.ndarray:
        return -self.R.T @ self.t

    @property
    def c2w(self) -> np.ndarray:
        """OpenCV camera-to-world 4×4."""
        T = np.eye(4)
        T[:3, :3] = self.R.T
        T[:3, 3] = self.center
        return T

    def quat_wxyz(self) -> np.ndarray:
        return Rotation.from_matrix(self.R).as_quat(scalar_first=True)

    def quat_xyzw(self) -> np.ndarray:
        return Rotation.from_matrix(self.R).as_quat()

    def expected_pixels(self, K: np.ndarray | None = None) -> np.ndarray:
        """``(P, 2)`` pixels of ``points`` by OpenCV (optionally with another K, e.g. rescaled)."""
        rvec, _ = cv2.Rodrigues(self.R)
        uv, _ = cv2.projectPoints(
            self.points.reshape(-1, 1, 3), rvec, self.t.reshape(3, 1), self.K if K is None else K, self.dist
        )
        return uv.reshape(-1, 2)


def intrinsics(fx: float = 30.0, fy: float = 28.0, cx: float = 15.3, cy: float = 12.6) -> np.ndarray:
    return np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])


def random_view(
    rng: np.random.Generator,
    K: np.ndarray | None = None,
    *,
    center: np.ndarray | None = None,
    width: int = WIDTH,
    height: int = HEIGHT,
    dist: np.ndarray | None = None,
    n_points: int = 6,
) -> View:
    """A random camera (random rotation, given or random centre) and ``n_points`` world points in view."""
    K = intrinsics() if K is None else K
    R = Rotation.random(random_state=int(rng.integers(1 << 31))).as_matrix()
    C = rng.uniform(-5, 5, 3) if center is None else np.asarray(center, dtype=np.float64)
    t = -R @ C
    uv = np.stack([rng.uniform(2, width - 2, n_points), rng.uniform(2, height - 2, n_points)], axis=1)
    depth = rng.uniform(2.0, 20.0, n_points)
    rays = np.linalg.solve(K, np.vstack([uv.T, np.ones(n_points)]))  # (3, P) normalised, z = 1
    cam = rays * depth
    world = (R.T @ (cam - t[:, None])).T
    return View(R, t, K, width, height, np.zeros(4) if dist is None else np.asarray(dist, float), world)


def write_image(path: Path, width: int = WIDTH, height: int = HEIGHT, value: int = 128) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    image = np.full((height, width, 3), value, np.uint8)
    image[0, 0] = (255, 0, 0)
    assert cv2.imwrite(str(path), image)
    return path


def write_mask(path: Path, width: int = WIDTH, height: int = HEIGHT, keep: bool = True) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    mask = np.full((height, width), 255 if keep else 0, np.uint8)
    mask[: height // 4, : width // 4] = 0
    assert cv2.imwrite(str(path), mask)
    return path


def colmap_camera(camera_id: int, model: str, view: View) -> pycolmap.Camera:
    K, d = view.K, view.dist
    if model == "SIMPLE_PINHOLE":
        assert K[0, 0] == K[1, 1]
        params = [K[0, 0], K[0, 2], K[1, 2]]
    elif model == "PINHOLE":
        params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2]]
    elif model == "OPENCV":
        params = [K[0, 0], K[1, 1], K[0, 2], K[1, 2], *d[:4]]
    else:
        raise ValueError(model)
    return pycolmap.Camera(
        model=model, width=view.width, height=view.height, params=params, camera_id=camera_id
    )


def write_colmap(
    folder: Path,
    views: dict[str, View],
    *,
    model: str = "PINHOLE",
    fmt: str = "binary",
    shared_camera: bool = True,
    points: np.ndarray | None = None,
) -> Path:
    """Write ``views`` (image name → view) as a COLMAP model through pycolmap; returns ``folder``."""
    rec = pycolmap.Reconstruction()
    camera_ids: dict[str, int] = {}
    for index, (name, view) in enumerate(views.items(), 1):
        camera_id = 1 if shared_camera else index
        if camera_id not in rec.cameras:
            rec.add_camera_with_trivial_rig(colmap_camera(camera_id, model, view))
        camera_ids[name] = camera_id
        image = pycolmap.Image(name=name, camera_id=camera_id, image_id=index)
        pose = pycolmap.Rigid3d(pycolmap.Rotation3d(view.quat_xyzw()), view.t)
        rec.add_image_with_trivial_frame(image, pose)
    for xyz in [] if points is None else points:
        rec.add_point3D(np.asarray(xyz, float), pycolmap.Track(), np.array([10, 20, 30], np.uint8))
    folder.mkdir(parents=True, exist_ok=True)
    if fmt == "binary":
        rec.write_binary(str(folder))
    else:
        rec.write_text(str(folder))
    return folder


def write_colmap_text_by_hand(folder: Path, views: dict[str, View], *, points2d: bool = True) -> Path:
    """A legacy COLMAP text model (``cameras.txt`` + ``images.txt`` only), as Para-Lane ships it."""
    folder.mkdir(parents=True, exist_ok=True)
    first = next(iter(views.values()))
    K = first.K
    (folder / "cameras.txt").write_text(
        "# Camera list with one line of data per camera:\n"
        f"1 PINHOLE {first.width} {first.height} "
        + " ".join(repr(float(v)) for v in (K[0, 0], K[1, 1], K[0, 2], K[1, 2]))
        + "\n"
    )
    lines = ["# Image list with two lines of data per image:"]
    for index, (name, view) in enumerate(views.items(), 1):
        q, t = view.quat_wxyz(), view.t
        lines.append(
            f"{index} {' '.join(repr(float(v)) for v in q)} {' '.join(repr(float(v)) for v in t)} 1 {name}"
        )
        if points2d:
            lines.append("10.5 11.5 -1 3.0 4.0 -1")
    (folder / "images.txt").write_text("\n".join(lines) + "\n")
    return folder


def write_json(path: Path, data: object) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data, indent=1))
    return path


def assert_projects(camera, points: np.ndarray, expected: np.ndarray, tol: float = TOLERANCE_PX) -> None:
    """The loaded camera must put the known points at the known pixels within ``tol`` px."""
    uv, depth = camera.project(points)
    assert np.all(depth > 0)
    error = np.abs(uv - expected).max()
    assert error < tol, f"max reprojection error {error:.3g} px"


# ---------------------------------------------------------------------- EUVS
MARS_NAMES = (
    "trav_6_channel_1_img_001.jpg",
    "trav_6_channel_1_img_002.jpg",
    "trav_6_channel_2_img_001.jpg",
    "trav_11_channel_1_img_001.jpg",
    "trav_11_channel_1_img_002.jpg",
)
MARS_TEST = ("trav_11_channel_1_img_001.jpg", "trav_11_channel_1_img_002.jpg")


@dataclass
class EuvsScene:
    folder: Path
    views: dict[str, View]
    gt_views: dict[str, View]
    test: tuple[str, ...]


def write_euvs_scene(
    folder: Path,
    rng: np.random.Generator,
    *,
    names=MARS_NAMES,
    test=MARS_TEST,
    train_file: str | None = "train_set.txt",
    masks: bool = True,
    gt_poses: bool = True,
    image_ext_size: tuple[int, int] = (WIDTH, HEIGHT),
) -> EuvsScene:
    """An EUVS scene folder: images/, sparse/0 (binary), set files, dynamic_masks/, poses/images.txt.

    The ground-truth poses live in another world: ``x_gt = s·R0·x + t0`` (s = 2.5), as a metric map
    frame differs from the SfM frame; ``gt_views`` hold the same cameras and points in that world.
    """
    K = intrinsics()
    views = {name: random_view(rng, K) for name in names}
    write_colmap(folder / "sparse" / "0", views, points=np.concatenate([v.points for v in views.values()]))
    for name in names:
        write_image(folder / "images" / name, *image_ext_size)
        if masks:
            write_mask(folder / "dynamic_masks" / (Path(name).stem + ".png"))
    (folder / "test_set.txt").write_text("\n".join(test) + "\n")
    if train_file:
        (folder / train_file).write_text("\n".join(sorted(set(names) - set(test))) + "\n")
    s, R0, t0 = (
        2.5,
        Rotation.from_euler("zyx", [40, -10, 5], degrees=True).as_matrix(),
        np.array([100.0, -50.0, 3.0]),
    )
    gt_views = {}
    for name, view in views.items():
        R_gt = view.R @ R0.T
        t_gt = s * view.t - R_gt @ t0
        gt_views[name] = View(
            R_gt, t_gt, view.K, view.width, view.height, view.dist, (s * (R0 @ view.points.T) + t0[:, None]).T
        )
    if gt_poses:
        lines = []
        for j, name in enumerate(sorted(names), 1):
            q, t = gt_views[name].quat_wxyz(), gt_views[name].t
            numbers = " ".join(repr(float(v)) for v in (*q, *t))
            lines.append(f"{j} {numbers} 1 {name}\n\n")
        (folder / "poses").mkdir(parents=True, exist_ok=True)
        (folder / "poses" / "images.txt").write_text("".join(lines))
    return EuvsScene(folder, views, gt_views, tuple(test))


# ---------------------------------------------------------------------- nerfstudio / DL3DV
# nerfstudio's colmap_to_json world permutation (rows 0, 2, 1; then row 2 negated).
NERFSTUDIO_APPLIED = np.eye(4)[[0, 2, 1, 3]] * np.array([[1.0], [1.0], [-1.0], [1.0]])


def nerfstudio_transform_matrix(view: View, applied: bool) -> list[list[float]]:
    """The view's pose as nerfstudio writes it: camera-to-world, OpenGL axes, world optionally permuted."""
    c2w = view.c2w.copy()
    c2w[0:3, 1:3] *= -1  # OpenCV camera axes → OpenGL (y up, z back)
    if applied:
        c2w = NERFSTUDIO_APPLIED @ c2w
    return c2w.tolist()


def write_transforms(
    folder: Path,
    views: dict[str, View],
    *,
    full_size: tuple[int, int],
    applied: bool,
    image_folder: str = "images",
    extra: dict | None = None,
) -> Path:
    """``transforms.json`` with intrinsics for ``full_size`` (w, h) and ``file_path`` under ``image_folder``."""
    first = next(iter(views.values()))
    K, d = first.K, first.dist
    meta: dict = {
        "w": full_size[0],
        "h": full_size[1],
        "fl_x": K[0, 0],
        "fl_y": K[1, 1],
        "cx": K[0, 2],
        "cy": K[1, 2],
        "k1": d[0],
        "k2": d[1],
        "p1": d[2],
        "p2": d[3],
        "camera_model": "OPENCV",
        "frames": [
            {
                "file_path": f"{image_folder}/{name}",
                "colmap_im_id": i + 1,
                "transform_matrix": nerfstudio_transform_matrix(view, applied),
            }
            for i, (name, view) in enumerate(views.items())
        ],
    }
    if applied:
        meta["applied_transform"] = NERFSTUDIO_APPLIED[:3].tolist()
    meta.update(extra or {})
    return write_json(folder / "transforms.json", meta)


# ---------------------------------------------------------------------- nuScenes
NU_CAMERAS = {
    "CAM_FRONT": 0.0,
    "CAM_FRONT_LEFT": 55.0,
    "CAM_BACK": 180.0,
}  # yaw of the camera in the ego frame
NU_OFFSETS_US = {"CAM_FRONT": 0, "CAM_FRONT_LEFT": 12_500, "CAM_BACK": 37_500}
# OpenCV camera axes in the ego frame (x forward, y left, z up): x_cam → −y, y_cam → −z, z_cam → +x.
EGO_FROM_FORWARD_CAMERA = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def nuscenes_tables(logfile: str, vehicle: str, location: str) -> dict[str, list[dict]]:
    """The seven nuScenes tables the loader reads, empty but for the one ``log0`` record."""
    tables: dict[str, list[dict]] = {
        k: [] for k in ("log", "scene", "sample", "sample_data", "sensor", "calibrated_sensor", "ego_pose")
    }
    log = {"token": "log0", "logfile": logfile, "vehicle": vehicle, "date_captured": "2018-07-24"}
    tables["log"].append({**log, "location": location})
    return tables


@dataclass
class NuFrame:
    """What the test knows about one camera sample_data: its points and where they must appear."""

    token: str
    channel: str
    timestamp: int
    is_key_frame: bool
    points: np.ndarray  # (P, 3) world
    pixels: np.ndarray  # (P, 2)


@dataclass
class NuScenesFixture:
    tables: dict[str, list[dict]]
    frames: dict[str, list[NuFrame]]  # scene name → camera frames
    root: Path

    def write(self) -> Path:
        for name, records in self.tables.items():
            write_json(self.root / "v1.0-mini" / f"{name}.json", records)
        return self.root

    def record(self, table: str, token: str) -> dict:
        return next(r for r in self.tables[table] if r["token"] == token)


def build_nuscenes(root: Path, rng: np.random.Generator, *, sweeps_between: int = 2) -> NuScenesFixture:
    """Two scenes of one log; three cameras (keyframes at 2 Hz + sweeps) and a lidar; moving ego."""
    K = intrinsics(fx=20.0, fy=20.0, cx=16.0, cy=12.0)
    tables = nuscenes_tables("n015-2018-07-24-11-22-45+0800", "n015", "singapore-onenorth")
    calib: dict[str, tuple[np.ndarray, np.ndarray, str]] = {}
    for channel in [*NU_CAMERAS, "LIDAR_TOP"]:
        is_camera = channel != "LIDAR_TOP"
        tables["sensor"].append(
            {"token": f"sensor_{channel}", "channel": channel, "modality": "camera" if is_camera else "lidar"}
        )
        jitter = Rotation.from_rotvec(rng.normal(0, 0.02, 3)).as_matrix()
        R = (
            Rotation.from_euler("z", NU_CAMERAS.get(channel, 0.0), degrees=True).as_matrix()
            @ jitter
            @ (EGO_FROM_FORWARD_CAMERA if is_camera else np.eye(3))
        )
        t = np.array([1.2, 0.3, 1.6]) + rng.normal(0, 0.05, 3)
        calib[channel] = (R, t, f"calib_{channel}")
        tables["calibrated_sensor"].append(
            {
                "token": f"calib_{channel}",
                "sensor_token": f"sensor_{channel}",
                "translation": t.tolist(),
                "rotation": Rotation.from_matrix(R).as_quat(scalar_first=True).tolist(),
                "camera_intrinsic": K.tolist() if is_camera else [],
            }
        )

    frames: dict[str, list[NuFrame]] = {}
    t_start = 1532402927600000
    for scene_index, (scene_name, n_samples) in enumerate((("scene-0061", 3), ("scene-0103", 2))):
        scene_token = f"scene{scene_index}"
        sample_tokens = [f"{scene_token}_sample{i}" for i in range(n_samples)]
        sample_times = [t_start + 500_000 * i for i in range(n_samples)]
        t_start += 20_000_000
        for i, token in enumerate(sample_tokens):
            tables["sample"].append(
                {
                    "token": token,
                    "timestamp": sample_times[i],
                    "scene_token": scene_token,
                    "prev": sample_tokens[i - 1] if i else "",
                    "next": sample_tokens[i + 1] if i + 1 < n_samples else "",
                }
            )
        tables["scene"].append(
            {
                "token": scene_token,
                "name": scene_name,
                "description": "test drive",
                "log_token": "log0",
                "nbr_samples": n_samples,
                "first_sample_token": sample_tokens[0],
                "last_sample_token": sample_tokens[-1],
            }
        )
        frames[scene_name] = []
        for channel in [*NU_CAMERAS, "LIDAR_TOP"]:
            is_camera = channel != "LIDAR_TOP"
            records = []
            for i in range(n_samples):
                steps = (
                    [(0, True)]
                    if i == n_samples - 1 or not is_camera
                    else [(0, True)] + [(k, False) for k in range(1, sweeps_between + 1)]
                )
                for k, key in steps:
                    stamp = (
                        sample_times[i] + NU_OFFSETS_US.get(channel, 0) + k * 500_000 // (sweeps_between + 1)
                    )
                    owner = sample_tokens[i] if key else sample_tokens[i + 1]  # sweeps: the following sample
                    records.append((stamp, key, owner))
            tokens = [f"{scene_token}_{channel}_{j}" for j in range(len(records))]
            for j, (stamp, key, owner) in enumerate(records):
                token = tokens[j]
                yaw = 0.3 + 0.05 * (stamp - sample_times[0]) / 1e6
                R_we = Rotation.from_euler("z", yaw).as_matrix()
                t_we = np.array([300.0 + 5.0 * (stamp - sample_times[0]) / 1e6, 1200.0, 0.0])
                tables["ego_pose"].append(
                    {
                        "token": f"ego_{token}",
                        "timestamp": stamp,
                        "translation": t_we.tolist(),
                        "rotation": Rotation.from_matrix(R_we).as_quat(scalar_first=True).tolist(),
                    }
                )
                folder = "samples" if key else "sweeps"
                filename = f"{folder}/{channel}/n015-2018-07-24-11-22-45+0800__{channel}__{stamp}.jpg"
                tables["sample_data"].append(
                    {
                        "token": token,
                        "sample_token": owner,
                        "ego_pose_token": f"ego_{token}",
                        "calibrated_sensor_token": f"calib_{channel}",
                        "timestamp": stamp,
                        "fileformat": "jpg" if is_camera else "pcd",
                        "is_key_frame": key,
                        "height": HEIGHT if is_camera else 0,
                        "width": WIDTH if is_camera else 0,
                        "filename": filename if is_camera else filename.replace(".jpg", ".pcd.bin"),
                        "prev": tokens[j - 1] if j else "",
                        "next": tokens[j + 1] if j + 1 < len(tokens) else "",
                    }
                )
                if not is_camera:
                    continue
                write_image(root / filename)
                R_ec, t_ec, _ = calib[channel]
                uv = np.stack([rng.uniform(2, WIDTH - 2, 5), rng.uniform(2, HEIGHT - 2, 5)], axis=1)
                depth = rng.uniform(3.0, 30.0, 5)
                cam = (np.linalg.solve(K, np.vstack([uv.T, np.ones(5)])) * depth).T
                ego = Rotation.from_matrix(R_ec).apply(cam) + t_ec  # sensor → ego
                world = Rotation.from_matrix(R_we).apply(ego) + t_we  # ego → global
                frames[scene_name].append(NuFrame(token, channel, stamp, key, world, uv))
    return NuScenesFixture(tables, frames, root)


# ---------------------------------------------------------------------- synthetic (docs/synthetic_format.md)
SYN_TRAVERSALS = [("lane0", "straight", 0), ("lane1", "straight", 1), ("turn", "lane_change", None)]
SYN_CAMERAS = [("front", 0.0), ("front_left", 45.0)]


def write_synthetic_scene(folder: Path, rng: np.random.Generator, *, n_index: int = 3) -> dict[str, View]:
    """One scene in the synthetic format: EUVS layout (PNG) + scene.json; lane0/front is the fit set."""
    K = intrinsics(fx=16.0, fy=16.0, cx=16.0, cy=12.0)
    views: dict[str, View] = {}
    frames = []
    for t_name, _, offset in SYN_TRAVERSALS:
        for c_name, _ in SYN_CAMERAS:
            for index in range(n_index):
                name = f"{t_name}_{c_name}_{index:03d}.png"
                lateral = 3.5 * (offset if offset is not None else 0.5)
                views[name] = random_view(rng, K, center=np.array([2.0 * index, lateral, 1.5]))
                split = "train" if (t_name, c_name) == ("lane0", "front") and index != 1 else "test"
                frames.append(
                    {
                        "name": name,
                        "traversal": t_name,
                        "camera": c_name,
                        "index": index,
                        "timestamp_us": index * 100000,
                        "split": split,
                        "has_dynamic": index == 2,
                    }
                )
    # scene.json lists frames sorted by name, as the generator's sorted keys would
    frames.sort(key=lambda f: f["name"])
    write_colmap(folder / "sparse" / "0", dict(sorted(views.items())))
    for name in views:
        write_image(folder / "images" / name)
        write_mask(folder / "dynamic_masks" / name)
    (folder / "train_set.txt").write_text(
        "\n".join(f["name"] for f in frames if f["split"] == "train") + "\n"
    )
    (folder / "test_set.txt").write_text("\n".join(f["name"] for f in frames if f["split"] == "test") + "\n")
    write_json(
        folder / "scene.json",
        {
            "format": "setdiff-synthetic/1",
            "scene": folder.name,
            "seed": 0,
            "preset": "default",
            "width": WIDTH,
            "height": HEIGHT,
            "units": "metres",
            "lane_width_m": 3.5,
            "num_lanes": 3,
            "world_up": [0, 0, 1],
            "traversals": [{"name": n, "kind": k, "lane_offset": o} for n, k, o in SYN_TRAVERSALS],
            "cameras": [
                {"name": n, "yaw_deg": y, "fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2], "cy": K[1, 2]}
                for n, y in SYN_CAMERAS
            ],
            "frames": frames,
            "dynamic_objects": 1,
        },
    )
    return views
