"""Run CLI verbs as separate processes and record the exact commands (for ``demo`` and ``ablate``).

Each stage is a fresh ``python -m setdiff_bench <verb> ...`` process: verbs keep process-wide state
(torch threads, accelerate, compiled kernels), and a separate process gives every stage a clean
start, its own progress bar, and its own one-line error.  The pipeline stops at the first stage
that fails and exits with that stage's code; every stage resumes, so rerunning continues.

With a ledger file (``Pipeline(ledger=...)``) the wall time of each command is kept across runs: a
stage that had already finished keeps its original time (marked resumed, with the seconds the rerun
took), and a stage interrupted part-way adds up the time of every attempt.  So rerunning a finished
pipeline does not replace "synth, 472 s" by "synth, 6 s".

:meth:`Pipeline.run_concurrently` runs independent stages side by side in lanes (each lane's stages in
order, the lanes at once), splitting the CPU threads between them (``SETDIFF_THREADS`` of each
process = the pipeline's threads // lanes).  Their output is quiet (``--no-progress``): two progress
bars cannot share one terminal.  :meth:`Pipeline.elapsed_seconds` counts a concurrent group once,
as its longest lane.
"""

from __future__ import annotations

import json
import os
import shlex
import subprocess
import sys
import threading
import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.runtime.threads import THREADS_ENV, compute_threads

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
        group, lane: for a stage of :meth:`Pipeline.run_concurrently`, which concurrent group (0, 1,
            ...) and which lane of it ran the stage; ``None`` for a stage run on its own.
        threads: the torch thread count the stage's process computed with (``SETDIFF_THREADS`` as the
            pipeline set it for a lane, else the machine's :func:`compute_threads`).
    """

    name: str
    command: str
    seconds: float
    resumed: bool = False
    rerun_seconds: float | None = None
    group: int | None = None
    lane: int | None = None
    threads: int | None = None

    def timing(self) -> str:
        """``"472 s"`` or ``"472 s, resumed (this run 2 s)"``."""
        if not self.resumed:
            return f"{self.seconds:.0f} s"
        return f"{self.seconds:.0f} s, resumed (this run {self.rerun_seconds or 0.0:.0f} s)"

    def concurrency(self) -> str:
        """``""``, or ``" (concurrent group 0, lane 1)"`` for a stage run beside others."""
        return "" if self.group is None else f" (concurrent group {self.group}, lane {self.lane})"


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
    _groups: int = 0
    _ledger_lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def run(self, name: str, argv: Sequence[str]) -> StageRecord:
        """Run ``setdiff-bench <argv>``; raise :class:`StageFailed` on a non-zero exit."""
        record = self._run_stage(name, argv, env={})
        self.records.append(record)
        return record

    def run_concurrently(self, lanes: Sequence[Sequence[tuple[str, Sequence[str]]]]) -> list[StageRecord]:
        """Run each lane's ``(name, argv)`` stages in order, all lanes at once (module docstring).

        Every lane runs to its end or first failure; then :class:`StageFailed` is raised for the first
        failed stage in lane order.  Records are appended in lane order (all of lane 0, then lane 1, ...).
        """
        group = self._groups
        self._groups += 1
        threads = str(max(1, compute_threads() // max(1, len(lanes))))

        def run_lane(lane: int) -> tuple[list[StageRecord], StageFailed | None]:
            done: list[StageRecord] = []
            for name, argv in lanes[lane]:
                quiet = [] if "--no-progress" in argv else ["--no-progress"]
                try:
                    record = self._run_stage(name, [*argv, *quiet], env={THREADS_ENV: threads})
                except StageFailed as failure:
                    return done, failure
                record.group, record.lane = group, lane
                done.append(record)
            return done, None

        with ThreadPoolExecutor(max_workers=len(lanes)) as pool:
            outcomes = list(pool.map(run_lane, range(len(lanes))))
        for done, _ in outcomes:
            self.records.extend(done)
        for _, failure in outcomes:
            if failure is not None:
                raise failure
        return [record for done, _ in outcomes for record in done]

    def elapsed_seconds(self, *, this_run: bool = False) -> float:
        """Wall time of the recorded stages: the work (``this_run``: this invocation's time), counting a
        concurrent group as its longest lane."""
        seconds = lambda r: (r.rerun_seconds or 0.0) if this_run and r.resumed else r.seconds  # noqa: E731
        total = sum(seconds(r) for r in self.records if r.group is None)
        lanes: dict[int, dict[int, float]] = {}
        for r in self.records:
            if r.group is not None:
                lane_times = lanes.setdefault(r.group, {})
                lane_times[r.lane or 0] = lane_times.get(r.lane or 0, 0.0) + seconds(r)
        return total + sum(max(lane_times.values()) for lane_times in lanes.values())

    def _run_stage(self, name: str, argv: Sequence[str], env: dict[str, str]) -> StageRecord:
        args = [str(a) for a in argv]
        command = "setdiff-bench " + shlex.join(args)
        print(f"[{name}] {command}", flush=True)
        env = {**os.environ, **env}
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
        record.threads = int(env[THREADS_ENV]) if env.get(THREADS_ENV) else compute_threads()
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
        with self._ledger_lock:  # concurrent lanes update one file
            ledger = self._read_ledger()
            ledger[command] = {
                "seconds": round(float(earlier.get("seconds", 0.0)) + seconds, 1),
                "complete": complete,
            }
            write_text_atomic(self.ledger, json.dumps(ledger, indent=1, sort_keys=True) + "\n")

    def commands_markdown(self) -> str:
        """The commands that produced the outputs, in order, as a Markdown list with timings."""
        lines = [f"1. `{r.command}` — {r.name}, {r.timing()}{r.concurrency()}" for r in self.records]
        return "\n".join(lines) + "\n"


def relative(path: Path, base: Path) -> str:
    """``path`` relative to ``base`` when inside it (commands stay short and copyable), else absolute."""
    try:
        return str(path.resolve().relative_to(base.resolve()))
    except ValueError:
        return str(path.resolve())
