"""``train`` under DDP with two real processes (``accelerate launch``, gloo on the CPU) against one process.

Two processes with gradient accumulation 1 must train what one process with accumulation 2 trains: the
same global sample sequence (each step's two samples split between the ranks), the same weights up to
float summation order, the same validation scores (each rank scores half of the validation packets and the
sums are reduced), and the files written once.  A run killed with SIGKILL on both ranks and started again
resumes the sample sequence at its last checkpoint.  The store is a small real packet store
(:func:`tests.evaluation.run.store_fixtures.build_store`).
"""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from setdiff_bench.models.setdiff.checkpoint import resolve_checkpoint
from setdiff_bench.models.setdiff.files import (
    LOG_FILE,
    MANIFEST_FILE,
    SAMPLES_FILE,
    VALIDATION_FILE,
    WEIGHTS_FILE,
)
from tests.evaluation.run.store_fixtures import StoreSpec, build_store
from tests.models.setdiff_fixtures import tiny_config_toml, train_argv

STEPS = 8


def config(steps: int, accumulation: int) -> str:
    return tiny_config_toml(
        steps=steps,
        learning_rate=1e-3,
        gradient_accumulation=accumulation,
        min_views=2,
        max_views=4,
        lpips_weight=0.0,
        validation_packets=2,
        validate_every=4,
        checkpoint_every=2,
        log_every=1,
    )


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


def train_command(config: Path, store: Path, out: Path, processes: int) -> list[str]:
    verb = train_argv(config, store, out, "--cpu", "--no-progress")
    if processes == 1:
        return [sys.executable, "-m", "setdiff_bench", *verb]
    # --multi_gpu on a machine without CUDA: torch.distributed with the gloo backend, one process per rank
    return [
        sys.executable,
        "-m",
        "accelerate.commands.launch",
        "--multi_gpu",
        "--num_processes",
        str(processes),
        "--num_machines",
        "1",
        "--mixed_precision",
        "no",
        "--dynamo_backend",
        "no",
        "--main_process_port",
        str(free_port()),
        "-m",
        "setdiff_bench",
        *verb,
    ]


def environment() -> dict[str, str]:
    return {**os.environ, "SETDIFF_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONPATH": str(Path.cwd())}


def run(command: list[str]) -> None:
    done = subprocess.run(
        command, env=environment(), capture_output=True, text=True, timeout=600, check=False
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]


def records(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def final_weights(out: Path) -> dict[str, torch.Tensor]:
    return load_file(resolve_checkpoint(out) / WEIGHTS_FILE)


@pytest.fixture(scope="module")
def runs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("ddp")
    store = root / "store"
    build_store(store, StoreSpec(scenes=("scene_a", "scene_b"), split="train", packets_per_group=2))
    build_store(store, StoreSpec(scenes=("scene_c",), split="test"))  # two validation packets
    configs = {}
    for accumulation in (1, 2):
        configs[accumulation] = root / f"accumulation{accumulation}.toml"
        configs[accumulation].write_text(config(STEPS, accumulation))
    outs = {"one": root / "one_process", "two": root / "two_processes", "killed": root / "killed"}
    run(train_command(configs[2], store, outs["one"], 1))
    run(train_command(configs[1], store, outs["two"], 2))

    # the same two-process run, killed (SIGKILL, every process) after its first checkpoint, then resumed
    command = train_command(configs[1], store, outs["killed"], 2)
    job = subprocess.Popen(
        command,
        env=environment(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    deadline = time.monotonic() + 300
    while not (outs["killed"] / "latest").is_file() and job.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(job.pid, signal.SIGKILL)
    job.wait()
    killed_at = json.loads((outs["killed"] / SAMPLES_FILE).read_text().splitlines()[-1])["step"]
    assert killed_at < STEPS, "the run ended before it could be killed"
    outs["killed_at"] = Path(str(killed_at))
    run(command)
    return outs


def test_ranks_draw_disjoint_samples_whose_union_is_the_one_process_sequence(runs: dict[str, Path]) -> None:
    one, two = records(runs["one"] / SAMPLES_FILE), records(runs["two"] / SAMPLES_FILE)
    assert [r["step"] for r in two] == list(range(1, STEPS + 1))
    assert two == one  # per step: [global position, packet id] of both ranks' samples
    for record in two:
        positions = [position for position, _ in record["samples"]]
        assert positions == [2 * (record["step"] - 1), 2 * record["step"] - 1]  # rank 0 even, rank 1 odd
    # eight training packets: each epoch (8 consecutive positions) visits every packet exactly once
    drawn = [packet for record in two for _, packet in record["samples"]]
    assert len(set(drawn[:8])) == 8 and len(set(drawn[8:16])) == 8


def test_two_processes_train_the_weights_of_one_process_with_accumulation_two(runs: dict[str, Path]) -> None:
    one, two = final_weights(runs["one"]), final_weights(runs["two"])
    assert one.keys() == two.keys()
    for key in one:
        torch.testing.assert_close(two[key], one[key], rtol=1e-4, atol=1e-5, msg=key)


def test_validation_is_reduced_across_ranks(runs: dict[str, Path]) -> None:
    one, two = records(runs["one"] / VALIDATION_FILE), records(runs["two"] / VALIDATION_FILE)
    assert [r["step"] for r in two] == [4, 8]
    for mine, reference in zip(two, one, strict=True):
        assert mine.keys() == reference.keys() == {"step", "psnr", "ssim"}
        # a mean over both validation packets: rank 1's packet alone would give another number
        assert mine["psnr"] == pytest.approx(reference["psnr"], abs=1e-3)
        assert mine["ssim"] == pytest.approx(reference["ssim"], abs=1e-4)


def test_only_the_main_process_writes(runs: dict[str, Path]) -> None:
    one, two = runs["one"], runs["two"]
    listing = sorted(str(p.relative_to(two)) for p in two.rglob("*"))
    assert listing == sorted(str(p.relative_to(one)) for p in one.rglob("*"))
    assert len(records(two / LOG_FILE)) == STEPS  # one line per step, not one per rank
    manifest = json.loads((two / MANIFEST_FILE).read_text())
    assert len(manifest["sessions"]) == 1 and manifest["sessions"][0]["end_step"] == STEPS


def test_a_killed_run_resumes_the_sample_sequence_where_it_stopped(runs: dict[str, Path]) -> None:
    killed, two = runs["killed"], runs["two"]
    assert records(killed / SAMPLES_FILE) == records(
        two / SAMPLES_FILE
    )  # steps after the checkpoint were redone
    assert [r["step"] for r in records(killed / LOG_FILE)] == list(range(1, STEPS + 1))
    for key, value in final_weights(killed).items():
        torch.testing.assert_close(value, final_weights(two)[key], rtol=1e-4, atol=1e-5, msg=key)
    sessions = json.loads((killed / MANIFEST_FILE).read_text())["sessions"]
    assert sessions[-1]["end_step"] == STEPS and sessions[-1]["start_step"] > 0
