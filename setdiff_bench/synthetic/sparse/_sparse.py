"""The named sparse presets and a scene's world rebuilt (the package's docstring describes the scene kind)."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.fit import FitConfig
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.synthetic.preset_tiers import CPU_FIT, LARGE_DETAIL, LARGE_FIT, TINY_DETAIL
from setdiff_bench.synthetic.sparse._build import (
    build_sparse_scene,
)
from setdiff_bench.synthetic.sparse._names import (
    FORMAT,
)
from setdiff_bench.synthetic.sparse._preset import SparsePreset

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
