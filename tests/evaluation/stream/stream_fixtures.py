"""A small recorded drive in world coordinates, its ticks as packets for the batch runner, and a tiny SetDiff
checkpoint, for the stream tests (and benchmarks/serve.py)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.evaluation.stream import Views
from setdiff_bench.geometry import normalize_packet
from setdiff_bench.io.images import uint8_to_float
from setdiff_bench.packets.index import merge_index, packet_id
from setdiff_bench.packets.writer import PacketHeader, ViewContent, write_packet

HEIGHT, WIDTH = 32, 48
#: The rig: (name, yaw in degrees) of the three cameras of every tick.
RIG = (("front", 0.0), ("front_left", 20.0), ("front_right", -20.0))


def rig_camera(
    x: float, yaw_deg: float, lateral: float = 0.0, size: tuple[int, int] = (HEIGHT, WIDTH)
) -> Camera:
    """A camera at world ``(x + 10, lateral + 5, 1)`` looking along world +x turned by ``yaw`` (z up)."""
    yaw = math.radians(yaw_deg)
    forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    right = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
    down = np.array([0.0, 0.0, -1.0])
    rotation = np.stack([right, down, forward])
    center = np.array([x + 10.0, lateral + 5.0, 1.0])
    w2c = np.eye(4)
    w2c[:3, :3] = rotation
    w2c[:3, 3] = -rotation @ center
    height, width = size
    focal = 0.8 * width
    K = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    return Camera(K=K, w2c=w2c, width=width, height=height)


def plane_points(camera: Camera, depth: float = 6.0) -> torch.Tensor:
    """``(3, H, W)`` world points of a fronto-parallel wall ``depth`` ahead (the C-map, alpha 1)."""
    v, u = np.meshgrid(np.arange(camera.height) + 0.5, np.arange(camera.width) + 0.5, indexing="ij")
    rays = (
        np.stack(
            [(u - camera.K[0, 2]) / camera.K[0, 0], (v - camera.K[1, 2]) / camera.K[1, 1], np.ones_like(u)],
            axis=-1,
        )
        * depth
    )
    world = (rays - camera.t) @ camera.R
    return torch.from_numpy(world.transpose(2, 0, 1).astype(np.float32))


def views(cameras: list[Camera], seed: int, names: list[str] | None = None) -> Views:
    """Views of these cameras: smooth random 8-bit images and wall C-maps."""
    generator = torch.Generator().manual_seed(seed)
    height, width = cameras[0].height, cameras[0].width
    coarse = torch.rand(len(cameras), 3, height // 8, width // 8, generator=generator)
    images = torch.nn.functional.interpolate(
        coarse, size=(height, width), mode="bilinear", align_corners=False
    )
    return Views(
        images=torch.round(images * 255).to(torch.uint8),
        cameras=cameras,
        cmaps=torch.stack([plane_points(c) for c in cameras]),
        alphas=torch.ones(len(cameras), 1, height, width),
        names=names,
    )


def recorded_references(size: tuple[int, int] = (HEIGHT, WIDTH), seed: int = 1) -> Views:
    """Six clean frames along lane 0 (front camera)."""
    return views(
        [rig_camera(2.0 * i, 0.0, size=size) for i in range(6)],
        seed=seed,
        names=[f"rec{i}" for i in range(6)],
    )


def tick_frames(tick: int, size: tuple[int, int] = (HEIGHT, WIDTH)) -> Views:
    """The rig's three renders at ``tick`` on the shifted lane (0.5 m per tick)."""
    return views(
        [rig_camera(0.5 * tick, yaw, lateral=3.0, size=size) for _, yaw in RIG],
        seed=100 + tick,
        names=[f"{name}/{tick:06d}.png" for name, _ in RIG],
    )


def hwc(tensor: torch.Tensor) -> np.ndarray:
    """A ``(C, H, W)`` tensor as a float32 ``(H, W, C)`` array."""
    return tensor.permute(1, 2, 0).numpy().astype(np.float32)


def write_tick_store(
    root: Path, references: Views, frames: Views, reference_ids: list[int], tick: int
) -> None:
    """A prepared-style packet of this tick: the chosen references + the frames, normalised as prepare does."""
    refs = [references.cameras[i] for i in reference_ids]
    cameras = [*refs, *frames.cameras]
    cmaps = torch.cat([references.cmaps[reference_ids], frames.cmaps])
    alphas = torch.ones(len(cameras), 1, HEIGHT, WIDTH)
    normalised = normalize_packet(cameras, cmaps, len(refs), alphas=alphas)
    images = uint8_to_float(torch.cat([references.images[reference_ids], frames.images]))
    names = [references.names[i] for i in reference_ids] + list(frames.names)
    contents = [
        ViewContent(
            frame=names[i],
            sensor="cam",
            traversal="lane",
            timestamp_us=None,
            camera=normalised.cameras[i],
            camera_world=cameras[i],
            image=hwc(images[i]),
            cmap=hwc(normalised.cmaps[i]),
            alpha=np.ones((HEIGHT, WIDTH), np.float32),
            gt=hwc(images[i]) if i >= len(refs) else None,
            mask=np.ones((HEIGHT, WIDTH), bool) if i >= len(refs) else None,
            overlap_score=1.0 if i < len(refs) else None,
        )
        for i in range(len(cameras))
    ]
    header = PacketHeader(
        packet_id=packet_id("stream", "drive", "tick", tick),
        dataset="synthetic",
        protocol="stream",
        group="tick",
        split="test",
        scene="drive",
        fit_key="lane0",
        scale=normalised.scale,
        recipe="stream-test",
    )
    write_packet(root, header, contents[: len(refs)], contents[len(refs) :])


def run_batch(store: Path, out: Path, checkpoint: Path | str, method: str = "setdiff") -> None:
    """Index a store of :func:`write_tick_store` packets and ``run --method METHOD`` on it (PSNR only, no warp);
    ``checkpoint`` is a folder or a shipped model's name."""
    merge_index(store)
    run_method(
        store,
        out,
        RunSettings(method, options={"checkpoint": str(checkpoint)}, metrics=("psnr",), warp="off"),
        progress=False,
    )


def serve_argv(checkpoint: Path | str, *options: str, device: str = "cpu") -> list[str]:
    """The words of ``setdiff-bench serve --checkpoint C --port 0 --device D`` (a free port) and ``options``."""
    return ["serve", "--checkpoint", str(checkpoint), "--port", "0", "--device", device, *options]


def save_tiny_checkpoint(folder: Path) -> Path:
    from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
    from setdiff_bench.models.setdiff.model import SetDiffModel
    from tests.models.setdiff_fixtures import tiny_config

    config = tiny_config(max_references=3)
    torch.manual_seed(0)
    model = SetDiffModel(config.model).eval()
    return save_checkpoint(folder, model, config)
