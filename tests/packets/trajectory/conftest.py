"""Fixtures of the novel-trajectory tests (issue 41): one street scene of the synthetic layout with its fit,
packets at lane shifts of 3 m and 6 m (to the left, toward the scene's other lanes), and a random-weight
FID Inception-v3 saved in pytorch-fid's state-dict format."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.packets.prepare import prepare
from setdiff_bench.runtime.threads import torch_threads
from tests.metrics.inception_fixtures import random_inception, save_inception
from tests.packets.packet_fixtures import StreetScene, write_scene

#: The trajectories of the tests: 3 m and 6 m to the left of lane 0 (``shift`` is metres to the right).
SHIFTS = ("shift:-3", "shift:-6")
GROUPS = ("shift-3m", "shift-6m")


@pytest.fixture(scope="package")
def street(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, StreetScene]:
    """``(dataset root, scene)``: ``street_00`` with its fit at ``street_00/fits/lane0.ply``."""
    with torch_threads(1):
        root = tmp_path_factory.mktemp("street")
        return root, write_scene(root / "street_00", 11)


@pytest.fixture(scope="package")
def shifted_store(street: tuple[Path, StreetScene], tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The scene's lane-shift packets (``prepare --trajectory shift:-3 --trajectory shift:-6``)."""
    root, _ = street
    out = tmp_path_factory.mktemp("shifted") / "store"
    with torch_threads(1):
        prepare("synthetic", root, out, fits=root, progress=False, trajectories=SHIFTS)
    return out


@pytest.fixture(scope="package")
def inception_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A random-weight FID Inception-v3 in pytorch-fid's format (:mod:`tests.metrics.inception_fixtures`)."""
    return save_inception(random_inception(), tmp_path_factory.mktemp("inception"))
