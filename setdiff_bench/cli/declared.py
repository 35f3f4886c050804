"""Names the CLI offers as choices, read from the library module that declares them without importing it.

A parser is built for every ``--help``, which must not import the heavy libraries (``tests/cli/
test_help_latency.py``); the synthetic preset registries, the leaderboard's formats and the LPIPS trunks live
in modules that import torch or pandas.  So their names are read from the modules' sources, as
:func:`setdiff_bench.cli.main.verb_summaries` reads the verb list; ``tests/cli/test_declared_choices.py`` checks
them against the imported modules.  A registry whose module imports nothing heavy (the loaders' ``DATASETS``,
built by a comprehension that no source reader should evaluate) is imported: :func:`dataset_names`.
"""

from __future__ import annotations

import ast
import importlib.machinery
import importlib.util
from pathlib import Path
from typing import Any


def module_source(module: str) -> Path:
    """The source file of ``module``, found without importing it or the packages between it and the top one
    (``setdiff_bench.reporting.leaderboard.render`` does not run the leaderboard package's ``__init__``).

    Raises:
        LookupError: no such module.
    """
    parts = module.split(".")
    spec = importlib.util.find_spec(parts[0])
    for depth in range(2, len(parts) + 1):
        if spec is None or spec.submodule_search_locations is None:
            break
        spec = importlib.machinery.PathFinder.find_spec(
            ".".join(parts[:depth]), spec.submodule_search_locations
        )
    if spec is None or spec.origin is None or spec.name != module:
        spec = importlib.util.find_spec(module)  # a package mapped elsewhere: its parents are imported
    if spec is None or spec.origin is None:
        raise LookupError(f"module {module} not found")
    return Path(spec.origin)


def _assigned(module: str, name: str) -> ast.expr:
    """The expression assigned to ``name`` at the top of ``module``'s source."""
    tree = ast.parse(module_source(module).read_text(encoding="utf-8"))
    for node in tree.body:
        target = node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 else None
        target = node.target if isinstance(node, ast.AnnAssign) else target
        if isinstance(target, ast.Name) and target.id == name and node.value is not None:
            return node.value
    raise LookupError(f"{module} assigns no {name}")


def declared_value(module: str, name: str) -> Any:
    """The literal (a string, a number, a tuple of them, ...) assigned to ``name`` at the top of ``module``
    (e.g. ``setdiff_bench.protocols.profiles.DEFAULT_PROFILE``), read from its source.

    Raises:
        LookupError: no such assignment, or not a literal.
    """
    try:
        return ast.literal_eval(_assigned(module, name))
    except ValueError:
        raise LookupError(f"{module}.{name} is not a literal") from None


def declared_literal(module: str, name: str) -> tuple[str, ...]:
    """The choices of the ``Literal`` type alias assigned to ``name`` at the top of ``module`` (e.g.
    ``WarpMode = Literal["auto", "on", "off"]`` in :mod:`setdiff_bench.evaluation.run`), in order,
    read from its source; ``typing.get_args`` of the imported alias gives the same.

    Raises:
        LookupError: no such assignment, or not ``Literal[...]`` of string literals.
    """
    value = _assigned(module, name)
    if not (
        isinstance(value, ast.Subscript) and isinstance(value.value, ast.Name) and value.value.id == "Literal"
    ):
        raise LookupError(f"{module}.{name} is not a Literal[...] alias")
    items = value.slice.elts if isinstance(value.slice, ast.Tuple) else [value.slice]
    choices = [item.value if isinstance(item, ast.Constant) else None for item in items]
    if not all(isinstance(choice, str) for choice in choices):
        raise LookupError(f"{module}.{name} holds other values than string literals")
    return tuple(choices)  # type: ignore[arg-type]


def registry_names(module: str, name: str) -> tuple[str, ...]:
    """The keys, in order, of the dict literal assigned to ``name`` at the top of ``module`` (a registry such as
    ``setdiff_bench.synthetic.presets.PRESETS``), read from its source.

    Raises:
        LookupError: ``module`` has no such assignment, or it is not a dict with string literal keys.
    """
    value = _assigned(module, name)
    keys = [key.value if isinstance(key, ast.Constant) else None for key in getattr(value, "keys", [None])]
    if not isinstance(value, ast.Dict) or not all(isinstance(key, str) for key in keys):
        raise LookupError(f"{module}.{name} is not a dict literal with string keys")
    return tuple(keys)  # type: ignore[arg-type]


def dataset_names() -> tuple[str, ...]:
    """The dataset keys of the loader registry (:data:`setdiff_bench.loaders.DATASETS`), in order.

    ``setdiff_bench.loaders`` itself imports only the standard library, the error classes and the lazy loader
    (each loader module is imported when its dataset is read), so it is imported here: reading the keys from
    its source would mean evaluating the comprehension that builds the registry.
    ``tests/cli/test_help_latency.py`` checks that ``prepare --help`` still imports nothing heavy.
    """
    # lazy: only the parser of a verb that offers datasets needs the registry
    from setdiff_bench.loaders import DATASETS

    return tuple(DATASETS)


def declared_field_default(module: str, cls: str, name: str) -> Any:
    """The literal default of field ``name`` of the class ``cls`` defined in ``module`` (or in the module that
    ``module`` imports it from), read from the sources without importing them: ``--help`` may not load torch,
    which importing :mod:`setdiff_bench.gaussians.fit` does through its package
    (module docstring).

    Raises:
        LookupError: no such class or field, or a default that is not a literal.
    """
    source = module_source(module)
    tree = ast.parse(source.read_text(encoding="utf-8"))
    package = module if source.name == "__init__.py" else module.rpartition(".")[0]
    for node in tree.body:
        if isinstance(node, ast.ClassDef) and node.name == cls:
            for item in node.body:
                if (
                    isinstance(item, ast.AnnAssign)
                    and isinstance(item.target, ast.Name)
                    and item.target.id == name
                    and item.value is not None
                ):
                    try:
                        return ast.literal_eval(item.value)
                    except ValueError:
                        raise LookupError(f"{module}.{cls}.{name}'s default is not a literal") from None
            raise LookupError(f"{module}.{cls} declares no field {name} with a default")
        if isinstance(node, ast.ImportFrom) and any(
            alias.name == cls and alias.asname in (None, cls) for alias in node.names
        ):  # a re-export: follow it (``from .fit_config import FitConfig`` too)
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""  # level 1: this package
            origin = ".".join(part for part in (base, node.module or "") if part)
            return declared_field_default(origin, cls, name)
    raise LookupError(f"{module} defines no class {cls}")
