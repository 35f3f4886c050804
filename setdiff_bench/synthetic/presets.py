"""The synthetic benchmark's presets: scene count, resolution, drive length, world detail, fit schedule.

``tiny``     1 scene, 48×80, 6 timesteps: seconds, for tests.
``default``  6 scenes, 144×256, 16 timesteps (192 frames per scene), 250-iteration fits: generates and fits
             everything in under 10 minutes on 2 CPU cores with ``--jobs 2`` (benchmarks/results/fit_quality.md).
``large``    8 scenes, 288×512, 40 timesteps, 7000-iteration fits: for a GPU (``--device cuda``).

What a tier shares with the sparse-view kind's presets (world detail, fit schedule) is declared once in
:mod:`.preset_tiers`; the driving kind itself is declared in :mod:`.kinds`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.fit import FitConfig
from setdiff_bench.synthetic.preset_tiers import CPU_FIT, LARGE_DETAIL, LARGE_FIT, TINY_DETAIL


@dataclass(frozen=True)
class Preset:
    """Generation parameters.

    Attributes:
        name: preset key.
        num_scenes: scenes generated per ``synth`` call.
        width, height: image size in pixels (90° horizontal field of view).
        timesteps: frames per camera per drive (10 Hz).
        step_m: distance driven per timestep (metres; 1.0 m = 36 km/h).
        holdout_every: every ``holdout_every``-th ``lane0 front`` timestep (offset ``holdout_every // 2``)
            is held out of the fit as an interpolation test frame.
        view_ahead_m: street length beyond the end of the drives.
        pixels_per_gaussian, min_spacing, max_spacing: world level of detail (see ``world.Detail``).
        foliage_count: Gaussians per tree-crown blob.
        points3d: number of SfM-like sparse points written to ``points3D.bin``.
        moving_vehicles: give each drive an oncoming vehicle (dynamic masks).
        tile_size: rasteriser tile size for ground-truth rendering (torch backend).
        fit: the 3DGS fit configuration used by ``synth`` for ``fits/lane0.ply``.
    """

    name: str
    num_scenes: int
    width: int
    height: int
    timesteps: int
    step_m: float
    holdout_every: int
    view_ahead_m: float
    pixels_per_gaussian: float
    min_spacing: float
    max_spacing: float
    foliage_count: int
    points3d: int
    moving_vehicles: bool
    tile_size: int
    fit: FitConfig = field(default_factory=FitConfig)


PRESETS: dict[str, Preset] = {
    "tiny": Preset(
        name="tiny",
        num_scenes=1,
        width=80,
        height=48,
        timesteps=4,
        step_m=1.5,
        holdout_every=4,
        view_ahead_m=30.0,
        **TINY_DETAIL,
        moving_vehicles=True,
        tile_size=8,
        fit=FitConfig.schedule(
            iterations=60, densify_every=10, opacity_reset_every=10_000, background_points=500, tile_size=8
        ),
    ),
    "default": Preset(
        name="default",
        num_scenes=6,
        width=256,
        height=144,
        timesteps=16,
        step_m=1.0,
        holdout_every=4,
        view_ahead_m=55.0,
        pixels_per_gaussian=4.0,
        min_spacing=0.3,
        max_spacing=3.0,
        foliage_count=60,
        points3d=6000,
        moving_vehicles=True,
        tile_size=8,
        fit=CPU_FIT,
    ),
    "large": Preset(
        name="large",
        num_scenes=8,
        width=512,
        height=288,
        timesteps=40,
        step_m=1.0,
        holdout_every=4,
        view_ahead_m=70.0,
        **LARGE_DETAIL,
        moving_vehicles=True,
        tile_size=16,
        fit=LARGE_FIT,
    ),
}


def get_preset(name: str) -> Preset:
    """The preset called ``name``; :class:`UsageError` listing the choices otherwise."""
    if name not in PRESETS:
        raise UsageError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}", "--preset")
    return PRESETS[name]
