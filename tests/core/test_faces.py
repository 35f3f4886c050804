"""Package faces: every name a face exports resolves, and a lazy face (``runtime.lazy.lazy_face``) imports none
of its private modules until a name is used."""

from __future__ import annotations

import ast
import importlib
import json
import subprocess
import sys
import types
from pathlib import Path

import pytest

from tests.core.test_import_graph import _modules

ROOT = Path(__file__).resolve().parents[2]

FACES = (
    "setdiff_bench.evaluation.run",
    "setdiff_bench.reporting.site",
    "setdiff_bench.reporting.ablation",
    "setdiff_bench.pipeline.demo",
    "setdiff_bench.synthetic.world",
    "setdiff_bench.synthetic.sparse",
    "setdiff_bench.gaussians.fit",
)


@pytest.mark.parametrize("face", FACES)
def test_every_exported_name_resolves_to_a_private_module_of_the_package(face: str) -> None:
    module = importlib.import_module(face)
    assert module.__all__ == sorted(module.__all__) or set(module.__all__) == set(dir(module)) & set(
        module.__all__
    )
    for name in module.__all__:
        value = getattr(module, name)
        if not isinstance(value, type | types.FunctionType):
            continue  # a constant or an instance (its __module__ is its class's)
        if value.__module__.startswith("setdiff_bench"):
            home = value.__module__
            assert home.startswith(face + "._"), f"{face}.{name} comes from {home}, not from the package"


def test_a_lazy_face_loads_only_what_is_used() -> None:
    code = (
        "import json, sys; import setdiff_bench.reporting.site as site; before = sorted(m for m in sys.modules "
        "if m.startswith('setdiff_bench.reporting.site.')); site.SiteSettings; after = sorted(m for m in "
        "sys.modules if m.startswith('setdiff_bench.reporting.site.')); print(json.dumps([before, after, "
        "site.__all__ == sorted(site._EXPORTS)]))"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    before, after, all_matches = json.loads(result.stdout)
    assert before == [] and after == ["setdiff_bench.reporting.site._settings"] and all_matches


def _top_level_names(tree: ast.Module) -> tuple[set[str], dict[str, str]]:
    """Names a module defines at its top level, and those it imports from first-party modules (name → module)."""
    defined: set[str] = set()
    imported: dict[str, str] = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            defined.add(node.name)
        elif isinstance(node, ast.Assign):
            defined.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            defined.add(node.target.id)
        elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("setdiff_bench"):
            imported.update({alias.asname or alias.name: str(node.module) for alias in node.names})
    return defined, imported


def _sources() -> list[Path]:
    return [
        path
        for folder in ("setdiff_bench", "loaders", "protocols", "tests", "benchmarks", "examples")
        for path in sorted((ROOT / folder).rglob("*.py"))
    ]


def test_one_name_one_address() -> None:
    """A name is imported from the module that defines it or from a package face, never through a sibling
    module that imports it (a re-export); and no module but a face lists a foreign name in ``__all__``."""
    modules = _modules()
    names = {
        module: _top_level_names(ast.parse(path.read_text(encoding="utf-8")))
        for module, path in modules.items()
    }
    faces = {module for module, path in modules.items() if path.name == "__init__.py"}
    through_sibling = []
    for path in _sources():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module in modules and node.module not in faces:
                defined, imported = names[node.module]
                through_sibling += [
                    f"{path.relative_to(ROOT)}: {alias.name} from {node.module} (defined in {imported[alias.name]})"
                    for alias in node.names
                    if alias.name not in defined
                    and alias.name in imported
                    and f"{node.module}.{alias.name}" not in modules
                ]
    assert through_sibling == []
    foreign_exports = []
    for module, path in modules.items():
        if module in faces:
            continue
        for node in ast.parse(path.read_text(encoding="utf-8")).body:
            targets = [t.id for t in getattr(node, "targets", []) if isinstance(t, ast.Name)]
            if "__all__" in targets and isinstance(node.value, ast.List | ast.Tuple):
                listed = [element.value for element in node.value.elts if isinstance(element, ast.Constant)]
                foreign_exports += [
                    f"{module}.__all__: {name}" for name in listed if name not in names[module][0]
                ]
    assert foreign_exports == []
