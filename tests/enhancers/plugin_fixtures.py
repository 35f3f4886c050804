"""A third-party enhancer package installed into a temporary folder: module + dist-info with an entry point.

``importlib.metadata`` finds distributions through ``sys.path``, so putting the folder there is all a
real ``pip install`` would add for this purpose.
"""

from __future__ import annotations

import textwrap
from pathlib import Path

PLUGIN_MODULE = '''
"""A test plugin: darkens every target by a fixed factor."""
from setdiff_bench.enhancers.base import MethodSpec

SPEC = MethodSpec(name="{name}", factory="{module}:create",
                  description="test plugin: multiplies the render by a factor", needs_gpu=False)


class Darken:
    name = "{name}"

    def __init__(self, factor: float) -> None:
        self.factor = factor
        self.options = {{"factor": factor}}

    def enhance(self, packet):
        return packet.targets.images * self.factor


def create(factor: float = 0.5):
    return Darken(factor)
'''


def install_plugin(
    folder: Path, name: str = "darken", module: str = "setdiff_test_plugin", target: str | None = None
) -> Path:
    """Write ``module.py`` and ``<module>-0.1.dist-info`` (METADATA, entry_points.txt) into ``folder``.

    ``target`` overrides the entry point's value (default ``module:SPEC``).
    """
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{module}.py").write_text(textwrap.dedent(PLUGIN_MODULE.format(name=name, module=module)))
    info = folder / f"{module}-0.1.dist-info"
    info.mkdir(exist_ok=True)
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {module}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(
        f"[setdiff_bench.enhancers]\n{name} = {target or module + ':SPEC'}\n"
    )
    return folder
