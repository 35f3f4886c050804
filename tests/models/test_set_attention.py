"""Restricted set attention (``view``, ``knn``) and the scale-free C-map bias, against hand-built references.

Every expected value here is computed by a naive loop over the attention definition (or by hand), not by
the functions under test.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
import torch
from diffusers.models.attention_processor import Attention, AttnProcessor2_0

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff import set_mixer
from setdiff_bench.models.setdiff.config import model_config_from_dict
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.inputs import ray_snapped_points, surface_points
from setdiff_bench.models.setdiff.set_mixer import (
    NO_MATCH_KEY,
    NO_MATCH_VALUE,
    RELATIVE_BIAS_CAP,
    SetSelfAttnProcessor,
    TokenGeometry,
    nearest_reference_keys,
    pool_token_geometry,
    relative_distance_bias,
    set_kwargs,
)
from tests.models.setdiff_fixtures import geometry_set, make_packet, residual_model


def attention_layer(width: int = 32, heads: int = 4) -> Attention:
    torch.manual_seed(0)
    return Attention(query_dim=width, heads=heads, dim_head=width // heads).eval()


def cell_points(xyz: list[list[tuple[float, float, float]]], valid: list[list[int]]) -> torch.Tensor:
    """``(V, 4, 1, L)`` latent-cell points of V views of L tokens in one row (the token grid is the cell grid)."""
    points = torch.tensor(xyz, dtype=torch.float32)  # (V, L, 3)
    ok = torch.tensor(valid, dtype=torch.float32)  # (V, L)
    return torch.cat([(points * ok[..., None]).permute(0, 2, 1), ok[:, None]], dim=1)[:, :, None]


def test_per_view_attention_is_each_views_own_attention() -> None:
    """``view``: each view's output is standard self-attention over its own tokens, so view 0 ignores view 2."""
    attn = attention_layer()
    tokens = torch.randn(3, 5, 32)
    processor = SetSelfAttnProcessor("view")
    with torch.no_grad():
        mixed = processor(attn, tokens, **set_kwargs(3))
        for view in range(3):
            alone = AttnProcessor2_0()(attn, tokens[view : view + 1])[0]
            torch.testing.assert_close(mixed[view], alone, atol=1e-6, rtol=1e-6)
        changed = tokens.clone()
        changed[2] = torch.randn(5, 32)
        again = processor(attn, changed, **set_kwargs(3))
    assert torch.equal(again[0], mixed[0]) and torch.equal(again[1], mixed[1])
    assert not torch.allclose(again[2], mixed[2])
    full = SetSelfAttnProcessor("full")(attn, changed, **set_kwargs(3))
    assert not torch.allclose(full[0], mixed[0])  # the full set does see view 2


# Two references of four tokens on the x axis (x = 0..3 and 10..13) and one target whose tokens sit at
# x = 0.4, 11.6, 2.9 and a fourth without a surface point.  With k = 2 the nearest reference tokens are, by
# hand (token index = view · 4 + position): 0.4 → 0 (0.4), 1 (0.6); 11.6 → 6 (0.4), 5 (0.6); 2.9 → 3 (0.1),
# 2 (0.9); the fourth none.  Reference tokens look only into the *other* reference: every token of view 0
# (x = 0..3) → 4 (x = 10), 5 (x = 11); every token of view 1 (x = 10..13) → 3 (x = 3), 2 (x = 2).
XYZ = [
    [(0.0, 0, 0), (1.0, 0, 0), (2.0, 0, 0), (3.0, 0, 0)],
    [(10.0, 0, 0), (11.0, 0, 0), (12.0, 0, 0), (13.0, 0, 0)],
    [(0.4, 0, 0), (11.6, 0, 0), (2.9, 0, 0), (50.0, 0, 0)],
]
VALID = [[1, 1, 1, 1], [1, 1, 1, 1], [1, 1, 1, 0]]
NEAREST_BY_HAND = {
    **{t: [4, 5] for t in range(4)},
    **{t: [3, 2] for t in range(4, 8)},
    8: [0, 1],
    9: [6, 5],
    10: [3, 2],
    11: [],
}


def test_nearest_reference_keys_by_hand() -> None:
    geometry = pool_token_geometry(cell_points(XYZ, VALID), 4).grouped(1)
    candidates = torch.arange(8)  # the references' tokens
    index, found = nearest_reference_keys(geometry, slice(8, 12), candidates, 2)
    for row, query in enumerate(range(8, 12)):
        assert index[0, row][found[0, row]].tolist() == NEAREST_BY_HAND[query], query
    own = torch.arange(4, 8)  # view 0's queries look into view 1 only
    index, found = nearest_reference_keys(geometry, slice(0, 4), own, 2)
    assert index[0].tolist() == [NEAREST_BY_HAND[t] for t in range(4)] and bool(found[0].all())


def naive_knn(attn: Attention, tokens: torch.Tensor, allowed: dict[int, list[int]]) -> torch.Tensor:
    """Each query token t of the flattened set attends to ``allowed[t]`` plus the no-match key: a loop over
    tokens and heads with the module's own projections."""
    heads = attn.heads
    flat = tokens.reshape(-1, tokens.shape[-1])
    q, k, v = attn.to_q(flat), attn.to_k(flat), attn.to_v(flat)
    d = q.shape[-1] // heads
    spare_k, spare_v = getattr(attn, NO_MATCH_KEY), getattr(attn, NO_MATCH_VALUE)
    out = torch.zeros_like(q)
    for t in range(flat.shape[0]):
        keys = allowed[t]
        for h in range(heads):
            part = slice(h * d, (h + 1) * d)
            logits = [float(q[t, part] @ k[j, part]) / math.sqrt(d) for j in keys]
            logits.append(float(q[t, part] @ spare_k[part]) / math.sqrt(d))
            weights = torch.softmax(torch.tensor(logits, dtype=torch.float64), 0)
            mixed = sum(float(w) * v[j, part].double() for w, j in zip(weights[:-1], keys, strict=True))
            out[t, part] = (mixed + float(weights[-1]) * spare_v[part].double()).float()
    return attn.to_out[1](attn.to_out[0](out)).reshape(tokens.shape[0], tokens.shape[1], -1)


@pytest.mark.parametrize("block_elements", [None, 1])
def test_knn_attends_exactly_own_view_nearest_references_and_no_match(
    monkeypatch: pytest.MonkeyPatch, block_elements: int | None
) -> None:
    """Also computed one query at a time (``block_elements`` 1): the blocks give the same result."""
    if block_elements is not None:
        monkeypatch.setattr(set_mixer, "BIAS_BLOCK_ELEMENTS", block_elements)
    attn = attention_layer()
    generator = torch.Generator().manual_seed(5)
    for name in (NO_MATCH_KEY, NO_MATCH_VALUE):
        attn.register_parameter(name, torch.nn.Parameter(torch.randn(32, generator=generator)))
    tokens = torch.randn(3, 4, 32, generator=generator)
    allowed = {t: list(range(t // 4 * 4, t // 4 * 4 + 4)) + NEAREST_BY_HAND[t] for t in range(12)}
    with torch.no_grad():
        mixed = SetSelfAttnProcessor("knn", neighbours=2)(
            attn, tokens, **set_kwargs(3, cell_points(XYZ, VALID), num_references=2)
        )
        expected = naive_knn(attn, tokens, allowed)
    torch.testing.assert_close(mixed, expected, atol=1e-5, rtol=1e-5)


def test_knn_without_points_is_own_view_and_no_match() -> None:
    """The CFG unconditional branch (no points): no neighbours, so view 0 is independent of the others."""
    attn = attention_layer()
    generator = torch.Generator().manual_seed(6)
    for name in (NO_MATCH_KEY, NO_MATCH_VALUE):
        attn.register_parameter(name, torch.nn.Parameter(torch.randn(32, generator=generator)))
    tokens = torch.randn(3, 4, 32, generator=generator)
    allowed = {t: list(range(t // 4 * 4, t // 4 * 4 + 4)) for t in range(12)}
    with torch.no_grad():
        mixed = SetSelfAttnProcessor("knn", neighbours=2)(attn, tokens, **set_kwargs(3, num_references=2))
        expected = naive_knn(attn, tokens, allowed)
    torch.testing.assert_close(mixed, expected, atol=1e-5, rtol=1e-5)
    with pytest.raises(RuntimeError, match="num_references"):
        SetSelfAttnProcessor("knn")(attn, tokens, **set_kwargs(3))


def test_knn_with_a_bias_and_no_references_is_own_view_and_no_match() -> None:
    """A set without references (the usage control "references removed") has no neighbour to fetch, also in
    a layer with a C-map bias: every token at the same point, so the bias is 0 and the own view is exact."""
    attn = attention_layer()
    generator = torch.Generator().manual_seed(7)
    for name in (NO_MATCH_KEY, NO_MATCH_VALUE):
        attn.register_parameter(name, torch.nn.Parameter(torch.randn(32, generator=generator)))
    attn.register_parameter(set_mixer.BIAS_PARAMETER, torch.nn.Parameter(torch.tensor(0.5)))
    tokens = torch.randn(3, 4, 32, generator=generator)
    points = cell_points([[(1.0, 2.0, 3.0)] * 4] * 3, [[1] * 4] * 3)
    allowed = {t: list(range(t // 4 * 4, t // 4 * 4 + 4)) for t in range(12)}
    with torch.no_grad():
        mixed = SetSelfAttnProcessor("knn", neighbours=2)(
            attn, tokens, **set_kwargs(3, points, num_references=0)
        )
        expected = naive_knn(attn, tokens, allowed)
    torch.testing.assert_close(mixed, expected, atol=1e-5, rtol=1e-5)


def test_relative_bias_by_hand() -> None:
    """Query at the origin with footprint 0.5; keys at x = 1 (r² = 4), x = 10 (r² = 400 → cap 64)."""
    geometry = TokenGeometry(
        points=torch.tensor([[[0.0, 0, 0], [1.0, 0, 0], [10.0, 0, 0], [1.0, 0, 0]]]),
        valid=torch.tensor([[True, True, True, False]]),
        coverage=torch.tensor([[1.0, 1.0, 1.0, 0.5]]),
        footprint=torch.tensor([[0.5, 0.5, 0.5, 0.5]]),
    )
    bias = relative_distance_bias(geometry, torch.tensor(0.25))[0, 0]
    assert bias[0, 1].item() == pytest.approx(-0.25 * 4.0)
    assert bias[0, 2].item() == pytest.approx(-0.25 * RELATIVE_BIAS_CAP)
    assert bias[0, 3].item() == pytest.approx(-0.25 * (0.5 * 4.0 + 0.5 * RELATIVE_BIAS_CAP))
    blind = replace(geometry, coverage=torch.tensor([[0.0, 1.0, 1.0, 1.0]]))
    row = relative_distance_bias(blind, torch.tensor(0.25))[0, 0, 0]
    assert torch.allclose(row, torch.full_like(row, -0.25 * RELATIVE_BIAS_CAP))  # no surface: no effect


def test_ray_snap_by_hand() -> None:
    """A 1×1 camera at the origin looking down +z (pixel centre on the axis): (0.3, −0.2, 2) snaps to (0, 0, 2),
    footprint 2 / f; a camera moved to (1, 0, 0) sees the point (1.3, 0, 4) at depth 4 → (1, 0, 4)."""
    K = np.array([[50.0, 0, 0.5], [0, 50.0, 0.5], [0, 0, 1]])
    at_origin = Camera(K=K, w2c=np.eye(4), width=1, height=1)
    moved = np.eye(4)
    moved[0, 3] = -1.0
    shifted = Camera(K=K, w2c=moved, width=1, height=1)
    points = torch.tensor([[0.3, -0.2, 2.0], [1.3, 0.0, 4.0]]).view(2, 3, 1, 1)
    snapped, footprint = ray_snapped_points(points, [at_origin, shifted])
    torch.testing.assert_close(snapped.flatten(1), torch.tensor([[0.0, 0.0, 2.0], [1.0, 0.0, 4.0]]))
    torch.testing.assert_close(footprint.flatten(), torch.tensor([2.0 / 50.0, 4.0 / 50.0]))


def scaled_packet(factor: float):
    packet = make_packet(2, 2, size=(32, 32), seed=4)
    for views in (packet.references, packet.targets):
        views.cmaps = views.cmaps.abs() + 1.0  # in front of every camera (cameras look down +z)
    if factor == 1.0:
        return packet

    def scale(views):
        cameras = []
        for camera in views.cameras:
            w2c = camera.w2c.copy()
            w2c[:3, 3] *= factor
            cameras.append(Camera(K=camera.K, w2c=w2c, width=camera.width, height=camera.height))
        return replace(views, cmaps=views.cmaps * factor, cameras=tuple(cameras))

    return replace(packet, references=scale(packet.references), targets=scale(packet.targets))


@pytest.mark.parametrize("tokens", [16, 4])
def test_relative_bias_is_scale_free(tokens: int) -> None:
    """Scaling the scene (C-map points and camera translations) by 10 leaves the relative bias unchanged
    (at the 16- and 4-token levels of a 32×32 image's 4×4 latent cells); the absolute one changes."""
    model = residual_model(attention_bias="cmap_relative", use_geometry=True)
    biases, absolute = [], []
    for factor in (1.0, 10.0):
        packet = scaled_packet(factor)
        cells = model.latent_points(surface_points(packet, snapped=True))
        geometry = pool_token_geometry(cells, tokens).grouped(1)
        biases.append(relative_distance_bias(geometry, torch.tensor(0.25)))
        absolute.append(torch.cdist(geometry.points, geometry.points))
    assert float(biases[0].std()) > 0.1  # not trivially constant
    torch.testing.assert_close(biases[1], biases[0], atol=1e-4, rtol=1e-5)
    torch.testing.assert_close(absolute[1], 10 * absolute[0], atol=0.05, rtol=1e-3)


def test_default_and_explicit_full_models_are_identical() -> None:
    """``set_attention = ["full", "full"]`` builds the default model: same parameters, same outputs bit for bit."""
    packet = make_packet(2, 2, size=(32, 32), seed=1)
    outputs, keys = [], []
    for extra in ({}, {"set_attention": ["full", "full"]}):
        model = residual_model(attention_bias="cmap_distance", **extra)
        with torch.no_grad():
            for parameter in model.unet.conv_out.parameters():
                parameter.normal_(0, 0.1, generator=torch.Generator().manual_seed(3))
        outputs.append(enhance_packet(model, packet))
        keys.append(sorted(model.state_dict()))
    assert keys[0] == keys[1]
    assert torch.equal(outputs[0], outputs[1])


@pytest.mark.parametrize("bias", ["none", "cmap_relative"])
def test_models_with_restricted_levels_run(bias: str) -> None:
    """A tiny model with ``knn`` at level 0 and ``view`` in the mid block enhances a packet with CFG; the
    ``knn`` layer holds the no-match parameters and the output depends on the references."""
    model = residual_model(set_attention=["knn", "view"], set_attention_neighbours=3, attention_bias=bias)
    names = [name for name, _ in model.unet.named_parameters() if NO_MATCH_KEY in name]
    assert names and all(".attn1." in name for name in names)
    with torch.no_grad():
        for parameter in model.unet.conv_out.parameters():
            parameter.normal_(0, 0.1, generator=torch.Generator().manual_seed(3))
    packet = make_packet(2, 2, size=(32, 32), seed=2)
    first = enhance_packet(model, packet, guidance_scale=1.5)
    other = replace(packet, references=replace(packet.references, images=1 - packet.references.images))
    assert first.shape == (2, 3, 32, 32) and torch.isfinite(first).all()
    assert not torch.equal(first, enhance_packet(model, other, guidance_scale=1.5))
    drawn = geometry_set(with_points=True, snapped_points=bias == "cmap_relative")
    model.train()
    model(drawn.batch).target_x0.square().mean().backward()  # trains: the no-match key gets a gradient
    assert all(p.grad is not None for n, p in model.unet.named_parameters() if NO_MATCH_VALUE in n)


def test_set_attention_config_errors() -> None:
    with pytest.raises(UsageError, match="set_attention entries"):
        model_config_from_dict({"preset": "tiny", "set_attention": ["nearest"]})
    with pytest.raises(UsageError, match="UNet has 2"):
        model_config_from_dict({"preset": "tiny", "set_attention": ["full", "full", "view"]})
    with pytest.raises(UsageError, match="needs C-maps"):
        model_config_from_dict({"preset": "tiny", "use_geometry": False, "set_attention": ["knn"]})
    with pytest.raises(UsageError, match="neighbours"):
        model_config_from_dict({"preset": "tiny", "set_attention_neighbours": 0})
    config = model_config_from_dict({"preset": "tiny", "set_attention": ["knn"]})
    assert config.needs_points and not config.snapped_points


def test_token_footprint_by_hand() -> None:
    """Pixel footprint 0.01 everywhere: a latent cell of 8×8 pixels spans 0.08, a token of 2×2 cells 0.16;
    half-covered tokens keep their valid cells' mean."""
    model = residual_model(attention_bias="cmap_relative")
    assert model.config.latent_factor == 8
    pixels = torch.zeros(1, 5, 32, 32)
    pixels[:, 3] = 1.0
    pixels[:, 4] = 0.01
    pixels[:, 3:, :, :16] = 0.0  # the left half has no surface
    pixels[:, :3, :, 16:] = torch.tensor([1.0, 2.0, 3.0]).view(3, 1, 1)
    geometry = pool_token_geometry(model.latent_points(pixels), 4)  # 4×4 cells → 2×2 tokens
    torch.testing.assert_close(geometry.coverage, torch.tensor([[0.0, 1.0, 0.0, 1.0]]))
    torch.testing.assert_close(geometry.footprint[0, [1, 3]], torch.tensor([0.16, 0.16]))
    torch.testing.assert_close(geometry.points[0, 1], torch.tensor([1.0, 2.0, 3.0]))
