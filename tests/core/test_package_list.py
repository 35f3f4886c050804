"""Packaging: setup.py's discovery finds every first-party package folder (setuptools installs only what it finds;
a folder it misses imports in an editable install and is missing from a wheel).

``find_packages`` finds folders with an ``__init__.py``; the two repository-root folders that pyproject's
``package-dir`` maps into the package must be the ones setup.py adds by name.  setup.py is read, not run.
"""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _setup_literal(name: str) -> object:
    """The literal value assigned to ``name`` at setup.py's top level."""
    for node in ast.parse((ROOT / "setup.py").read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == name for t in node.targets):
            return ast.literal_eval(node.value)
    raise AssertionError(f"setup.py assigns no {name}")


def test_every_folder_with_modules_is_a_package() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    folders = {ROOT / folder for folder in config["package-dir"].values()}
    missing = sorted(
        str(module.parent.relative_to(ROOT))
        for folder in folders
        for module in folder.rglob("*.py")
        if "__pycache__" not in module.parts and not (module.parent / "__init__.py").is_file()
    )
    assert sorted(set(missing)) == []


def test_root_folders_mapped_into_the_package_are_added_by_setup() -> None:
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"]
    assert "packages" not in config, "pyproject lists packages by hand; setup.py finds them"
    mapped = sorted(
        name for name, folder in config["package-dir"].items() if folder != name.replace(".", "/")
    )
    assert mapped == ["setdiff_bench.loaders", "setdiff_bench.protocols"]
    assert sorted(_setup_literal("ROOT_PACKAGES")) == mapped  # type: ignore[arg-type]
