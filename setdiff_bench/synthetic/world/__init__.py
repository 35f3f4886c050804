"""The procedural street world as 3D Gaussians: a :class:`StreetLayout` turned into a static
:class:`GaussianModel` plus vehicle templates that move per timestamp.

Level of detail: surfaces are tiled with a grid whose spacing grows with the distance to the stretch
of street the cameras drive along (``Detail``), so a ~100 m street stays at a few tens of thousands of
Gaussians while keeping roughly ``pixels_per_gaussian`` pixels between neighbouring disk centres at
the benchmark focal length.  Every Gaussian carries a category (ground, façade, object, foliage,
vehicle, far background, sky) so that the SfM-like point sampler can skip what SfM never triangulates.

The surfaces are built by concept: ``_ground`` (road, parking, curbs, sidewalks),
``_buildings`` (façades), ``_objects`` (cars, poles, trees, foliage) and ``_sky``
(far background and sky dome), each tiled with the ``_detail`` spacing.

The package's modules are private (``_world`` assembles; ``_ground``, ``_buildings``, ``_objects``, ``_sky``,
``_detail``); this face exports what other code uses.
"""

from __future__ import annotations

from setdiff_bench.synthetic.world._detail import FACADE_DETAIL, Detail
from setdiff_bench.synthetic.world._ground import road_texture
from setdiff_bench.synthetic.world._objects import car_soup
from setdiff_bench.synthetic.world._world import CATEGORIES, SFM_CATEGORIES, World, build_static

__all__ = [
    "CATEGORIES",
    "FACADE_DETAIL",
    "SFM_CATEGORIES",
    "Detail",
    "World",
    "build_static",
    "car_soup",
    "road_texture",
]
