"""Fitting a driving scene's 3DGS: ``fits/lane0.ply`` with ``preset.fit`` on the scene's ``train_set.txt``
frames (the ``lane0`` front camera minus the held-out interpolation frames), the folder read through the
loader that recognises it (:data:`FITTING`, :func:`fit_driving_scene`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from setdiff_bench.synthetic.fits import FitRecipe
from setdiff_bench.synthetic.presets import Preset

#: The driving scene's one fit, named after the traversal it is fitted on (``generate.TRAINING_TRAVERSAL``).
FIT_KEY = "lane0"


def driving_fit_keys(preset: Preset) -> tuple[str, ...]:
    """The fits of a driving scene: ``("lane0",)`` whatever the preset."""
    del preset
    return (FIT_KEY,)


def driving_fit_source(scene_dir: Path, preset: Preset, key: str) -> dict[str, Any]:
    """What ``fits/lane0.ply`` is fitted on: the scene folder's training split."""
    del preset, key
    return {"scene_dir": scene_dir}


#: The driving kind's fits (``scene_<seed>_<index>: generated in … s, fitted N Gaussians in … s``).
FITTING = FitRecipe(
    driving_fit_keys,
    driving_fit_source,
    present="fit already present",
    fitted="fitted {gaussians} Gaussians in {seconds:.1f} s",
)

#: ``fit_driving_scene(scene_dir, preset, *, device, overwrite, report) -> [summary line]``
#: (:meth:`~setdiff_bench.synthetic.fits.FitRecipe.fit`).
fit_driving_scene = FITTING.fit
