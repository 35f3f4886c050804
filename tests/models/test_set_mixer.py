"""The set mixer against diffusers' standard attention processor on hand-regrouped tokens."""

from __future__ import annotations

import pytest
import torch
from diffusers.models.attention_processor import Attention, AttnProcessor2_0

from setdiff_bench.models.setdiff.set_mixer import SetSelfAttnProcessor, install_set_mixer, set_kwargs


def attention_layer() -> Attention:
    torch.manual_seed(0)
    return Attention(query_dim=32, heads=4, dim_head=8).eval()


def test_single_view_equals_standard_attention() -> None:
    attn = attention_layer()
    tokens = torch.randn(3, 10, 32)
    with torch.no_grad():
        mixed = SetSelfAttnProcessor()(attn, tokens, **set_kwargs(1))
        standard = AttnProcessor2_0()(attn, tokens)
    torch.testing.assert_close(mixed, standard, atol=1e-6, rtol=1e-6)


@pytest.mark.parametrize(("sets", "views"), [(1, 4), (2, 3)])
def test_views_attend_jointly(sets: int, views: int) -> None:
    """(B·V, L, C) tokens give the same result as plain attention over each set's concatenated tokens."""
    attn = attention_layer()
    tokens = torch.randn(sets * views, 6, 32)
    with torch.no_grad():
        mixed = SetSelfAttnProcessor()(attn, tokens, num_views=views)
    with torch.no_grad():
        for s in range(sets):
            joined = torch.cat(list(tokens[s * views : (s + 1) * views]), dim=0)[None]  # (1, V·L, C)
            expected = AttnProcessor2_0()(attn, joined)[0].reshape(views, 6, -1)
            torch.testing.assert_close(mixed[s * views : (s + 1) * views], expected, atol=1e-5, rtol=1e-5)


def test_needs_the_set_size() -> None:
    attn = attention_layer()
    with pytest.raises(RuntimeError, match="num_views"):
        SetSelfAttnProcessor()(attn, torch.randn(2, 5, 32))
    with pytest.raises(RuntimeError, match="not a multiple"):
        SetSelfAttnProcessor()(attn, torch.randn(4, 5, 32), num_views=3)
    with pytest.raises(ValueError, match="at least one view"):
        set_kwargs(0)


def test_through_the_attention_module() -> None:
    """``Attention.forward`` passes ``num_views`` on to the processor (diffusers filters kwargs by signature)."""
    attn = attention_layer()
    attn.set_processor(SetSelfAttnProcessor())
    tokens = torch.randn(4, 5, 32)
    with torch.no_grad():
        torch.testing.assert_close(
            attn(tokens, **set_kwargs(2)), SetSelfAttnProcessor()(attn, tokens, num_views=2)
        )


def test_install_replaces_only_self_attention() -> None:
    from diffusers import UNet2DConditionModel

    from setdiff_bench.models.setdiff.presets import TINY_UNET

    unet = UNet2DConditionModel.from_config(dict(TINY_UNET))
    mixed = install_set_mixer(unet)
    processors = unet.attn_processors
    assert len(mixed) == 4 and all(name.endswith("attn1.processor") for name in mixed)
    for name, processor in processors.items():
        if name.endswith("attn1.processor"):
            assert isinstance(processor, SetSelfAttnProcessor), name
        else:
            assert isinstance(processor, AttnProcessor2_0), name
    assert not any("processor" in key for key in unet.state_dict())  # no new parameters
