"""``setdiff-bench serve`` with a real server on a free 127.0.0.1 port: round trip, equality with the batch
runner over a recorded drive, every bad-input case, backpressure, two concurrent sessions, SIGTERM."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import grpc
import numpy as np
import pytest
import torch

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamSession, Views
from setdiff_bench.io.images import read_rgb
from setdiff_bench.io.run_layout import IMAGES_DIR
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve.client import EnhancerClient
from setdiff_bench.serve.server import RunningServer, start_server
from setdiff_bench.serve.settings import ServeSettings
from setdiff_bench.serve.wire import to_array
from tests.evaluation.stream.stream_fixtures import (
    RIG,
    recorded_references,
    run_batch,
    serve_argv,
    tick_frames,
    write_tick_store,
)

TICKS = 30
LARGE = (144, 256)  # a tick that takes ~0.7 s on one CPU thread, so requests overlap


@pytest.fixture(scope="module")
def server(checkpoint: Path) -> Iterator[RunningServer]:
    running = start_server(
        load_enhancer("setdiff", str(checkpoint), device="cpu"),
        ServeSettings(port=0, workers=4, max_queue=16, max_sessions=4, max_cameras=4),
    )
    yield running
    running.stop(grace=5)


@pytest.fixture
def client(server: RunningServer) -> Iterator[EnhancerClient]:
    with EnhancerClient(f"127.0.0.1:{server.port}", timeout=60) as client:
        client.wait_ready()
        yield client


def test_drive_of_30_ticks_equals_batch_runner(
    client: EnhancerClient, checkpoint: Path, tmp_path: Path
) -> None:
    """A 3-camera, 30-tick drive streamed through the server equals `run --method setdiff` on the same views."""
    assert client.healthy()
    version = client.get_version()
    assert version.method == "setdiff" and version.checkpoint == str(checkpoint)
    references = recorded_references()
    session = client.start_session(references)
    chooser = StreamSession(load_enhancer("setdiff", str(checkpoint), device="cpu"), references)
    streamed = {}
    for tick in range(TICKS):
        frames = tick_frames(tick)
        streamed[tick] = client.enhance(session, frames)
        write_tick_store(tmp_path / "store", references, frames, chooser.select(frames.cameras), tick)
    client.close_session(session)
    run_batch(tmp_path / "store", tmp_path / "run", checkpoint)
    compared = 0
    for tick, images in streamed.items():
        assert images.shape == (3, 32, 48, 3) and images.dtype == np.uint8
        for position, (sensor, _) in enumerate(RIG):
            [written] = (tmp_path / "run" / IMAGES_DIR).rglob(f"{sensor}/{tick:06d}.png")
            batch = np.rint(read_rgb(written) * 255).astype(np.uint8)
            assert np.array_equal(batch, images[position]), (tick, sensor)
            compared += 1
    assert compared == 3 * TICKS


def _code(call) -> tuple[grpc.StatusCode, str]:
    with pytest.raises(grpc.RpcError) as caught:
        call()
    return caught.value.code(), caught.value.details()


def test_each_bad_input_is_refused_and_the_server_keeps_serving(client: EnhancerClient) -> None:
    session = client.start_session(recorded_references())
    good = tick_frames(0)
    request = client.enhance_request(session, good)

    wrong_size = client.enhance_request(session, tick_frames(0, size=(48, 64)))
    nan_image = client.enhance_request(session, good)
    pixels = good.images[0].permute(1, 2, 0).float().numpy() / 255
    pixels[0, 0, 0] = np.nan
    nan_image.frames[0].rgb.CopyFrom(to_array(pixels.astype(np.float32)))
    nan_pose = client.enhance_request(session, good)
    nan_pose.frames[1].camera.world_to_camera[3] = float("nan")
    non_rigid = client.enhance_request(session, good)
    for i in (0, 5, 10):  # scale the rotation block by 2
        non_rigid.frames[2].camera.world_to_camera[i] *= 2.0
    short_bytes = client.enhance_request(session, good)
    short_bytes.frames[0].rgb.data = short_bytes.frames[0].rgb.data[:-1]
    too_many = client.enhance_request(
        session,
        Views(
            torch.cat([good.images, good.images]), [*good.cameras] * 2, torch.cat([good.cmaps, good.cmaps])
        ),
    )
    unknown = pb.EnhanceRequest(session_uuid="no-such-session", frames=request.frames)
    cases = {
        "wrong image size": (wrong_size, grpc.StatusCode.INVALID_ARGUMENT, "expects 48x32"),
        "NaN image": (nan_image, grpc.StatusCode.INVALID_ARGUMENT, "NaN"),
        "NaN pose": (nan_pose, grpc.StatusCode.INVALID_ARGUMENT, "NaN"),
        "non-rigid pose": (non_rigid, grpc.StatusCode.INVALID_ARGUMENT, "rotation"),
        "byte count": (short_bytes, grpc.StatusCode.INVALID_ARGUMENT, "bytes"),
        "too many cameras": (too_many, grpc.StatusCode.INVALID_ARGUMENT, "at most 4"),
        "unknown session": (unknown, grpc.StatusCode.NOT_FOUND, "unknown session"),
    }
    for name, (bad, code, words) in cases.items():
        got, details = _code(lambda bad=bad: client.stub.enhance(bad, timeout=30))
        assert got == code, (name, got, details)
        assert words in details and "\n" not in details, (name, details)
        assert client.enhance(session, request).shape == (3, 32, 48, 3)  # still serving
    assert _code(lambda: client.close_session("no-such-session"))[0] == grpc.StatusCode.NOT_FOUND
    assert (
        _code(lambda: client.start_session(Views(good.images, good.cameras)))[0]
        == grpc.StatusCode.INVALID_ARGUMENT
    )  # no C-maps and no PLY
    client.close_session(session)


def test_bounded_queue_answers_resource_exhausted(checkpoint: Path) -> None:
    running = start_server(
        load_enhancer("setdiff", str(checkpoint), device="cpu"), ServeSettings(port=0, workers=2, max_queue=2)
    )
    try:
        with EnhancerClient(f"127.0.0.1:{running.port}") as client:
            session = client.start_session(recorded_references(LARGE))
            request = client.enhance_request(session, tick_frames(0, LARGE))
            calls = [client.stub.enhance.future(request, timeout=120) for _ in range(8)]
            codes = []
            for call in calls:
                try:
                    call.result()
                    codes.append(grpc.StatusCode.OK)
                except grpc.RpcError as error:
                    codes.append(error.code())
            assert codes.count(grpc.StatusCode.RESOURCE_EXHAUSTED) >= 1, codes
            assert codes.count(grpc.StatusCode.OK) >= 1, codes
            assert set(codes) <= {grpc.StatusCode.OK, grpc.StatusCode.RESOURCE_EXHAUSTED}, codes
            assert client.enhance(session, request).shape == (3, *LARGE, 3)  # and serves again afterwards
    finally:
        running.stop(grace=10)


def test_session_limit_answers_resource_exhausted(client: EnhancerClient, server: RunningServer) -> None:
    opened = [client.start_session(recorded_references()) for _ in range(4 - len(server.service.sessions))]
    code, details = _code(lambda: client.start_session(recorded_references()))
    assert code == grpc.StatusCode.RESOURCE_EXHAUSTED and "at most 4" in details
    for session in opened:
        client.close_session(session)


def test_two_concurrent_sessions_are_isolated(client: EnhancerClient, checkpoint: Path) -> None:
    """Two sessions with different recordings, driven from two threads at once, each get what they would alone."""
    enhancer = load_enhancer("setdiff", str(checkpoint), device="cpu")
    recordings = {"a": recorded_references(seed=1), "b": recorded_references(seed=2)}
    expected = {
        key: [StreamSession(enhancer, refs).enhance(tick_frames(t)) for t in range(5)]
        for key, refs in recordings.items()
    }
    sessions = {key: client.start_session(refs) for key, refs in recordings.items()}
    barrier = threading.Barrier(2)

    def drive(key: str) -> list[np.ndarray]:
        barrier.wait()
        return [client.enhance(sessions[key], tick_frames(t)) for t in range(5)]

    with ThreadPoolExecutor(2) as pool:
        got = dict(zip(sessions, pool.map(drive, sessions)))
    for key in sessions:
        for t in range(5):
            want = torch.round(expected[key][t].clamp(0, 1) * 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()
            assert np.array_equal(got[key][t], want), (key, t)
        client.close_session(sessions[key])
    assert not np.array_equal(got["a"][0], got["b"][0])  # the recordings do matter


def test_sigterm_finishes_in_flight_requests(checkpoint: Path) -> None:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(Path(__file__).resolve().parents[3])}
    process = subprocess.Popen(
        [sys.executable, "-m", "setdiff_bench", *serve_argv(checkpoint, "--grace", "60")],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        line = process.stdout.readline()
        assert line.startswith("serving on 127.0.0.1:"), (
            line,
            process.stderr.read() if process.poll() else "",
        )
        port = int(line.split(":")[1].split()[0])
        with EnhancerClient(f"127.0.0.1:{port}") as client:
            session = client.start_session(recorded_references(LARGE))
            request = client.enhance_request(session, tick_frames(0, LARGE))
            client.enhance(session, request)  # warm
            in_flight = client.stub.enhance.future(request, timeout=120)
            threading.Event().wait(0.2)
            process.send_signal(signal.SIGTERM)
            reply = in_flight.result()
            assert len(reply.images) == 3
            assert process.wait(timeout=60) == 0
            assert "stopped" in process.stdout.read()
            with pytest.raises(grpc.RpcError):
                client.stub.get_version(pb.Empty(), timeout=5)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()


def test_server_binds_localhost_by_default() -> None:
    assert ServeSettings().host == "127.0.0.1"


def test_example_replays_a_store_through_the_server(
    server: RunningServer, checkpoint: Path, tmp_path: Path
) -> None:
    """examples/drive_packets.py: world cameras and C-maps recovered from a store give the batch runner's images."""
    references = recorded_references()
    chooser = StreamSession(load_enhancer("setdiff", str(checkpoint), device="cpu"), references)
    for tick in range(3):
        frames = tick_frames(tick)
        write_tick_store(tmp_path / "store", references, frames, chooser.select(frames.cameras), tick)
    run_batch(tmp_path / "store", tmp_path / "run", checkpoint)
    root = Path(__file__).resolve().parents[3]
    subprocess.run(
        [
            sys.executable,
            str(root / "examples" / "drive_packets.py"),
            "--packets",
            str(tmp_path / "store"),
            "--out",
            str(tmp_path / "out"),
            "--address",
            f"127.0.0.1:{server.port}",
        ],
        check=True,
        env={**os.environ, "PYTHONPATH": str(root), "OMP_NUM_THREADS": "1"},
        capture_output=True,
    )
    replayed = sorted((tmp_path / "out").rglob("*.png"))
    assert len(replayed) == 9
    worst = 0
    for path in replayed:
        [batch] = (tmp_path / "run" / IMAGES_DIR).rglob(f"{path.parent.name}/{path.name}")
        difference = np.abs(np.rint(read_rgb(path) * 255) - np.rint(read_rgb(batch) * 255))
        worst = max(worst, int(difference.max()))
    assert worst <= 1  # C-maps pass a float64 round trip to the world frame and back (0 when last run)
