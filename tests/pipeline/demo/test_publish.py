"""Published vs scratch: ``publish`` replaces a results folder whole, with provenance, only from a finished,
unchanged run of committed code; stage timings survive reruns."""

from __future__ import annotations

import json
import os
import stat
import subprocess
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

import setdiff_bench.pipeline.stages as stages
from setdiff_bench.cli.main import main
from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.pipeline.demo import SUMMARY_FILE, threads_line
from setdiff_bench.pipeline.publish import PROVENANCE_FILE, publish
from setdiff_bench.pipeline.stages import LEDGER_FILE, Pipeline, StageFailed, StageRecord

REVISION = "0123456789abcdef0123456789abcdef01234567"


def make_run(run: Path, *, dirty: bool = False) -> None:
    """A finished demo run as ``demo`` leaves it: outputs, then demo.json with their hashes."""
    (run / "work").mkdir(parents=True)
    (run / "work" / "big.bin").write_bytes(b"not published")
    (run / "synthetic.md").write_text("| method | PSNR |\n")
    (run / "synthetic.parquet").write_bytes(b"PAR1")
    (run / "README.md").write_text("# report\n")
    files = {p.name: sha256_file(p) for p in run.iterdir() if p.is_file()}
    summary = {
        "invocation": "setdiff-bench demo --preset tiny --out runs/demo --seed 0",
        "files": files,
        "provenance": {"git": {"revision": REVISION, "dirty": dirty}, "seed": 0, "torch_threads": 2},
    }
    (run / SUMMARY_FILE).write_text(json.dumps(summary))


@pytest.fixture
def umask_022() -> Iterator[None]:
    previous = os.umask(0o022)
    try:
        yield
    finally:
        os.umask(previous)


def test_publish_replaces_the_whole_folder_with_provenance(tmp_path: Path, umask_022: None) -> None:
    run, published = tmp_path / "runs" / "demo", tmp_path / "results" / "synthetic"
    make_run(run)
    published.mkdir(parents=True)
    (published / "ablation_setsize.md").write_text("from an older run\n")
    (published / "synthetic.md").write_text("older table\n")
    (run / "diagnosis.md").write_text("an analysis written into the run folder\n")
    assert main(["publish", "--run", str(run), "--to", str(published)]) == 0
    names = sorted(p.name for p in published.iterdir())
    assert names == [
        "README.md",
        SUMMARY_FILE,
        "diagnosis.md",
        PROVENANCE_FILE,
        "synthetic.md",
        "synthetic.parquet",
    ]
    assert (published / "synthetic.md").read_text() == "| method | PSNR |\n"
    provenance = json.loads((published / PROVENANCE_FILE).read_text())
    assert provenance["git"]["revision"] == REVISION and provenance["seed"] == 0
    assert provenance["run_command"].startswith("setdiff-bench demo ")
    assert provenance["published_with"].startswith("setdiff-bench publish --run ")
    for name, entry in provenance["files"].items():
        assert entry["sha256"] == sha256_file(published / name)
    assert provenance["files"]["diagnosis.md"]["origin"] == "added to the run folder"
    assert provenance["files"]["synthetic.md"]["origin"] == "demo"
    assert stat.S_IMODE(published.stat().st_mode) == 0o755
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o644 for p in published.iterdir())
    assert sorted(p.name for p in published.parent.iterdir()) == ["synthetic"]  # nothing staged is left over


def test_publish_refuses_what_it_cannot_vouch_for(tmp_path: Path) -> None:
    published = tmp_path / "results" / "synthetic"
    published.mkdir(parents=True)
    (published / "keep.md").write_text("published\n")
    unfinished = tmp_path / "unfinished"
    unfinished.mkdir()
    (unfinished / "README.md").write_text("x\n")
    with pytest.raises(UsageError, match="no finished demo run"):
        publish(unfinished, published, command="c")
    edited = tmp_path / "edited"
    make_run(edited)
    (edited / "synthetic.md").write_text("hand-edited\n")
    with pytest.raises(UsageError, match="changed after the demo"):
        publish(edited, published, command="c")
    dirty = tmp_path / "dirty"
    make_run(dirty, dirty=True)
    with pytest.raises(UsageError, match="uncommitted changes"):
        publish(dirty, published, command="c")
    assert [p.name for p in published.iterdir()] == ["keep.md"]  # untouched by every refusal
    publish(dirty, published, command="c", allow_dirty=True)
    assert json.loads((published / PROVENANCE_FILE).read_text())["git"]["dirty"] is True


def test_demo_default_output_is_git_ignored() -> None:
    from setdiff_bench.pipeline.presets import DEMO_BENCHMARKS

    root = Path(__file__).resolve().parents[3]
    if not (root / ".git").exists():
        pytest.skip("not a git checkout")
    for benchmark in DEMO_BENCHMARKS.values():  # each benchmark's own default folder
        out = benchmark.default_out
        result = subprocess.run(
            ["git", "-C", str(root), "check-ignore", "-q", f"{out}/README.md"], check=False
        )
        assert result.returncode == 0 and not out.startswith("results"), out


class FakeProcess:
    def __init__(self, returncode: int) -> None:
        self.returncode = returncode


def test_stage_ledger_keeps_original_and_interrupted_times(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A finished stage keeps its first time on a rerun (marked resumed); a failed attempt's time is added."""
    clock = iter([0.0, 100.0, 200.0, 203.0, 300.0, 340.0, 400.0, 460.0, 500.0, 502.0])
    codes = iter([0, 0, 1, 0, 0])
    monkeypatch.setattr(stages.time, "perf_counter", lambda: next(clock))
    monkeypatch.setattr(stages.subprocess, "run", lambda *a, **k: FakeProcess(next(codes)))
    ledger = tmp_path / "work" / LEDGER_FILE
    first = Pipeline(cwd=tmp_path, quiet=True, ledger=ledger).run("synth", ["synth", "--out", "s"])
    assert (first.seconds, first.resumed) == (100.0, False)
    again = Pipeline(cwd=tmp_path, quiet=True, ledger=ledger).run("synth", ["synth", "--out", "s"])
    assert (again.seconds, again.resumed, again.rerun_seconds) == (100.0, True, 3.0)
    assert "100 s, resumed (this run 3 s)" in again.timing()
    with pytest.raises(StageFailed):
        Pipeline(cwd=tmp_path, quiet=True, ledger=ledger).run("train", ["train", "--out", "c"])
    resumed = Pipeline(cwd=tmp_path, quiet=True, ledger=ledger).run("train", ["train", "--out", "c"])
    assert (resumed.seconds, resumed.resumed, resumed.rerun_seconds) == (100.0, True, 60.0)  # 40 s + 60 s
    later = Pipeline(cwd=tmp_path, quiet=True, ledger=ledger).run("train", ["train", "--out", "c"])
    assert (later.seconds, later.resumed, later.rerun_seconds) == (100.0, True, 2.0)


def test_concurrent_lanes_run_at_once_with_split_threads_and_keep_lane_order(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Two lanes start together (a barrier only two simultaneous processes can pass), each process gets
    half the threads and ``--no-progress``; a failing stage is raised after the other lane finished."""
    monkeypatch.setenv("SETDIFF_THREADS", "4")
    both_running = threading.Barrier(2, timeout=10)
    seen: list[tuple[str, str]] = []

    def fake_run(argv: list[str], **kwargs: object) -> FakeProcess:
        verb_args = argv[3:]
        env = kwargs["env"]
        assert isinstance(env, dict)
        seen.append((" ".join(verb_args), env["SETDIFF_THREADS"]))
        if verb_args[1] in ("first", "slow"):
            both_running.wait()
        return FakeProcess(1 if verb_args[1] == "broken" else 0)

    monkeypatch.setattr(stages.subprocess, "run", fake_run)
    pipeline = Pipeline(cwd=tmp_path, quiet=True, ledger=tmp_path / LEDGER_FILE)
    records = pipeline.run_concurrently(
        [[("a", ["run", "first"]), ("b", ["run", "second"])], [("c", ["run", "slow"])]]
    )
    assert [(r.name, r.group, r.lane) for r in records] == [("a", 0, 0), ("b", 0, 0), ("c", 0, 1)]
    assert [r.threads for r in records] == [2, 2, 2]  # the count each lane's process computed with
    assert [r.name for r in pipeline.records] == ["a", "b", "c"]
    assert sorted(seen) == [
        ("run first --no-progress", "2"),
        ("run second --no-progress", "2"),
        ("run slow --no-progress", "2"),
    ]
    assert len(json.loads((tmp_path / LEDGER_FILE).read_text())) == 3
    with pytest.raises(StageFailed, match="'d'"):
        pipeline.run_concurrently([[("d", ["run", "broken"])], [("e", ["run", "fine"])]])
    assert [r.name for r in pipeline.records] == ["a", "b", "c", "e"]
    assert pipeline.run("f", ["run", "alone"]).threads == 4  # a stage on its own has every thread


def test_elapsed_time_counts_a_concurrent_group_as_its_longest_lane() -> None:
    pipeline = Pipeline(
        records=[
            StageRecord("synth", "s", 100.0),
            StageRecord("run a", "a", 20.0, group=0, lane=0),
            StageRecord("run b", "b", 30.0, resumed=True, rerun_seconds=1.0, group=0, lane=0),
            StageRecord("run c", "c", 45.0, group=0, lane=1),
            StageRecord("leaderboard", "l", 5.0),
        ]
    )
    assert pipeline.elapsed_seconds() == 100.0 + max(20.0 + 30.0, 45.0) + 5.0
    assert pipeline.elapsed_seconds(this_run=True) == 100.0 + max(20.0 + 1.0, 45.0) + 5.0


def test_report_states_the_threads_the_stages_ran_with() -> None:
    """The demo README's provenance line names the stages' own thread counts when lanes shared the cores."""
    provenance = {"torch_threads": 2}
    alone = {"stages": [{"threads": 2}, {"threads": 2}]}
    lanes = {"stages": [{"threads": 2}, {"threads": 1}, {"threads": 1}, {"threads": 1}, {"threads": 2}]}
    older = {"stages": [{"name": "synth"}]}  # demo.json written before stages recorded their threads
    assert threads_line(alone, provenance) == "2 torch threads"
    assert threads_line(lanes, provenance) == "2 torch threads (1 each for the 3 stages run side by side)"
    assert threads_line(older, provenance) == "2 torch threads"
