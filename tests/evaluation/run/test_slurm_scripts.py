"""``benchmarks/slurm/submit.sh`` and ``shards.sbatch`` as written, under a stand-in ``sbatch``.

The stand-in runs each submitted job at once (array tasks in parallel, with the ``SLURM_ARRAY_*``
variables SLURM sets) and prints a job id, so dependencies hold trivially.  The sharded store's index must
equal, byte for byte, the index of an unsharded ``prepare``, and the chain must end in a leaderboard.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pandas as pd
import pytest

from setdiff_bench.io.run_layout import METRICS_FILE
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.runtime.threads import torch_threads
from tests.packets.packet_fixtures import write_dataset

REPO = Path(__file__).resolve().parents[3]
FAKE_SBATCH = '''#!{python}
"""Stand-in for SLURM's sbatch: run the job now; arrays as parallel tasks; print a job id."""
import os, subprocess, sys
from pathlib import Path

args, array, script = sys.argv[1:], None, None
rest = []
for arg in args:
    if arg.startswith("--array="):
        low, high = arg.split("=", 1)[1].split("-")
        array = range(int(low), int(high) + 1)
    elif arg.startswith("--"):
        continue
    elif script is None:
        script = arg
    else:
        rest.append(arg)
counter = Path(os.environ["FAKE_SLURM_DIR"]) / "jobs"
job = len(counter.read_text().splitlines()) + 1 if counter.exists() else 1
counter.write_text((counter.read_text() if counter.exists() else "") + f"{{job}} {{' '.join(args)}}\\n")
tasks = [None] if array is None else list(array)
procs = []
for task in tasks:
    env = dict(os.environ)
    if task is not None:
        env.update(SLURM_ARRAY_TASK_ID=str(task), SLURM_ARRAY_TASK_COUNT=str(len(tasks)),
                   SLURM_ARRAY_TASK_MIN=str(tasks[0]), SLURM_ARRAY_JOB_ID=str(job))
    log = open(Path(os.environ["FAKE_SLURM_DIR"]) / f"job{{job}}_{{task}}.log", "w")
    procs.append(subprocess.Popen(["bash", script, *rest], env=env, stdout=log, stderr=subprocess.STDOUT))
if any(p.wait() != 0 for p in procs):
    sys.exit(1)
print(job)
'''


def test_submit_chain_shards_prepare_and_run_and_ends_in_a_leaderboard(tmp_path: Path) -> None:
    root = tmp_path / "street"
    with torch_threads(1):
        write_dataset(root, seeds=(11, 12))
    reference = tmp_path / "reference"
    with torch_threads(1):
        prepare("synthetic", root, reference, fits=root, progress=False, test_scenes=["street_01"])

    bin_dir, slurm_dir = tmp_path / "bin", tmp_path / "slurm"
    bin_dir.mkdir()
    slurm_dir.mkdir()
    fake = bin_dir / "sbatch"
    fake.write_text(textwrap.dedent(FAKE_SBATCH.format(python=sys.executable)))
    fake.chmod(0o755)
    packets, runs = tmp_path / "packets", tmp_path / "runs"
    env = {
        **os.environ,
        "PATH": f"{bin_dir}{os.pathsep}{os.environ['PATH']}",
        "FAKE_SLURM_DIR": str(slurm_dir),
        "DATASET": "synthetic",
        "ROOT": str(root),
        "FITS": str(root),
        "PACKETS": str(packets),
        "RUNS": str(runs),
        "METHOD": "identity",
        "SHARDS": "2",
        "SETDIFF": f"{sys.executable} -m setdiff_bench",
        "SETDIFF_THREADS": "1",
        "PYTHONPATH": str(REPO),
        "EXTRA_PREPARE": "--test-scene street_01",
    }
    done = subprocess.run(
        ["bash", str(REPO / "benchmarks" / "slurm" / "submit.sh")],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
        check=False,
        cwd=tmp_path,
    )
    logs = "".join(p.read_text() for p in sorted(slurm_dir.glob("*.log")))
    assert done.returncode == 0, done.stderr + logs
    assert done.stdout.startswith("submitted: prepare 1, index 2, run 3, merge + leaderboard 4")
    jobs = (slurm_dir / "jobs").read_text().splitlines()
    assert "--dependency=afterok:3" in jobs[3] and "--array=0-1" in jobs[2]
    assert (packets / INDEX_FILE).read_bytes() == (reference / INDEX_FILE).read_bytes()
    board = pd.read_parquet(runs / "leaderboards" / "synthetic.parquet")
    assert set(board["method"]) == {"identity"} and board["value"].notna().all()
    assert len(pd.read_parquet(runs / "identity" / METRICS_FILE)) > 0


@pytest.mark.parametrize("stage", ["bogus"])
def test_sbatch_script_refuses_an_unknown_stage(tmp_path: Path, stage: str) -> None:
    if shutil.which("bash") is None:
        pytest.skip("no bash")
    done = subprocess.run(
        ["bash", str(REPO / "benchmarks" / "slurm" / "shards.sbatch"), stage],
        env={**os.environ, "PACKETS": str(tmp_path)},
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 2 and "unknown stage 'bogus'" in done.stderr
