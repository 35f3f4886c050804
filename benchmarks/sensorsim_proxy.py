"""Sensorsim proxy benchmark: what the enhancing proxy adds over calling the upstream renderer directly, and
many concurrent rollouts through it (``benchmarks/results/sensorsim_proxy.json``).

Setup: a synthetic scene fitted with the tiny preset (``setdiff-bench synth --preset tiny``, made here unless
``--scenes`` names a folder of fitted scenes), served by ``setdiff-bench serve --protocol sensorsim`` (the
upstream 3DGS renderer) and by a proxy in front of it (``--role proxy --checkpoint tiny_setdiff``), each in its
own process with one torch thread.  The client drives AlpaSim's default rollout: 2 cameras (front, front-left:
the scene's recorded rig) at each of ``--sizes`` (320x512: AlpaSim's default camera, and 576x1024; intrinsics
scaled from the recorded 80x48), one ``batch_render_rgb`` per tick at 10 Hz (or as fast as the slower of the two allows), JPEG q95,
along the scene's held-out lane (lane 1: one lane over from the recorded one).

``overhead`` phase (per tick, p50 over ``--ticks``):

* ``direct_ms``: client → upstream renderer;
* ``proxy_ms``: client → proxy → upstream renderer;
* ``enhancer_alone_ms``: the enhancer's time on the same tick in this process (``StreamSession.enhance_packet``,
  the packet built beforehand), ``cmap_ms``: the proxy's C-map render of the 2 cameras from the PLY,
  ``png_round_trip_ms``: the upstream's PNG encode + the proxy's decode of the 2 frames;
* ``enhancer_in_proxy_ms``: the enhancer's own time on the same request, as the proxy reports it (the reply's
  ``server-timing`` trailing metadata, ``enhance`` stage);
* ``overhead_ratio``: p50 over ticks of ``(proxy_ms - direct_ms) / enhancer_in_proxy_ms`` (goal: <= 1.15):
  what the proxy costs beyond its enhancer, measured on the same tick, so a loaded machine slows both sides
  of the ratio alike; ``overhead_ratio_vs_enhancer_alone`` divides by the enhancer timed in this process
  instead (``enhancer_alone_ms``), which a loaded machine skews.

``load`` phase: ``--rollouts`` client threads at once (8), each ``--load-ticks`` ticks (100) of 2 cameras at
``--load-height x --load-width`` on one of four lateral offsets; every reply must succeed and equal byte for
byte the reply to the same request made alone beforehand (no references or frames mixed between rollouts);
the proxy's resident memory once the rollouts' sessions expired, against its idle level after a warm-up round of
the same rollouts (``--warmup-ticks`` ticks: the first concurrent round grows grpc's threads and the allocator's
per-thread arenas once, as ``benchmarks/serve.py`` measures its idle level).

    python benchmarks/sensorsim_proxy.py [--scenes DIR] [--sizes 320x512 576x1024] [--ticks 3] [--rollouts 8 --load-ticks 100]
    python benchmarks/sensorsim_proxy.py --scenes DIR --sizes --update     # the load phase alone, other phases kept
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # run as a script from anywhere
    sys.path.insert(0, str(ROOT))

from benchmarks.common import RESULTS, machine, write_result  # noqa: E402
from benchmarks.serve import rss_mib  # noqa: E402
from setdiff_bench.cameras import Camera  # noqa: E402
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb  # noqa: E402
from setdiff_bench.serve.sensorsim.service import parse_server_timing  # noqa: E402
from tests.serve.sensorsim_fixtures import pinhole_spec, render_request, stub  # noqa: E402
from tests.serve.serve_fixtures import environment, served  # noqa: E402

#: The recorded rig's cameras used as AlpaSim's two (synthetic scenes name them so).
SENSORS = ("front", "front_left")


def fitted_scenes(folder: Path | None, work: Path) -> Path:
    """A folder of fitted scenes: ``folder`` or one tiny synthetic scene made (and kept) under ``work``."""
    if folder is not None:
        return folder
    out = work / "scenes"
    subprocess.run(
        [
            sys.executable,
            "-m",
            "setdiff_bench",
            "synth",
            "--out",
            str(out),
            "--preset",
            "tiny",
            "--scenes",
            "1",
        ],
        check=True,
        env=environment(),
    )
    return out


def rollout_cameras(
    scene_dir: Path, ticks: int, lateral: float = 0.0
) -> list[list[tuple[str, Camera, Camera]]]:
    """Per tick, per camera: ``(name, native camera, posed camera)`` along the scene's lane 1.

    The ego pose moves linearly from lane 1's first to its last front camera over ``ticks`` (and ``lateral``
    metres sideways); each camera keeps its recorded offset from the front camera (AlpaSim's rig_to_camera).
    """
    from setdiff_bench.loaders import load_scenes

    [scene] = load_scenes("synthetic", scene_dir)
    lane = {
        sensor: sorted(
            (f for f in scene.frames if f.traversal == "lane1" and f.sensor == sensor),
            key=lambda f: f.timestamp_us,
        )
        for sensor in SENSORS
    }
    first, last = lane["front"][0].camera.c2w, lane["front"][-1].camera.c2w
    offsets = {s: np.linalg.inv(first) @ lane[s][0].camera.c2w for s in SENSORS}
    side = first[:3, 0]  # camera x: to the right
    out = []
    for tick in range(ticks):
        ego = first.copy()
        ego[:3, 3] = first[:3, 3] + (last[:3, 3] - first[:3, 3]) * tick / max(1, ticks - 1) + lateral * side
        out.append(
            [
                (sensor, lane[sensor][0].camera, posed(lane[sensor][0].camera, ego @ offsets[sensor]))
                for sensor in SENSORS
            ]
        )
    return out


def posed(native: Camera, c2w: np.ndarray) -> Camera:
    """``native`` moved to the camera-to-world pose ``c2w``."""
    return Camera.from_c2w(c2w, native.K, native.width, native.height)


def batch(
    scene_id: str,
    tick: int,
    cameras: list[tuple[str, Camera, Camera]],
    size: tuple[int, int],
    image_format: int,
) -> pb.BatchRGBRenderRequest:
    """One tick: each camera's native spec (80x48) scaled by the server to ``size``."""
    request = pb.BatchRGBRenderRequest()
    for name, native, posed in cameras:
        item = render_request(posed, name, tick, image_format, pinhole_spec(native, name), scene_id=scene_id)
        item.resolution_h, item.resolution_w = size
        request.items.add(camera_name=name, request=item)
    return request


def p50(samples: list[float]) -> float:
    return float(statistics.median(samples))


def p99(samples: list[float]) -> float:
    return float(np.percentile(samples, 99))


def timed(call: Any) -> tuple[Any, float]:
    start = time.perf_counter()
    out = call()
    return out, (time.perf_counter() - start) * 1000.0


def check(reply: pb.BatchRGBRenderReturn) -> None:
    failed = [f"{i.camera_name}: {i.error_message}" for i in reply.items if not i.success]
    if failed:
        raise RuntimeError("; ".join(failed))


def overhead(
    args: argparse.Namespace, scenes: Path, scene_id: str, direct: Any, proxy: Any, size: tuple[int, int]
) -> dict[str, Any]:
    ticks = rollout_cameras(scenes / scene_id, args.ticks)
    for tick in range(1):  # warm-up: scene load, session open, first renders
        check(
            direct.batch_render_rgb(
                batch(scene_id, tick, ticks[tick], size, pb.ImageFormat.JPEG), timeout=600
            )
        )
        check(
            proxy.batch_render_rgb(batch(scene_id, tick, ticks[tick], size, pb.ImageFormat.JPEG), timeout=600)
        )
    direct_ms, proxy_ms, inside_ms, ratios = [], [], [], []
    for tick, cameras in enumerate(ticks):
        request = batch(scene_id, tick, cameras, size, pb.ImageFormat.JPEG)
        reply, ms = timed(lambda request=request: direct.batch_render_rgb(request, timeout=600))
        check(reply)
        direct_ms.append(ms)
        (reply, call), ms = timed(
            lambda request=request: proxy.batch_render_rgb.with_call(request, timeout=600)
        )
        check(reply)
        proxy_ms.append(ms)
        inside_ms.append(parse_server_timing(call.trailing_metadata())["enhance"])
        ratios.append((proxy_ms[-1] - direct_ms[-1]) / inside_ms[-1])
        time.sleep(max(0.0, 0.1 - (proxy_ms[-1] + direct_ms[-1]) / 1000.0))  # 10 Hz at most
    enhancer_ms, cmap_ms, png_ms = enhancer_time(args, scenes, scene_id, ticks, size)
    added = p50(proxy_ms) - p50(direct_ms)
    return {
        "size": list(size),
        "cameras": len(SENSORS),
        "ticks": len(ticks),
        "direct_ms": {"p50": p50(direct_ms), "p99": p99(direct_ms)},
        "proxy_ms": {"p50": p50(proxy_ms), "p99": p99(proxy_ms)},
        "added_ms_p50": added,
        "enhancer_in_proxy_ms_p50": p50(inside_ms),
        "enhancer_alone_ms_p50": p50(enhancer_ms),
        "cmap_render_ms_p50": p50(cmap_ms),
        "png_round_trip_ms_p50": p50(png_ms),
        "overhead_ratio": p50(ratios),
        "overhead_ratio_per_tick": ratios,
        "overhead_ratio_vs_enhancer_alone": added / p50(enhancer_ms),
        "goal_ratio": 1.15,
        "met": p50(ratios) <= 1.15,
        "per_camera_added_ms_p50": added / len(SENSORS),
    }


def enhancer_time(
    args: argparse.Namespace, scenes: Path, scene_id: str, ticks: list[Any], size: tuple[int, int]
) -> tuple[list[float], list[float], list[float]]:
    """Per tick, in this process (one thread): the enhancer's own time, the proxy's C-map render of the
    tick's cameras, and the PNG round trip of its frames (upstream encode + proxy decode)."""
    from setdiff_bench.enhancers.setdiff import load_enhancer
    from setdiff_bench.evaluation.stream import Views
    from setdiff_bench.serve.sensorsim.enhancing import Frame, SceneSessions
    from setdiff_bench.serve.sensorsim.imaging import decode, encode
    from setdiff_bench.serve.sensorsim.lens import LensCamera, render_lens
    from setdiff_bench.serve.sensorsim.scenes import SceneLibrary, scaled_camera
    from setdiff_bench.serve.settings import ServeSettings

    torch.set_num_threads(1)
    enhancer = load_enhancer("setdiff", args.checkpoint, device="cpu")
    scene = SceneLibrary(scenes).get(scene_id)
    sessions = SceneSessions(enhancer, ServeSettings())
    enhancer_ms, cmap_ms, png_ms = [], [], []
    for cameras in ticks:
        lens = [LensCamera(scaled_camera(posed, *size)) for _, _, posed in cameras]
        drawn, ms = timed(lambda lens=lens: render_lens(scene.gaussians, lens, with_geometry=True))
        cmap_ms.append(ms)
        rgb = (drawn.rgb.clamp(0, 1) * 255).round().to(torch.uint8)
        frames = [
            Frame(name, rgb[i].permute(1, 2, 0).numpy(), lens[i], drawn.cmap[i], drawn.alpha[i])
            for i, (name, _, _) in enumerate(cameras)
        ]
        sessions.enhance(scene, frames)  # opens the session once
        [session] = sessions.sessions.values()
        views = Views(
            rgb, [c.camera for c in lens], drawn.cmap, drawn.alpha, [name for name, _, _ in cameras]
        )
        packet = session.stream.packet(views)
        _, ms = timed(lambda packet=packet, session=session: session.stream.enhance_packet(packet))
        enhancer_ms.append(ms)
        started = time.perf_counter()
        for frame in frames:
            decode(encode(frame.rgb, pb.ImageFormat.PNG), *size, frame.name)
        png_ms.append((time.perf_counter() - started) * 1000.0)
    return enhancer_ms, cmap_ms, png_ms


def load(args: argparse.Namespace, scenes: Path, scene_id: str, proxy: Any, pid: int) -> dict[str, Any]:
    size = (args.load_height, args.load_width)
    lanes = [rollout_cameras(scenes / scene_id, args.load_ticks, lateral=0.5 * k) for k in range(4)]
    requests = [
        [batch(scene_id, t, cameras, size, pb.ImageFormat.JPEG) for t, cameras in enumerate(lane)]
        for lane in lanes
    ]
    alone = [[proxy.batch_render_rgb(r, timeout=600) for r in lane] for lane in requests]
    time.sleep(args.idle_timeout + 2.0)  # sessions expire
    after_alone = rss_mib(pid)

    def concurrently(ticks: int) -> dict[str, Any]:
        """``args.rollouts`` rollouts at once over the first ``ticks`` ticks, each reply checked against alone."""
        errors: list[str] = []
        mismatches = [0]
        latencies: list[float] = []
        lock = threading.Lock()

        def rollout(index: int) -> None:
            lane = index % 4
            for tick, request in enumerate(requests[lane][:ticks]):
                reply, ms = timed(lambda request=request: proxy.batch_render_rgb(request, timeout=600))
                with lock:
                    latencies.append(ms)
                    errors.extend(f"{i.camera_name}: {i.error_message}" for i in reply.items if not i.success)
                    mismatches[0] += reply != alone[lane][tick]

        started = time.perf_counter()
        threads = [threading.Thread(target=rollout, args=(i,)) for i in range(args.rollouts)]
        for thread in threads:
            thread.start()
        busy_peak = 0.0
        while any(t.is_alive() for t in threads):
            busy_peak = max(busy_peak, rss_mib(pid))
            time.sleep(0.5)
        return {
            "calls": len(latencies),
            "errors": errors[:5],
            "error_count": len(errors),
            "replies_differing_from_alone": mismatches[0],
            "tick_ms": {"p50": p50(latencies), "p99": p99(latencies)},
            "wall_s": time.perf_counter() - started,
            "busy_peak_rss_mib": busy_peak,
        }

    warmup = concurrently(args.warmup_ticks)  # grows grpc's threads and the allocator's arenas once
    time.sleep(args.idle_timeout + 2.0)
    idle = rss_mib(pid)
    run = concurrently(args.load_ticks)
    time.sleep(args.idle_timeout + 2.0)
    after = rss_mib(pid)
    return {
        "rollouts": args.rollouts,
        "cameras": len(SENSORS),
        "ticks": args.load_ticks,
        "size": list(size),
        "warmup": warmup,
        **run,
        "rss_mib": {
            "after_sequential_pass": after_alone,
            "idle": idle,
            "after_expiry": after,
            "after_minus_idle": after - idle,
        },
        "memory_goal_mib": 16.0,
        "met": not run["error_count"] and not run["replies_differing_from_alone"] and after - idle <= 16.0,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--scenes", type=Path, default=None, help="folder of fitted scenes (default: made here)"
    )
    parser.add_argument("--work", type=Path, default=Path("runs/sensorsim_bench"))
    parser.add_argument("--checkpoint", default="tiny_setdiff")
    parser.add_argument(
        "--sizes",
        nargs="*",
        default=["320x512", "576x1024"],
        help="HxW of the overhead phase, each in turn (none: skip it)",
    )
    parser.add_argument("--ticks", type=int, default=3)
    parser.add_argument("--rollouts", type=int, default=8)
    parser.add_argument("--load-ticks", type=int, default=100)
    parser.add_argument("--load-height", type=int, default=48)
    parser.add_argument("--load-width", type=int, default=80)
    parser.add_argument("--idle-timeout", type=float, default=3.0)
    parser.add_argument("--warmup-ticks", type=int, default=10, help="ticks of the concurrent warm-up round")
    parser.add_argument("--skip-load", action="store_true")
    parser.add_argument(
        "--update", action="store_true", help="keep the other phases of an existing result file"
    )
    parser.add_argument("--output", default="sensorsim_proxy")
    args = parser.parse_args()
    scenes = fitted_scenes(args.scenes, args.work)
    scene_id = sorted(p.name for p in scenes.iterdir() if (p / "fits" / "lane0.ply").is_file())[0]
    common = ["--protocol", "sensorsim", "--scenes", str(scenes), "--port", "0", "--workers", "12"]
    result: dict[str, Any] = {}
    if args.update and (RESULTS / f"{args.output}.json").is_file():
        result = json.loads((RESULTS / f"{args.output}.json").read_text())
    result.update({"machine": machine(), "scene": scene_id, "checkpoint": args.checkpoint})
    with served(["serve", *common]) as (_, upstream_port):
        proxy_argv = [
            "serve",
            *common,
            "--role",
            "proxy",
            "--upstream",
            f"127.0.0.1:{upstream_port}",
            "--checkpoint",
            args.checkpoint,
            "--session-idle-timeout",
            str(args.idle_timeout),
        ]
        with served(proxy_argv) as (process, proxy_port):
            direct, proxy = stub(f"127.0.0.1:{upstream_port}"), stub(f"127.0.0.1:{proxy_port}")
            command = "python " + " ".join(sys.argv)
            if not args.skip_load:
                result["load"] = {"command": command, **load(args, scenes, scene_id, proxy, process.pid)}
                print(result["load"], flush=True)
                write_result(args.output, result)  # each phase is kept as soon as it ends
            if args.sizes:
                result["overhead"] = {"command": command}
            for size in args.sizes:
                height, width = (int(v) for v in size.split("x"))
                result["overhead"][size] = overhead(args, scenes, scene_id, direct, proxy, (height, width))
                print(size, result["overhead"][size], flush=True)
                write_result(args.output, result)
    print("wrote", write_result(args.output, result))


if __name__ == "__main__":
    main()
