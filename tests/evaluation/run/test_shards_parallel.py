"""``run --shard i/n`` as a cluster runs it: four shard processes at once into one folder, no file lock, one
shard killed (SIGKILL) and run again, then ``run --merge``; the leaderboard must be byte-identical to a
one-process run's, and an unfinished run must be refused in one line by ``--merge`` and by the leaderboard.

The method is a test plugin that copies the render after a pause, so a shard can be killed between packets.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.evaluation.run import comparable_metrics, fragment_path
from setdiff_bench.io.run_layout import FRAGMENTS_DIR, METRICS_FILE
from setdiff_bench.packets.store import PacketStore
from tests.evaluation.run.store_fixtures import StoreSpec, build_store, leaderboard_argv, run_argv

SHARDS = 4
PAUSE_S = 0.4
PLUGIN = f'''
"""Test plugin: the render unchanged, after a pause (so that a shard can be killed between packets)."""
import time

from setdiff_bench.enhancers.base import MethodSpec

SPEC = MethodSpec(name="slowcopy", factory="slowcopy_plugin:create", description="test: copy after a pause",
                  needs_gpu=False)


class SlowCopy:
    name = "slowcopy"
    options = {{}}

    def enhance(self, packet):
        time.sleep({PAUSE_S})
        return packet.targets.images.clone()


def create():
    return SlowCopy()
'''


def install_plugin(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "slowcopy_plugin.py").write_text(textwrap.dedent(PLUGIN))
    info = folder / "slowcopy_plugin-0.1.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: slowcopy_plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[setdiff_bench.enhancers]\nslowcopy = slowcopy_plugin:SPEC\n")
    return folder


class Cli:
    """``python -m setdiff_bench`` in subprocesses that see the plugin."""

    def __init__(self, plugin: Path) -> None:
        self.env = {
            **os.environ,
            "SETDIFF_THREADS": "1",
            "PYTHONPATH": os.pathsep.join([str(plugin), str(Path.cwd())]),
        }

    def command(self, *args: str) -> list[str]:
        return [sys.executable, "-m", "setdiff_bench", *args]

    def run(self, *args: str, cwd: Path | None = None) -> subprocess.CompletedProcess[str]:
        return subprocess.run(
            self.command(*args),
            env=self.env,
            capture_output=True,
            text=True,
            timeout=300,
            check=False,
            cwd=cwd,
        )

    def start(self, *args: str) -> subprocess.Popen[str]:
        return subprocess.Popen(
            self.command(*args),
            env=self.env,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            start_new_session=True,
        )


def run_args(store: Path, out: Path, *extra: str) -> list[str]:
    return run_argv("slowcopy", store, out, "--metrics", "psnr,ssim", *extra)


def leaderboard_args(runs: Path, out: Path) -> list[str]:
    return leaderboard_argv("synthetic", runs, out, "--format", "parquet,md", "--metrics", "psnr,ssim")


@pytest.fixture(scope="module")
def cluster(tmp_path_factory: pytest.TempPathFactory) -> dict[str, object]:
    root = tmp_path_factory.mktemp("shards")
    store = build_store(root / "store", StoreSpec(scenes=("scene_a", "scene_b"), packets_per_group=3))
    cli = Cli(install_plugin(root / "plugin"))
    one, sharded = root / "one" / "runs" / "slowcopy", root / "sharded" / "runs" / "slowcopy"
    done = cli.run(*run_args(store, one))
    assert done.returncode == 0, done.stderr

    selection = PacketStore(store).packet_ids("test")
    killed_shard = SHARDS - 1
    killed_packets = selection[killed_shard::SHARDS]
    jobs = {i: cli.start(*run_args(store, sharded, "--shard", f"{i}/{SHARDS}")) for i in range(SHARDS)}
    deadline = time.monotonic() + 120
    while not fragment_path(sharded, killed_packets[0]).is_file() and time.monotonic() < deadline:
        time.sleep(0.02)
    os.killpg(jobs[killed_shard].pid, signal.SIGKILL)
    jobs[killed_shard].wait()
    for i, job in jobs.items():
        if i != killed_shard:
            assert job.wait(timeout=300) == 0, job.stderr.read() if job.stderr else ""
    written_before_kill = sum(fragment_path(sharded, pid).is_file() for pid in killed_packets)
    early_merge = cli.run(*run_args(store, sharded, "--merge"))
    early_board = cli.run(*leaderboard_args(sharded.parent, root / "sharded" / "board_early"))
    rerun = cli.run(*run_args(store, sharded, "--shard", f"{killed_shard}/{SHARDS}"))
    assert rerun.returncode == 0, rerun.stderr
    merge = cli.run(*run_args(store, sharded, "--merge"))
    assert merge.returncode == 0, merge.stderr
    boards = {}
    for name, folder in (("one", one), ("sharded", sharded)):
        boards[name] = folder.parent.parent / "board"  # relative paths: the command line is in the Markdown
        made = cli.run(*leaderboard_args(Path("runs"), Path("board")), cwd=folder.parent.parent)
        assert made.returncode == 0, made.stderr
    return {
        "one": one,
        "sharded": sharded,
        "boards": boards,
        "early_merge": early_merge,
        "early_board": early_board,
        "written_before_kill": written_before_kill,
        "killed_packets": killed_packets,
        "rerun": rerun,
    }


def test_the_killed_shard_stopped_between_packets_and_its_rerun_did_the_rest(cluster: dict) -> None:
    assert 1 <= cluster["written_before_kill"] < len(cluster["killed_packets"])
    done = len(cluster["killed_packets"]) - cluster["written_before_kill"]
    assert (
        f"enhanced {done} packets, {cluster['written_before_kill']} already done" in cluster["rerun"].stdout
    )


def test_an_unfinished_run_is_refused_in_one_line(cluster: dict) -> None:
    for refused in (cluster["early_merge"], cluster["early_board"]):
        assert refused.returncode == 2
        lines = refused.stderr.strip().splitlines()
        assert len(lines) == 1 and "incomplete" in lines[0], refused.stderr
    assert "have no fragment" in cluster["early_merge"].stderr


def test_sharded_leaderboard_is_byte_identical_to_one_process(cluster: dict) -> None:
    one, sharded = cluster["boards"]["one"], cluster["boards"]["sharded"]
    names = sorted(p.name for p in one.iterdir())
    assert names and names == sorted(p.name for p in sharded.iterdir())
    for name in names:
        assert (one / name).read_bytes() == (sharded / name).read_bytes(), name
    pd.testing.assert_frame_equal(
        comparable_metrics(cluster["one"] / METRICS_FILE),
        comparable_metrics(cluster["sharded"] / METRICS_FILE),
    )
    assert len(list((cluster["sharded"] / FRAGMENTS_DIR).iterdir())) == 12
    assert not list(cluster["sharded"].glob(".*")), "no lock or claim file is left behind"
