"""A small street world in the synthetic benchmark's on-disk layout (docs/synthetic_format.md), plus a fit PLY.

The "true" world is a set of opaque Gaussians (ground, two façades, a few boxes) with known colours.
Ground-truth images are renders of it; the fit PLY is the same world with jittered positions and
colours (a stand-in for an imperfect 3DGS).  Cameras are built here with numpy (look-at, OpenCV axes),
written to COLMAP through pycolmap, and described in ``scene.json`` exactly as the format document says.

Layout per scene: lanes ``lane0/1/2`` (y = 0, 3.5, 7 m) and ``turn`` (lane 0 → 1 with heading following the
path); cameras ``front`` (yaw 0°), ``front_left`` (+45°), ``front_right`` (−45°); ``STEPS`` timesteps
1.5 m apart at 10 Hz; ``lane0/front`` timestep ``HOLDOUT`` is held out of the fit.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import pycolmap
import torch
from scipy.spatial.transform import Rotation

from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.ply import write_ply
from setdiff_bench.gaussians.render import render

WIDTH, HEIGHT = 48, 32
FOCAL = 24.0
STEPS = 5
HOLDOUT = 2
STEP_M = 1.5
LANE_M = 3.5
TRAVERSALS = (
    ("lane0", "straight", 0),
    ("lane1", "straight", 1),
    ("lane2", "straight", 2),
    ("turn", "lane_change", None),
)
CAMERAS = (("front", 0.0), ("front_left", 45.0), ("front_right", -45.0))
DYNAMIC_INDEX = 3  # frames at this timestep carry a masked-out rectangle


@dataclass
class StreetScene:
    folder: Path
    truth: GaussianModel
    fit: GaussianModel
    cameras: dict[str, Camera]  # frame name → camera (world frame)
    train: list[str]
    test: list[str]


def intrinsics() -> np.ndarray:
    return np.array([[FOCAL, 0.0, WIDTH / 2], [0.0, FOCAL, HEIGHT / 2], [0.0, 0.0, 1.0]])


def look_at_w2c(center: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """OpenCV world-to-camera of a camera at ``center`` looking along ``forward`` with world up +z."""
    f = forward / np.linalg.norm(forward)
    right = np.cross(f, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(f, right)
    R = np.stack([right, down, f])
    w2c = np.eye(4)
    w2c[:3, :3] = R
    w2c[:3, 3] = -R @ center
    return w2c


def ego_pose(traversal: str, offset: int | None, index: int, jitter: float) -> tuple[np.ndarray, float]:
    """Car position ``(x, y, z)`` and heading (radians) of ``traversal`` at timestep ``index``."""
    x = index * STEP_M + 0.15 * index * index + jitter  # uneven spacing: no exact ties in Eq. 2
    if offset is not None:
        return np.array([x, offset * LANE_M, 1.6]), 0.0
    s = index / (STEPS - 1)  # lane change from 0 to 1 along a smooth step
    y = LANE_M * (3 * s * s - 2 * s * s * s)
    slope = LANE_M * (6 * s - 6 * s * s) / ((STEPS - 1) * STEP_M)
    return np.array([x, y, 1.6]), float(np.arctan(slope))


def world_gaussians(rng: np.random.Generator) -> GaussianModel:
    """Ground (z = 0), façades at y = −5 and y = 12, three boxes; ~3000 small opaque Gaussians."""
    parts, colors = [], []
    gx, gy = np.meshgrid(np.arange(-4.0, 26.0, 0.6), np.arange(-5.0, 12.0, 0.6), indexing="ij")
    ground = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1)
    parts.append(ground)
    colors.append(
        np.stack(
            [0.3 + 0.2 * np.sin(ground[:, 0]), 0.3 + 0.1 * np.cos(ground[:, 1]), np.full(len(ground), 0.35)],
            1,
        )
    )
    for y_wall in (-5.0, 12.0):
        wx, wz = np.meshgrid(np.arange(-4.0, 26.0, 0.6), np.arange(0.3, 7.0, 0.6), indexing="ij")
        wall = np.stack([wx.ravel(), np.full(wx.size, y_wall), wz.ravel()], 1)
        parts.append(wall)
        colors.append(
            np.stack(
                [
                    0.5 + 0.4 * np.sin(wall[:, 0] * 0.7),
                    0.4 + 0.3 * np.sin(wall[:, 2]),
                    0.6 + 0.3 * np.cos(wall[:, 0] * 0.3),
                ],
                1,
            )
        )
    for cx, cy in ((6.0, -3.0), (12.0, 9.5), (18.0, -2.5)):
        bx, by, bz = np.meshgrid(
            np.arange(-0.9, 1.0, 0.45), np.arange(-0.9, 1.0, 0.45), np.arange(0.2, 1.8, 0.45), indexing="ij"
        )
        box = np.stack([bx.ravel() + cx, by.ravel() + cy, bz.ravel()], 1)
        parts.append(box)
        colors.append(np.tile(rng.uniform(0.1, 0.9, 3), (len(box), 1)))
    means = np.concatenate(parts)
    rgb = np.clip(np.concatenate(colors) + rng.normal(0, 0.03, (len(means), 3)), 0.02, 0.98)
    n = len(means)
    sh = torch.zeros(n, 1, 3)
    sh[:, 0, :] = (torch.tensor(rgb, dtype=torch.float32) - 0.5) / 0.28209479177387814
    quats = torch.zeros(n, 4)
    quats[:, 0] = 1.0
    return GaussianModel(
        torch.tensor(means, dtype=torch.float32),
        quats,
        torch.full((n, 3), float(np.log(0.32))),
        torch.full((n,), 3.5),
        sh,
    )


def perturbed(model: GaussianModel, rng: np.random.Generator) -> GaussianModel:
    """The "fitted" model: positions jittered by 4 cm, colours by 0.04."""
    means = model.means + torch.tensor(rng.normal(0, 0.04, tuple(model.means.shape)), dtype=torch.float32)
    sh = model.sh + torch.tensor(rng.normal(0, 0.04 / 0.282, tuple(model.sh.shape)), dtype=torch.float32)
    return GaussianModel(
        means, model.quats.clone(), model.log_scales.clone(), model.opacity_logits.clone(), sh
    )


def write_scene(folder: Path, seed: int, *, fit_in_scene: bool = True) -> StreetScene:
    """Write one scene folder (EUVS layout + scene.json) and its fit ``<folder>/fits/lane0.ply``."""
    rng = np.random.default_rng(seed)
    truth = world_gaussians(rng)
    K = intrinsics()
    cameras: dict[str, Camera] = {}
    entries = []
    jitter = float(rng.uniform(-0.3, 0.3))
    for t_name, _, offset in TRAVERSALS:
        for c_name, yaw_deg in CAMERAS:
            for index in range(STEPS):
                name = f"{t_name}_{c_name}_{index:03d}.png"
                center, heading = ego_pose(t_name, offset, index, jitter)
                yaw = heading + np.deg2rad(yaw_deg)
                w2c = look_at_w2c(center, np.array([np.cos(yaw), np.sin(yaw), -0.05]))
                cameras[name] = Camera(K, w2c, WIDTH, HEIGHT)
                train = t_name == "lane0" and c_name == "front" and index != HOLDOUT
                entries.append(
                    {
                        "name": name,
                        "traversal": t_name,
                        "camera": c_name,
                        "index": index,
                        "timestamp_us": index * 100_000,
                        "split": "train" if train else "test",
                        "has_dynamic": index == DYNAMIC_INDEX,
                    }
                )
    names = list(cameras)
    with torch.no_grad():
        rgb = render(truth, [cameras[n] for n in names]).rgb
    for i, name in enumerate(names):
        image = (np.clip(rgb[i].permute(1, 2, 0).numpy(), 0, 1) * 255 + 0.5).astype(np.uint8)
        (folder / "images").mkdir(parents=True, exist_ok=True)
        assert cv2.imwrite(str(folder / "images" / name), image[:, :, ::-1])
        mask = np.full((HEIGHT, WIDTH), 255, np.uint8)
        if name.endswith(f"_{DYNAMIC_INDEX:03d}.png"):
            mask[8:20, 10:30] = 0
        (folder / "dynamic_masks").mkdir(parents=True, exist_ok=True)
        assert cv2.imwrite(str(folder / "dynamic_masks" / name), mask)
    picked = rng.choice(len(truth), size=400, replace=False)
    write_colmap(folder / "sparse" / "0", cameras, truth.means[picked].double().numpy())
    train = sorted(e["name"] for e in entries if e["split"] == "train")
    test = sorted(e["name"] for e in entries if e["split"] == "test")
    (folder / "train_set.txt").write_text("\n".join(train) + "\n")
    (folder / "test_set.txt").write_text("\n".join(test) + "\n")
    description = {
        "format": "setdiff-synthetic/1",
        "scene": folder.name,
        "seed": seed,
        "preset": "test",
        "width": WIDTH,
        "height": HEIGHT,
        "units": "metres",
        "lane_width_m": LANE_M,
        "num_lanes": 3,
        "world_up": [0, 0, 1],
        "traversals": [{"name": n, "kind": k, "lane_offset": o} for n, k, o in TRAVERSALS],
        "cameras": [
            {"name": n, "yaw_deg": y, "fx": FOCAL, "fy": FOCAL, "cx": WIDTH / 2, "cy": HEIGHT / 2}
            for n, y in CAMERAS
        ],
        "frames": sorted(entries, key=lambda e: e["name"]),
        "dynamic_objects": 1,
    }
    (folder / "scene.json").write_text(json.dumps(description, indent=1, sort_keys=True))
    fit = perturbed(truth, rng)
    if fit_in_scene:
        write_ply(folder / "fits" / "lane0.ply", fit)
    return StreetScene(folder, truth, fit, cameras, train, test)


def write_colmap(folder: Path, cameras: dict[str, Camera], points: np.ndarray) -> None:
    """A binary COLMAP model (one shared PINHOLE camera, ``points`` as grey 3D points) through pycolmap."""
    rec = pycolmap.Reconstruction()
    K = next(iter(cameras.values())).K
    rec.add_camera_with_trivial_rig(
        pycolmap.Camera(
            model="PINHOLE",
            width=WIDTH,
            height=HEIGHT,
            params=[K[0, 0], K[1, 1], K[0, 2], K[1, 2]],
            camera_id=1,
        )
    )
    for image_id, (name, camera) in enumerate(sorted(cameras.items()), 1):
        quat = Rotation.from_matrix(camera.R).as_quat()  # x, y, z, w
        rec.add_image_with_trivial_frame(
            pycolmap.Image(name=name, camera_id=1, image_id=image_id),
            pycolmap.Rigid3d(pycolmap.Rotation3d(quat), camera.t),
        )
    for xyz in points:
        rec.add_point3D(np.asarray(xyz, np.float64), pycolmap.Track(), np.array([128, 128, 128], np.uint8))
    folder.mkdir(parents=True, exist_ok=True)
    rec.write_binary(str(folder))


def write_dataset(root: Path, seeds: tuple[int, ...] = (11, 12, 13)) -> dict[str, StreetScene]:
    """Scenes ``street_00, street_01, …`` under ``root`` (sorted names = seed order)."""
    return {f"street_{i:02d}": write_scene(root / f"street_{i:02d}", seed) for i, seed in enumerate(seeds)}


def prepare_argv(root: Path, out: Path, *extra: str, fits: Path | None = None) -> list[str]:
    """``setdiff-bench`` arguments preparing the synthetic dataset ``root`` into ``out`` (fits found under
    ``fits``, by default ``root`` itself), then ``extra``."""
    return [
        "prepare",
        "synthetic",
        "--root",
        str(root),
        "--fits",
        str(fits or root),
        "--out",
        str(out),
        *extra,
    ]


def tree_bytes(root: Path) -> dict[str, bytes]:
    """Every file under ``root`` (relative POSIX path → bytes)."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()}
