"""SetDiff at large sizes: the blockwise C-map distance bias and the chunked encoder / Ψ / decoder give the
unblocked results, and no token × token tensor is ever allocated."""

from __future__ import annotations

import math
from typing import Any

import pytest
import torch
import torch.nn.functional as F
from torch.utils._python_dispatch import TorchDispatchMode

from setdiff_bench.models.setdiff import model as model_module
from setdiff_bench.models.setdiff import set_mixer
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.set_mixer import BIAS_DISTANCE_CAP, biased_attention
from tests.models.setdiff_fixtures import make_packet, residual_model


def explicit_attention(
    query: torch.Tensor,
    key: torch.Tensor,
    value: torch.Tensor,
    points: torch.Tensor,
    valid: torch.Tensor,
    scale: float,
) -> torch.Tensor:
    """softmax(QKᵀ/√d − s·min(d², cap))·V written out (the definition, with the whole T × T matrix)."""
    squared = ((points[:, :, None] - points[:, None]) ** 2).sum(-1).clamp(max=BIAS_DISTANCE_CAP)
    squared = torch.where(valid[:, :, None] & valid[:, None, :], squared, torch.tensor(BIAS_DISTANCE_CAP))
    logits = query @ key.transpose(-1, -2) / math.sqrt(query.shape[-1]) - scale * squared[:, None]
    return logits.softmax(-1) @ value


def attention_inputs(
    sets: int = 2, heads: int = 2, tokens: int = 37, dim: int = 8
) -> tuple[torch.Tensor, ...]:
    generator = torch.Generator().manual_seed(3)
    query, key, value = (torch.randn(sets, heads, tokens, dim, generator=generator) for _ in range(3))
    points = torch.randn(sets, tokens, 3, generator=generator)
    valid = torch.rand(sets, tokens, generator=generator) > 0.25
    return query, key, value, points, valid


@pytest.mark.parametrize(
    "block_elements", [1 << 24, 2 * 37 * 5, 1], ids=["one_block", "ragged", "row_by_row"]
)
def test_biased_attention_equals_the_definition(monkeypatch: pytest.MonkeyPatch, block_elements: int) -> None:
    """Blocks of 5 queries (the last one ragged: 37 = 7·5 + 2), one row at a time, or one block: all equal
    the attention written out with the full matrix."""
    monkeypatch.setattr(set_mixer, "BIAS_BLOCK_ELEMENTS", block_elements)
    query, key, value, points, valid = attention_inputs()
    output = biased_attention(query, key, value, points, valid, torch.tensor(1.7))
    expected = explicit_attention(query, key, value, points, valid, 1.7)
    torch.testing.assert_close(output, expected, atol=1e-5, rtol=1e-4)


def test_biased_attention_gradients_match_the_definition(monkeypatch: pytest.MonkeyPatch) -> None:
    """Training backpropagates through the blocks: gradients of Q, K, V and the bias strength equal those
    of the written-out attention."""
    monkeypatch.setattr(set_mixer, "BIAS_BLOCK_ELEMENTS", 2 * 37 * 4)
    inputs = attention_inputs()
    leaves = [x.clone().requires_grad_(True) for x in inputs[:3]]
    log_scale = torch.tensor(0.4, requires_grad=True)
    weights = torch.randn(inputs[0].shape, generator=torch.Generator().manual_seed(9))
    (biased_attention(*leaves, *inputs[3:], log_scale.exp()) * weights).sum().backward()
    blocked = [x.grad.clone() for x in leaves] + [log_scale.grad.clone()]
    for x in (*leaves, log_scale):
        x.grad = None
    (explicit_attention(*leaves, *inputs[3:], log_scale.exp()) * weights).sum().backward()
    for got, want in zip(blocked, [x.grad for x in leaves] + [log_scale.grad], strict=True):
        torch.testing.assert_close(got, want, atol=1e-5, rtol=1e-4)


class LargestAllocation(TorchDispatchMode):
    """Records the element count of the largest tensor any aten op returns."""

    def __init__(self) -> None:
        super().__init__()
        self.largest = 0

    def __torch_dispatch__(self, func: Any, types: Any, args: tuple = (), kwargs: dict | None = None) -> Any:
        out = func(*args, **(kwargs or {}))
        for item in out if isinstance(out, tuple | list) else (out,):
            if isinstance(item, torch.Tensor):
                self.largest = max(self.largest, item.numel())
        return out


def test_no_token_by_token_tensor(monkeypatch: pytest.MonkeyPatch) -> None:
    """With 2 sets of 600 tokens the unblocked bias would hold 2·600² = 720 000 elements; blocked at
    20 000 elements, no op returns more than a block (plus Q/K/V-sized tensors)."""
    monkeypatch.setattr(set_mixer, "BIAS_BLOCK_ELEMENTS", 20_000)
    query, key, value, points, valid = attention_inputs(tokens=600)
    with LargestAllocation() as tracker:
        biased_attention(query, key, value, points, valid, torch.tensor(2.0))
    assert tracker.largest <= max(20_000, query.numel())
    with LargestAllocation() as unblocked:
        F.scaled_dot_product_attention(
            query, key, value, attn_mask=set_mixer.distance_bias(points, valid, torch.tensor(2.0))
        )
    assert unblocked.largest >= 2 * 600 * 600  # the test would notice a T × T tensor


def test_chunked_inference_equals_one_call(monkeypatch: pytest.MonkeyPatch) -> None:
    """A packet whose encoder / Ψ / decoder calls are split into chunks of one view gives the outputs of
    one call for all views (the UNet sees the whole set either way)."""
    model = residual_model(attention_bias="cmap_distance", attention_bias_layers="lowest")
    torch.nn.init.normal_(model.geometry_encoder.out.weight, std=1e-2)
    packet = make_packet(3, 3, (32, 48), seed=4)
    whole = enhance_packet(model, packet)
    monkeypatch.setattr(model_module, "INFERENCE_CHUNK_PIXELS", 32 * 48)
    monkeypatch.setattr(set_mixer, "BIAS_BLOCK_ELEMENTS", 50)
    chunked = enhance_packet(model, packet)
    torch.testing.assert_close(chunked, whole, atol=2e-5, rtol=1e-4)
    assert model_module.views_per_chunk(32, 48) == 1
