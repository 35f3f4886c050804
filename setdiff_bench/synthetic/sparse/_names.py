"""Names in a sparse-view scene's DL3DV layout: the scene folder, the frame files, the image folder, the
``scene.json`` format, the COLMAP model's full-resolution scale, and the frames each fit uses
(the 3DGS-Enhancer rule, :func:`setdiff_bench.protocols.rules.sparse_view_indices`).
"""

from __future__ import annotations

from setdiff_bench.protocols.rules import sparse_view_indices
from setdiff_bench.synthetic.kinds import SCENE_KINDS
from setdiff_bench.synthetic.sparse._preset import SparsePreset

FORMAT = "setdiff-synthetic-sparse/1"
IMAGES_DIR = "images_4"
FULL_SCALE = 4
"""The COLMAP camera is written at ``FULL_SCALE`` × the image size, as DL3DV's model refers to the
full-resolution frames and ``images_4`` holds them downscaled 4×; the loader rescales K exactly."""


def sparse_scene_name(seed: int, index: int) -> str:
    """``sparse_{seed:04d}_{index:02d}`` (DL3DV names scenes by a hash; the loader takes any folder name)."""
    return SCENE_KINDS["sparse"].scene_name(seed, index)


def frame_file(index: int) -> str:
    """DL3DV's frame name, 1-based: ``frame_00001.png``."""
    return f"frame_{index + 1:05d}.png"


def fit_views(preset: SparsePreset) -> dict[str, list[str]]:
    """``{"n3": [frame names], …}``: the views the 3DGS-Enhancer rule fits at each of ``preset.views``."""
    return {
        f"n{k}": [frame_file(i) for i in sparse_view_indices(preset.frames, k, preset.gaps)]
        for k in preset.views
    }
