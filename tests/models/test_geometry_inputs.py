"""The geometry-grounding ablation switch: a cue left out of ``geometry_inputs`` carries no information."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.intrinsics import intrinsics_matrix
from setdiff_bench.models.setdiff.config import ModelConfig
from setdiff_bench.models.setdiff.geometry_encoder import geometry_input
from setdiff_bench.rotations import look_at


def cameras(offset: float) -> list[Camera]:
    return [
        Camera(intrinsics_matrix(20, 20, 8, 8), look_at([offset + i, 0, 0], [i, 10, 0]), 16, 16)
        for i in range(2)
    ]


def test_cmap_only_ignores_poses_and_pose_only_ignores_cmaps() -> None:
    cmaps_a, cmaps_b = torch.rand(2, 3, 16, 16), torch.rand(2, 3, 16, 16)
    cmap_only = [geometry_input(cmaps_a, cameras(o), inputs=("cmap",)) for o in (0.0, 3.0)]
    assert torch.equal(cmap_only[0], cmap_only[1])
    assert torch.equal(cmap_only[0][:, :3], cmaps_a) and torch.count_nonzero(cmap_only[0][:, 3:]) == 0
    pose_only = [geometry_input(c, cameras(0.0), inputs=("plucker",)) for c in (cmaps_a, cmaps_b)]
    assert torch.equal(pose_only[0], pose_only[1])
    assert torch.count_nonzero(pose_only[0][:, :3]) == 0
    both = geometry_input(cmaps_a, cameras(0.0))
    assert torch.equal(both[:, :3], cmaps_a) and torch.equal(both[:, 3:], pose_only[0][:, 3:])


def test_geometry_inputs_validated_and_part_of_the_architecture() -> None:
    with pytest.raises(UsageError, match="geometry_inputs"):
        ModelConfig(geometry_inputs=("depth",))
    with pytest.raises(UsageError, match="geometry_inputs"):
        ModelConfig(geometry_inputs=())
    a = ModelConfig(geometry_inputs=("cmap",)).architecture()
    b = ModelConfig().architecture()
    assert a["geometry_inputs"] == ["cmap"] and b["geometry_inputs"] == ["cmap", "plucker"]
    assert np.array_equal(np.array(a["geometry_channels"]), np.array(b["geometry_channels"]))
