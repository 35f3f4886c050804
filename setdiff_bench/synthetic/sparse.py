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
"""

from __future__ import annotations

import json
import math
import os
import shutil
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.cameras import Camera, intrinsics_matrix, look_at
from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.fit import FitConfig
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.atomic import staged_folder, write_text_atomic
from setdiff_bench.io.images import write_png
from setdiff_bench.protocols.rules import sparse_view_indices
from setdiff_bench.synthetic import textures as tx
from setdiff_bench.synthetic.capture import CapturedFrame, concat_models, expected_depth
from setdiff_bench.synthetic.colmap_writer import ColmapImage, write_colmap_model
from setdiff_bench.synthetic.layout import StreetLayout, random_car, random_layout, random_style
from setdiff_bench.synthetic.rig import intrinsics
from setdiff_bench.synthetic.sfm import sample_sparse_points
from setdiff_bench.synthetic.soup import GaussianSoup
from setdiff_bench.synthetic.world import FACADE_DETAIL, SFM_CATEGORIES, Detail, build_static, car_soup

FORMAT = "setdiff-synthetic-sparse/1"
IMAGES_DIR = "images_4"
FULL_SCALE = 4
"""The COLMAP camera is written at ``FULL_SCALE`` × the image size, as DL3DV's model refers to the
full-resolution frames and ``images_4`` holds them downscaled 4×; the loader rescales K exactly."""
STREAM_TAG = 37
OBJECT_CATEGORY = 2  # world.CATEGORIES index of "object"


@dataclass(frozen=True)
class SparsePreset:
    """Generation parameters of the sparse-view scene kind.

    Attributes:
        name: preset key (``sparse_tiny``, ``sparse``, ``sparse_large``).
        num_scenes: scenes generated per ``synth`` call.
        width, height: image size in pixels (16:9, as DL3DV's 960×540 ``images_4``).
        frames: frames per capture (N of the 3DGS-Enhancer rule).
        hfov_deg: horizontal field of view (degrees).
        radius_m: the walk's radius around the plaza centre (metres; :func:`random_walk`).
        arc_deg: how far around the centre the walk goes (degrees, ±10 % per scene).
        sweep_period: frames per full left-right-left heading sweep.
        outward, strafe_m: path variants measured for the reference ceiling and not used by the presets
            (docs): look away from the centre; or walk ``strafe_m`` metres straight along one curb
            looking across the street.
        street_trees: keep the street's trees (module docstring).
        sweep_deg: range of the heading sweep's amplitude (degrees).
        pitch_deg: mean pitch (degrees; ±5° over 0.8 ``sweep_period``).
        plaza_objects: cars, kiosks and planted trees placed in the roadway.
        pixels_per_gaussian, min_spacing, max_spacing, foliage_count: world level of detail (``world.Detail``).
        points3d: SfM-like points in ``points3D.bin`` (sampled on all frames, as SfM of the whole video).
        tile_size: rasteriser tile size for the ground truth.
        views: the view counts fitted by ``synth`` (``fits/n{k}.ply``).
        gaps: the 3DGS-Enhancer gap rule's gaps (``protocols/dl3dv.toml``).
        fit: the 3DGS fit configuration of each sparse fit.
    """

    name: str
    num_scenes: int
    width: int
    height: int
    frames: int
    hfov_deg: float
    radius_m: float
    arc_deg: float
    sweep_period: float
    plaza_objects: int
    pixels_per_gaussian: float
    min_spacing: float
    max_spacing: float
    foliage_count: int
    points3d: int
    tile_size: int
    outward: bool = False
    street_trees: bool = False
    strafe_m: float = 0.0
    sweep_deg: tuple[float, float] = (10.0, 18.0)
    pitch_deg: float = -8.0
    views: tuple[int, ...] = (3, 6, 9)
    gaps: tuple[int, ...] = (50, 25)
    fit: FitConfig = field(default_factory=FitConfig)


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
        pixels_per_gaussian=5.0,
        min_spacing=0.7,
        max_spacing=4.0,
        foliage_count=12,
        points3d=1500,
        tile_size=8,
        fit=FitConfig.schedule(
            iterations=40, densify_every=10, opacity_reset_every=10_000, background_points=300, tile_size=8
        ),
    ),
    "sparse": SparsePreset(
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
        fit=FitConfig.schedule(
            iterations=250,
            densify_every=20,
            opacity_reset_every=10_000,
            max_gaussians=16_000,
            background_points=3000,
            tile_size=8,
        ),
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
        pixels_per_gaussian=3.0,
        min_spacing=0.12,
        max_spacing=3.0,
        foliage_count=200,
        points3d=30000,
        tile_size=16,
        fit=FitConfig.schedule(iterations=7000, densify_every=100, background_points=10_000, tile_size=16),
    ),
}


def get_sparse_preset(name: str) -> SparsePreset:
    """The sparse preset called ``name``; :class:`UsageError` listing the choices otherwise."""
    if name not in SPARSE_PRESETS:
        raise UsageError(
            f"unknown sparse preset {name!r}; choose one of {', '.join(SPARSE_PRESETS)}", "--preset"
        )
    return SPARSE_PRESETS[name]


def sparse_scene_name(seed: int, index: int) -> str:
    """``sparse_{seed:04d}_{index:02d}`` (DL3DV names scenes by a hash; the loader takes any folder name)."""
    return f"sparse_{seed:04d}_{index:02d}"


def frame_file(index: int) -> str:
    """DL3DV's frame name, 1-based: ``frame_00001.png``."""
    return f"frame_{index + 1:05d}.png"


# ---------------------------------------------------------------------- the walk
@dataclass(frozen=True)
class Walk:
    """The handheld path, one row per frame.

    Attributes:
        positions: ``(N, 3)`` camera centres (metres, world frame, z up).
        headings: ``(N,)`` yaw about +z (radians, 0 = along +x).
        pitches: ``(N,)`` radians (negative = looking down).
        center: ``(2,)`` the plaza centre the walk goes around (x, y metres).
    """

    positions: np.ndarray
    headings: np.ndarray
    pitches: np.ndarray
    center: np.ndarray


def random_walk(preset: SparsePreset, layout: StreetLayout, rng: np.random.Generator) -> Walk:
    """A walk around the plaza's centre ``(0, road middle)`` looking inwards (module docstring).

    The path is an arc of ``arc_deg`` (±10 %) of an ellipse with semi-axes ``radius_m`` × 1.1-1.5 along
    the street and ``radius_m`` × 0.85-1 across it (at most the roadway's half width − 1 m), at an uneven
    pace and a radius that breathes by ±8 %; the heading points at the centre (away from it with
    ``outward``), swept by ``sweep_deg`` over ``sweep_period`` frames, with handheld shake (±1.5° and 0.3°
    noise); height 1.55 ± 0.2 m (+1 cm noise), pitch ``pitch_deg`` ± 5°.  With ``strafe_m`` > 0 the walk
    instead goes ``strafe_m`` metres straight along one side of the roadway, looking across it.
    """
    n = preset.frames
    i = np.arange(n, dtype=np.float64)
    s = i / max(n - 1, 1)
    center = np.array([0.0, 0.5 * (layout.road_right + layout.road_left)])
    half_road = 0.5 * (layout.road_left - layout.road_right)
    ry = min(preset.radius_m * rng.uniform(0.85, 1.0), half_road - 1.0)
    rx = preset.radius_m * rng.uniform(1.1, 1.5)
    direction = float(rng.choice([-1.0, 1.0]))
    arc = math.radians(preset.arc_deg * rng.uniform(0.9, 1.1))
    pace = s + 0.03 * np.sin(2 * math.pi * s * rng.uniform(1.0, 2.0) + rng.uniform(0, 2 * math.pi))
    angle = rng.uniform(0, 2 * math.pi) + direction * arc * pace
    breathe = 1.0 + 0.08 * np.sin(2 * math.pi * s * rng.uniform(0.7, 1.5) + rng.uniform(0, 2 * math.pi))
    x = center[0] + rx * breathe * np.cos(angle)
    y = center[1] + ry * breathe * np.sin(angle)
    look = np.arctan2(center[1] - y, center[0] - x) + (math.pi if preset.outward else 0.0)
    if preset.strafe_m > 0:
        side = float(rng.choice([-1.0, 1.0]))  # +1: walk along the right curb looking left (+y)
        x = center[0] + direction * preset.strafe_m * (pace - 0.5)
        edge = layout.road_right + 1.2 if side > 0 else layout.road_left - 1.2
        y = edge + side * 0.6 * (breathe - 1.0) / 0.08
        look = np.full(n, side * math.pi / 2)
    period = preset.sweep_period * rng.uniform(0.9, 1.1)
    sweep = math.radians(rng.uniform(*preset.sweep_deg)) * np.sin(
        2 * math.pi * i / period + rng.uniform(0, 2 * math.pi)
    )
    shake = math.radians(1.5) * np.sin(2 * math.pi * i / (0.23 * period) + rng.uniform(0, 2 * math.pi))
    heading = look + sweep + shake + math.radians(0.3) * rng.standard_normal(n)
    height = 1.55 + 0.2 * np.sin(2 * math.pi * i / (1.3 * period) + rng.uniform(0, 2 * math.pi))
    height = height + 0.01 * rng.standard_normal(n)
    pitch = np.radians(
        preset.pitch_deg + 5.0 * np.sin(2 * math.pi * i / (0.8 * period) + rng.uniform(0, 2 * math.pi))
    )
    pitch = pitch + math.radians(0.3) * rng.standard_normal(n)
    return Walk(np.stack([x, y, height], axis=1), heading, pitch, center)


def walk_camera(walk: Walk, index: int, preset: SparsePreset) -> Camera:
    """The pinhole camera of frame ``index`` at the preset's image size (OpenCV axes, world-to-camera)."""
    center = walk.positions[index]
    yaw, pitch = float(walk.headings[index]), float(walk.pitches[index])
    direction = np.array([math.cos(yaw) * math.cos(pitch), math.sin(yaw) * math.cos(pitch), math.sin(pitch)])
    fx, fy, cx, cy = intrinsics(preset.width, preset.height, preset.hfov_deg)
    return Camera(
        intrinsics_matrix(fx, fy, cx, cy),
        look_at(center, center + direction),
        preset.width,
        preset.height,
        source=frame_file(index),
    )


# ---------------------------------------------------------------------- the plaza
def _clear_of(points: np.ndarray, x: float, y: float, radius: float) -> bool:
    return bool(np.min(np.hypot(points[:, 0] - x, points[:, 1] - y)) >= radius)


def plaza_objects(
    preset: SparsePreset, layout: StreetLayout, walk: Walk, detail: Detail, rng: np.random.Generator
) -> GaussianSoup:
    """``preset.plaza_objects`` draws of a car at any angle (45 %), a façade-textured kiosk (30 %) or a stone
    block / planter (25 %) in the roadway around the walk, each at least 4 / 3 / 2 m from every camera
    position and 3.5 m from the others (a draw that finds no place in 60 tries is skipped)."""
    soup = GaussianSoup()
    placed: list[tuple[float, float]] = []
    reach = float(np.abs(walk.positions[:, 0] - walk.center[0]).max()) + 5.0
    lo_x, hi_x = walk.center[0] - reach, walk.center[0] + reach
    lo_y, hi_y = layout.road_right + 1.0, layout.road_left - 1.0
    for _ in range(preset.plaza_objects):
        kind = str(rng.choice(["car", "kiosk", "block"], p=[0.45, 0.3, 0.25]))
        clearance = {"car": 4.0, "kiosk": 3.0, "block": 2.0}[kind]
        for _attempt in range(60):
            x, y = float(rng.uniform(lo_x, hi_x)), float(rng.uniform(lo_y, hi_y))
            if _clear_of(walk.positions, x, y, clearance) and all(
                math.hypot(x - px, y - py) >= 3.5 for px, py in placed
            ):
                break
        else:
            continue
        placed.append((x, y))
        yaw = float(rng.uniform(-math.pi, math.pi))
        if kind == "car":
            soup.extend(car_soup(random_car(rng, x, y, yaw), detail, rng))
        elif kind == "kiosk":
            length, width, height = (
                float(rng.uniform(1.8, 3.2)),
                float(rng.uniform(1.4, 2.2)),
                float(rng.uniform(2.3, 3.0)),
            )
            style = random_style(rng, length)
            spacing = detail.spacing(np.array([x, y, 1.2]), FACADE_DETAIL)
            side = tx.facade_texture(rng, style, length, height)
            soup.add_box(
                np.array([x, y, 0.0]),
                (length, width, height),
                yaw,
                spacing,
                {"side": side, "front": tx.noisy_color(rng, style.wall, 0.08), "top": tx.solid(style.trim)},
            )
        else:  # a planter or a stone block: a low box with a textured top
            size = (float(rng.uniform(1.0, 2.2)), float(rng.uniform(0.8, 1.4)), float(rng.uniform(0.45, 0.9)))
            stone = tx.noisy_color(rng, (0.55, 0.53, 0.5), 0.1, 0.4)
            top = tx.noisy_color(rng, (0.3, 0.22, 0.15), 0.15, 0.2) if rng.random() < 0.6 else stone
            soup.add_box(
                np.array([x, y, 0.0]),
                size,
                yaw,
                min(detail.spacing(np.array([x, y, 0.3])), 0.2),
                {"side": stone, "top": top},
            )
    return soup


# ---------------------------------------------------------------------- a scene in memory
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


def fit_views(preset: SparsePreset) -> dict[str, list[str]]:
    """``{"n3": [frame names], …}``: the views the 3DGS-Enhancer rule fits at each of ``preset.views``."""
    return {
        f"n{k}": [frame_file(i) for i in sparse_view_indices(preset.frames, k, preset.gaps)]
        for k in preset.views
    }


def sparse_description(build: SparseBuild, num_points: int) -> dict[str, object]:
    """The ``scene.json`` object (docs/synthetic_format.md, "Sparse-view scenes")."""
    p = build.preset
    fx, fy, cx, cy = intrinsics(p.width, p.height, p.hfov_deg)
    return {
        "format": FORMAT,
        "scene": build.name,
        "seed": build.seed,
        "index": build.index,
        "preset": p.name,
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


def write_sparse_scene(build: SparseBuild, frames: Sequence[CapturedFrame], destination: Path) -> None:
    """Write the DL3DV layout of the scene into ``destination`` (an empty folder)."""
    p = build.preset
    for frame in frames:
        write_png(destination / IMAGES_DIR / frame.name, frame.rgb)
    eligible = torch.zeros(len(build.static), dtype=torch.bool)
    for category in SFM_CATEGORIES:
        eligible |= build.categories == category
    points = sample_sparse_points(build.static, eligible, list(frames), p.points3d, build.sparse_rng)
    images = [
        ColmapImage(f.name, "camera", f.camera.resized(p.width * FULL_SCALE, p.height * FULL_SCALE))
        for f in frames
    ]
    write_colmap_model(
        destination / "colmap" / "sparse" / "0", images, points.xyz, points.rgb, camera_model="OPENCV"
    )
    description = sparse_description(build, int(points.xyz.shape[0]))
    write_text_atomic(destination / "scene.json", json.dumps(description, indent=1, sort_keys=True) + "\n")


def generate_sparse_scene(
    out_root: str | os.PathLike[str],
    preset: SparsePreset,
    seed: int,
    index: int,
    *,
    overwrite: bool = False,
    progress: Callable[[int, int], None] | None = None,
    device: str | torch.device = "cpu",
) -> Path:
    """Generate sparse-view scene ``index`` of ``seed`` under ``out_root``; returns its folder.

    A complete existing scene (its ``scene.json`` present, same preset) is kept unless ``overwrite``;
    the scene is written in a staging folder and renamed into place when complete.
    """
    root = Path(out_root)
    final = root / sparse_scene_name(seed, index)
    if (final / "scene.json").is_file() and not overwrite:
        try:
            existing = json.loads((final / "scene.json").read_text(encoding="utf-8")).get("preset")
        except (OSError, json.JSONDecodeError, AttributeError):
            existing = None
        if existing != preset.name:
            raise UsageError(
                f"scene exists with preset {existing!r}, not {preset.name!r}; pass --overwrite to regenerate it",
                final / "scene.json",
            )
        return final
    root.mkdir(parents=True, exist_ok=True)
    build = build_sparse_scene(preset, seed, index)
    frames = render_sparse_frames(build, progress, device)
    with staged_folder(final) as staging:
        write_sparse_scene(build, frames, staging)
    return final


def fit_sparse_scene(
    scene_dir: Path,
    preset: SparsePreset,
    *,
    device: str = "cpu",
    overwrite: bool = False,
    report: Callable[[str, int, int], None] | None = None,
) -> list[str]:
    """Fit ``fits/n{k}.ply`` for every ``k`` of ``preset.views`` on the 3DGS-Enhancer rule's views (the
    scene read through the DL3DV loader, cameras pinhole as the protocol says); returns one summary
    line per fit.  ``report(fit_key, iteration, iterations)`` receives progress."""
    from setdiff_bench.gaussians.fit import fit_scene

    lines = []
    iterations = preset.fit.iterations
    every = max(1, iterations // 100)
    for key, names in fit_views(preset).items():
        ply = scene_dir / "fits" / f"{key}.ply"
        if ply.is_file() and not overwrite:
            lines.append(f"{key} already present")
            continue
        checkpoint = ply.with_suffix(".checkpoint")
        if overwrite:
            shutil.rmtree(checkpoint, ignore_errors=True)

        def fitted(iteration: int, loss: float, key: str = key) -> None:
            del loss
            if report is not None and (iteration % every == 0 or iteration == iterations):
                report(key, iteration, iterations)

        t0 = time.perf_counter()
        result = fit_scene(
            scene_dir.parent,
            ply,
            preset.fit,
            frames=names,
            device=device,
            checkpoint_dir=checkpoint,
            checkpoint_every=max(1, iterations // 5),
            progress=False,
            dataset="dl3dv",
            scene_name=scene_dir.name,
            loader_options={"distortion": "ignore"},
            on_iteration=fitted,
        )
        shutil.rmtree(checkpoint, ignore_errors=True)
        lines.append(f"{key}: {len(result.model)} Gaussians in {time.perf_counter() - t0:.1f} s")
    return lines


def static_world(scene_dir: Path) -> GaussianModel:
    """The static world of a synthetic scene of either kind, rebuilt from its ``scene.json``."""
    description = json.loads((Path(scene_dir) / "scene.json").read_text(encoding="utf-8"))
    seed, index = int(description["seed"]), int(description["index"])
    if description.get("format") == FORMAT:
        return build_sparse_scene(get_sparse_preset(description["preset"]), seed, index).static
    from setdiff_bench.synthetic.generate import build_scene
    from setdiff_bench.synthetic.presets import get_preset

    return build_scene(get_preset(description["preset"]), seed, index).world.static
