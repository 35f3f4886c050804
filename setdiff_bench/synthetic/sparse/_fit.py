"""Fitting a sparse-view scene's 3DGS models: ``fits/n{k}.ply`` on the views the 3DGS-Enhancer rule picks
for each of the preset's view counts, the scene read through the DL3DV loader with pinhole cameras as the
protocol says (:data:`FITTING`, :func:`fit_sparse_scene`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from setdiff_bench.synthetic.fits import FitRecipe
from setdiff_bench.synthetic.kinds import SCENE_KINDS
from setdiff_bench.synthetic.sparse._names import fit_views
from setdiff_bench.synthetic.sparse._preset import SparsePreset


def sparse_fit_keys(preset: SparsePreset) -> tuple[str, ...]:
    """The fits of a sparse-view scene: ``n{k}`` for each ``k`` of ``preset.views``."""
    return tuple(f"n{k}" for k in preset.views)


def sparse_fit_source(scene_dir: Path, preset: SparsePreset, key: str) -> dict[str, Any]:
    """What ``fits/<key>.ply`` is fitted on: the 3DGS-Enhancer rule's views of the scene (:func:`fit_views`),
    from the preset's initial points (``init``)."""
    return {
        "scene_dir": scene_dir.parent,
        "frames": fit_views(preset)[key],
        "dataset": SCENE_KINDS["sparse"].dataset,
        "scene_name": scene_dir.name,
        "loader_options": {"distortion": "ignore"},
        "init": preset.init,
    }


#: The sparse kind's fits (``sparse_<seed>_<index>: generated in … s, n3: N Gaussians in … s, …``).
FITTING = FitRecipe(
    sparse_fit_keys,
    sparse_fit_source,
    present="{key} already present",
    fitted="{key}: {gaussians} Gaussians in {seconds:.1f} s",
)

#: ``fit_sparse_scene(scene_dir, preset, *, device, overwrite, report) -> [summary line per fit]``
#: (:meth:`~setdiff_bench.synthetic.fits.FitRecipe.fit`).
fit_sparse_scene = FITTING.fit
