"""Helpers shared by the tests that run documented commands (``--help`` examples, the README): read the
examples out of help texts, shrink an example to small sizes, run one with bash in a folder, and keep a
``serve`` command running while a client drives it.

Not a test module (pytest collects ``test_*.py`` only); tests import it as ``tests.cli.helpers``.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shlex
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

from setdiff_bench.cli.main import build_parser

ROOT = Path(__file__).resolve().parents[2]
#: How a documented command calls the program: the console script or the module (the README's first block).
PROGRAM = re.compile(r"(?:setdiff-bench|python3? -m setdiff_bench) ")

#: Size options and their small values (``small``).
SMALL = {
    "--steps": "2",
    "--setdiff-steps": "2",
    "--difix-steps": "2",
    "--iterations": "20",
    "--scenes": "1",
    "--preset": "tiny",
    "--port": "0",
}


def help_texts() -> dict[str, str]:
    """``{"verb [sub]": help text}`` of every verb and sub-command."""
    texts: dict[str, str] = {}

    def walk(parser: argparse.ArgumentParser, name: str) -> None:
        texts[name] = parser.format_help()
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub_name, sub_parser in action.choices.items():
                    walk(sub_parser, f"{name} {sub_name}".strip())

    walk(build_parser(), "")
    return texts


def extract_examples(text: str) -> list[str]:
    """The ``setdiff-bench`` commands under every ``Examples:`` / ``Example:`` heading of a help text,
    each as one line (a trailing ``\\`` joins the next line)."""
    examples: list[str] = []
    in_block = False
    for line in text.splitlines():
        stripped = line.strip()
        if re.search(r"\bexamples?:$", stripped, re.IGNORECASE):
            in_block = True
            continue
        if not in_block or not stripped:
            continue
        if not line.startswith(" "):
            in_block = False
            continue
        if examples and examples[-1].endswith("\\"):
            examples[-1] = examples[-1][:-1].rstrip() + " " + stripped
        elif "setdiff-bench " in stripped and not stripped.startswith(("-", "[")):
            examples.append(stripped)
    return examples


def small(example: str) -> str:
    """``example`` at small sizes: the :data:`SMALL` values, ``--preset tiny`` added to ``demo`` / ``synth`` /
    ``fit`` examples that name no preset, and ``--port 0`` added to ``serve`` examples that name no port."""
    for flag, value in SMALL.items():
        example = re.sub(rf"(?<!\S){re.escape(flag)} \S+", f"{flag} {value}", example)
    verb = words(example)[0]
    if verb in ("demo", "synth", "fit") and "--preset" not in example:
        example += " --preset tiny"
    if verb == "serve" and "--port" not in example:  # the default port may be taken: any free one
        example = re.sub(r"(?<=serve) ", " --port 0 ", example, count=1)
    return example


def words(example: str) -> list[str]:
    """The argument words after ``setdiff-bench`` or ``python3 -m setdiff_bench`` (a prefix dropped)."""
    return shlex.split(PROGRAM.split(example, maxsplit=1)[1], comments=True)


def command_environment() -> dict[str, str]:
    """The environment documented commands run in: one torch thread, this interpreter's scripts first on
    ``PATH`` (so ``setdiff-bench``, ``python`` and ``python3`` are the ones under test)."""
    return {
        **os.environ,
        "SETDIFF_THREADS": "1",
        "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}",
    }


def run_shell(command: str, folder: Path, timeout: float = 900) -> subprocess.CompletedProcess[str]:
    """Run ``command`` with bash in ``folder``; it must exit 0."""
    result = subprocess.run(
        ["bash", "-c", command],
        cwd=folder,
        env=command_environment(),
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert result.returncode == 0, (command, result.stdout[-2000:], result.stderr[-2000:])
    return result


@contextlib.contextmanager
def served(command: str, folder: Path) -> Iterator[str]:
    """Run a ``setdiff-bench serve`` command in ``folder`` until the block ends, yielding its first line
    (``serving on HOST:PORT ...``); then SIGTERM, after which it must exit 0."""
    process = subprocess.Popen(
        ["bash", "-c", f"exec {command}"],
        cwd=folder,
        env=command_environment(),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert process.stdout is not None
    first = ""
    try:
        first = process.stdout.readline()  # serve prints it once its SIGTERM handler is installed
        assert first.startswith("serving on"), (
            command,
            first,
            process.stderr.read() if process.stderr else "",
        )
        yield first
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=120)
    assert process.returncode == 0, (command, first, out, err)


def run_example(example: str, world: Path) -> str:
    """Run ``example`` (small) in ``world`` with bash; a ``serve`` example until it listens.

    Returns:
        What it printed on stdout (a ``serve`` example: its first line, ``serving on ...``).
    """
    command = small(example)
    if " --allow-dirty" not in command and words(command)[0] == "publish" and repository_is_dirty():
        command += " --allow-dirty"  # publish refuses uncommitted code; tests run on work in progress
    if words(command)[0] == "serve":
        with served(command, world) as first:
            return first
    return run_shell(command, world).stdout


def repository_is_dirty() -> bool:
    """Whether the checkout under test has uncommitted changes."""
    status = subprocess.run(["git", "status", "--porcelain"], cwd=ROOT, capture_output=True, text=True)
    return status.returncode != 0 or bool(status.stdout.strip())
