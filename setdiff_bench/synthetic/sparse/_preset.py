"""The generation parameters of a sparse-view scene (:class:`SparsePreset`); the named presets are
``SPARSE_PRESETS`` in :mod:`setdiff_bench.synthetic.sparse._sparse`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from setdiff_bench.gaussians.fit import FitConfig


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
        init: the fits' initial points (:func:`setdiff_bench.gaussians.fit.initial_points`):
            ``"sparse"``, the scene's ``points3D`` (whole-video points: geometry and colour the n fit views
            never saw), or ``"random"``, the fit's own random points (what 3DGS-Enhancer's n-view fits
            start from, docs/sparse_benchmark.md).
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
    init: str = "sparse"
