"""The gaussians package's module graph: no import cycle, and the gsplat backend imports on its own."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import setdiff_bench.gaussians

PACKAGE = "setdiff_bench.gaussians"


def first_party_imports(path: Path, module: str) -> set[str]:
    """Modules of ``PACKAGE`` that ``path`` imports anywhere (top level or inside a function)."""
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: against the importing module's package, one level up per extra dot
                anchor = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
                base = f"{anchor}.{base}" if base else anchor
            names = [base] + [f"{base}.{alias.name}" for alias in node.names]
        else:
            continue
        found.update(name for name in names if name.startswith(PACKAGE + "."))
    return found


def test_no_import_cycle_in_the_gaussians_package():
    root = Path(setdiff_bench.gaussians.__file__).parent
    modules = {}
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).with_suffix("").parts
        name = ".".join((PACKAGE, *parts[:-1])) if parts[-1] == "__init__" else ".".join((PACKAGE, *parts))
        modules[name] = path
    graph = {name: first_party_imports(path, name) & set(modules) - {name} for name, path in modules.items()}
    assert graph[f"{PACKAGE}.render"] >= {f"{PACKAGE}.backends.gsplat_backend"}  # the walk sees imports

    def cycle_from(start: str, trail: tuple[str, ...]) -> tuple[str, ...] | None:
        for nxt in sorted(graph[start]):
            if nxt in trail:
                return (*trail[trail.index(nxt) :], nxt)
            found = cycle_from(nxt, (*trail, nxt))
            if found:
                return found
        return None

    for name in sorted(graph):
        cycle = cycle_from(name, (name,))
        assert cycle is None, " -> ".join(cycle)


def test_gsplat_backend_imports_on_its_own():
    """Without importing ``render`` first, and on a CPU machine without gsplat (it is imported when used)."""
    code = (
        "import sys; import setdiff_bench.gaussians.backends.gsplat_backend as b; "
        "print(callable(b.render), 'setdiff_bench.gaussians.render' in sys.modules, 'gsplat' in sys.modules)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout.split()
    assert out == ["True", "False", "False"]
