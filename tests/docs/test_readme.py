"""The README is for users (issue 38): short, no lab narrative, the two commands where ``.ci/run`` finds
them, and every ``setdiff-bench`` command in it written as the CLI accepts it (the cheap ones run)."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from setdiff_bench.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
MAIN_JOB = (
    'python3 -m pip install torch==2.13.0 -e ".[model]" && python3 -m setdiff_bench weights lpips --download '
    "&& python3 -m setdiff_bench demo"
)
TESTS = (
    'python3 -m pip install torch==2.13.0 -e ".[model,test]" && python3 -m setdiff_bench weights lpips '
    "--download && python3 -m pytest -q"
)
#: Commands cheap enough to run here (no data, no model, seconds).
CHEAP = ("setdiff-bench list methods", "setdiff-bench list datasets", "setdiff-bench weights list")


def code_blocks(text: str) -> list[str]:
    return re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S)


def commands(text: str) -> list[str]:
    """Every ``setdiff-bench ...`` command of the README's code blocks, continuation lines joined."""
    found = []
    for block in code_blocks(text):
        joined = block.replace("\\\n", " ")
        for line in joined.splitlines():
            if line.strip().startswith("setdiff-bench "):
                found.append(line.strip())
    return found


def prose(text: str) -> str:
    return re.sub(r"```.*?```", "", text, flags=re.S)


def test_readme_is_short() -> None:
    assert len(README.read_text(encoding="utf-8").splitlines()) <= 300


def test_the_two_commands_stay_where_ci_finds_them() -> None:
    first = code_blocks(README.read_text(encoding="utf-8"))[0].splitlines()
    main_job = first.index(next(line for line in first if line.startswith("# 1. main job")))
    tests = first.index("# 2. tests")
    assert first[main_job + 1] == MAIN_JOB
    assert first[tests + 1] == TESTS
    extracted = subprocess.run(
        ["awk", "/^# 2\\. tests/{getline; print; exit}", str(README)], capture_output=True, text=True
    ).stdout.strip()
    assert extracted == TESTS


def test_no_first_person_lab_narrative() -> None:
    text = prose(README.read_text(encoding="utf-8"))
    assert not re.findall(r"\b(?:I|we|We|our|Our|my|My)\b", text)


@pytest.mark.parametrize("command", commands(README.read_text(encoding="utf-8")))
def test_every_command_parses(command: str) -> None:
    argv = shlex.split(command.split("setdiff-bench ", 1)[1], comments=True)
    argv = [word.replace("$R", "/data/fox") for word in argv]
    build_parser(argv).parse_args(argv)


@pytest.mark.parametrize("command", CHEAP)
def test_the_cheap_commands_run(command: str) -> None:
    assert command in README.read_text(encoding="utf-8")
    argv = [sys.executable, "-m", "setdiff_bench", *command.split()[1:]]
    result = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip()


def test_every_table_has_a_header_row() -> None:
    lines = prose(README.read_text(encoding="utf-8")).splitlines()
    for number, line in enumerate(lines):
        if line.startswith("|") and (number == 0 or not lines[number - 1].startswith("|")):
            assert not re.fullmatch(r"\|[-:| ]+\|", line), f"table without a header before line {number + 1}"
            assert re.fullmatch(r"\|[-:| ]+\|", lines[number + 1]), f"no separator under line {number + 1}"


def test_docs_link_only_files_in_the_repository() -> None:
    for page in sorted((ROOT / "docs").glob("*.md")):
        text = prose(page.read_text(encoding="utf-8"))
        targets = [t.split("#")[0] for t in re.findall(r"\]\(([^)\s]+)\)", text) if "://" not in t]
        missing = [t for t in targets if t and not (page.parent / t).exists()]
        assert not missing, f"{page.relative_to(ROOT)} links to missing files: {missing}"
