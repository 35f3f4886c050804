"""Every bad input of the catalogue, end to end through the CLI: exit code 2, one stderr line naming the file
and the problem, and nothing left on disk (no new, changed or temporary file anywhere the command could write)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from tests.reliability.catalogue import CASES, DOC, PWNED, Case
from tests.reliability.world import World, tree_state


def invoke(argv: list[str]) -> int:
    """``main(argv)``; argparse's usage errors leave through ``SystemExit``."""
    try:
        return main(argv)
    except SystemExit as exit_:
        return int(exit_.code or 0)


def invoke_like_a_process(argv: list[str]) -> tuple[int, list[str]]:
    """``invoke(argv)`` and the warnings a plain ``setdiff-bench`` process would print to stderr (Python's
    default filters: everything but deprecation warnings) — each would be a second stderr line."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.resetwarnings()
        warnings.simplefilter("default")
        warnings.filterwarnings("ignore", category=DeprecationWarning)
        warnings.filterwarnings("ignore", category=PendingDeprecationWarning)
        code = invoke(argv)
    return code, [f"{w.category.__name__}: {w.message} ({w.filename}:{w.lineno})" for w in caught]


@pytest.mark.parametrize("case", CASES, ids=[c.id for c in CASES])
def test_bad_input(
    case: Case,
    world: World,
    tmp_path: Path,
    capfd: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    call = case.setup(tmp_path, world)
    for key, value in call.env.items():
        monkeypatch.setenv(key, value)
    monkeypatch.delenv("SETDIFF_DEBUG", raising=False)
    watched = [tmp_path, *world.shared]
    before = tree_state(watched)
    capfd.readouterr()

    code, printed_warnings = invoke_like_a_process(call.argv)

    captured = capfd.readouterr()  # file-descriptor level: C libraries writing to stderr are seen too
    lines = captured.err.splitlines()
    assert code == 2, (code, captured.err)
    assert not printed_warnings, printed_warnings
    assert len(lines) == 1, f"expected one stderr line, got {lines!r}"
    line = lines[0]
    assert line.startswith(f"setdiff-bench {call.argv[0]}"), line
    assert ": error: " in line, line
    assert call.names in line, f"{call.names!r} not named in {line!r}"
    assert case.problem in line, f"{case.problem!r} not in {line!r}"
    assert "Traceback" not in captured.err and "Traceback" not in captured.out
    assert tree_state(watched) == before, "the failed command left files behind or changed its inputs"
    assert not (tmp_path / PWNED).exists()


def test_catalogue_is_large_distinct_and_documented() -> None:
    ids = [c.id for c in CASES]
    assert len(ids) == len(set(ids)) >= 30
    assert len({c.input for c in CASES}) == len(CASES)
    areas = {c.area for c in CASES}
    assert areas == {"loaders", "ply", "packets", "weights", "checkpoints", "cli"}
    documented = set(re.findall(r"test_bad_input\[([a-z0-9-]+)\]", DOC.read_text()))
    assert documented == set(ids), (sorted(set(ids) - documented), sorted(documented - set(ids)))


@pytest.mark.parametrize("case_id", ["truncated-png", "inf-pose"])
def test_one_line_in_a_real_process(case_id: str, world: World, tmp_path: Path) -> None:
    """The same promise for a real ``python -m setdiff_bench`` process: its whole stderr is one line (libpng's
    own message and numpy warnings would show up here, at the file-descriptor level)."""
    case = next(c for c in CASES if c.id == case_id)
    call = case.setup(tmp_path, world)
    before = tree_state([tmp_path, *world.shared])
    env = {**os.environ, **call.env, "OMP_NUM_THREADS": "1"}
    env.pop("SETDIFF_DEBUG", None)
    result = subprocess.run(
        [sys.executable, "-m", "setdiff_bench", *call.argv],
        capture_output=True,
        text=True,
        env=env,
        cwd=Path(__file__).parents[2],
        timeout=300,
    )
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1, result.stderr
    assert case.problem in result.stderr and call.names in result.stderr
    assert tree_state([tmp_path, *world.shared]) == before
