"""Helpers shared by the synthetic tests (a uniquely named module: test folders are not packages)."""

from __future__ import annotations

import dataclasses

from setdiff_bench.synthetic.presets import Preset, get_preset

SEED = 7


def small_preset() -> Preset:
    """The tiny preset with 3 timesteps (36 frames): same code path, a third of the rendering."""
    return dataclasses.replace(get_preset("tiny"), timesteps=3, holdout_every=3)
