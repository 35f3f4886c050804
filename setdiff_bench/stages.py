"""Run CLI verbs as separate processes and record the exact commands (for ``demo`` and ``ablate``).

Each stage is a fresh ``python -m setdiff_bench <verb> ...`` process: verbs keep process-wide state
(torch threads, accelerate, compiled kernels), and a separate process gives every stage a clean
start, its own progress bar, and its own one-line error.  The pipeline stops at the first stage
that fails and exits with that stage's code; every stage resumes, so rerunning continues.
"""

from __future__ import annotations

import os
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from setdiff_bench.errors import SetDiffBenchError


class StageFailed(SetDiffBenchError):
    """A stage's process exited non-zero; it has already printed its own error line."""

    def __init__(self, name: str, code: int) -> None:
        super().__init__(f"stage {name!r} failed with exit code {code}")
        self.code = code


@dataclass
class StageRecord:
    """One stage that ran: its name, the command as a user would type it, and its wall time."""

    name: str
    command: str
    seconds: float


@dataclass
class Pipeline:
    """Runs stages in order and keeps their records.

    Attributes:
        cwd: working directory of every stage (commands are recorded relative to it).
        records: the stages run so far.
        quiet: hide progress bars (passes ``--no-progress`` where a verb accepts it).
    """

    cwd: Path = field(default_factory=Path.cwd)
    records: list[StageRecord] = field(default_factory=list)
    quiet: bool = False

    def run(self, name: str, argv: Sequence[str]) -> StageRecord:
        """Run ``setdiff-bench <argv>``; raise :class:`StageFailed` on a non-zero exit."""
        args = [str(a) for a in argv]
        command = "setdiff-bench " + shlex.join(args)
        print(f"[{name}] {command}", flush=True)
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        start = time.perf_counter()
        result = subprocess.run([sys.executable, "-m", "setdiff_bench", *args], cwd=self.cwd, env=env)
        seconds = time.perf_counter() - start
        if result.returncode != 0:
            raise StageFailed(name, result.returncode)
        record = StageRecord(name, command, seconds)
        self.records.append(record)
        print(f"[{name}] done in {seconds:.1f} s", flush=True)
        return record

    def commands_markdown(self) -> str:
        """The commands that produced the outputs, in order, as a Markdown list with timings."""
        lines = [f"1. `{r.command}` — {r.name}, {r.seconds:.0f} s" for r in self.records]
        return "\n".join(lines) + "\n"


def relative(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` when inside it (commands stay short and copyable), else absolute."""
    try:
        return str(path.resolve().relative_to(base.resolve()))
    except ValueError:
        return str(path.resolve())
