"""Sessions with a real server on a free 127.0.0.1 port: an unexpected error answers INTERNAL in one line,
abandoned sessions expire and free their slot and memory, 20 clients killed mid-drive do not lock out the
21st, the per-session memory bound, and FIFO turns on the model."""

from __future__ import annotations

import logging
import signal
import threading
import time
import weakref
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import grpc
import numpy as np
import pytest

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve.client import EnhancerClient, view_messages
from setdiff_bench.serve.server import RunningServer, start_server
from setdiff_bench.serve.sessions import FairLock
from setdiff_bench.serve.settings import ServeSettings
from setdiff_bench.serve.wire import to_array
from tests.evaluation.stream.stream_fixtures import HEIGHT, WIDTH, recorded_references, tick_frames
from tests.serve.serve_fixtures import start_driver

#: The tests' 48×32 frames are smaller than the shipped models' 256×144: the domain warning is expected.
pytestmark = pytest.mark.filterwarnings("ignore::setdiff_bench.errors.OutOfDistributionWarning")


@pytest.fixture(scope="module")
def enhancer() -> Any:
    return load_enhancer("setdiff", "tiny_setdiff", device="cpu")


@contextmanager
def serving(
    enhancer: Any, clock: Any = time.monotonic, **settings: Any
) -> Iterator[tuple[RunningServer, EnhancerClient]]:
    running = start_server(enhancer, ServeSettings(port=0, **settings), clock=clock)
    try:
        with EnhancerClient(f"127.0.0.1:{running.port}", timeout=60) as client:
            client.wait_ready()
            yield running, client
    finally:
        running.stop(grace=5)


def refused(call: Any) -> tuple[grpc.StatusCode, str]:
    with pytest.raises(grpc.RpcError) as caught:
        call()
    return caught.value.code(), caught.value.details()


class Broken:
    """The shipped enhancer, except that enhancing raises a Python error (a bug inside the server)."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner
        self.name = inner.name
        self.checkpoint = inner.checkpoint
        self.options = inner.options
        self.fail = True

    def enhance(self, packet: Any) -> Any:
        if self.fail:
            raise ZeroDivisionError("secret internals\nTraceback (most recent call last)")
        return self.inner.enhance(packet)


def test_unexpected_error_answers_internal_in_one_line(
    enhancer: Any, caplog: pytest.LogCaptureFixture
) -> None:
    broken = Broken(enhancer)
    with serving(broken) as (running, client), caplog.at_level(logging.ERROR, "setdiff_bench.serve"):
        session = client.start_session(recorded_references())
        code, details = refused(lambda: client.enhance(session, tick_frames(0)))
        assert code == grpc.StatusCode.INTERNAL
        assert details.startswith("internal server error in enhance (incident ")
        assert "\n" not in details and "secret" not in details and "ZeroDivision" not in details
        incident = details.split("incident ")[1].split(";")[0]
        assert any(incident in r.getMessage() and r.exc_info for r in caplog.records)  # traceback: server log
        assert running.service.internal_errors == 1
        broken.fail = False
        assert client.enhance(session, tick_frames(0)).shape == (3, HEIGHT, WIDTH, 3)  # still serving
        client.close_session(session)


class Clock:
    """A clock the test moves (seconds): expiry decisions do not depend on how busy the machine is."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now


def wait_until(condition: Any, seconds: float = 30.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        time.sleep(0.05)


def test_abandoned_session_expires_and_its_slot_is_reused(enhancer: Any) -> None:
    clock = Clock()
    with serving(enhancer, clock, max_sessions=2, session_idle_timeout=60) as (running, client):
        kept = client.start_session(recorded_references())
        abandoned = client.start_session(recorded_references(seed=2))
        held = weakref.ref(running.service.sessions[abandoned].stream)
        code, details = refused(lambda: client.start_session(recorded_references()))
        assert code == grpc.StatusCode.RESOURCE_EXHAUSTED and "expire after 60 s" in details
        client.enhance(abandoned, tick_frames(0))
        clock.now += 40
        client.enhance(kept, tick_frames(1))  # the kept session calls; the other stays silent
        clock.now += 30  # abandoned: 70 s idle; kept: 30 s
        wait_until(lambda: abandoned not in running.service.sessions)  # the reaper thread expires it
        assert set(running.service.sessions) == {kept}
        assert held() is None  # its references are freed (by reference counting: no gc.collect() needed)
        code, details = refused(lambda: client.enhance(abandoned, tick_frames(0)))
        assert code == grpc.StatusCode.NOT_FOUND and "expired after 60 s without a call" in details
        assert refused(lambda: client.close_session(abandoned))[0] == grpc.StatusCode.NOT_FOUND
        reused = client.start_session(recorded_references())  # the slot is free again
        assert client.enhance(reused, tick_frames(0)).shape == (3, HEIGHT, WIDTH, 3)
        assert client.enhance(kept, tick_frames(2)).shape == (3, HEIGHT, WIDTH, 3)  # 30 s idle: still open
        clock.now += 59  # idle for 59 s of its 60: still open
        assert client.enhance(kept, tick_frames(3)).shape == (3, HEIGHT, WIDTH, 3)
        clock.now += 61  # both silent for 61 s: a call finds them expired even before the reaper looks
        assert refused(lambda: client.enhance(reused, tick_frames(0)))[0] == grpc.StatusCode.NOT_FOUND
        wait_until(lambda: not running.service.sessions)


def test_client_chosen_lease(enhancer: Any) -> None:
    with serving(enhancer, session_idle_timeout=60) as (running, client):
        reply = client.stub.start_session(
            pb.StartSessionRequest(references=view_messages(recorded_references()), idle_timeout_s=0.3)
        )
        assert reply.idle_timeout_s == pytest.approx(0.3)
        time.sleep(0.3 + 0.5)  # the reaper looks every min(1 s, timeout / 4)
        code, details = refused(lambda: client.enhance(reply.session_uuid, tick_frames(0)))
        assert code == grpc.StatusCode.NOT_FOUND and "expired" in details
        for bad in (120.0, -1.0, float("nan")):
            code, details = refused(
                lambda bad=bad: client.start_session(recorded_references(), idle_timeout_s=bad)
            )
            assert code == grpc.StatusCode.INVALID_ARGUMENT and "idle_timeout_s" in details, details
        assert client.stub.start_session(
            pb.StartSessionRequest(references=view_messages(recorded_references()))
        ).idle_timeout_s == pytest.approx(60)
        assert not running.service.sessions or len(running.service.sessions) == 1


def test_twenty_clients_killed_mid_drive_do_not_lock_out_the_21st(enhancer: Any, tmp_path: Path) -> None:
    """20 simulator processes (16 slots) open sessions, drive, and are SIGKILLed mid-drive; the 21st gets in.

    The lease is 3 s: long enough that a driver's first tick reaches the server within it on a loaded 2-core
    machine (with 1 s, a driver descheduled between its session and its tick lost the session)."""
    timeout = 3.0
    with serving(enhancer, max_sessions=16, session_idle_timeout=timeout, max_queue=64) as (running, client):
        start_file, tick_file = tmp_path / "start.bin", tmp_path / "tick.bin"
        start_file.write_bytes(
            pb.StartSessionRequest(references=view_messages(recorded_references())).SerializeToString()
        )
        tick_file.write_bytes(client.enhance_request("", tick_frames(0)).SerializeToString())
        address = f"127.0.0.1:{running.port}"
        drivers = [start_driver(address, start_file, tick_file) for _ in range(20)]
        try:
            killed = 0
            for driver in drivers:  # each is killed after its first enhanced tick
                line = driver.stdout.readline()
                assert line.startswith("tick "), (line, driver.stderr.read() if driver.poll() else "")
                driver.send_signal(signal.SIGKILL)
                driver.wait()
                killed += 1
            assert killed == 20
        finally:
            for driver in drivers:
                if driver.poll() is None:
                    driver.kill()
                    driver.wait()
        start = time.monotonic()
        while True:  # a 21st simulator, retrying as the drivers do
            try:
                session = client.start_session(recorded_references())
                break
            except grpc.RpcError as error:
                assert error.code() == grpc.StatusCode.RESOURCE_EXHAUSTED
                assert time.monotonic() - start < timeout + 30, "locked out"  # generous: a very busy machine
                time.sleep(0.1)
        assert client.enhance(session, tick_frames(3)).shape == (3, HEIGHT, WIDTH, 3)
        wait_until(lambda: len(running.service.expired) >= 20)  # every killed client's session expires
        assert set(running.service.sessions) <= {session}


def test_session_over_the_memory_bound_is_refused_at_start(enhancer: Any) -> None:
    per_reference = 28 * HEIGHT * WIDTH  # float32 RGB + C-map + alpha per pixel
    bound_mib = 4.5 * per_reference / 2**20  # room for 4 references, not 5
    with serving(enhancer, max_session_mib=bound_mib) as (running, client):
        six = recorded_references()
        code, details = refused(lambda: client.start_session(six))
        assert code == grpc.StatusCode.RESOURCE_EXHAUSTED and "at most" in details and "MiB" in details
        assert not running.service.sessions
        four = recorded_references()
        four.images, four.cmaps, four.alphas = four.images[:4], four.cmaps[:4], four.alphas[:4]
        four.cameras, four.names = four.cameras[:4], four.names[:4]
        session = client.start_session(four)
        held = running.service.sessions[session]
        references = held.stream.references
        actual = sum(
            t.element_size() * t.nelement() for t in (references.images, references.cmaps, references.alphas)
        )
        assert held.held_bytes == actual == 4 * per_reference  # the bound counts what the session holds
        assert client.enhance(session, tick_frames(0)).shape == (3, HEIGHT, WIDTH, 3)
        client.close_session(session)


def test_fair_lock_serves_in_arrival_order() -> None:
    lock = FairLock()
    order: list[str] = []

    def take(name: str) -> None:
        with lock.hold(name):
            order.append(name)

    threads = [threading.Thread(target=take, args=(name,)) for name in "abcdef"]
    with lock.hold("first"):
        for queued, thread in enumerate(threads, start=1):
            thread.start()
            while len(lock._queue) < queued:  # wait until it queues behind the holder: arrival order known
                time.sleep(0.001)
    for thread in threads:
        thread.join(timeout=10)
    assert order == list("abcdef")
    assert list(lock.grants) == ["first", *"abcdef"]


def test_concurrent_sessions_take_turns_on_the_model(enhancer: Any) -> None:
    """Four sessions calling at once take the model in the order their ticks arrived, and each gets what it
    would alone."""
    ticks = 6
    with serving(enhancer, workers=8) as (running, client):
        recordings = [recorded_references(seed=s) for s in range(1, 5)]
        sessions = [client.start_session(refs) for refs in recordings]
        requests = [[client.enhance_request(s, tick_frames(t)) for t in range(ticks)] for s in sessions]
        barrier = threading.Barrier(4)
        got: dict[int, list[np.ndarray]] = {}

        def drive(index: int) -> None:
            barrier.wait()
            got[index] = [client.enhance(sessions[index], request) for request in requests[index]]

        threads = [threading.Thread(target=drive, args=(i,)) for i in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=120)
        grants = list(running.service.model_lock.grants)
        assert sorted(grants) == sorted(s for s in sessions for _ in range(ticks))
        arrivals = list(running.service.model_lock.arrivals)
        assert arrivals == sorted(arrivals)  # served in the order they asked: FIFO across sessions
        for index, refs in enumerate(recordings):
            alone = StreamSession(enhancer, refs)
            for t in range(ticks):
                want = np.rint(alone.enhance(tick_frames(t)).permute(0, 2, 3, 1).numpy() * 255).astype(
                    np.uint8
                )
                assert np.array_equal(got[index][t], want), (index, t)
        for session in sessions:
            client.close_session(session)


def test_invalid_argument_names_the_field_once(enhancer: Any) -> None:
    """Issue 45: the NaN error repeated its prefix ("frames[0] 'x' rgb: frames[0] 'x' rgb: contains NaN")."""
    with serving(enhancer) as (_, client):
        session = client.start_session(recorded_references())
        frames = tick_frames(0)
        request = client.enhance_request(session, frames)
        pixels = frames.images[0].permute(1, 2, 0).float().numpy() / 255
        pixels[0, 0, 0] = np.nan
        request.frames[0].rgb.CopyFrom(to_array(pixels.astype(np.float32)))
        code, details = refused(lambda: client.stub.enhance(request, timeout=30))
        assert code == grpc.StatusCode.INVALID_ARGUMENT
        assert details == "frames[0] 'front/000000.png' rgb: contains NaN or infinite values"
        client.close_session(session)


def test_load_benchmark_smoke(tmp_path: Path) -> None:
    """benchmarks/serve.py --load on a small scale: kills, expiry, byte equality and memory are all reported."""
    from benchmarks.serve import load_test

    result = load_test(
        "tiny_setdiff", "setdiff", [2], ticks=3, idle_timeout=0.5, seed=1, with_lock_comparison=False
    )
    [phase] = result["phases"]
    assert phase["clients"] == 2 and phase["killed_mid_drive"] == 1 and phase["clients_finished"] == 2
    assert phase["byte_equal_to_batch_runner"] and result["all_byte_equal"]
    assert phase["failures"] == [] and phase["ticks_timed"] == 2 * 3
    assert result["full_sessions"]["predicted_held_mib"] == pytest.approx(2 * 16 * 28 * 144 * 256 / 2**20)


def test_serve_settings_agree_with_the_stream_api_and_load_no_torch() -> None:
    import subprocess
    import sys

    from setdiff_bench.evaluation import stream

    assert ServeSettings().max_cameras == stream.MAX_CAMERAS_PER_TICK == 16
    probe = "import sys, setdiff_bench.cli.serve; print('torch' in sys.modules, 'grpc' in sys.modules)"
    loaded = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    assert loaded.stdout.split() == ["False", "False"]  # serve --help stays fast


def test_session_ids_that_cannot_be_ours_are_refused_without_echo(enhancer: Any) -> None:
    with serving(enhancer) as (_, client):
        request = client.enhance_request("x" * 10_000, tick_frames(0))
        for call in (
            lambda: client.stub.enhance(request, timeout=30),
            lambda: client.close_session("bad\nid"),
            lambda: client.close_session(""),
        ):
            code, details = refused(call)
            assert code == grpc.StatusCode.INVALID_ARGUMENT and "not a session id" in details
            assert len(details) < 200 and "\n" not in details
        assert refused(lambda: client.close_session("0" * 36))[0] == grpc.StatusCode.NOT_FOUND


def test_sigterm_right_after_the_serving_line_stops_gracefully() -> None:
    """The "serving on" line is printed only once the SIGTERM handler is installed: a supervisor that
    signals as soon as it reads the line gets a graceful stop (exit 0, "stopped"), not a kill (-15)."""
    from tests.evaluation.stream.stream_fixtures import serve_argv
    from tests.serve.serve_fixtures import served

    with served(serve_argv("tiny_difix", "--method", "difix")) as (process, _):
        process.send_signal(signal.SIGTERM)
        out, _ = process.communicate(timeout=60)
    assert process.returncode == 0 and out.strip().endswith("stopped")
