"""``build_static``: the street world's Gaussians assembled from its surfaces (the package's docstring says how)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.synthetic.layout import StreetLayout
from setdiff_bench.synthetic.soup import GaussianSoup
from setdiff_bench.synthetic.world._buildings import facade_soup
from setdiff_bench.synthetic.world._detail import Detail
from setdiff_bench.synthetic.world._ground import ground_soup
from setdiff_bench.synthetic.world._objects import foliage_soup, street_object_soup
from setdiff_bench.synthetic.world._sky import far_background_soup, sky_soup

CATEGORIES = ("ground", "facade", "object", "foliage", "far", "sky")
"""Category names; ``World.categories`` holds indices into this tuple."""
SFM_CATEGORIES = (0, 1, 2, 3)
"""Categories whose surfaces may appear in the sparse SfM-like point cloud."""


@dataclass
class World:
    """A scene's Gaussians.

    Attributes:
        layout: the street plan.
        static: the static Gaussians (world frame).
        categories: ``(N,)`` int64 index into :data:`CATEGORIES` per static Gaussian.
        vehicles: templates of moving vehicles in their own frame (x forward, y left, z up, origin at the
            centre of the footprint on the ground), one per traversal that has one.
    """

    layout: StreetLayout
    static: GaussianModel
    categories: torch.Tensor
    vehicles: dict[str, GaussianModel]


def build_static(
    layout: StreetLayout, detail: Detail, rng: np.random.Generator
) -> tuple[GaussianModel, torch.Tensor]:
    """All static Gaussians of ``layout`` → ``(model, categories (N,))``."""
    parts: list[tuple[int, GaussianSoup]] = [
        (0, ground_soup(layout, detail, rng)),
        (1, facade_soup(layout, detail, rng)),
        (2, street_object_soup(layout, detail, rng)),
        (3, foliage_soup(layout, detail, rng)),
        (4, far_background_soup(layout, detail, rng)),
        (5, sky_soup(layout, rng)),
    ]
    soup = GaussianSoup()
    categories = []
    for category, part in parts:
        soup.extend(part)
        categories.append(np.full(len(part), category, np.int64))
    return soup.to_model(), torch.from_numpy(np.concatenate(categories))
