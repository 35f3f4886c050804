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

The scene kind by concept, each a private module: ``_preset`` (generation parameters), ``_names`` (the
layout's names), ``_walk`` (the path and cameras), ``_plaza`` (the plaza's objects), ``_build`` (a scene in
memory and its rendering), ``_writer`` (the DL3DV layout on disk), ``_fit`` (the sparse fits) and ``_sparse``
(the named presets and a scene's world rebuilt; what a tier shares with the driving presets is in
:mod:`setdiff_bench.synthetic.preset_tiers`); :mod:`setdiff_bench.synthetic.kinds` declares the kind beside the
driving one.

The package's modules are private; this face exports what other code uses.
"""

from __future__ import annotations

from setdiff_bench.synthetic.sparse._build import build_sparse_scene
from setdiff_bench.synthetic.sparse._fit import FITTING, fit_sparse_scene
from setdiff_bench.synthetic.sparse._names import FULL_SCALE, IMAGES_DIR, fit_views, sparse_scene_name
from setdiff_bench.synthetic.sparse._sparse import SPARSE_PRESETS, get_sparse_preset, static_world
from setdiff_bench.synthetic.sparse._writer import (
    RECIPE,
    fit_view_points,
    generate_sparse_scene,
    write_sparse_model,
)

__all__ = [
    "FITTING",
    "FULL_SCALE",
    "IMAGES_DIR",
    "RECIPE",
    "SPARSE_PRESETS",
    "build_sparse_scene",
    "fit_sparse_scene",
    "fit_view_points",
    "fit_views",
    "generate_sparse_scene",
    "get_sparse_preset",
    "sparse_scene_name",
    "static_world",
    "write_sparse_model",
]
