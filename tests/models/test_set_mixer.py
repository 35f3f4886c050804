"""The set mixer against diffusers' standard attention processor on hand-regrouped tokens."""

from __future__ import annotations

import pytest
import torch
from diffusers.models.attention_processor import Attention, AttnProcessor2_0

from setdiff_bench.models.setdiff.set_mixer import SetContext, SetSelfAttnProcessor, install_set_mixer


def attention_layer() -> Attention:
    torch.manual_seed(0)
    return Attention(query_dim=32, heads=4, dim_head=8).eval()


def test_single_view_equals_standard_attention() -> None:
    attn = attention_layer()
    tokens = torch.randn(3, 10, 32)
    context = SetContext()
    with torch.no_grad(), context.views(1):
        mixed = SetSelfAttnProcessor(context)(attn, tokens)
        standard = AttnProcessor2_0()(attn, tokens)
    torch.testing.assert_close(mixed, standard, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize(("sets", "views"), [(1, 4), (2, 3)])
def test_views_attend_jointly(sets: int, views: int) -> None:
    """(B·V, L, C) tokens give the same result as plain attention over each set's concatenated tokens."""
    attn = attention_layer()
    tokens = torch.randn(sets * views, 6, 32)
    context = SetContext()
    with torch.no_grad(), context.views(views):
        mixed = SetSelfAttnProcessor(context)(attn, tokens)
    with torch.no_grad():
        for s in range(sets):
            joined = torch.cat(list(tokens[s * views:(s + 1) * views]), dim=0)[None]  # (1, V·L, C)
            expected = AttnProcessor2_0()(attn, joined)[0].reshape(views, 6, -1)
            torch.testing.assert_close(mixed[s * views:(s + 1) * views], expected, atol=1e-5, rtol=1e-5)


def test_needs_a_set_context() -> None:
    attn = attention_layer()
    with pytest.raises(RuntimeError, match="outside SetContext"):
        SetSelfAttnProcessor(SetContext())(attn, torch.randn(2, 5, 32))
    context = SetContext()
    with context.views(3), pytest.raises(RuntimeError, match="not a multiple"):
        SetSelfAttnProcessor(context)(attn, torch.randn(4, 5, 32))
    assert context.num_views is None


def test_install_replaces_only_self_attention() -> None:
    from diffusers import UNet2DConditionModel

    from setdiff_bench.models.setdiff.config import TINY_UNET

    unet = UNet2DConditionModel.from_config(dict(TINY_UNET))
    mixed = install_set_mixer(unet, SetContext())
    processors = unet.attn_processors
    assert len(mixed) == 4 and all(name.endswith("attn1.processor") for name in mixed)
    for name, processor in processors.items():
        expected = SetSelfAttnProcessor if name.endswith("attn1.processor") else AttnProcessor2_0
        assert isinstance(processor, expected), name
    assert not any("processor" in key for key in unet.state_dict())  # no new parameters
