"""Writing a sparse-view scene in DL3DV's on-disk layout (read by ``loaders/dl3dv.py`` unchanged): the
``images_4`` frames, the COLMAP model at the full resolution with the SfM-like points, and
``scene.json`` (docs/synthetic_format.md, "Sparse-view scenes"); :func:`generate_sparse_scene` builds,
renders and writes a scene through a staging folder.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.io.images import write_png
from setdiff_bench.synthetic.capture import CapturedFrame
from setdiff_bench.synthetic.colmap_writer import ColmapImage, write_colmap_model
from setdiff_bench.synthetic.rig import intrinsics
from setdiff_bench.synthetic.sfm import SparsePoints, sample_sparse_points
from setdiff_bench.synthetic.sparse._build import (
    STREAM_TAG,
    SparseBuild,
    build_sparse_scene,
    render_sparse_frames,
)
from setdiff_bench.synthetic.sparse._names import (
    FORMAT,
    FULL_SCALE,
    IMAGES_DIR,
    fit_views,
    frame_file,
    sparse_scene_name,
)
from setdiff_bench.synthetic.staging import SceneRecipe, scene_header
from setdiff_bench.synthetic.world import SFM_CATEGORIES


def sparse_description(build: SparseBuild, num_points: int) -> dict[str, object]:
    """The ``scene.json`` object (docs/synthetic_format.md, "Sparse-view scenes")."""
    p = build.preset
    fx, fy, cx, cy = intrinsics(p.width, p.height, p.hfov_deg)
    return {
        **scene_header(FORMAT, build.name, build.seed, build.index, p.name),
        "kind": "walk",
        "width": p.width,
        "height": p.height,
        "images_dir": IMAGES_DIR,
        "full_resolution": [p.width * FULL_SCALE, p.height * FULL_SCALE],
        "camera": {"model": "OPENCV", "hfov_deg": p.hfov_deg, "fx": fx, "fy": fy, "cx": cx, "cy": cy},
        "units": "metres",
        "world_up": [0, 0, 1],
        "num_frames": p.frames,
        "path_length_m": float(np.sum(np.linalg.norm(np.diff(build.walk.positions, axis=0), axis=1))),
        "heading_range_deg": [
            float(np.degrees(build.walk.headings.min())),
            float(np.degrees(build.walk.headings.max())),
        ],
        "height_range_m": [float(build.walk.positions[:, 2].min()), float(build.walk.positions[:, 2].max())],
        "fit_views": fit_views(p),
        "num_points3d": num_points,
    }


def sfm_eligible(build: SparseBuild) -> torch.Tensor:
    """``(N,)`` bool: the world's Gaussians SfM could triangulate (ground, façades, objects, foliage)."""
    eligible = torch.zeros(len(build.static), dtype=torch.bool)
    for category in SFM_CATEGORIES:
        eligible |= build.categories == category
    return eligible


def write_sparse_model(build: SparseBuild, points: SparsePoints, destination: Path) -> None:
    """The COLMAP model of every frame of the walk (one OPENCV camera at ``FULL_SCALE`` × the image size) with
    ``points`` as ``points3D``, into ``destination/colmap/sparse/0``."""
    p = build.preset
    images = [
        ColmapImage(frame_file(i), "camera", camera.resized(p.width * FULL_SCALE, p.height * FULL_SCALE))
        for i, camera in enumerate(build.cameras)
    ]
    write_colmap_model(
        destination / "colmap" / "sparse" / "0", images, points.xyz, points.rgb, camera_model="OPENCV"
    )


def fit_view_points(build: SparseBuild, frame_indices: Sequence[int]) -> SparsePoints:
    """SfM-like points of the fit views alone (:func:`sample_sparse_points` on those frames, seen in at least
    two of them): what an ideal matcher would triangulate from the n views a sparse-view fit is given.  The
    draws come from ``SeedSequence([seed, index, STREAM_TAG, len(frame_indices)])``, apart from the scene's."""
    views = replace(build, cameras=[build.cameras[i] for i in frame_indices])
    frames = render_sparse_frames(views)
    rng = np.random.default_rng([build.seed, build.index, STREAM_TAG, len(frame_indices)])
    return sample_sparse_points(build.static, sfm_eligible(build), frames, build.preset.points3d, rng)


def write_sparse_scene(build: SparseBuild, frames: Sequence[CapturedFrame], destination: Path) -> None:
    """Write the DL3DV layout of the scene into ``destination`` (an empty folder)."""
    for frame in frames:
        write_png(destination / IMAGES_DIR / frame.name, frame.rgb)
    points = sample_sparse_points(
        build.static, sfm_eligible(build), list(frames), build.preset.points3d, build.sparse_rng
    )
    write_sparse_model(build, points, destination)
    description = sparse_description(build, int(points.xyz.shape[0]))
    write_text_atomic(destination / "scene.json", json.dumps(description, indent=1, sort_keys=True) + "\n")


#: How a sparse-view scene is made (:class:`~setdiff_bench.synthetic.staging.SceneRecipe`).
RECIPE = SceneRecipe(sparse_scene_name, build_sparse_scene, render_sparse_frames, write_sparse_scene)

#: ``generate_sparse_scene(out_root, preset, seed, index, *, overwrite, progress, device) -> scene folder``:
#: sparse-view scene ``index`` of ``seed`` under ``out_root``, a complete scene (its ``scene.json`` present,
#: same preset) kept unless ``overwrite`` (:meth:`~setdiff_bench.synthetic.staging.SceneRecipe.make`).
generate_sparse_scene = RECIPE.make
