"""setdiff-bench: benchmark and enhancers for 3D Gaussian Splatting novel-view synthesis.

The data path (see ``docs/architecture.md``): loaders → protocols → fit → render → packets →
enhancers → metrics → leaderboards.  ``import setdiff_bench as sb`` gives what a notebook needs, and
loads each part only when it is first used (``python -X importtime -c "import setdiff_bench"``)::

    store = sb.PacketStore("runs/demo/work/packets")
    enhancer = sb.create_enhancer("setdiff", checkpoint="tiny_setdiff")
    print(sb.score_packet(enhancer, store, store.packet_ids("test")[0]).means())

Reference: ``docs/api.md``.
"""

from __future__ import annotations

import os as _os
from importlib import import_module
from typing import TYPE_CHECKING, Any

from setdiff_bench.errors import SetDiffBenchError, UsageError
from setdiff_bench.version import __version__

# pyproject installs the repository's ``loaders/`` and ``protocols/`` folders as ``setdiff_bench.loaders`` and
# ``setdiff_bench.protocols``.  Run from a source checkout without an install (``PYTHONPATH=.``, a copy on a
# machine with nothing installed), the package finds them beside itself.  Installed, it never looks there.
_CHECKOUT = _os.path.dirname(_os.path.dirname(_os.path.abspath(__file__)))
if _os.path.isfile(_os.path.join(_CHECKOUT, "pyproject.toml")) and _os.path.isfile(
    _os.path.join(_CHECKOUT, "protocols", "__init__.py")
):
    __path__.append(_CHECKOUT)  # setdiff_bench.<name> not found in the package: <checkout>/<name>

#: Public name → ``"module:attribute"`` it is loaded from on first use.
_LAZY: dict[str, str] = {
    # vocabulary
    "Camera": "setdiff_bench.cameras:Camera",
    "Packet": "setdiff_bench.types:Packet",
    "PacketKey": "setdiff_bench.types:PacketKey",
    "Scene": "setdiff_bench.types:Scene",
    # datasets and protocols
    "DATASETS": "setdiff_bench.loaders:DATASETS",
    "list_scenes": "setdiff_bench.loaders:list_scenes",
    "load_scenes": "setdiff_bench.loaders:load_scenes",
    "list_protocols": "setdiff_bench.protocols:list_protocols",
    "load_protocol": "setdiff_bench.protocols:load_protocol",
    # packets
    "PacketStore": "setdiff_bench.packets.store:PacketStore",
    # enhancers
    "Enhancer": "setdiff_bench.enhancers.base:Enhancer",
    "MethodSpec": "setdiff_bench.enhancers.base:MethodSpec",
    "available_methods": "setdiff_bench.enhancers.base:available_methods",
    "create_enhancer": "setdiff_bench.enhancers.base:create_enhancer",
    # scoring and runs
    "PacketScore": "setdiff_bench.evaluation.packet_scoring:PacketScore",
    "EnhancerOutputError": "setdiff_bench.evaluation.packet_scoring:EnhancerOutputError",
    "score_packet": "setdiff_bench.evaluation.packet_scoring:score_packet",
    "RunSettings": "setdiff_bench.evaluation.run:RunSettings",
    "RunResult": "setdiff_bench.evaluation.run:RunResult",
    "run_method": "setdiff_bench.evaluation.run:run_method",
    # closed loop
    "StreamSession": "setdiff_bench.evaluation.stream:StreamSession",
    "Views": "setdiff_bench.evaluation.stream:Views",
    # leaderboards
    "leaderboard": "setdiff_bench.api:leaderboard",
    "Leaderboard": "setdiff_bench.reporting.leaderboard:Leaderboard",
    "leaderboard_frame": "setdiff_bench.reporting.leaderboard:to_frame",
    "render_markdown": "setdiff_bench.reporting.leaderboard:render_markdown",
}

__all__ = [
    "DATASETS",
    "Camera",
    "Enhancer",
    "EnhancerOutputError",
    "Leaderboard",
    "MethodSpec",
    "Packet",
    "PacketKey",
    "PacketScore",
    "PacketStore",
    "RunResult",
    "RunSettings",
    "Scene",
    "SetDiffBenchError",
    "StreamSession",
    "UsageError",
    "Views",
    "__version__",
    "available_methods",
    "create_enhancer",
    "leaderboard",
    "leaderboard_frame",
    "list_protocols",
    "list_scenes",
    "load_protocol",
    "load_scenes",
    "render_markdown",
    "run_method",
    "score_packet",
]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time each name loads on first use
    from setdiff_bench.api import leaderboard
    from setdiff_bench.cameras import Camera
    from setdiff_bench.enhancers.base import Enhancer, MethodSpec, available_methods, create_enhancer
    from setdiff_bench.evaluation.packet_scoring import EnhancerOutputError, PacketScore, score_packet
    from setdiff_bench.evaluation.run import RunResult, RunSettings, run_method
    from setdiff_bench.evaluation.stream import StreamSession, Views
    from setdiff_bench.loaders import DATASETS, list_scenes, load_scenes
    from setdiff_bench.packets.store import PacketStore
    from setdiff_bench.protocols import list_protocols, load_protocol
    from setdiff_bench.reporting.leaderboard import Leaderboard, render_markdown
    from setdiff_bench.reporting.leaderboard import to_frame as leaderboard_frame
    from setdiff_bench.types import Packet, PacketKey, Scene


def __getattr__(name: str) -> Any:
    """Load a public name on first use and keep it (PEP 562)."""
    target = _LAZY.get(name)
    if target is None:
        raise AttributeError(f"module 'setdiff_bench' has no attribute {name!r}")
    module, _, attribute = target.partition(":")
    value = getattr(import_module(module), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    """The documented API only (``docs/api.md``): not the helpers this module imports for itself."""
    return sorted(__all__)
