"""Resume, SIGKILL, shards and repair: the store always ends byte-identical to one uninterrupted run."""

from __future__ import annotations

import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from setdiff_bench.packets.index import INDEX_FILE, PACKETS_DIR
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.shards import Shard
from tests.packets.packet_fixtures import prepare_argv, tree_bytes


def snapshot(root: Path) -> dict[str, tuple[int, int, bytes]]:
    """Relative path → (mtime_ns, inode, bytes) of every file."""
    return {
        p.relative_to(root).as_posix(): (p.stat().st_mtime_ns, p.stat().st_ino, p.read_bytes())
        for p in sorted(root.rglob("*"))
        if p.is_file()
    }


def complete_packets(out: Path) -> int:
    folder = out / PACKETS_DIR
    return sum(1 for p in folder.iterdir() if not p.name.startswith(".")) if folder.is_dir() else 0


def test_second_run_does_nothing(prepared, street):
    root, _ = street
    out, first, _ = prepared
    assert first.written == 17 and first.skipped == 0 and first.index_written
    before = snapshot(out)
    again = prepare("synthetic", root, out, fits=root, progress=False)
    assert (again.planned, again.written, again.skipped, again.removed, again.index_written) == (
        17,
        0,
        17,
        0,
        False,
    )
    assert snapshot(out) == before  # not a byte, inode or mtime changed


def _cli(root: Path, out: Path, *extra: str) -> subprocess.Popen:
    command = [sys.executable, "-m", "setdiff_bench", *prepare_argv(root, out, "--quiet", *extra)]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)


def _kill_after_progress(
    process: subprocess.Popen, out: Path, at_least: int, rng: random.Random, max_delay: float = 0.4
) -> None:
    """SIGKILL the process group once ``at_least`` packets exist, after a random extra delay of at most
    ``max_delay`` seconds."""
    deadline = time.monotonic() + 120
    while complete_packets(out) < at_least:
        assert process.poll() is None, f"run ended before it could be killed: {process.communicate()}"
        assert time.monotonic() < deadline, "no progress"
        time.sleep(0.02)
    time.sleep(rng.uniform(0.0, max_delay))
    assert process.poll() is None, "run ended before it could be killed"
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    assert process.returncode == -signal.SIGKILL


def test_sigkill_twice_then_restart_is_byte_identical(prepared, street, tmp_path):
    root, _ = street
    reference, _, _ = prepared
    out = tmp_path / "killed"
    rng = random.Random(20240611)
    _kill_after_progress(_cli(root, out), out, 1, rng)
    done = complete_packets(out)
    assert 1 <= done < 17 and not (out / INDEX_FILE).exists()
    # Two workers finish the last packets quickly: kill as soon as one more exists, without the extra
    # delay (with it, a loaded machine let the run finish all 17 before the kill arrived).
    _kill_after_progress(_cli(root, out, "--workers", "2"), out, done + 1, rng, max_delay=0.0)
    assert complete_packets(out) < 17
    final = _cli(root, out)
    stdout, stderr = final.communicate(timeout=300)
    assert final.returncode == 0, stderr.decode()
    assert " 0 outdated removed" in stdout.decode()
    assert not list((out / PACKETS_DIR).glob(".tmp-*"))
    assert tree_bytes(out) == tree_bytes(reference)


def test_shards_write_disjoint_packets_and_merge_one_index(prepared, street, tmp_path):
    root, _ = street
    reference, _, _ = prepared
    out = tmp_path / "sharded"
    second = prepare("synthetic", root, out, fits=root, shard=Shard(1, 2), progress=False)
    first = prepare("synthetic", root, out, fits=root, shard=Shard(0, 2), progress=False)
    assert first.written + second.written == 17 and first.written > 0 and second.written > 0
    assert first.index_written and second.index_written
    assert tree_bytes(out) == tree_bytes(reference)

    # repair: a corrupted file is caught by its hash, a packet the plan no longer has is removed
    victim = sorted((out / PACKETS_DIR).iterdir())[3]
    target = victim / "tgt_00_rgb.png"
    target.write_bytes(target.read_bytes()[:-7] + b"garbage")
    stray = out / PACKETS_DIR / "synthetic__street-00__lane+1__0099"
    shutil.copytree(victim, stray)
    repaired = prepare("synthetic", root, out, fits=root, progress=False)
    assert (repaired.written, repaired.removed) == (1, 1)
    assert tree_bytes(out) == tree_bytes(reference)


@pytest.mark.parametrize("shard", ["2/2", "x", "1/0"])
def test_bad_shard_is_one_line_error(shard, street, tmp_path, capsys):
    from setdiff_bench.cli.main import main

    root, _ = street
    code = main(prepare_argv(root, tmp_path, "--shard", shard))
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--shard" in err and len(err.splitlines()) == 1
