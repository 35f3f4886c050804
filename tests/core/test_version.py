"""The version is declared in setdiff_bench/version.py and must equal pyproject.toml's (the one packaging reads)."""

from __future__ import annotations

import tomllib
from pathlib import Path

import setdiff_bench
from setdiff_bench.version import __version__

ROOT = Path(__file__).resolve().parents[2]


def test_version_matches_pyproject() -> None:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert __version__ == project["version"] == setdiff_bench.__version__
