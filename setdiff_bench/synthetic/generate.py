"""Generate synthetic scenes on disk in the EUVS layout (docs/synthetic_format.md).

A scene is built in a hidden staging folder next to its destination and renamed into place only
when every file is written, so an interrupted run never leaves a half-written scene; a finished
scene is skipped on the next run unless ``overwrite``.  Every random draw comes from
``numpy.random.SeedSequence([seed, index])`` split into independent streams (layout, textures, drives,
vehicles, sparse points), so the same ``(preset, seed, index)`` gives byte-identical files.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.io.images import write_png
from setdiff_bench.synthetic.capture import CapturedFrame, capture_drive
from setdiff_bench.synthetic.colmap_writer import ColmapImage, write_colmap_model
from setdiff_bench.synthetic.kinds import SCENE_KINDS
from setdiff_bench.synthetic.layout import (
    EGO_LANES,
    MovingVehicle,
    StreetLayout,
    random_layout,
    random_moving_vehicle,
)
from setdiff_bench.synthetic.presets import Preset
from setdiff_bench.synthetic.rig import (
    FRAME_RATE_HZ,
    RIG,
    Traversal,
    intrinsics,
    lane_change_drive,
    straight_drive,
)
from setdiff_bench.synthetic.sfm import sample_sparse_points
from setdiff_bench.synthetic.soup import GaussianSoup
from setdiff_bench.synthetic.staging import SceneRecipe, scene_header
from setdiff_bench.synthetic.world import SFM_CATEGORIES, Detail, World, build_static, car_soup

FORMAT = "setdiff-synthetic/1"
TRAINING_TRAVERSAL = "lane0"
TRAINING_SENSOR = "front"


@dataclass
class SceneBuild:
    """A scene in memory: the world, the drives and each drive's moving vehicle (if any)."""

    name: str
    seed: int
    index: int
    preset: Preset
    world: World
    traversals: list[Traversal]
    moving: dict[str, MovingVehicle]
    sparse_rng: np.random.Generator


def scene_name(seed: int, index: int) -> str:
    """``scene_{seed:04d}_{index:02d}`` (the driving kind's names, :data:`.kinds.SCENE_KINDS`)."""
    return SCENE_KINDS["driving"].scene_name(seed, index)


def is_training_frame(traversal: str, sensor: str, index: int, holdout_every: int) -> bool:
    """The fit frames: ``lane0`` ``front``, except every ``holdout_every``-th timestep (offset ``holdout_every // 2``)."""
    if traversal != TRAINING_TRAVERSAL or sensor != TRAINING_SENSOR:
        return False
    return holdout_every <= 0 or index % holdout_every != holdout_every // 2


def build_scene(preset: Preset, seed: int, index: int) -> SceneBuild:
    """Lay out, populate and drive one scene (nothing rendered yet)."""
    if seed < 0 or index < 0:
        raise UsageError(f"seed and scene index must be non-negative, got {seed} and {index}", "--seed")
    streams = [np.random.default_rng(s) for s in np.random.SeedSequence([seed, index]).spawn(5)]
    layout_rng, world_rng, drive_rng, vehicle_rng, sparse_rng = streams
    drive_end = (preset.timesteps - 1) * preset.step_m
    layout = random_layout(layout_rng, -10.0, drive_end + preset.view_ahead_m)
    fx = intrinsics(preset.width, preset.height)[0]
    detail = Detail(
        focal_px=fx,
        pixels_per_gaussian=preset.pixels_per_gaussian,
        min_spacing=preset.min_spacing,
        max_spacing=preset.max_spacing,
        path_x=(0.0, drive_end),
        path_y=(0.0, (EGO_LANES - 1) * layout.lane_width),
        foliage_count=preset.foliage_count,
    )
    static, categories = build_static(layout, detail, world_rng)
    traversals = [
        straight_drive(f"lane{k}", k, layout.lane_width, preset.timesteps, preset.step_m, drive_rng)
        for k in range(EGO_LANES)
    ]
    traversals.append(
        lane_change_drive("turn", layout.lane_width, preset.timesteps, preset.step_m, drive_rng)
    )
    moving: dict[str, MovingVehicle] = {}
    templates: dict[str, GaussianModel] = {}
    if preset.moving_vehicles:
        duration = preset.timesteps / FRAME_RATE_HZ
        for traversal in traversals:
            vehicle = random_moving_vehicle(vehicle_rng, layout, duration, (0.0, drive_end))
            moving[traversal.name] = vehicle
            soup = GaussianSoup()
            soup.extend(car_soup(vehicle.car, detail, vehicle_rng, local=True))
            templates[traversal.name] = soup.to_model()
    world = World(layout, static, categories, templates)
    return SceneBuild(scene_name(seed, index), seed, index, preset, world, traversals, moving, sparse_rng)


def render_frames(
    build: SceneBuild, progress: Callable[[int, int], None] | None = None, device: str | torch.device = "cpu"
) -> list[CapturedFrame]:
    """Ground truth for every drive, camera and timestep (sorted by frame name), rendered on ``device``."""
    p = build.preset
    frames: list[CapturedFrame] = []
    total = len(build.traversals) * p.timesteps * len(RIG)
    for traversal in build.traversals:
        vehicle = None
        if traversal.name in build.moving:
            vehicle = (build.world.vehicles[traversal.name], build.moving[traversal.name])
        for frame in capture_drive(
            build.world.static,
            traversal,
            RIG,
            p.width,
            p.height,
            vehicle=vehicle,
            tile_size=p.tile_size,
            device=device,
        ):
            frames.append(frame)
            if progress is not None:
                progress(len(frames), total)
    return sorted(frames, key=lambda f: f.name)


def scene_description(build: SceneBuild, frames: list[CapturedFrame], num_points: int) -> dict[str, object]:
    """The ``scene.json`` object (docs/synthetic_format.md)."""
    p = build.preset
    fx, fy, cx, cy = intrinsics(p.width, p.height)
    layout: StreetLayout = build.world.layout
    return {
        **scene_header(FORMAT, build.name, build.seed, build.index, p.name),
        "width": p.width,
        "height": p.height,
        "units": "metres",
        "lane_width_m": layout.lane_width,
        "num_lanes": layout.num_lanes,
        "world_up": [0, 0, 1],
        "frame_rate_hz": FRAME_RATE_HZ,
        "holdout_every": p.holdout_every,
        "traversals": [
            {"name": t.name, "kind": t.kind, "lane_offset": t.lane_offset} for t in build.traversals
        ],
        "cameras": [
            {"name": spec.name, "yaw_deg": spec.yaw_deg, "fx": fx, "fy": fy, "cx": cx, "cy": cy}
            for spec in RIG
        ],
        "frames": [
            {
                "name": f.name,
                "traversal": f.traversal,
                "camera": f.sensor,
                "index": f.index,
                "timestamp_us": f.timestamp_us,
                "split": "train"
                if is_training_frame(f.traversal, f.sensor, f.index, p.holdout_every)
                else "test",
                "has_dynamic": f.has_dynamic,
            }
            for f in frames
        ],
        "dynamic_objects": len(build.moving),
        "num_points3d": num_points,
    }


def write_scene(build: SceneBuild, frames: list[CapturedFrame], destination: Path) -> None:
    """Write every file of the scene into ``destination`` (an empty folder)."""
    p = build.preset
    for frame in frames:
        write_png(destination / "images" / frame.name, frame.rgb)
        mask = np.where(frame.static_mask, 255, 0).astype(np.uint8)
        write_png(destination / "dynamic_masks" / (Path(frame.name).stem + ".png"), mask)
    train = [f for f in frames if is_training_frame(f.traversal, f.sensor, f.index, p.holdout_every)]
    static = build.world.static
    eligible = torch.zeros(len(static), dtype=torch.bool)
    for category in SFM_CATEGORIES:
        eligible |= build.world.categories == category
    points = sample_sparse_points(static, eligible, train, p.points3d, build.sparse_rng)
    order = {spec.name: i for i, spec in enumerate(RIG)}
    images = [
        ColmapImage(f.name, f.sensor, f.camera)
        for f in sorted(frames, key=lambda f: (order[f.sensor], f.name))
    ]
    write_colmap_model(destination / "sparse" / "0", images, points.xyz, points.rgb)
    train_names = sorted(f.name for f in train)
    test_names = sorted(f.name for f in frames if f.name not in set(train_names))
    write_text_atomic(destination / "train_set.txt", "".join(n + "\n" for n in train_names))
    write_text_atomic(destination / "test_set.txt", "".join(n + "\n" for n in test_names))
    description = scene_description(build, frames, int(points.xyz.shape[0]))
    write_text_atomic(destination / "scene.json", json.dumps(description, indent=1, sort_keys=True) + "\n")


#: How a driving scene is made (:class:`~setdiff_bench.synthetic.staging.SceneRecipe`).
RECIPE = SceneRecipe(scene_name, build_scene, render_frames, write_scene)

#: ``generate_scene(out_root, preset, seed, index, *, overwrite, progress, device) -> scene folder``: scene
#: ``index`` of ``seed`` under ``out_root``, a complete scene (its ``scene.json`` present) kept unless
#: ``overwrite`` (:meth:`~setdiff_bench.synthetic.staging.SceneRecipe.make`).
generate_scene = RECIPE.make
