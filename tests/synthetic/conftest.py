"""Shared fixtures: one small generated scene per test session (the tiny preset, fewer timesteps)."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from synthetic_fixtures import SEED, single_thread, small_preset

from setdiff_bench.synthetic.generate import generate_scene


@pytest.fixture(autouse=True)
def _one_thread() -> Iterator[None]:
    with single_thread():
        yield


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory):
    with single_thread():
        return generate_scene(tmp_path_factory.mktemp("synthetic"), small_preset(), SEED, 0)
