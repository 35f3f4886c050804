"""Small real packet stores for the run / leaderboard tests, written with the packet store's own writer.

The scene is analytic: a textured plane ``z = depth`` seen by pinhole cameras that translate along x
(a lane shift), so every C-map point, ground-truth pixel and reprojection is known in closed form.
Targets' "renders" are the ground truth blurred, tinted and noised (a stand-in for a 3DGS render
that is worse than the capture), references are clean captures.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.packets.index import merge_index, packet_id
from setdiff_bench.packets.writer import PacketHeader, ViewContent, write_packet

HEIGHT, WIDTH = 32, 48


def texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Smooth colour texture of the plane at world ``(x, y)`` → ``(..., 3)`` float in [0, 1]."""
    r = 0.5 + 0.4 * np.sin(2.1 * x + 0.3) * np.cos(1.3 * y)
    g = 0.5 + 0.4 * np.sin(1.7 * y - 0.5 * x + 1.0)
    b = 0.5 + 0.35 * np.cos(2.9 * x + 1.1 * y)
    return np.stack([r, g, b], axis=-1).clip(0, 1)


def camera_at(x: float, *, yaw_deg: float = 0.0, height: int = HEIGHT, width: int = WIDTH) -> Camera:
    """A pinhole camera at world ``(x, 0, 0)`` looking along +z (turned by ``yaw`` about y)."""
    yaw = math.radians(yaw_deg)
    rotation = np.array(
        [[math.cos(yaw), 0.0, -math.sin(yaw)], [0.0, 1.0, 0.0], [math.sin(yaw), 0.0, math.cos(yaw)]]
    )
    w2c = np.eye(4)
    w2c[:3, :3] = rotation
    w2c[:3, 3] = -rotation @ np.array([x, 0.0, 0.0])
    focal = 0.9 * width
    K = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    return Camera(K=K, w2c=w2c, width=width, height=height)


def plane_view(camera: Camera, depth: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ground-truth image ``(H, W, 3)``, C-map points ``(H, W, 3)`` and alpha ``(H, W)`` of the plane z = depth."""
    v, u = np.meshgrid(np.arange(camera.height) + 0.5, np.arange(camera.width) + 0.5, indexing="ij")
    xn, yn = camera.pixel_to_normalized(np.stack([u.ravel(), v.ravel()], axis=1))
    dirs = np.stack([xn, yn, np.ones_like(xn)], axis=1) @ camera.R  # world directions (R^T d)
    origin = camera.center
    t = (depth - origin[2]) / dirs[:, 2]
    points = origin + t[:, None] * dirs
    image = texture(points[:, 0], points[:, 1]).reshape(camera.height, camera.width, 3)
    return (
        image.astype(np.float32),
        points.reshape(camera.height, camera.width, 3).astype(np.float32),
        np.ones((camera.height, camera.width), np.float32),
    )


def degrade(image: np.ndarray, seed: int) -> np.ndarray:
    """A 'render': blurred, tinted and noised version of ``image`` (deterministic)."""
    rng = np.random.default_rng(seed)
    blurred = cv2.GaussianBlur(image, (0, 0), 1.2)
    return (0.85 * blurred + 0.05 + rng.normal(0.0, 0.03, image.shape)).clip(0, 1).astype(np.float32)


@dataclass(frozen=True)
class StoreSpec:
    """What :func:`build_store` writes."""

    dataset: str = "synthetic"
    protocol: str = "synthetic"
    groups: tuple[str, ...] = ("lane+1", "lane+2")
    scenes: tuple[str, ...] = ("scene_a",)
    split: str = "test"
    packets_per_group: int = 1
    references: int = 2
    targets: int = 3
    depth: float = 2.5
    sensors: tuple[str, ...] = ("front",)
    timestamps: bool = False
    masked_target: bool = True


def build_store(root: Path, spec: StoreSpec = StoreSpec()) -> Path:
    """Write a complete store under ``root`` (packets + merged ``index.parquet``); returns ``root``."""
    counter = 0
    for scene in spec.scenes:
        for g, group in enumerate(spec.groups):
            for p in range(spec.packets_per_group):
                counter += 1
                refs, tgts = [], []
                for i in range(spec.references):
                    camera = camera_at(-0.5 + 0.25 * i)
                    image, points, alpha = plane_view(camera, spec.depth)
                    refs.append(
                        ViewContent(
                            frame=f"ref_{g}_{p}_{i:02d}.png",
                            sensor=spec.sensors[0],
                            traversal="lane0",
                            timestamp_us=None,
                            camera=camera,
                            camera_world=camera,
                            image=image,
                            cmap=points * alpha[:, :, None],
                            alpha=alpha,
                            overlap_score=0.9 - 0.1 * i,
                        )
                    )
                for j in range(spec.targets):
                    sensor = spec.sensors[j % len(spec.sensors)]
                    step = (g * spec.packets_per_group + p) * spec.targets + j
                    camera = camera_at(
                        0.25 * (j // len(spec.sensors)) + 0.1 * g,
                        yaw_deg=0.0 if sensor == spec.sensors[0] else 8.0,
                    )
                    gt, points, alpha = plane_view(camera, spec.depth)
                    mask = np.ones((HEIGHT, WIDTH), bool)
                    if spec.masked_target and j == 1:
                        mask[4:12, 10:30] = False
                    tgts.append(
                        ViewContent(
                            frame=f"{sensor}/{step:06d}.jpg",
                            sensor=sensor,
                            traversal=f"lane{g + 1}",
                            timestamp_us=(10_000_000 + 100_000 * step) if spec.timestamps else None,
                            camera=camera,
                            camera_world=camera,
                            image=degrade(gt, seed=counter * 100 + j),
                            cmap=points * alpha[:, :, None],
                            alpha=alpha,
                            gt=gt,
                            mask=mask,
                        )
                    )
                header = PacketHeader(
                    packet_id=packet_id(spec.protocol, scene, group, p),
                    dataset=spec.dataset,
                    protocol=spec.protocol,
                    group=group,
                    split=spec.split,
                    scene=scene,
                    fit_key="lane0",
                    scale=1.0,
                    recipe=f"test-{counter}",
                )
                write_packet(root, header, refs, tgts)
    merge_index(root)
    return root


def target_frames(spec: StoreSpec) -> list[str]:
    """Every target frame name a store built from ``spec`` has, per (scene, group, packet)."""
    names: list[str] = []
    for _scene in spec.scenes:
        for g in range(len(spec.groups)):
            for p in range(spec.packets_per_group):
                for j in range(spec.targets):
                    step = (g * spec.packets_per_group + p) * spec.targets + j
                    names.append(f"{spec.sensors[j % len(spec.sensors)]}/{step:06d}.jpg")
    return names


def files_of(folder: Path, patterns: Sequence[str] = ("images/**/*.png",)) -> dict[str, bytes]:
    """Relative path → bytes of the files matching ``patterns`` (for byte-identity comparisons)."""
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for pattern in patterns
        for p in sorted(folder.glob(pattern))
        if p.is_file()
    }


def run_argv(method: str, packets: Path, out: Path, *options: str) -> list[str]:
    """The words of ``setdiff-bench run --method M --packets P --out O --no-progress`` and ``options``."""
    return [
        "run",
        "--method",
        method,
        "--packets",
        str(packets),
        "--out",
        str(out),
        "--no-progress",
        *options,
    ]


def leaderboard_argv(dataset: str, runs: Path, out: Path, *options: str) -> list[str]:
    """The words of ``setdiff-bench leaderboard --dataset D --runs R --out O`` and ``options``."""
    return ["leaderboard", "--dataset", dataset, "--runs", str(runs), "--out", str(out), *options]
