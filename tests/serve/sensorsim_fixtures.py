"""Helpers of the sensorsim tests: a small fitted scene on disk (a random 3DGS, its recorded frames in the nerfstudio
layout), and a client that calls what AlpaSim's runtime calls, in its order, built from our ``sensorsim.proto``.

The requests are built here by hand from AlpaSim's conventions (camera-to-world poses, scalar-first
quaternions, OpenCV principal points), not with the service's own converters."""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from pathlib import Path

import grpc
import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.evaluation.stream import Views
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.ply import write_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.geometry import normalize_packet
from setdiff_bench.io.images import uint8_to_float, write_png
from setdiff_bench.packets.index import packet_id
from setdiff_bench.packets.writer import PacketHeader, ViewContent, write_packet
from setdiff_bench.serve.sensorsim import common_pb2 as common
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb
from setdiff_bench.serve.sensorsim import sensorsim_pb2_grpc as pb_grpc
from tests.evaluation.stream.stream_fixtures import hwc, rig_camera

SCENE_ID = "street"
#: AlpaSim's two default cameras (``wizard/configs/cameras/2cam.yaml``) and the yaw we give them (degrees).
CAMERAS = (("camera_front_wide_120fov", 0.0), ("camera_front_tele_30fov", 15.0))
#: AlpaSim's message limit.
MESSAGE_BYTES = 64 * 1024 * 1024
OPENGL_FLIP = np.diag([1.0, -1.0, -1.0, 1.0])


def street_gaussians(count: int = 500, seed: int = 0) -> GaussianModel:
    """Opaque coloured Gaussians in a box ahead of the drive (world x 14..34, y -4..14, z -1..4)."""
    generator = torch.Generator().manual_seed(seed)
    low = torch.tensor([14.0, -4.0, -1.0])
    high = torch.tensor([34.0, 14.0, 4.0])
    means = low + (high - low) * torch.rand(count, 3, generator=generator)
    return GaussianModel(
        means=means,
        quats=torch.nn.functional.normalize(torch.randn(count, 4, generator=generator), dim=-1),
        log_scales=torch.log(0.4 + 0.4 * torch.rand(count, 3, generator=generator)),
        opacity_logits=torch.full((count,), 3.0),
        sh=(torch.rand(count, 1, 3, generator=generator) - 0.5) * 3.0,
    )


def make_scene(root: Path, size: tuple[int, int] = (32, 48), frames: int = 6) -> Path:
    """``root/street``: ``scene.ply`` and ``frames`` recorded renders along lane 0 (``transforms.json``)."""
    folder = root / SCENE_ID
    (folder / "images").mkdir(parents=True, exist_ok=True)
    gaussians = street_gaussians()
    write_ply(folder / "scene.ply", gaussians)
    height, width = size
    entries = []
    for index in range(frames):
        camera = rig_camera(2.0 * index, 0.0, size=size)
        with torch.no_grad():
            rgb = render(gaussians, [camera], with_geometry=False).rgb[0].clamp(0, 1)
        write_png(folder / "images" / f"{index:03d}.png", rgb.permute(1, 2, 0).numpy())
        entries.append(
            {
                "file_path": f"images/{index:03d}.png",
                "transform_matrix": (camera.c2w @ OPENGL_FLIP).tolist(),
            }
        )
    first = rig_camera(0.0, 0.0, size=size)
    meta = {
        "fl_x": first.fx,
        "fl_y": first.fy,
        "cx": first.cx,
        "cy": first.cy,
        "w": width,
        "h": height,
        "frames": entries,
    }
    (folder / "transforms.json").write_text(json.dumps(meta))
    return folder


# ---------------------------------------------------------------------------------------------- requests
def pose(c2w: np.ndarray) -> common.Pose:
    """A camera-to-world matrix as AlpaSim's pose (scalar-first quaternion)."""
    R = c2w[:3, :3]
    w = math.sqrt(max(0.0, 1.0 + R[0, 0] + R[1, 1] + R[2, 2])) / 2.0
    x = math.copysign(math.sqrt(max(0.0, 1.0 + R[0, 0] - R[1, 1] - R[2, 2])) / 2.0, R[2, 1] - R[1, 2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - R[0, 0] + R[1, 1] - R[2, 2])) / 2.0, R[0, 2] - R[2, 0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - R[0, 0] - R[1, 1] + R[2, 2])) / 2.0, R[1, 0] - R[0, 1])
    return common.Pose(
        vec=common.Vec3(x=c2w[0, 3], y=c2w[1, 3], z=c2w[2, 3]), quat=common.Quat(w=w, x=x, y=y, z=z)
    )


def pinhole_spec(camera: Camera, logical_id: str) -> pb.CameraSpec:
    """An OpenCV pinhole spec of ``camera`` (OpenCV principal point: ours minus half a pixel)."""
    return pb.CameraSpec(
        opencv_pinhole_param=pb.OpenCVPinholeCameraParam(
            principal_point_x=camera.cx - 0.5,
            principal_point_y=camera.cy - 0.5,
            focal_length_x=camera.fx,
            focal_length_y=camera.fy,
            radial_coeffs=[0.0] * 6,
            tangential_coeffs=[0.0] * 2,
            thin_prism_coeffs=[0.0] * 4,
        ),
        logical_id=logical_id,
        resolution_h=camera.height,
        resolution_w=camera.width,
        shutter_type=pb.ShutterType.ROLLING_TOP_TO_BOTTOM,
    )


def tick_cameras(tick: int, size: tuple[int, int] = (32, 48), lateral: float = 3.0) -> list[Camera]:
    """The two cameras at ``tick`` of a drive one lane over (0.5 m per tick)."""
    return [rig_camera(0.5 * tick, yaw, lateral=lateral, size=size) for _, yaw in CAMERAS]


def render_request(
    camera: Camera,
    logical_id: str,
    tick: int,
    image_format: int = pb.ImageFormat.JPEG,
    spec: pb.CameraSpec | None = None,
    scene_id: str = SCENE_ID,
) -> pb.RGBRenderRequest:
    """What ``construct_rgb_render_request`` of AlpaSim's runtime sends for one camera (10 Hz, 30 ms shutter)."""
    start = 100_000 * tick
    return pb.RGBRenderRequest(
        scene_id=scene_id,
        resolution_h=camera.height,
        resolution_w=camera.width,
        camera_intrinsics=spec or pinhole_spec(camera, logical_id),
        frame_start_us=start,
        frame_end_us=start + 30_000,
        sensor_pose=pb.PosePair(start_pose=pose(camera.c2w), end_pose=pose(camera.c2w)),
        dynamic_objects=[pb.DynamicObject(track_id="car-1", pose_pair=pb.PosePair())],
        image_format=image_format,
        image_quality=95,
        insert_ego_mask=False,
    )


def batch_request(
    tick: int, image_format: int = pb.ImageFormat.JPEG, size: tuple[int, int] = (32, 48)
) -> pb.BatchRGBRenderRequest:
    """A tick of AlpaSim's default rollout: both cameras in one ``batch_render_rgb``."""
    request = pb.BatchRGBRenderRequest()
    for camera, (name, _) in zip(tick_cameras(tick, size), CAMERAS, strict=True):
        request.items.add(camera_name=name, request=render_request(camera, name, tick, image_format))
    return request


def stub(address: str) -> pb_grpc.SensorsimServiceStub:
    """A stub on an insecure channel with AlpaSim's 64 MiB limits."""
    channel = grpc.insecure_channel(
        address,
        options=[
            ("grpc.max_receive_message_length", MESSAGE_BYTES),
            ("grpc.max_send_message_length", MESSAGE_BYTES),
        ],
    )
    return pb_grpc.SensorsimServiceStub(channel)


def start_rollout(client: pb_grpc.SensorsimServiceStub) -> list[str]:
    """AlpaSim's calls before the first frame, in its order; returns the scene's camera ids."""
    version = client.get_version(common.Empty(), timeout=60, wait_for_ready=True)
    assert version.version_id
    scenes = client.get_available_scenes(common.Empty(), timeout=60)
    assert SCENE_ID in scenes.scene_ids
    cameras = client.get_available_cameras(pb.AvailableCamerasRequest(scene_id=SCENE_ID), timeout=60)
    masks = client.get_available_ego_masks(common.Empty(), timeout=60)
    assert list(masks.ego_mask_metadata) == []
    return [camera.logical_id for camera in cameras.available_cameras]


def decoded(reply: pb.BatchRGBRenderReturn, names: Sequence[str]) -> dict[str, np.ndarray]:
    """The reply checked as AlpaSim's runtime checks it (every camera once, all succeeded), decoded to RGB."""
    import cv2

    assert [item.camera_name for item in reply.items] == list(names)
    out = {}
    for item in reply.items:
        assert item.success, item.error_message
        image = cv2.imdecode(np.frombuffer(item.result.image_bytes, np.uint8), cv2.IMREAD_COLOR)
        out[item.camera_name] = image[:, :, ::-1]
    return out


# ---------------------------------------------------------------------------------------------- the batch runner
def write_tick_packet(root: Path, tick: int, references: Views, frames: Views) -> None:
    """A prepared-style packet of one tick (references + frames, with their C-maps *and alphas*, normalised as
    ``prepare`` does) for ``run`` to enhance: what the sensorsim proxy enhanced, as the batch runner sees it."""
    cameras = [*references.cameras, *frames.cameras]
    alphas = torch.cat([references.alphas, frames.alphas])
    normalised = normalize_packet(
        cameras, torch.cat([references.cmaps, frames.cmaps]), len(references.cameras), alphas=alphas
    )
    images = uint8_to_float(torch.cat([references.images, frames.images]))
    names = [*references.names, *frames.names]
    count = len(references.cameras)
    contents = []
    for i, camera in enumerate(cameras):
        target = i >= count
        contents.append(
            ViewContent(
                frame=names[i],
                sensor="cam",
                traversal="lane",
                timestamp_us=None,
                camera=normalised.cameras[i],
                camera_world=camera,
                image=hwc(images[i]),
                cmap=hwc(normalised.cmaps[i]),
                alpha=alphas[i, 0].numpy(),
                gt=hwc(images[i]) if target else None,
                mask=np.ones(alphas.shape[-2:], bool) if target else None,
                overlap_score=None if target else 1.0,
            )
        )
    header = PacketHeader(
        packet_id=packet_id("sensorsim", SCENE_ID, "tick", tick),
        dataset="synthetic",
        protocol="sensorsim",
        group="tick",
        split="test",
        scene=SCENE_ID,
        fit_key="lane0",
        scale=normalised.scale,
        recipe="sensorsim-test",
    )
    write_packet(root, header, contents[:count], contents[count:])
