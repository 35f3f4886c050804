"""The registry entry: what ``[project.entry-points."setdiff_bench.enhancers"]`` in pyproject.toml names.

It is read whenever setdiff-bench lists its methods, so it imports nothing heavy: the factory is a
``"module:attribute"`` string, imported only when the method is built.
"""

from setdiff_bench.enhancers.base import MethodSpec

SPEC = MethodSpec(
    name="unsharp",
    factory="setdiff_unsharp.enhancer:create",
    description="template plugin: unsharp mask of each render (-o amount=1.0 -o sigma=1.0)",
)
