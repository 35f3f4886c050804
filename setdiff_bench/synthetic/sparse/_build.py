"""A sparse-view scene in memory (:class:`SparseBuild`): its street, plaza objects, walk, Gaussians and
cameras drawn from ``numpy.random.SeedSequence([seed, index, STREAM_TAG])`` split into streams (layout,
world, path, objects, sparse points), so scene *i* depends only on ``(preset, seed, i)``; and the
rendering of its ground-truth frames (:func:`render_sparse_frames`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.synthetic.capture import CapturedFrame, concat_models, expected_depth
from setdiff_bench.synthetic.layout import StreetLayout, random_layout
from setdiff_bench.synthetic.rig import intrinsics
from setdiff_bench.synthetic.sparse._names import frame_file, sparse_scene_name
from setdiff_bench.synthetic.sparse._plaza import plaza_objects
from setdiff_bench.synthetic.sparse._preset import SparsePreset
from setdiff_bench.synthetic.sparse._walk import Walk, random_walk, walk_camera
from setdiff_bench.synthetic.world import Detail, build_static

STREAM_TAG = 37
OBJECT_CATEGORY = 2  # world.CATEGORIES index of "object"


@dataclass
class SparseBuild:
    """A sparse-view scene in memory: its world, walk and cameras (nothing rendered yet)."""

    name: str
    seed: int
    index: int
    preset: SparsePreset
    layout: StreetLayout
    static: GaussianModel
    categories: torch.Tensor
    walk: Walk
    cameras: list[Camera]
    sparse_rng: np.random.Generator


def build_sparse_scene(preset: SparsePreset, seed: int, index: int) -> SparseBuild:
    """Lay out the street, place the plaza's objects, draw the walk and build the Gaussians."""
    if seed < 0 or index < 0:
        raise UsageError(f"seed and scene index must be non-negative, got {seed} and {index}", "--seed")
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence([seed, index, STREAM_TAG]).spawn(5)]
    layout_rng, world_rng, walk_rng, object_rng, sparse_rng = streams
    layout = random_layout(layout_rng, -60.0, 60.0)
    walk = random_walk(preset, layout, walk_rng)
    fx = intrinsics(preset.width, preset.height, preset.hfov_deg)[0]
    detail = Detail(
        focal_px=fx,
        pixels_per_gaussian=preset.pixels_per_gaussian,
        min_spacing=preset.min_spacing,
        max_spacing=preset.max_spacing,
        path_x=(float(walk.positions[:, 0].min()), float(walk.positions[:, 0].max())),
        path_y=(float(walk.positions[:, 1].min()), float(walk.positions[:, 1].max())),
        foliage_count=preset.foliage_count,
    )
    objects = plaza_objects(preset, layout, walk, detail, object_rng)
    if not preset.street_trees:
        layout = replace(layout, trees=())
    static, categories = build_static(layout, detail, world_rng)
    if len(objects):
        static = concat_models(static, objects.to_model())
        categories = torch.cat([categories, torch.full((len(objects),), OBJECT_CATEGORY, dtype=torch.int64)])
    cameras = [walk_camera(walk, i, preset) for i in range(preset.frames)]
    return SparseBuild(
        sparse_scene_name(seed, index),
        seed,
        index,
        preset,
        layout,
        static,
        categories,
        walk,
        cameras,
        sparse_rng,
    )


def render_sparse_frames(
    build: SparseBuild,
    progress: Callable[[int, int], None] | None = None,
    device: str | torch.device = "cpu",
    batch: int = 4,
) -> list[CapturedFrame]:
    """Ground truth of every frame (``batch`` cameras per render call), in frame order."""
    p = build.preset
    static = build.static.to(device)
    frames: list[CapturedFrame] = []
    for start in range(0, len(build.cameras), batch):
        cameras = build.cameras[start : start + batch]
        with torch.no_grad():
            out = render(static, cameras, with_geometry=True, tile_size=p.tile_size)
            depth = expected_depth(out.depth, out.alpha)
        for v, camera in enumerate(cameras):
            index = start + v
            frames.append(
                CapturedFrame(
                    name=frame_file(index),
                    traversal="walk",
                    sensor="camera",
                    index=index,
                    timestamp_us=0,
                    camera=camera,
                    rgb=out.rgb[v].clamp(0, 1).permute(1, 2, 0).contiguous().cpu().numpy(),
                    static_mask=np.ones((p.height, p.width), bool),
                    depth=depth[v, 0].cpu().numpy(),
                )
            )
            if progress is not None:
                progress(len(frames), len(build.cameras))
    return frames
