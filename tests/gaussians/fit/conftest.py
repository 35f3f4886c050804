"""Fit fixtures: the tiny synthetic scene (generated once per session) and its training views."""

from __future__ import annotations

import pytest

from setdiff_bench.gaussians.fit import load_fit_scene, load_fit_views, select_fit_frames
from setdiff_bench.runtime.threads import torch_threads
from setdiff_bench.synthetic.generate import generate_scene
from setdiff_bench.synthetic.presets import get_preset


@pytest.fixture(scope="session")
def tiny_scene_dir(tmp_path_factory):
    with torch_threads(1):
        return generate_scene(tmp_path_factory.mktemp("fit"), get_preset("tiny"), 0, 0)


@pytest.fixture(scope="session")
def tiny_scene(tiny_scene_dir):
    return load_fit_scene(tiny_scene_dir)


@pytest.fixture(scope="session")
def tiny_views(tiny_scene):
    return load_fit_views(tiny_scene, select_fit_frames(tiny_scene, None))
