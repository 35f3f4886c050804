"""Crash safety: ``prepare`` and ``run`` are SIGKILLed at random moments and resumed with the same command;
the finished outputs must be byte-identical to an uninterrupted run.

Each kill lands at a random moment of the command's work: the test waits until the process has started
writing (the first change under the output folder since its launch, temporary files included; ``run``
writes nothing before its first packet is scored), then sleeps a uniformly random time in ``[0, window]`` (``window``: the
in-process duration of the same work) and kills the whole process group (``prepare`` workers
included).  If the process finishes first, the attempt is not counted and the next attempt starts in a
fresh folder.  The default run kills each command twice, the slow suite ten times each.

Byte identity: the whole packet store (every packet file, fragment, ``index.parquet``), and for ``run``
every enhanced PNG, ``run.json``, ``enhancer.json``, the fragments and ``metrics.parquet`` without their
timing column (:func:`setdiff_bench.evaluation.run.comparable_metrics`), and ``manifest.json`` without its ``timing``
block, the fragment digest (fragments hold timing) and the git block (other helpers commit meanwhile).  No temporary file may be left behind.
"""

from __future__ import annotations

import json
import os
import random
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.evaluation.run import RunSettings, comparable_metrics, run_method
from setdiff_bench.io.run_layout import ENHANCER_FILE, FRAGMENTS_DIR, MANIFEST_FILE, METRICS_FILE, RUN_FILE
from setdiff_bench.packets.index import PACKETS_DIR
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store, files_of
from tests.packets.packet_fixtures import prepare_argv, tree_bytes
from tests.reliability.world import World, run_argv, tree_state

REPO = Path(__file__).parents[2]
ENV = {**os.environ, "OMP_NUM_THREADS": "1"}
RUN_METRICS = "psnr,ssim"
RUN_METHOD = "reproject"


@dataclass
class CrashLog:
    """What the kill loop did: one entry per SIGKILL (seconds after work began, outputs complete then)."""

    kills: list[tuple[float, int]] = field(default_factory=list)
    folders: list[Path] = field(default_factory=list)

    def mid_work(self, total: int) -> int:
        """Kills after which some, but not all, of ``total`` results existed."""
        return sum(1 for _, done in self.kills if 0 < done < total)


def crash_and_resume(
    command: Callable[[Path, int], list[str]],
    folders: Path,
    done: Callable[[Path], int],
    verify: Callable[[Path], None],
    *,
    total: int,
    kills: int,
    window_s: float,
    seed: int,
    max_attempts: int = 60,
) -> CrashLog:
    """SIGKILL ``command`` ``kills`` times at random moments of its work, resuming it in the same folder.

    A moment is drawn once the process has begun writing (the first change under its folder since it was
    launched, temporary files included), uniformly in ``[0, window_s]``.

    Args:
        command: ``(folder, attempt) -> setdiff-bench arguments`` of the process writing into ``folder``.
        folders: output folders are ``<folders>_0``, ``<folders>_1``, … (a new one is used when a process
            finished unkilled).
        done: how many result units (packets) the folder holds complete.
        verify: called on every folder once a resumed command has completed it.
        total: the result units of a complete folder (no kill may find more).
        seed: of the random kill moments.
    """

    def fresh_folder(index: int) -> Path:
        return folders.with_name(f"{folders.name}_{index}")

    rng = random.Random(seed)
    log = CrashLog()
    folder = fresh_folder(0)
    log.folders.append(folder)
    for attempt in range(max_attempts):
        at_launch = tree_state([folder])
        process = subprocess.Popen(
            [sys.executable, "-m", "setdiff_bench", *command(folder, attempt)],
            cwd=REPO,
            env=ENV,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )
        if len(log.kills) < kills:
            deadline = time.monotonic() + 300
            while tree_state([folder]) == at_launch and process.poll() is None:
                assert time.monotonic() < deadline, "the command never started writing"
                time.sleep(0.005)
            began = time.monotonic()
            delay = rng.uniform(0.0, window_s)
            while time.monotonic() - began < delay and process.poll() is None:
                time.sleep(0.002)
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGKILL)
                process.communicate()
                log.kills.append((round(time.monotonic() - began, 3), done(folder)))
                continue
        _, stderr = process.communicate(timeout=600)
        assert process.returncode == 0, stderr
        verify(folder)
        if len(log.kills) >= kills:
            assert all(d <= total for _, d in log.kills)
            return log
        folder = fresh_folder(len(log.folders))  # finished before the kill: start over elsewhere
        log.folders.append(folder)
    raise AssertionError(f"could not kill the command {kills} times in {max_attempts} attempts: {log}")


def no_temporaries(folder: Path) -> None:
    leftovers = [p for p in folder.rglob(".*") if ".tmp" in p.name]
    assert not leftovers, leftovers


# ---------------------------------------------------------------------- prepare
@pytest.fixture(scope="module")
def prepared_reference(world: World, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, float]:
    """The street dataset prepared once, uninterrupted and in-process; and how long that took."""
    out = tmp_path_factory.mktemp("prepared") / "store"
    start = time.perf_counter()
    with torch_threads(1):
        prepare("synthetic", world.street, out, fits=world.street, progress=False)
    return out, time.perf_counter() - start


def prepare_crashes(
    world: World, reference: Path, seconds: float, tmp_path: Path, kills: int, seed: int
) -> CrashLog:
    expected = tree_bytes(reference)
    total = sum(1 for p in (reference / PACKETS_DIR).iterdir())

    def command(folder: Path, attempt: int) -> list[str]:
        workers = (
            ["--workers", "2"] if attempt % 3 == 2 else []
        )  # now and then, killed with its worker processes
        return prepare_argv(world.street, folder, "--quiet", *workers)

    def done(folder: Path) -> int:
        packets = folder / "packets"
        return sum(1 for p in packets.iterdir() if not p.name.startswith(".")) if packets.is_dir() else 0

    def verify(folder: Path) -> None:
        no_temporaries(folder)
        assert tree_bytes(folder) == expected

    return crash_and_resume(
        command, tmp_path / "store", done, verify, total=total, kills=kills, window_s=seconds, seed=seed
    )


def test_prepare_killed_twice_resumes_byte_identical(
    world: World, prepared_reference, tmp_path: Path
) -> None:
    reference, seconds = prepared_reference
    log = prepare_crashes(world, reference, seconds, tmp_path, kills=2, seed=1)
    assert len(log.kills) == 2


@pytest.mark.slow
def test_prepare_killed_ten_times_resumes_byte_identical(
    world: World, prepared_reference, tmp_path: Path
) -> None:
    reference, seconds = prepared_reference
    log = prepare_crashes(world, reference, seconds, tmp_path, kills=10, seed=2)
    print(f"prepare: window {seconds:.2f} s, (s after work began, packets complete) per kill: {log.kills}")
    total = sum(1 for _ in (reference / PACKETS_DIR).iterdir())
    assert len(log.kills) == 10 and log.mid_work(total) >= 3, log


# ---------------------------------------------------------------------- run
@pytest.fixture(scope="module")
def run_reference(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path, float]:
    """A 12-packet store, and one uninterrupted in-process run of it; and how long the run took."""
    base = tmp_path_factory.mktemp("run_reference")
    with torch_threads(1):
        store = build_store(base / "store", StoreSpec(scenes=("scene_a", "scene_b"), packets_per_group=3))
        start = time.perf_counter()
        run_method(
            store,
            base / "run",
            RunSettings(RUN_METHOD, metrics=tuple(RUN_METRICS.split(",")), device="cpu", warp_cache=None),
            progress=False,
        )
    return store, base / "run", time.perf_counter() - start


def comparable_manifest(folder: Path) -> dict:
    manifest = json.loads((folder / MANIFEST_FILE).read_text())
    for key in ("timing", "fragments_sha256", "git"):  # git: other helpers commit to this tree meanwhile
        manifest.pop(key)
    return manifest


def comparable_fragments(folder: Path) -> dict[str, pd.DataFrame]:
    return {p.name: comparable_metrics(p) for p in sorted((folder / FRAGMENTS_DIR).glob("*.parquet"))}


def run_crashes(
    store: Path, reference: Path, seconds: float, tmp_path: Path, kills: int, seed: int
) -> CrashLog:
    expected_images = files_of(reference)
    expected_files = files_of(reference, (RUN_FILE, ENHANCER_FILE))
    expected_metrics = comparable_metrics(reference / METRICS_FILE)
    expected_fragments = comparable_fragments(reference)
    expected_manifest = comparable_manifest(reference)
    total = len(expected_fragments)

    def command(folder: Path, attempt: int) -> list[str]:
        return run_argv(store, folder, method=RUN_METHOD, metrics=RUN_METRICS)

    def done(folder: Path) -> int:
        return sum(1 for p in folder.glob("fragments/*.parquet") if not p.name.startswith("."))

    def verify(folder: Path) -> None:
        no_temporaries(folder)
        assert files_of(folder) == expected_images
        assert files_of(folder, (RUN_FILE, ENHANCER_FILE)) == expected_files
        pd.testing.assert_frame_equal(comparable_metrics(folder / METRICS_FILE), expected_metrics)
        fragments = comparable_fragments(folder)
        assert fragments.keys() == expected_fragments.keys()
        for name, frame in fragments.items():
            pd.testing.assert_frame_equal(frame, expected_fragments[name])
        assert comparable_manifest(folder) == expected_manifest
        assert sorted(p.name for p in folder.iterdir()) == sorted(p.name for p in reference.iterdir())

    return crash_and_resume(
        command, tmp_path / "run", done, verify, total=total, kills=kills, window_s=seconds, seed=seed
    )


def test_run_killed_twice_resumes_byte_identical(run_reference, tmp_path: Path) -> None:
    store, reference, seconds = run_reference
    log = run_crashes(store, reference, seconds, tmp_path, kills=2, seed=3)
    assert len(log.kills) == 2


@pytest.mark.slow
def test_run_killed_ten_times_resumes_byte_identical(run_reference, tmp_path: Path) -> None:
    store, reference, seconds = run_reference
    log = run_crashes(store, reference, seconds, tmp_path, kills=10, seed=4)
    print(f"run: window {seconds:.2f} s, (s after work began, packets complete) per kill: {log.kills}")
    total = sum(1 for _ in (reference / FRAGMENTS_DIR).glob("*.parquet"))
    assert len(log.kills) == 10 and log.mid_work(total) >= 3, log
