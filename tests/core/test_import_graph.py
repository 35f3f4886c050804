"""No import knots: no first-party module cycle and no package importing a package that imports it back.

Every ``import``/``from ... import`` of ``setdiff_bench`` in the library is read with :mod:`ast`, at module
level *and* inside functions (a function-level import that only dodges a cycle at import time is still a
knot).  Imports under ``if TYPE_CHECKING:`` are left out: they never run, they only name types.

Run ``python3 -m pytest tests/core/test_import_graph.py -q`` to check; ``python3 tests/core/test_import_graph.py``
prints every cycle found.
"""

from __future__ import annotations

import ast
from collections.abc import Iterable, Iterator
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "setdiff_bench"


#: Repository folders pyproject installs inside the package (``package-dir``): folder → dotted package name.
INSTALLED_AS = {"loaders": "setdiff_bench.loaders", "protocols": "setdiff_bench.protocols"}


def _modules() -> dict[str, Path]:
    """Dotted module name → source file, for every module and package of the library, the repository's
    ``loaders/`` and ``protocols/`` under the names they are installed as."""
    found: dict[str, Path] = {}
    roots = [(PACKAGE, PACKAGE.name)] + [
        (PACKAGE.parent / folder, name) for folder, name in INSTALLED_AS.items()
    ]
    for root, dotted in roots:
        for path in sorted(root.rglob("*.py")):
            parts = [dotted, *path.relative_to(root).with_suffix("").parts]
            if parts[-1] == "__init__":
                parts.pop()
            found[".".join(parts)] = path
    return found


def _is_type_checking(node: ast.AST) -> bool:
    if not isinstance(node, ast.If):
        return False
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST) -> Iterator[ast.Import | ast.ImportFrom]:
    """Every import statement that can run: module level, in functions and classes; not under TYPE_CHECKING."""
    stack: list[ast.AST] = [tree]
    while stack:
        node = stack.pop()
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.Import | ast.ImportFrom):
                yield child
            elif _is_type_checking(child):
                assert isinstance(child, ast.If)
                stack.extend(child.orelse)
            else:
                stack.append(child)


def _owner(name: str, modules: dict[str, Path]) -> str | None:
    """The innermost library module that ``name`` (a module or ``module.attribute``) lives in."""
    while name and name not in modules:
        name = name.rpartition(".")[0]
    return name or None


def import_graph() -> dict[str, set[str]]:
    """Module → the first-party modules it imports (the importer itself left out)."""
    modules = _modules()
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        is_package = path.name == "__init__.py"
        targets: set[str] = set()
        for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            else:
                if node.level:
                    base = module.split(".") if is_package else module.split(".")[:-1]
                    base = base[: len(base) - node.level + 1]
                    source = ".".join([*base, *([node.module] if node.module else [])])
                else:
                    source = node.module or ""
                # ``from package import submodule`` imports the submodule; ``from module import name`` the module
                names = [f"{source}.{alias.name}" for alias in node.names]
            for name in names:
                if name.split(".")[0] != PACKAGE.name:
                    continue
                owner = _owner(name, modules)
                if owner is not None and owner != module:
                    targets.add(owner)
        graph[module] = targets
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one node (Tarjan), each sorted, sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(graph):
        if root in index:
            continue
        work: list[tuple[str, Iterator[str]]] = [(root, iter(sorted(graph.get(root, ()))))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, successors = work[-1]
            for successor in successors:
                if successor not in index:
                    index[successor] = low[successor] = len(index)
                    stack.append(successor)
                    on_stack.add(successor)
                    work.append((successor, iter(sorted(graph.get(successor, ())))))
                    break
                if successor in on_stack:
                    low[node] = min(low[node], index[successor])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    component = []
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        component.append(member)
                        if member == node:
                            break
                    if len(component) > 1:
                        found.append(sorted(component))
    return sorted(found)


def _package_at(module: str, depth: int) -> str:
    return ".".join(module.split(".")[:depth])


def _container(module: str, packages: set[str]) -> str:
    """The package a module sits in (a package is its own); a top-level module is a floor of its own."""
    if module in packages or module.count(".") == 1:
        return module
    return module.rpartition(".")[0]


def package_graph(graph: dict[str, set[str]], packages: set[str] | None = None) -> dict[str, set[str]]:
    """Package → packages it imports, compared where their paths part (``setdiff_bench.enhancers`` →
    ``setdiff_bench.evaluation``; ``setdiff_bench.models.setdiff`` → a sibling of it); imports inside one package,
    or of a package's own ancestor or descendant, are left out."""
    if packages is None:
        packages = {name for name, path in _modules().items() if path.name == "__init__.py"}
    found: dict[str, set[str]] = {}
    for importer, targets in graph.items():
        for target in targets:
            here, there = _container(importer, packages), _container(target, packages)
            for depth in range(2, max(here.count("."), there.count(".")) + 2):
                source, destination = _package_at(here, depth), _package_at(there, depth)
                if source == destination:
                    continue
                if destination.startswith(source + ".") or source.startswith(destination + "."):
                    break
                found.setdefault(source, set()).add(destination)
                break
    return found


def _describe(components: Iterable[list[str]], graph: dict[str, set[str]]) -> str:
    lines = []
    for component in components:
        members = set(component)
        lines.append(f"cycle of {len(component)}:")
        for node in component:
            inside = sorted(graph.get(node, set()) & members)
            lines.append(f"  {node} -> {', '.join(inside)}")
    return "\n".join(lines)


def test_no_first_party_module_cycle() -> None:
    graph = import_graph()
    found = cycles(graph)
    assert not found, "import cycles (module level or function level):\n" + _describe(found, graph)


def test_no_package_imports_a_package_that_imports_it_back() -> None:
    packages = package_graph(import_graph())
    found = cycles(packages)
    assert not found, "package import cycles:\n" + _describe(found, packages)


def test_the_scan_sees_function_level_and_relative_imports(tmp_path: Path) -> None:
    """The reader counts what it must: an import inside a function is an edge, one under TYPE_CHECKING is not."""
    source = (
        "from typing import TYPE_CHECKING\n"
        "import setdiff_bench.errors\n"
        "if TYPE_CHECKING:\n"
        "    from setdiff_bench.cameras import Camera\n"
        "def f():\n"
        "    from setdiff_bench.io import atomic\n"
        "    class C:\n"
        "        def g(self):\n"
        "            from setdiff_bench.types import PacketKey\n"
    )
    nodes = list(_import_nodes(ast.parse(source)))
    names = sorted(
        alias.name if isinstance(node, ast.Import) else f"{node.module}.{alias.name}"
        for node in nodes
        for alias in node.names
    )
    assert names == [
        "setdiff_bench.errors",
        "setdiff_bench.io.atomic",
        "setdiff_bench.types.PacketKey",
        "typing.TYPE_CHECKING",
    ]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    graph = {"x.p.a": {"x.q.b", "x.p.c"}, "x.q.b": {"x.p.c"}, "x.p.c": {"x.p.a"}, "x.p.r.d": {"x.p"}}
    assert package_graph(graph, {"x.p", "x.q", "x.p.r"}) == {"x.p": {"x.q"}, "x.q": {"x.p"}}


if __name__ == "__main__":
    modules = import_graph()
    print(_describe(cycles(modules), modules) or "no module cycles")
    packages = package_graph(modules)
    print(_describe(cycles(packages), packages) or "no package cycles")


def private_imports() -> list[tuple[str, str]]:
    """(importer, private module) pairs where a library module imports another package's private module: a
    module named ``_name`` inside a package whose ``__init__`` is its face."""
    found = []
    for importer, targets in import_graph().items():
        for target in targets:
            package, _, leaf = target.rpartition(".")
            private = leaf.startswith("_") and not leaf.startswith("__")
            if private and not (importer == package or importer.startswith(package + ".")):
                found.append((importer, target))
    return sorted(found)


def test_packages_are_entered_through_their_face() -> None:
    assert private_imports() == []
