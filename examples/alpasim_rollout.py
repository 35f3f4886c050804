"""A closed-loop rollout as AlpaSim drives it, through the enhancing proxy in front of the 3DGS renderer:
the video of render | enhanced, one lane over from the recorded drive.

It starts ``setdiff-bench serve --protocol sensorsim`` twice (the renderer on the scenes folder, and the proxy
with the enhancer in front of it) unless ``--renderer`` / ``--proxy`` name running ones, then calls what
AlpaSim's runtime calls, in its order: ``get_version``, ``get_available_scenes``, ``get_available_cameras``,
``get_available_ego_masks``, and one ``batch_render_rgb`` per tick (10 Hz, 30 ms shutter, JPEG q95) for every
camera of the scene.  The ego trajectory is the scene's recorded one (its first camera's poses in rig axes)
moved ``--shift-m`` metres to the right (default: to the scene's lane 1 where it has one, else 3.5 m), and each
camera's pose is the ego pose composed with the camera's ``rig_to_camera`` from ``get_available_cameras``
(AlpaSim's ``sensor_pose``).  Each tick asks the renderer (the plain render) and the proxy (the enhanced one)
for the same frames; the video shows them side by side.

    setdiff-bench synth --out runs/scenes --preset tiny --scenes 1          # a fitted scene, if you have none
    python examples/alpasim_rollout.py --scenes runs/scenes --out runs/alpasim_rollout [--ticks 30]
    python examples/alpasim_rollout.py --scenes runs/scenes --out OUT --renderer HOST:PORT --proxy HOST:PORT

Writes ``OUT/rollout.webm`` (render | enhanced, every camera stacked), ``OUT/<camera>/<tick>_{render,enhanced}.jpg``
and the servers' messages to ``OUT/{renderer,proxy}.log``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path

import cv2
import grpc
import numpy as np

from setdiff_bench.loaders import detect_dataset, load_scenes
from setdiff_bench.reporting.grids import compose
from setdiff_bench.reporting.site import write_video
from setdiff_bench.rotations import quaternion_to_matrix
from setdiff_bench.serve.sensorsim import common_pb2 as common
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb
from setdiff_bench.serve.sensorsim import sensorsim_pb2_grpc as pb_grpc
from setdiff_bench.serve.sensorsim.lens import pose_message
from setdiff_bench.serve.sensorsim.scenes import RIG_AXES_IN_CAMERA, SCENE_PLY_NAMES

#: AlpaSim's runtime defaults: 10 Hz, 30 ms shutter, JPEG quality 95, 64 MiB messages.
FRAME_INTERVAL_US = 100_000
SHUTTER_US = 30_000
MESSAGE_BYTES = 64 * 1024 * 1024


@contextmanager
def serving(argv: list[str], log: Path) -> Iterator[str]:
    """``setdiff-bench serve ...`` in its own process (its messages to ``log``); yields ``127.0.0.1:PORT`` once it
    listens, and stops it with SIGTERM (in-flight calls finish) at the end."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with log.open("w") as messages:
        process = subprocess.Popen(
            [sys.executable, "-m", "setdiff_bench", "serve", *argv, "--port", "0"],
            stdout=subprocess.PIPE,
            stderr=messages,
            text=True,
            env={**os.environ, "SETDIFF_THREADS": os.environ.get("SETDIFF_THREADS", "1")},
        )
        try:
            line = process.stdout.readline()
            if not line.startswith("serving on "):
                process.wait(timeout=60)
                raise SystemExit(f"serve did not start: {line!r}; see {log}")
            yield "127.0.0.1:" + line.split(":")[1].split()[0]
        finally:
            process.terminate()
            process.wait(timeout=60)


def stub(address: str) -> pb_grpc.SensorsimServiceStub:
    options = [
        ("grpc.max_receive_message_length", MESSAGE_BYTES),
        ("grpc.max_send_message_length", MESSAGE_BYTES),
    ]
    return pb_grpc.SensorsimServiceStub(grpc.insecure_channel(address, options=options))


def matrix(pose: common.Pose) -> np.ndarray:
    out = np.eye(4)
    q = pose.quat
    out[:3, :3] = quaternion_to_matrix([q.w, q.x, q.y, q.z], order="wxyz")
    out[:3, 3] = [pose.vec.x, pose.vec.y, pose.vec.z]
    return out


def ego_trajectory(scene_dir: Path, ticks: int, shift_m: float | None) -> list[np.ndarray]:
    """Rig-to-world poses at 10 Hz along the recorded drive, moved ``shift_m`` to the right (None: to lane 1)."""
    [scene] = load_scenes(detect_dataset(scene_dir), scene_dir)
    recorded = [f for f in scene.frames if f.split != "test"]
    first_sensor = recorded[0].sensor
    drive = [f.camera.c2w @ RIG_AXES_IN_CAMERA for f in recorded if f.sensor == first_sensor]
    if shift_m is None:
        lane1 = [f for f in scene.frames if f.traversal == "lane1" and f.sensor == first_sensor]
        right = -drive[0][:3, 1]  # rig y points left
        shift_m = float(right @ (lane1[0].camera.center - recorded[0].camera.center)) if lane1 else 3.5
    poses = []
    for tick in range(ticks):
        position = (len(drive) - 1) * tick / max(1, ticks - 1)
        low = int(np.floor(position))
        high = min(low + 1, len(drive) - 1)
        pose = drive[low].copy()
        pose[:3, 3] = drive[low][:3, 3] + (position - low) * (drive[high][:3, 3] - drive[low][:3, 3])
        pose[:3, 3] -= shift_m * drive[low][:3, 1]  # rig y is left: minus moves right
        poses.append(pose)
    side = "right" if shift_m >= 0 else "left"
    print(f"rollout: {ticks} ticks along {len(drive)} recorded frames, {abs(shift_m):.2f} m to the {side}")
    return poses


def tick_request(
    scene_id: str, tick: int, ego: np.ndarray, cameras: list, size: tuple[int, int]
) -> pb.BatchRGBRenderRequest:
    """What AlpaSim's runtime sends for one tick: every camera, sensor_pose = ego ∘ rig_to_camera."""
    request = pb.BatchRGBRenderRequest()
    start = tick * FRAME_INTERVAL_US
    for camera in cameras:
        pose = pose_message(ego @ matrix(camera.rig_to_camera))
        item = request.items.add(camera_name=camera.logical_id)
        item.request.CopyFrom(
            pb.RGBRenderRequest(
                scene_id=scene_id,
                resolution_h=size[0],
                resolution_w=size[1],
                camera_intrinsics=camera.intrinsics,
                frame_start_us=start,
                frame_end_us=start + SHUTTER_US,
                sensor_pose=pb.PosePair(start_pose=pose, end_pose=pose),
                image_format=pb.ImageFormat.JPEG,
                image_quality=95,
            )
        )
    return request


def images(reply: pb.BatchRGBRenderReturn) -> dict[str, np.ndarray]:
    """The reply checked as AlpaSim's runtime checks it, decoded to RGB."""
    out = {}
    for item in reply.items:
        if not item.success:
            raise SystemExit(f"{item.camera_name}: {item.error_message}")
        decoded = cv2.imdecode(np.frombuffer(item.result.image_bytes, np.uint8), cv2.IMREAD_COLOR)
        out[item.camera_name] = decoded[:, :, ::-1]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", type=Path, required=True, help="folder of fitted scenes")
    parser.add_argument("--scene-id", default=None, help="default: the first scene listed")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--checkpoint", default="tiny_setdiff", help="the proxy's enhancer")
    parser.add_argument("--ticks", type=int, default=20)
    parser.add_argument("--height", type=int, default=144)
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument(
        "--shift-m", type=float, default=None, help="metres to the right of the recorded drive"
    )
    parser.add_argument("--renderer", default=None, help="HOST:PORT of a running renderer")
    parser.add_argument("--proxy", default=None, help="HOST:PORT of a running proxy (in front of --renderer)")
    args = parser.parse_args()
    with ExitStack() as stack:
        renderer = args.renderer or stack.enter_context(
            serving(["--protocol", "sensorsim", "--scenes", str(args.scenes)], args.out / "renderer.log")
        )
        proxy_argv = ["--protocol", "sensorsim", "--role", "proxy", "--scenes", str(args.scenes)]
        proxy_argv += ["--upstream", renderer, "--checkpoint", args.checkpoint]
        proxy = args.proxy or stack.enter_context(serving(proxy_argv, args.out / "proxy.log"))
        plain, enhanced = stub(renderer), stub(proxy)
        print("renderer:", plain.get_version(common.Empty(), timeout=300, wait_for_ready=True).version_id)
        print("proxy:   ", enhanced.get_version(common.Empty(), timeout=300, wait_for_ready=True).version_id)
        scenes = list(enhanced.get_available_scenes(common.Empty(), timeout=300).scene_ids)
        scene_id = args.scene_id or scenes[0]
        if scene_id not in scenes:
            raise SystemExit(f"scene {scene_id!r} is not served; served: {', '.join(scenes)}")
        request = pb.AvailableCamerasRequest(scene_id=scene_id)
        cameras = list(enhanced.get_available_cameras(request, timeout=300).available_cameras)
        enhanced.get_available_ego_masks(common.Empty(), timeout=300)
        print("cameras:", ", ".join(c.logical_id for c in cameras))
        scene_dir = args.scenes / scene_id
        assert any((scene_dir / name).is_file() for name in SCENE_PLY_NAMES)
        frames = []
        for tick, ego in enumerate(ego_trajectory(scene_dir, args.ticks, args.shift_m)):
            batch = tick_request(scene_id, tick, ego, cameras, (args.height, args.width))
            rendered = images(plain.batch_render_rgb(batch, timeout=300))
            better = images(enhanced.batch_render_rgb(batch, timeout=300))
            rows = []
            for name in rendered:
                (args.out / name).mkdir(parents=True, exist_ok=True)
                for kind, image in (("render", rendered[name]), ("enhanced", better[name])):
                    cv2.imwrite(str(args.out / name / f"{tick:04d}_{kind}.jpg"), image[:, :, ::-1])
                rows.append([rendered[name], better[name]])
            frames.append(compose(rows, ["3DGS render", "enhanced"], list(rendered)))
            print(f"tick {tick + 1}/{args.ticks}", flush=True)
    print("wrote", write_video(args.out / "rollout.webm", frames, fps=10.0))


if __name__ == "__main__":
    main()
