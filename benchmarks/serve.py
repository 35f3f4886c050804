"""Serve benchmark: the stream API in-process against the gRPC round trip on 127.0.0.1, same run.

Latency per tick (p50 / p99, ms) and frames per second for a 3-camera rig driven along a synthetic
recorded trajectory (``tests/evaluation/stream/stream_fixtures``), for

* ``in_process``: :class:`setdiff_bench.evaluation.stream.StreamSession` called directly (uint8 in, uint8 out);
* ``grpc``: ``setdiff-bench serve`` in its own process, called through
  :class:`setdiff_bench.serve.client.EnhancerClient` (request encoding, transport, decoding included);
* ``in_process_cached``: the same with the reference-latent cache on.

Goal: the service adds <= 20 % over in-process (``overhead_ratio = grpc p50 / in_process p50``) at
256x144 on the CPU.  Both run with one torch thread.  ``--memory N`` instead sends N small requests to
a served process and samples its resident memory every N/10 requests (flat-memory check).

The model is a tiny random SetDiff (``--checkpoint`` to use a trained one): the enhancer's own cost
is small, which makes the overhead ratio a conservative (large) estimate.

    python benchmarks/serve.py [--height 144 --width 256] [--ticks 40] [--checkpoint CKPT]
    python benchmarks/serve.py --memory 10000 --height 32 --width 48
    python benchmarks/serve.py --load 1 4 16 [--ticks 20] [--checkpoint tiny_setdiff]

``--load N ...`` is the many-simulators test (``benchmarks/results/serve_load.json``): one served process
(the shipped ``tiny_setdiff`` by default, 32x48 frames), and for each N, N client *processes* at once, each
opening a session with one of four recorded drives and driving a 3-camera sequence tick by tick.  A quarter
of them (at least one) are SIGKILLed at a random tick and restarted (a crashed simulator): their sessions
are left open and must expire (``--session-idle-timeout``) to free the slot a restarted client waits for.
Per N: p50 / p99 tick latency seen by the clients, frames per second, per-client fairness (Jain's index of
the clients' mean latencies; max / min), every finished client's images byte-equal to ``run --method`` on
the same views, and the server's resident memory after all clients are gone against its idle level.
"""

from __future__ import annotations

import argparse
import json
import os
import random
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import torch

from benchmarks.common import machine, write_result
from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.io.images import read_rgb
from setdiff_bench.io.run_layout import IMAGES_DIR
from setdiff_bench.serve.client import EnhancerClient, view_messages
from tests.evaluation.stream.stream_fixtures import (
    RIG,
    recorded_references,
    run_batch,
    save_tiny_checkpoint,
    serve_argv,
    tick_frames,
    write_tick_store,
)

ROOT = Path(__file__).resolve().parents[1]


def percentiles(samples: list[float], frames_per_tick: int) -> dict[str, float]:
    ms = np.asarray(samples) * 1000.0
    return {
        "p50_ms": float(np.percentile(ms, 50)),
        "p99_ms": float(np.percentile(ms, 99)),
        "mean_ms": float(ms.mean()),
        "ticks": len(ms),
        "frames_per_s": float(frames_per_tick * len(ms) / (ms.sum() / 1000.0)),
    }


def in_process(
    checkpoint: Path, size: tuple[int, int], ticks: int, cache: bool, device: str
) -> dict[str, float]:
    session = StreamSession(
        load_enhancer("setdiff", str(checkpoint), device=device),
        recorded_references(size),
        cache_reference_latents=cache,
    )
    frames = [tick_frames(t, size) for t in range(ticks)]
    session.enhance(frames[0])  # warm-up
    samples = []
    for tick in frames:
        start = time.perf_counter()
        out = session.enhance(tick)
        torch.round(out * 255).to(torch.uint8).permute(0, 2, 3, 1).numpy()
        samples.append(time.perf_counter() - start)
    return percentiles(samples, 3)


def start_served(
    checkpoint: Path | str, *extra: str, device: str = "cpu"
) -> tuple[subprocess.Popen[str], int]:
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    process = subprocess.Popen(
        [
            sys.executable,
            "-c",
            "import torch, sys; torch.set_num_threads(1); "
            "from setdiff_bench.cli.main import main; sys.exit(main(sys.argv[1:]))",
            *serve_argv(checkpoint, *extra, device=device),
        ],
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    line = process.stdout.readline()
    return process, int(line.split(":")[1].split()[0])


def stop_served(process: subprocess.Popen[str]) -> None:
    process.terminate()
    process.wait(timeout=60)


def over_grpc(checkpoint: Path, size: tuple[int, int], ticks: int, device: str) -> dict[str, float]:
    process, port = start_served(checkpoint, device=device)
    try:
        with EnhancerClient(f"127.0.0.1:{port}") as client:
            session = client.start_session(recorded_references(size))
            frames = [tick_frames(t, size) for t in range(ticks)]
            client.enhance(session, frames[0])
            samples = []
            for tick in frames:
                start = time.perf_counter()
                client.enhance(session, tick)  # request built and reply decoded inside the timing
                samples.append(time.perf_counter() - start)
            client.close_session(session)
    finally:
        stop_served(process)
    return percentiles(samples, 3)


def rss_mib(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    raise RuntimeError("no VmRSS")


def memory(checkpoint: Path, size: tuple[int, int], requests: int) -> dict[str, Any]:
    process, port = start_served(checkpoint)
    samples = []
    try:
        with EnhancerClient(f"127.0.0.1:{port}") as client:
            session = client.start_session(recorded_references(size))
            requests_built = [client.enhance_request(session, tick_frames(t, size)) for t in range(50)]
            every = max(1, requests // 10)
            start = time.perf_counter()
            for i in range(requests):
                client.enhance(session, requests_built[i % len(requests_built)])
                if i % every == 0 or i == requests - 1:
                    samples.append({"requests": i + 1, "rss_mib": rss_mib(process.pid)})
            seconds = time.perf_counter() - start
            client.close_session(session)
    finally:
        stop_served(process)
    after_warmup = [s["rss_mib"] for s in samples[1:]]
    return {
        "requests": requests,
        "seconds": seconds,
        "samples": samples,
        "growth_after_first_sample_mib": max(after_warmup) - after_warmup[0] if after_warmup else 0.0,
    }


# ------------------------------------------------------------------------------------------------ load test
#: Recorded drives the clients share out (client i drives recording i % 4): sessions differ, and every
#: client's images are checked against the batch runner on its own recording.
RECORDINGS = 4

#: A simulator process (grpc + the generated messages only, so 16 start fast): opens a session (retrying
#: while the server is full), drives every tick, prints ``tick N`` after each, closes, and writes its images
#: and latencies to OUT.npz.
WORKER = r"""
import sys, time, grpc, numpy as np
from setdiff_bench.serve import enhancer_pb2 as pb, enhancer_pb2_grpc as pb_grpc
address, folder, ticks, out = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
options = [("grpc.max_receive_message_length", 1 << 28), ("grpc.max_send_message_length", 1 << 28)]
stub = pb_grpc.EnhancerStub(grpc.insecure_channel(address, options=options))
start = pb.StartSessionRequest.FromString(open(f"{folder}/start.bin", "rb").read())
requests = [pb.EnhanceRequest.FromString(open(f"{folder}/tick{t:04d}.bin", "rb").read()) for t in range(ticks)]
began = time.perf_counter()
while True:
    try:
        session = stub.start_session(start, timeout=60).session_uuid
        break
    except grpc.RpcError as error:
        if error.code() != grpc.StatusCode.RESOURCE_EXHAUSTED or time.perf_counter() - began > 120:
            raise
        time.sleep(0.05)
waited = time.perf_counter() - began
images, latencies = [], []
for t, request in enumerate(requests):
    request.session_uuid = session
    tick_start = time.perf_counter()
    reply = stub.enhance(request, timeout=120)
    images.append(np.stack([np.frombuffer(a.data, np.uint8).reshape(tuple(a.shape)) for a in reply.images]))
    latencies.append(time.perf_counter() - tick_start)
    print(f"tick {t}", flush=True)
stub.close_session(pb.SessionId(session_uuid=session), timeout=60)
np.savez(out, images=np.stack(images), latencies=np.asarray(latencies), waited=waited)
print("done", flush=True)
"""


def batch_expected(folder: Path, checkpoint: str, method: str, ticks: int) -> dict[int, np.ndarray]:
    """``run --method`` on each recording's ticks (references as a session picks them):
    ``{recording: (ticks, 3, H, W, 3) uint8}``; also writes each recording's requests for the workers."""
    from setdiff_bench.serve import enhancer_pb2 as pb

    enhancer = load_enhancer(method, checkpoint, device="cpu")
    expected = {}
    for recording in range(RECORDINGS):
        references = recorded_references(seed=1 + recording)
        chooser = StreamSession(enhancer, references)
        store, run, requests = (folder / f"rec{recording}" / name for name in ("store", "run", "requests"))
        requests.mkdir(parents=True)
        start = pb.StartSessionRequest(references=view_messages(references))
        (requests / "start.bin").write_bytes(start.SerializeToString())
        for tick in range(ticks):
            frames = tick_frames(tick)
            write_tick_store(store, references, frames, chooser.select(frames.cameras), tick)
            message = pb.EnhanceRequest(frames=view_messages(frames))  # the worker sets its session
            (requests / f"tick{tick:04d}.bin").write_bytes(message.SerializeToString())
        run_batch(store, run, checkpoint, method)
        images = np.zeros(
            (ticks, len(RIG), *read_rgb(next((run / IMAGES_DIR).rglob("*.png"))).shape), np.uint8
        )
        for tick in range(ticks):
            for position, (sensor, _) in enumerate(RIG):
                [written] = (run / IMAGES_DIR).rglob(f"{sensor}/{tick:06d}.png")
                images[tick, position] = np.rint(read_rgb(written) * 255).astype(np.uint8)
        expected[recording] = images
    return expected


class Slot:
    """One simulated client: a worker process, SIGKILLed at ``kill_at`` (if set) and then restarted once."""

    def __init__(self, index: int, address: str, folder: Path, ticks: int, kill_at: int | None) -> None:
        self.index, self.address, self.folder, self.ticks, self.kill_at = (
            index,
            address,
            folder,
            ticks,
            kill_at,
        )
        self.recording = index % RECORDINGS
        self.ticks_done = 0
        self.killed = 0
        self.result: Path | None = None
        self.error = ""

    def spawn(self, attempt: int) -> tuple[subprocess.Popen[str], Path]:
        out = self.folder / "out" / f"client{self.index}_{attempt}.npz"
        out.parent.mkdir(parents=True, exist_ok=True)
        process = subprocess.Popen(
            [
                sys.executable,
                "-c",
                WORKER,
                self.address,
                str(self.folder / f"rec{self.recording}" / "requests"),
                str(self.ticks),
                str(out),
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env={**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"},
        )
        return process, out

    def drive(self) -> None:
        attempt = 0
        while True:
            process, out = self.spawn(attempt)
            for line in process.stdout:
                if line.startswith("tick "):
                    self.ticks_done += 1
                    if self.kill_at is not None and attempt == 0 and int(line.split()[1]) == self.kill_at:
                        process.kill()  # SIGKILL mid-drive: the session stays open on the server
                        break
            process.wait()
            if attempt == 0 and self.kill_at is not None:
                self.killed += 1
                attempt += 1
                continue
            if process.returncode != 0:
                self.error = process.stderr.read()[-2000:]
            else:
                self.result = out
            return


def load_phase(
    address: str, folder: Path, clients: int, ticks: int, rng: random.Random, kill: bool = True
) -> tuple[list[Slot], float]:
    victims = set(rng.sample(range(clients), max(1, clients // 4))) if kill else set()
    slots = [
        Slot(i, address, folder, ticks, rng.randrange(1, ticks - 1) if i in victims else None)
        for i in range(clients)
    ]
    threads = [threading.Thread(target=slot.drive) for slot in slots]
    start = time.perf_counter()
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    return slots, time.perf_counter() - start


#: ``full_sessions``: references per session and their size (one 144x256 reference holds 28 x 144 x 256 B).
FULL_REFERENCES, FULL_SIZE = 16, (144, 256)


def full_sessions(address: str, pid: int, sessions: int, idle_timeout: float) -> dict[str, Any]:
    """Fill every session slot with a large reference set, abandon them all, and follow the server's memory:
    idle, full (against the bound's prediction), and after the sessions expired."""
    from setdiff_bench.serve import enhancer_pb2 as pb
    from setdiff_bench.serve.client import EnhancerClient
    from setdiff_bench.serve.settings import reference_bytes
    from tests.evaluation.stream.stream_fixtures import rig_camera, views

    references = views([rig_camera(0.5 * i, 0.0, size=FULL_SIZE) for i in range(FULL_REFERENCES)], seed=7)
    request = pb.StartSessionRequest(references=view_messages(references))
    predicted = sessions * FULL_REFERENCES * reference_bytes(*FULL_SIZE) / 2**20
    before = rss_mib(pid)
    with EnhancerClient(address) as client:
        for _ in range(sessions):
            client.stub.start_session(request, timeout=120)
        full = rss_mib(pid)
    time.sleep(idle_timeout + 1.5)  # abandoned: all expire
    after = rss_mib(pid)
    return {
        "sessions": sessions,
        "references_per_session": FULL_REFERENCES,
        "reference_size": list(FULL_SIZE),
        "predicted_held_mib": predicted,
        "rss_before_mib": before,
        "rss_full_mib": full,
        "rss_full_minus_before_mib": full - before,
        "rss_after_expiry_mib": after,
        "rss_after_minus_before_mib": after - before,
    }


class ArrivalLock:
    """Python's ``threading.Lock`` (no order promised) with :class:`~setdiff_bench.serve.server.FairLock`'s
    records (``grants``, ``arrivals``): the comparison the FIFO lock is measured against.  A call's arrival
    number is taken just before it asks for the lock, so two calls arriving within a few microseconds may
    count as an overtake that no lock could have avoided; FIFO's records are exact (taken under its lock)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._counter = threading.Lock()
        self._asked = 0
        self.grants: list[str] = []
        self.arrivals: list[int] = []

    @contextmanager
    def hold(self, owner: str) -> Iterator[None]:
        with self._counter:
            ticket = self._asked
            self._asked += 1
        with self._lock:
            self.grants.append(owner)
            self.arrivals.append(ticket)
            yield


def overtakes(arrivals: list[int]) -> list[int]:
    """For each grant, how many calls that asked later were served before it (0 everywhere under FIFO)."""
    return [sum(1 for earlier in arrivals[:i] if earlier > mine) for i, mine in enumerate(arrivals)]


def compare_locks(
    checkpoint: str, method: str, folder: Path, clients: int, ticks: int, expected: dict[int, np.ndarray]
) -> dict[str, Any]:
    """The same N clients (no kills) against an in-process server with the FIFO model lock, then with a plain
    ``threading.Lock``: per-client latency spread and how often a later tick overtook an earlier one."""
    from setdiff_bench.serve.server import start_server
    from setdiff_bench.serve.settings import ServeSettings

    enhancer = load_enhancer(method, checkpoint, device="cpu")
    results = {}
    for name in ("fifo", "threading_lock"):
        running = start_server(
            enhancer, ServeSettings(port=0, workers=8, max_queue=4 * clients, max_sessions=clients)
        )
        if name == "threading_lock":
            running.service.model_lock = ArrivalLock()
        try:
            phase_folder = folder / f"locks_{name}"
            phase_folder.mkdir()
            for recording in range(RECORDINGS):
                (phase_folder / f"rec{recording}").symlink_to(folder / f"rec{recording}")
            slots, seconds = load_phase(
                f"127.0.0.1:{running.port}", phase_folder, clients, ticks, random.Random(0), kill=False
            )
        finally:
            running.stop(grace=5)
        means, latencies, equal = [], [], True
        for slot in slots:
            if slot.result is None:
                raise RuntimeError(f"client {slot.index} failed: {slot.error}")
            data = np.load(slot.result)
            means.append(float(data["latencies"].mean()))
            latencies.extend(data["latencies"].tolist())
            equal = equal and bool(np.array_equal(data["images"], expected[slot.recording]))
        passed = overtakes(list(running.service.model_lock.arrivals))
        stats = percentiles(latencies, len(RIG))
        results[name] = {
            "latency_p50_ms": stats["p50_ms"],
            "latency_p99_ms": stats["p99_ms"],
            "throughput_frames_per_s": len(latencies) * len(RIG) / seconds,
            "fairness_jain_of_client_mean_latency": jain(means),
            "client_mean_latency_max_over_min": max(means) / min(means),
            "grants_overtaken": sum(1 for n in passed if n),
            "max_overtaken_by": max(passed),
            "grants": len(passed),
            "byte_equal_to_batch_runner": equal,
        }
        print(name, json.dumps(results[name]), flush=True)
    return {"clients": clients, "ticks_per_client": ticks, "server": "in the benchmark's process", **results}


def jain(values: list[float]) -> float:
    """Jain's fairness index: 1 when all equal, 1/n when one takes everything."""
    array = np.asarray(values, dtype=np.float64)
    return float(array.sum() ** 2 / (len(array) * (array**2).sum()))


def load_test(
    checkpoint: str,
    method: str,
    clients: list[int],
    ticks: int,
    idle_timeout: float,
    seed: int,
    with_lock_comparison: bool = True,
) -> dict[str, Any]:
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as temporary:
        folder = Path(temporary)
        expected = batch_expected(folder, checkpoint, method, ticks)
        process, port = start_served(
            checkpoint,
            "--method",
            method,
            "--session-idle-timeout",
            str(idle_timeout),
            "--max-sessions",
            str(max(clients)),
            "--max-queue",
            str(4 * max(clients)),
            "--workers",
            "8",
        )
        address = f"127.0.0.1:{port}"
        try:
            cold_rss = rss_mib(process.pid)
            for recording in range(RECORDINGS):
                (folder / "warm").mkdir(exist_ok=True)
                (folder / "warm" / f"rec{recording}").symlink_to(folder / f"rec{recording}")
            # one warm-up round of everything measured below (the largest concurrency with kills, every slot
            # full): grpc's threads and the allocator's arenas reach their working size; "idle" is after it
            full_sessions(address, process.pid, max(clients), idle_timeout)
            load_phase(address, folder / "warm", max(clients), 3, random.Random(0))
            time.sleep(idle_timeout + 1.5)
            idle_rss = rss_mib(process.pid)
            phases = []
            for count in clients:
                for recording in range(RECORDINGS):  # the phase folders share the serialised requests
                    link = folder / f"n{count}" / f"rec{recording}"
                    link.parent.mkdir(exist_ok=True)
                    link.symlink_to(folder / f"rec{recording}")
                peak = [rss_mib(process.pid)]
                sampling = threading.Event()

                def sample(stop: threading.Event = sampling, peak: list[float] = peak) -> None:
                    while not stop.wait(0.2):
                        peak.append(rss_mib(process.pid))

                sampler = threading.Thread(target=sample)
                sampler.start()
                slots, seconds = load_phase(address, folder / f"n{count}", count, ticks, rng)
                sampling.set()
                sampler.join()
                time.sleep(idle_timeout + 1.5)  # killed clients' sessions expire
                after_rss = rss_mib(process.pid)
                failures = [
                    f"client {s.index}: {s.error.strip().splitlines()[-1:]}" for s in slots if s.error
                ]
                latencies, per_client_mean, waited, equal, compared = [], [], [], True, 0
                for slot in slots:
                    if slot.result is None:
                        continue
                    data = np.load(slot.result)
                    latencies.extend(data["latencies"].tolist())
                    if not slot.killed:  # fairness among the clients that drove side by side from the start
                        per_client_mean.append(float(data["latencies"].mean()))
                    waited.append(float(data["waited"]))
                    equal = equal and bool(np.array_equal(data["images"], expected[slot.recording]))
                    compared += 1
                frames = sum(slot.ticks_done for slot in slots) * len(RIG)
                stats = percentiles(latencies, len(RIG)) if latencies else {}
                phases.append(
                    {
                        "clients": count,
                        "killed_mid_drive": sum(s.killed for s in slots),
                        "killed_at_ticks": sorted(s.kill_at for s in slots if s.kill_at is not None),
                        "clients_finished": compared,
                        "failures": failures,
                        "latency_p50_ms": stats.get("p50_ms"),
                        "latency_p99_ms": stats.get("p99_ms"),
                        "latency_mean_ms": stats.get("mean_ms"),
                        "ticks_timed": len(latencies),
                        "frames_enhanced": frames,
                        "wall_s": seconds,
                        "throughput_frames_per_s": frames / seconds,
                        "fairness_jain_of_client_mean_latency": jain(per_client_mean)
                        if per_client_mean
                        else None,
                        "client_mean_latency_max_over_min": max(per_client_mean) / min(per_client_mean)
                        if per_client_mean
                        else None,
                        "start_session_wait_max_s": max(waited) if waited else None,
                        "byte_equal_to_batch_runner": equal and compared == count,
                        "rss_idle_mib": idle_rss,
                        "rss_peak_mib": max(peak),
                        "rss_after_clients_gone_mib": after_rss,
                        "rss_after_minus_idle_mib": after_rss - idle_rss,
                    }
                )
                print(json.dumps(phases[-1]), flush=True)
            full = full_sessions(address, process.pid, max(clients), idle_timeout)
            full["rss_after_minus_idle_mib"] = full["rss_after_expiry_mib"] - idle_rss
        finally:
            stop_served(process)
        locks = (
            compare_locks(checkpoint, method, folder, max(clients), ticks, expected)
            if with_lock_comparison
            else None
        )
    return {
        "lock_comparison": locks,
        "phases": phases,
        "rss_cold_mib": cold_rss,
        "rss_idle_mib": idle_rss,
        "full_sessions": full,
        "all_byte_equal": all(phase["byte_equal_to_batch_runner"] for phase in phases),
        "max_rss_after_minus_idle_mib": max(
            [phase["rss_after_minus_idle_mib"] for phase in phases] + [full["rss_after_minus_idle_mib"]]
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--height", type=int, default=144)
    parser.add_argument("--width", type=int, default=256)
    parser.add_argument("--ticks", type=int, default=40)
    parser.add_argument("--checkpoint", type=Path, default=None)
    parser.add_argument(
        "--device", default="cpu", help="cpu, or cuda (e.g. --height 576 --width 1024 on a GPU)"
    )
    parser.add_argument(
        "--memory", type=int, default=0, help="instead: N requests, served process RSS sampled"
    )
    parser.add_argument(
        "--load",
        type=int,
        nargs="+",
        default=None,
        metavar="N",
        help="instead: the load test with N concurrent client processes per phase (e.g. 1 4 16)",
    )
    parser.add_argument(
        "--idle-timeout", type=float, default=2.0, help="--load: the server's session idle timeout"
    )
    parser.add_argument("--seed", type=int, default=0, help="--load: which clients are killed, and when")
    parser.add_argument(
        "--method", default="setdiff", choices=("setdiff", "difix"), help="--load: the checkpoint's method"
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    size = (args.height, args.width)
    if args.load:
        if any(n < 1 for n in args.load) or args.ticks < 3:
            parser.error("--load needs N >= 1 and --ticks >= 3")
        checkpoint = str(args.checkpoint or "tiny_setdiff")
        method = args.method
        result = load_test(checkpoint, method, args.load, args.ticks, args.idle_timeout, args.seed)
        path = write_result(
            "serve_load",
            {
                "machine": machine(),
                "checkpoint": checkpoint,
                "method": method,
                "frame_size": [32, 48],
                "cameras_per_tick": len(RIG),
                "ticks_per_client": args.ticks,
                "recordings": RECORDINGS,
                "session_idle_timeout_s": args.idle_timeout,
                "server": "setdiff-bench serve in its own process, one torch thread, --workers 8",
                "clients": "one process each (grpc only), all started at once; a quarter (at least one) "
                "SIGKILLed at a random tick and restarted, its session left to expire",
                "command": "python benchmarks/serve.py --load "
                + " ".join(map(str, args.load))
                + f" --ticks {args.ticks}",
                **result,
            },
        )
        print(f"→ {path}")
        return
    with tempfile.TemporaryDirectory() as folder:
        checkpoint = args.checkpoint or save_tiny_checkpoint(Path(folder) / "tiny_setdiff")
        if args.memory:
            result = memory(checkpoint, size, args.memory)
            path = write_result(
                "serve_memory",
                {
                    "machine": machine(),
                    "size": list(size),
                    "memory": result,
                    "checkpoint": "tiny random" if args.checkpoint is None else str(args.checkpoint),
                },
            )
            print(
                f"{args.memory} requests in {result['seconds']:.0f} s; RSS "
                f"{[round(s['rss_mib'], 1) for s in result['samples']]} MiB; "
                f"growth after first sample {result['growth_after_first_sample_mib']:.1f} MiB → {path}"
            )
            return
        runs = {
            "in_process": in_process(checkpoint, size, args.ticks, False, args.device),
            "grpc": over_grpc(checkpoint, size, args.ticks, args.device),
            "in_process_cached": in_process(checkpoint, size, args.ticks, True, args.device),
        }
    payload = {
        "machine": machine(),
        "size": list(size),
        "device": args.device,
        "cameras_per_tick": 3,
        "references_per_tick": 3,
        "checkpoint": "tiny random" if args.checkpoint is None else str(args.checkpoint),
        "runs": runs,
        "overhead_ratio_p50": runs["grpc"]["p50_ms"] / runs["in_process"]["p50_ms"],
        "overhead_ratio_p99": runs["grpc"]["p99_ms"] / runs["in_process"]["p99_ms"],
        "cache_saving_p50": 1.0 - runs["in_process_cached"]["p50_ms"] / runs["in_process"]["p50_ms"],
        "goal": "grpc p50 <= 1.2 x in-process p50",
    }
    path = write_result(f"serve_{args.device}_{args.height}x{args.width}", payload)
    for name, run in runs.items():
        print(
            f"{name:18s} p50 {run['p50_ms']:7.1f} ms  p99 {run['p99_ms']:7.1f} ms  {run['frames_per_s']:6.2f} frames/s"
        )
    print(
        f"overhead ratio (p50) {payload['overhead_ratio_p50']:.3f}; cache saves {payload['cache_saving_p50']:.1%} "
        f"of a tick → {path}"
    )


if __name__ == "__main__":
    main()
