"""Run CLI verbs as separate processes and record the exact commands (for ``demo`` and ``ablate``).

Each stage is a fresh ``python -m setdiff_bench <verb> ...`` process: verbs keep process-wide state
(torch threads, accelerate, compiled kernels), and a separate process gives every stage a clean
start, its own progress bar, and its own one-line error.  The pipeline stops at the first stage
that fails and exits with that stage's code; every stage resumes, so rerunning continues.

With a ledger file (``Pipeline(ledger=...)``) the wall time of each command is kept across runs: a
stage that had already finished keeps its original time (marked resumed, with the seconds the rerun
took), and a stage interrupted part-way adds up the time of every attempt.  So rerunning a finished
pipeline does not replace "synth, 472 s" by "synth, 6 s".
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.io.atomic import write_text_atomic

#: Stage timings kept across runs (``Pipeline(ledger=<work folder> / LEDGER_FILE)``).
LEDGER_FILE = "stages.json"


class StageFailed(SetDiffBenchError):
    """A stage's process exited non-zero; it has already printed its own error line."""

    def __init__(self, name: str, code: int) -> None:
        super().__init__(f"stage {name!r} failed with exit code {code}")
        self.code = code


@dataclass
class StageRecord:
    """One stage that ran: its name, the command as a user would type it, and its wall time.

    Attributes:
        seconds: wall time of the stage's work (summed over interrupted attempts).
        resumed: the work was done, entirely or in part, by an earlier run of the pipeline.
        rerun_seconds: with ``resumed``, the seconds this run's invocation took (a resumed stage only
            checks its outputs).
    """

    name: str
    command: str
    seconds: float
    resumed: bool = False
    rerun_seconds: float | None = None

    def timing(self) -> str:
        """``"472 s"`` or ``"472 s, resumed (this run 2 s)"``."""
        if not self.resumed:
            return f"{self.seconds:.0f} s"
        return f"{self.seconds:.0f} s, resumed (this run {self.rerun_seconds or 0.0:.0f} s)"


@dataclass
class Pipeline:
    """Runs stages in order and keeps their records.

    Attributes:
        cwd: working directory of every stage (commands are recorded relative to it).
        records: the stages run so far.
        quiet: hide progress bars (passes ``--no-progress`` where a verb accepts it).
        ledger: JSON file keeping each command's time across runs (module docstring), or ``None``.
    """

    cwd: Path = field(default_factory=Path.cwd)
    records: list[StageRecord] = field(default_factory=list)
    quiet: bool = False
    ledger: Path | None = None

    def run(self, name: str, argv: Sequence[str]) -> StageRecord:
        """Run ``setdiff-bench <argv>``; raise :class:`StageFailed` on a non-zero exit."""
        args = [str(a) for a in argv]
        command = "setdiff-bench " + shlex.join(args)
        print(f"[{name}] {command}", flush=True)
        env = dict(os.environ)
        env.setdefault("PYTHONUNBUFFERED", "1")
        earlier = self._read_ledger().get(command, {})
        start = time.perf_counter()
        try:
            result = subprocess.run([sys.executable, "-m", "setdiff_bench", *args], cwd=self.cwd, env=env)
        except BaseException:  # Ctrl-C reaches the stage too; keep the time its work took so far
            self._note(command, earlier, time.perf_counter() - start, complete=False)
            raise
        seconds = time.perf_counter() - start
        if result.returncode != 0:
            self._note(command, earlier, seconds, complete=False)
            raise StageFailed(name, result.returncode)
        if earlier.get("complete"):
            record = StageRecord(
                name, command, float(earlier["seconds"]), resumed=True, rerun_seconds=seconds
            )
        elif earlier:
            record = StageRecord(
                name, command, float(earlier["seconds"]) + seconds, resumed=True, rerun_seconds=seconds
            )
            self._note(command, earlier, seconds, complete=True)
        else:
            record = StageRecord(name, command, seconds)
            self._note(command, earlier, seconds, complete=True)
        self.records.append(record)
        print(
            f"[{name}] done in {seconds:.1f} s"
            + (f" (work recorded: {record.timing()})" if record.resumed else ""),
            flush=True,
        )
        return record

    def _read_ledger(self) -> dict[str, dict[str, object]]:
        if self.ledger is None or not self.ledger.is_file():
            return {}
        try:
            data = json.loads(self.ledger.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            return {}  # a damaged ledger only loses timings, never work
        return data if isinstance(data, dict) else {}

    def _note(self, command: str, earlier: dict[str, object], seconds: float, *, complete: bool) -> None:
        """Add ``seconds`` to ``command``'s time in the ledger (unless it was complete already)."""
        if self.ledger is None or earlier.get("complete"):
            return
        ledger = self._read_ledger()
        ledger[command] = {
            "seconds": round(float(earlier.get("seconds", 0.0)) + seconds, 1),
            "complete": complete,
        }
        write_text_atomic(self.ledger, json.dumps(ledger, indent=1, sort_keys=True) + "\n")

    def commands_markdown(self) -> str:
        """The commands that produced the outputs, in order, as a Markdown list with timings."""
        lines = [f"1. `{r.command}` — {r.name}, {r.timing()}" for r in self.records]
        return "\n".join(lines) + "\n"


def relative(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` when inside it (commands stay short and copyable), else absolute."""
    try:
        return str(path.resolve().relative_to(base.resolve()))
    except ValueError:
        return str(path.resolve())
