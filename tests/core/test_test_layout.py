"""Tests mirror the package: every test folder is named after a package or module of ``setdiff_bench`` (``tests/a/b``
tests ``setdiff_bench.a.b``), apart from the few folders that test the project as a whole."""

from __future__ import annotations

import importlib.util
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]

#: Folders that test the project as a whole, not one package: the top-level package's own modules and project
#: rules (core), the documentation, the benchmark scripts, and the crash / fuzz / safe-loading catalogue.
WHOLE_PROJECT = {"core", "docs", "benchmarks", "reliability"}


def _names_part_of_the_package(parts: tuple[str, ...]) -> bool:
    """``setdiff_bench.<parts>`` is a package or module (found, not imported)."""
    return importlib.util.find_spec("setdiff_bench." + ".".join(parts)) is not None


def test_every_test_folder_names_a_package() -> None:
    folders = {
        init.parent.relative_to(TESTS).parts
        for init in TESTS.rglob("__init__.py")
        if init.parent != TESTS and "__pycache__" not in init.parts
    }
    strays = sorted(
        "/".join(f) for f in folders if f[0] not in WHOLE_PROJECT and not _names_part_of_the_package(f)
    )
    assert strays == [], f"test folders that name no package or module of setdiff_bench: {strays}"
