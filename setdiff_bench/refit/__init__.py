"""Enhance and refit: distil enhanced novel views back into a 3DGS (the field's "X 3D" rows).

An enhancer ``X`` is scored three ways (docs/refit.md): ``X`` post-processes the original fit's renders
(``run``), ``X 3D`` is the render of the fit refitted with ``X``'s enhanced novel views (this package), and
``X 3D+`` is ``X`` applied to that render.  :func:`refit_scene` runs one scene's refit with a
:class:`RefitSettings` schedule — ``progressive`` (Difix3D+) or ``one-shot`` (3DGS-Enhancer) — and writes the
refit PLY where ``prepare --fits`` finds it, with a manifest beside it (:func:`setdiff_bench.io.refit_layout.refit_paths`).

Example::

    from setdiff_bench.refit import RefitSettings, RefitTask, refit_scene

    task = RefitTask("synthetic", Path("scenes"), "scene_0000_00", Path("runs/refit"), "setdiff",
                     {"checkpoint": "tiny_setdiff"}, group="lane+2", fits=Path("scenes"))
    result = refit_scene(task, RefitSettings.preset("progressive", steps=300))

The settings are importable without torch (the CLI reads them at start-up); the rest loads on first use.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from setdiff_bench.refit.settings import SCHEDULE_PRESETS, RefitSettings, Schedule

if TYPE_CHECKING:
    from setdiff_bench.refit.scene import RefitResult, RefitTask, refit_scene

__all__ = [
    "SCHEDULE_PRESETS",
    "RefitResult",
    "RefitSettings",
    "RefitTask",
    "Schedule",
    "refit_scene",
]

_LAZY = {"RefitResult", "RefitTask", "refit_scene"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        from setdiff_bench.refit import scene

        return getattr(scene, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
