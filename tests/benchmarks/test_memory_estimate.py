"""The memory estimate that ``run`` and the stream session check before enhancing, against a measurement:
the peak resident memory of a fresh process enhancing one packet (``benchmarks/memory.py``)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import benchmarks.memory as memory_benchmark

#: The estimate may be off by this factor either way (measured 0.97–1.09 for SetDiff at 288×512 and
#: 576×1024 in benchmarks/results/enhance_memory_cpu.json); a larger error would refuse packets that
#: fit or let through ones that do not.
FACTOR = 1.5


@pytest.mark.parametrize("case", ["setdiff:3+3@288x512", "difix:3+3@288x512"])
def test_estimate_within_a_factor_of_the_measured_peak(case: str) -> None:
    done = subprocess.run(
        [sys.executable, str(Path(memory_benchmark.__file__)), "--child", case],
        capture_output=True,
        text=True,
        check=True,
        env={"SETDIFF_THREADS": "1", "OMP_NUM_THREADS": "1", "PATH": ""},
        timeout=600,
    )
    row = json.loads(done.stdout.strip().splitlines()[-1])
    assert 1 / FACTOR <= row["measured_over_estimate"] <= FACTOR, row


def test_case_names_parse() -> None:
    assert memory_benchmark.parse_case("plain:8+2@576x1024") == ("plain", 8, 2, 576, 1024)
    with pytest.raises(SystemExit, match="unknown model"):
        memory_benchmark.parse_case("sd:1+1@8x8")
