"""Each shipped enhancer (``setdiff-bench weights list``), called as a user would: the stream API with
``load_enhancer(method, name)``, and ``setdiff-bench serve --checkpoint NAME`` in its own process driven by
:class:`EnhancerClient` and by ``examples/drive_packets.py`` -- each against ``run --method`` on the same views.

The shipped configs leave ``max_references`` unset (null), the case the stream tests' fixture checkpoint did
not cover (issue 42: every session failed with a ``TypeError`` answered as ``UNKNOWN``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from setdiff_bench.enhancers.setdiff import load_enhancer
from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.evaluation.tick_limits import DEFAULT_REFERENCES_PER_TICK
from setdiff_bench.io.images import read_rgb
from setdiff_bench.io.run_layout import IMAGES_DIR
from setdiff_bench.serve.client import EnhancerClient
from tests.evaluation.stream.stream_fixtures import (
    RIG,
    recorded_references,
    run_batch,
    serve_argv,
    tick_frames,
    write_tick_store,
)
from tests.serve.serve_fixtures import ROOT, SHIPPED_ENHANCERS, environment, served

#: The tests' 48×32 frames are smaller than the shipped models' 256×144: the domain warning is expected.
pytestmark = pytest.mark.filterwarnings("ignore::setdiff_bench.errors.OutOfDistributionWarning")

TICKS = 4


def test_both_shipped_enhancers_are_listed() -> None:
    assert {"tiny_setdiff", "tiny_difix"} <= {name for name, _ in SHIPPED_ENHANCERS}


def batch_images(tmp_path: Path, name: str, method: str) -> dict[tuple[int, str], np.ndarray]:
    """``run --method METHOD --checkpoint NAME`` over the drive's ticks, as packets with the stream's choice
    of references: ``{(tick, sensor): (H, W, 3) uint8}``."""
    references = recorded_references()
    chooser = StreamSession(load_enhancer(method, name, device="cpu"), references)
    for tick in range(TICKS):
        frames = tick_frames(tick)
        write_tick_store(tmp_path / "store", references, frames, chooser.select(frames.cameras), tick)
    run_batch(tmp_path / "store", tmp_path / "run", name, method)
    images = {}
    for tick in range(TICKS):
        for sensor, _ in RIG:
            [written] = (tmp_path / "run" / IMAGES_DIR).rglob(f"{sensor}/{tick:06d}.png")
            images[tick, sensor] = np.rint(read_rgb(written) * 255).astype(np.uint8)
    return images


@pytest.mark.parametrize(("name", "method"), SHIPPED_ENHANCERS)
def test_stream_session_with_each_shipped_model(name: str, method: str, tmp_path: Path) -> None:
    enhancer = load_enhancer(method, name, device="cpu")
    session = StreamSession(enhancer, recorded_references())
    configured = enhancer.options.get("max_references")
    assert session.max_references == (configured or min(DEFAULT_REFERENCES_PER_TICK, 6))
    expected = batch_images(tmp_path, name, method)
    for tick in range(TICKS):
        streamed = session.enhance(tick_frames(tick))
        assert streamed.shape == (3, 3, 32, 48)
        quantised = np.rint(streamed.permute(0, 2, 3, 1).numpy() * 255).astype(np.uint8)
        for position, (sensor, _) in enumerate(RIG):
            assert np.array_equal(quantised[position], expected[tick, sensor]), (tick, sensor)


#: The real server's path is the same for every shipped model: the default suite serves the driving SetDiff
#: and DiFix; the others are ``slow`` (each is still streamed above, and served in the slow suite).
SERVED_BY_DEFAULT = {"tiny_setdiff", "tiny_difix"}


@pytest.mark.parametrize(
    ("name", "method"),
    [
        pytest.param(name, method, marks=() if name in SERVED_BY_DEFAULT else pytest.mark.slow)
        for name, method in SHIPPED_ENHANCERS
    ],
)
def test_serve_each_shipped_model_with_a_real_server(name: str, method: str, tmp_path: Path) -> None:
    """``serve --checkpoint NAME``: a client drives 4 ticks (byte-equal to ``run``), then the example replays
    the same ticks from a packet store (within one level: C-maps take a float64 trip to the world frame)."""
    expected = batch_images(tmp_path, name, method)
    with served(serve_argv(name, "--method", method)) as (_, port):
        address = f"127.0.0.1:{port}"
        with EnhancerClient(address, timeout=60) as client:
            client.wait_ready()
            version = client.get_version()
            assert version.method == method and version.checkpoint.endswith(name)
            session = client.start_session(recorded_references())
            for tick in range(TICKS):
                images = client.enhance(session, tick_frames(tick))
                assert images.shape == (3, 32, 48, 3) and images.dtype == np.uint8
                for position, (sensor, _) in enumerate(RIG):
                    assert np.array_equal(images[position], expected[tick, sensor]), (tick, sensor)
            client.close_session(session)
        example = subprocess.run(
            [
                sys.executable,
                str(ROOT / "examples" / "drive_packets.py"),
                "--packets",
                str(tmp_path / "store"),
                "--out",
                str(tmp_path / "out"),
                "--address",
                address,
            ],
            env=environment(),
            capture_output=True,
            text=True,
            timeout=300,
        )
    assert example.returncode == 0, example.stderr
    assert "Warning" not in example.stderr, example.stderr  # torch's non-writable-array warning (issue 45)
    replayed = sorted((tmp_path / "out").rglob("*.png"))
    assert len(replayed) == 3 * TICKS
    for path in replayed:
        tick = int(path.stem)
        got = np.rint(read_rgb(path) * 255).astype(np.int16)
        assert np.abs(got - expected[tick, path.parent.name]).max() <= 1, path
