"""Shared fixtures: one small generated scene per test session (the tiny preset, fewer timesteps)."""

from __future__ import annotations

import pytest

from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.synthetic.generate import generate_scene
from tests.synthetic.synthetic_fixtures import SEED, small_preset


@pytest.fixture(scope="session")
def scene_dir(tmp_path_factory):
    with torch_threads(1):
        return generate_scene(tmp_path_factory.mktemp("synthetic"), small_preset(), SEED, 0)
