"""Shared fixtures: one small generated scene per test session (the tiny preset, fewer timesteps)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from synthetic_fixtures import SEED, small_preset

from setdiff_bench.synthetic.generate import generate_scene
from setdiff_bench.threads import torch_threads


@pytest.fixture(autouse=True)
def _single_torch_thread() -> Iterator[None]:
    with torch_threads(1):
        yield


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory):
    with torch_threads(1):
        return generate_scene(tmp_path_factory.mktemp("synthetic"), small_preset(), SEED, 0)
