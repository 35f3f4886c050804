"""An interrupted ``setdiff-bench train`` (SIGINT / SIGTERM) checkpoints the step in progress and the
same command resumes from it; short runs checkpoint at least four times."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from setdiff_bench.models.setdiff.checkpoint import resolve_checkpoint
from setdiff_bench.models.setdiff.train import checkpoint_interval
from tests.models.setdiff_fixtures import tiny_config_toml, train_argv, write_store

STEPS = 40
CONFIG = tiny_config_toml(
    model={"preset": "tiny"},
    steps=STEPS,
    learning_rate=1e-3,
    min_views=3,
    max_views=4,
    lpips_weight=0.0,
    validation_packets=0,
    log_every=1,
    checkpoint_every=500,
)


def test_checkpoint_interval() -> None:
    assert checkpoint_interval(500, 20) == 5  # the tiny demo's 20 steps: 4 checkpoints
    assert checkpoint_interval(500, 230) == 57
    assert checkpoint_interval(500, 1000) == 250
    assert checkpoint_interval(1000, 40_000) == 500  # never more than 500 steps apart
    assert checkpoint_interval(100, 40_000) == 100
    assert checkpoint_interval(500, 3) == 1


def latest_step(out: Path) -> int:
    try:
        return int(resolve_checkpoint(out).name.removeprefix("step-"))
    except Exception:
        return -1


def test_interrupted_training_checkpoints_and_resumes(tmp_path: Path) -> None:
    """SIGTERM (a job scheduler's stop) mid-run; SIGINT takes the same path (tests/runtime/test_interrupts.py)."""
    write_store(tmp_path / "packets")
    (tmp_path / "tiny.toml").write_text(CONFIG)
    out = tmp_path / "run"
    command = [
        sys.executable,
        "-m",
        "setdiff_bench",
        *train_argv(tmp_path / "tiny.toml", tmp_path / "packets", out, "--cpu", "--no-progress"),
    ]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    process = subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    interval = checkpoint_interval(500, STEPS)
    deadline = time.monotonic() + 240
    while latest_step(out) < interval and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    assert latest_step(out) == interval, "no periodic checkpoint before the end of training"
    process.send_signal(signal.SIGTERM)
    _, stderr = process.communicate(timeout=240)
    assert process.returncode == 130, stderr
    stopped = latest_step(out)
    assert interval <= stopped < STEPS, stderr
    assert f"stopped at step {stopped}/{STEPS}" in stderr and "rerun the same command to resume" in stderr
    log = [json.loads(line)["step"] for line in (out / "train_log.jsonl").read_text().splitlines()]
    assert log == list(range(1, stopped + 1))  # the checkpoint is the last step done: nothing is lost

    resumed = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert resumed.returncode == 0, resumed.stderr
    assert latest_step(out) == STEPS
    log = [json.loads(line)["step"] for line in (out / "train_log.jsonl").read_text().splitlines()]
    assert log == list(range(1, STEPS + 1))  # resumed right after the saved step, none redone or skipped
