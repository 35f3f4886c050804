"""Helpers shared by the synthetic tests (a uniquely named module: test folders are not packages)."""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Iterator

import torch

from setdiff_bench.synthetic.presets import Preset, get_preset

SEED = 7


def small_preset() -> Preset:
    """The tiny preset with 3 timesteps (36 frames): same code path, a third of the rendering."""
    return dataclasses.replace(get_preset("tiny"), timesteps=3, holdout_every=3)


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """One torch thread: the rasteriser runs many small ops, which OpenMP slows down badly on a busy machine."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
