"""Sparse-view scenes: a handheld walk around a pedestrian plaza, written in DL3DV's on-disk layout.

The second synthetic scene kind (docs/synthetic_format.md, "Sparse-view scenes").  The world is the
driving benchmark's (:func:`~setdiff_bench.synthetic.layout.random_layout` turned into Gaussians by
:func:`~setdiff_bench.synthetic.world.build_static`, same façades, textures, parked cars, poles, sky and
renderer), closed to traffic and furnished as a plaza: cars parked at any angle, kiosks and stone
blocks stand in the roadway (:func:`plaza_objects`), so objects at 2-10 m occlude the parked cars
(8-15 m) and façades (15-25 m) differently from frame to frame; street trees are left out (their fuzzy
crowns have no consistent depth between views, see the docs).  One camera walks ``frames`` frames on an
arc of about ``arc_deg`` around the plaza's centre, looking inwards (:func:`random_walk`): the heading
turns with the walk (about 50° per 50 frames for ``sparse``) and is swept ±10-18° on top, the height
varies between 1.35 and 1.75 m and the pitch between -13° and -3°, with handheld shake — a DL3DV-style
capture around a place.  Under the 3DGS-Enhancer rule (fit views 50 frames apart), a frame between two
fit views looks at the plaza from between their directions, so each fit view sees a different part of
it: what makes a set of references matter (benchmarks/reference_ceiling.py).

On disk (``<out>/<scene>/``, read by ``loaders/dl3dv.py`` unchanged)::

    images_4/frame_00001.png …       # ground truth, 8-bit RGB, the preset's size (DL3DV's images_4)
    colmap/sparse/0/{cameras,images,points3D}.bin   # one OPENCV camera (zero distortion) at 4x that
                                                   # size (the "full resolution"), world-to-camera
    scene.json                       # format setdiff-synthetic-sparse/1: seed, index, preset, path, views
    fits/n3.ply, n6.ply, n9.ply      # written by `synth` unless --no-fit: 3DGS fitted on the views the
                                     # 3DGS-Enhancer rule picks (protocols/rules.py sparse_view_indices)

Every random draw comes from ``numpy.random.SeedSequence([seed, index, 37])`` split into streams
(layout, world, path, objects, sparse points), so scene *i* depends only on ``(preset, seed, i)``; the
trailing 37 keeps these streams apart from a driving scene of the same ``(seed, i)``.

The scene kind by concept: :mod:`.sparse_preset` (generation parameters), :mod:`.sparse_names` (the layout's
names), :mod:`.sparse_walk` (the path and cameras), :mod:`.sparse_plaza` (the plaza's objects),
:mod:`.sparse_build` (a scene in memory and its rendering), :mod:`.sparse_writer` (the DL3DV layout on disk)
and :mod:`.sparse_fit` (the sparse fits); :mod:`.kinds` declares the kind beside the driving one.  This module
holds the named presets (what a tier shares with the driving presets is in :mod:`.preset_tiers`) and rebuilds a
scene's world.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.fit import FitConfig
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.synthetic.preset_tiers import CPU_FIT, LARGE_DETAIL, LARGE_FIT, TINY_DETAIL
from setdiff_bench.synthetic.sparse_build import (
    OBJECT_CATEGORY,
    STREAM_TAG,
    SparseBuild,
    build_sparse_scene,
    render_sparse_frames,
)
from setdiff_bench.synthetic.sparse_fit import fit_sparse_scene
from setdiff_bench.synthetic.sparse_names import (
    FORMAT,
    FULL_SCALE,
    IMAGES_DIR,
    fit_views,
    frame_file,
    sparse_scene_name,
)
from setdiff_bench.synthetic.sparse_plaza import plaza_objects
from setdiff_bench.synthetic.sparse_preset import SparsePreset
from setdiff_bench.synthetic.sparse_walk import Walk, random_walk, walk_camera
from setdiff_bench.synthetic.sparse_writer import (
    generate_sparse_scene,
    sparse_description,
    write_sparse_scene,
)

__all__ = [
    "FORMAT",
    "FULL_SCALE",
    "IMAGES_DIR",
    "OBJECT_CATEGORY",
    "SPARSE_PRESETS",
    "STREAM_TAG",
    "SparseBuild",
    "SparsePreset",
    "Walk",
    "build_sparse_scene",
    "fit_sparse_scene",
    "fit_views",
    "frame_file",
    "generate_sparse_scene",
    "get_sparse_preset",
    "plaza_objects",
    "random_walk",
    "render_sparse_frames",
    "sparse_description",
    "sparse_scene_name",
    "static_world",
    "walk_camera",
    "write_sparse_scene",
]


#: ``sparse``: the embedded sparse-view benchmark's walks; its fits start from the scene's ``points3D``, points
#: sampled on every frame (SfM of the whole video), so an n-view fit already knows geometry and colour its n
#: views never saw: the milder tier (docs/sparse_benchmark.md).
SPARSE_WALKS = SparsePreset(
    name="sparse",
    num_scenes=12,
    width=256,
    height=144,
    frames=150,
    hfov_deg=70.0,
    radius_m=6.5,
    arc_deg=150.0,
    sweep_period=100.0,
    plaza_objects=10,
    pixels_per_gaussian=3.0,
    min_spacing=0.15,
    max_spacing=3.0,
    foliage_count=60,
    points3d=6000,
    tile_size=8,
    fit=CPU_FIT,
)

#: ``sparse_random_init``'s fit iterations (docs/sparse_benchmark.md, "A tier in the paper's regime").
RANDOM_INIT_ITERATIONS = 1000

SPARSE_PRESETS: dict[str, SparsePreset] = {
    "sparse_tiny": SparsePreset(
        name="sparse_tiny",
        num_scenes=1,
        width=64,
        height=40,  # both sides multiples of 8, as the models' autoencoder needs
        frames=30,
        hfov_deg=70.0,
        radius_m=4.0,
        arc_deg=150.0,
        sweep_period=20.0,
        plaza_objects=3,
        **TINY_DETAIL,
        tile_size=8,
        fit=FitConfig.schedule(
            iterations=40, densify_every=10, opacity_reset_every=10_000, background_points=300, tile_size=8
        ),
    ),
    "sparse": SPARSE_WALKS,
    "sparse_random_init": replace(
        SPARSE_WALKS, name="sparse_random_init", init="random", fit=CPU_FIT.rescaled(RANDOM_INIT_ITERATIONS)
    ),
    "sparse_large": SparsePreset(
        name="sparse_large",
        num_scenes=12,
        width=512,
        height=288,
        frames=300,
        hfov_deg=70.0,
        radius_m=7.0,
        arc_deg=300.0,
        sweep_period=100.0,
        plaza_objects=18,
        **LARGE_DETAIL,
        tile_size=16,
        fit=LARGE_FIT,
    ),
}


def get_sparse_preset(name: str) -> SparsePreset:
    """The sparse preset called ``name``; :class:`UsageError` listing the choices otherwise."""
    if name not in SPARSE_PRESETS:
        raise UsageError(
            f"unknown sparse preset {name!r}; choose one of {', '.join(SPARSE_PRESETS)}", "--preset"
        )
    return SPARSE_PRESETS[name]


def static_world(scene_dir: Path) -> GaussianModel:
    """The static world of a synthetic scene of either kind, rebuilt from its ``scene.json``."""
    description = json.loads((Path(scene_dir) / "scene.json").read_text(encoding="utf-8"))
    seed, index = int(description["seed"]), int(description["index"])
    if description.get("format") == FORMAT:
        return build_sparse_scene(get_sparse_preset(description["preset"]), seed, index).static
    from setdiff_bench.synthetic.generate import build_scene
    from setdiff_bench.synthetic.presets import get_preset

    return build_scene(get_preset(description["preset"]), seed, index).world.static
