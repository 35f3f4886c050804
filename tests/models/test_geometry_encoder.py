"""Ψ's structure and its input (C-map + Plücker rays)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from setdiff_bench.models.setdiff.geometry_encoder import GeometryEncoder, geometry_input
from tests.models.setdiff_fixtures import look_camera


def test_structure_and_zero_init() -> None:
    encoder = GeometryEncoder((8, 16, 16, 32, 32), out_channels=4, downsample=8, groups=8)
    blocks = list(encoder.blocks)
    assert len(blocks) == 5
    for block in blocks:
        assert [type(m) for m in block] == [nn.Conv2d, nn.GroupNorm, nn.SiLU]
    assert [block[0].stride for block in blocks] == [(1, 1), (2, 2), (2, 2), (2, 2), (1, 1)]
    geometry = torch.randn(3, 9, 64, 96)
    out = encoder(geometry)
    assert out.shape == (3, 4, 8, 12)
    assert torch.count_nonzero(out) == 0
    nn.init.normal_(encoder.out.weight)
    assert torch.count_nonzero(encoder(geometry)) > 0


def test_rejects_wrong_channel_count() -> None:
    with pytest.raises(ValueError, match="9"):
        GeometryEncoder((8, 8, 8, 8, 8))(torch.randn(1, 6, 16, 16))


def test_geometry_input_channels() -> None:
    """C-map channels first (clamped), then the Plücker moment o × d and the unit direction d."""
    height, width = 8, 8
    camera = look_camera(0.0, 2.0, height, width)  # at (2, 0, 0), looking down +z
    cmaps = torch.full((1, 3, height, width), 30.0)
    out = geometry_input(cmaps, [camera], cmap_clip=10.0)
    assert out.shape == (1, 9, height, width)
    assert torch.all(out[0, :3] == 10.0)
    # pixel (row 3, col 3) has its centre at (3.5, 3.5); cx = cy = 4, f = 6.4
    d = np.array([(3.5 - 4) / 6.4, (3.5 - 4) / 6.4, 1.0])
    d /= np.linalg.norm(d)
    moment = np.cross([2.0, 0.0, 0.0], d)
    np.testing.assert_allclose(out[0, 6:, 3, 3].numpy(), d, atol=1e-6)
    np.testing.assert_allclose(out[0, 3:6, 3, 3].numpy(), moment, atol=1e-6)


def test_no_clip_when_zero() -> None:
    camera = look_camera(0.0, 0.0, 8, 8)
    out = geometry_input(torch.full((1, 3, 8, 8), 30.0), [camera], cmap_clip=0.0)
    assert torch.all(out[0, :3] == 30.0)
