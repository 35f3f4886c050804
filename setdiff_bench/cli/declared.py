"""Names the CLI offers as choices, read from the library module that declares them without importing it.

A parser is built for every ``--help``, which must not import the heavy libraries (``tests/cli/
test_help_latency.py``); the synthetic preset registries live in modules that import torch.  So their keys are
read from the modules' sources, as :func:`setdiff_bench.cli.main.verb_summaries` reads the verb list;
``tests/cli/test_declared_choices.py`` checks them against the imported registries.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path


def registry_names(module: str, name: str) -> tuple[str, ...]:
    """The keys, in order, of the dict literal assigned to ``name`` at the top of ``module`` (a registry such as
    ``setdiff_bench.synthetic.presets.PRESETS``), read from its source; ``module`` is not imported (its parent
    packages are).

    Raises:
        LookupError: ``module`` has no such assignment, or its keys are not all string literals.
    """
    spec = importlib.util.find_spec(module)
    if spec is None or spec.origin is None:
        raise LookupError(f"module {module} not found")
    tree = ast.parse(Path(spec.origin).read_text(encoding="utf-8"))
    for node in tree.body:
        target = node.targets[0] if isinstance(node, ast.Assign) and len(node.targets) == 1 else None
        target = node.target if isinstance(node, ast.AnnAssign) else target
        if isinstance(target, ast.Name) and target.id == name and isinstance(node.value, ast.Dict):
            keys = [key.value if isinstance(key, ast.Constant) else None for key in node.value.keys]
            if all(isinstance(key, str) for key in keys):
                return tuple(keys)  # type: ignore[arg-type]
    raise LookupError(f"{module}.{name} is not a dict literal with string keys")
