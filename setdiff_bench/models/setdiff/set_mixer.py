"""The set mixer: every UNet self-attention (``attn1``) attends over the tokens of all views of a set.

The UNet sees views stacked on the batch axis in "(b v)" order (view-minor: all V views of set 0,
then all of set 1, ...).  In each transformer block the set mixer regroups the self-attention tokens
``(B·V, L, C) → (B, V·L, C)``, runs multi-head attention over the union, and splits the result back,
so every token of any reference or target can attend to every other token of the same set (paper
§3.2, "Set mixer").  There is no view position encoding, so the UNet is permutation-equivariant over
views.  Text cross-attention (``attn2``) stays per view.  The pretrained ``to_q/to_k/to_v/to_out``
weights are reused; no new parameters.

V may change from call to call.  It travels with each UNet call as
``cross_attention_kwargs={"num_views": V}`` (:func:`set_kwargs`), which diffusers hands to every
attention processor of that call — per model, not a process-global patch like DiFix3D's
``mv_unet.py``.  A context object set around the call would not survive gradient checkpointing:
checkpointed blocks are recomputed during the backward pass, after such a context has been left,
whereas the kwargs are arguments of the checkpointed call and are replayed with it.  ``attn2`` gets a
thin ``PerViewAttnProcessor`` that accepts the key (diffusers would otherwise warn on every call).

Written here because diffusers ships no processor for joint attention across batch items.
"""

from __future__ import annotations

import functools
from typing import Any

import torch
import torch.nn.functional as F

NUM_VIEWS_KEY = "num_views"


def set_kwargs(num_views: int) -> dict[str, int]:
    """The ``cross_attention_kwargs`` of a UNet call whose batch is ``(B·num_views)`` in "(b v)" order."""
    if num_views < 1:
        raise ValueError(f"a set needs at least one view, got {num_views}")
    return {NUM_VIEWS_KEY: int(num_views)}


class SetSelfAttnProcessor:
    """Joint self-attention over the union of all V views' tokens (replaces ``attn1`` processors)."""

    def __call__(self, attn: Any, hidden_states: torch.Tensor, encoder_hidden_states: torch.Tensor | None = None,
                 attention_mask: torch.Tensor | None = None, temb: torch.Tensor | None = None,
                 num_views: int | None = None, **kwargs: Any) -> torch.Tensor:
        """``hidden_states`` ``(B·V, L, C)`` → ``(B·V, L, C_out)``, attending across the V views of each set."""
        if num_views is None:
            raise RuntimeError("set mixer called without cross_attention_kwargs={'num_views': V}")
        if encoder_hidden_states is not None or attention_mask is not None:
            raise RuntimeError("set mixer replaces self-attention only: got encoder_hidden_states or a mask")
        if hidden_states.ndim != 3:
            raise RuntimeError(f"set mixer expects (B·V, L, C) tokens, got shape {tuple(hidden_states.shape)}")
        batch_views, tokens, _ = hidden_states.shape
        if batch_views % num_views:
            raise RuntimeError(f"UNet batch {batch_views} is not a multiple of the set size {num_views}")
        sets = batch_views // num_views
        heads = attn.heads
        query = attn.to_q(hidden_states)
        key = attn.to_k(hidden_states)
        value = attn.to_v(hidden_states)
        head_dim = query.shape[-1] // heads

        def to_heads(x: torch.Tensor) -> torch.Tensor:  # (B·V, L, h·d) → (B, h, V·L, d); a view in "(b v)" order
            return x.reshape(sets, num_views * tokens, heads, head_dim).transpose(1, 2)

        mixed = F.scaled_dot_product_attention(to_heads(query), to_heads(key), to_heads(value))
        mixed = mixed.transpose(1, 2).reshape(batch_views, tokens, heads * head_dim).to(query.dtype)
        mixed = attn.to_out[0](mixed)
        mixed = attn.to_out[1](mixed)
        return mixed / attn.rescale_output_factor


@functools.cache
def per_view_processor_class() -> type:
    """:class:`PerViewAttnProcessor` (built on first use so that importing this module stays light)."""
    from diffusers.models.attention_processor import AttnProcessor2_0

    class PerViewAttnProcessor(AttnProcessor2_0):
        """diffusers' standard SDPA processor, accepting (and ignoring) the set size."""

        def __call__(self, attn: Any, hidden_states: torch.Tensor, encoder_hidden_states: torch.Tensor | None = None,
                     attention_mask: torch.Tensor | None = None, temb: torch.Tensor | None = None,
                     num_views: int | None = None, **kwargs: Any) -> torch.Tensor:
            return super().__call__(attn, hidden_states, encoder_hidden_states, attention_mask, temb, **kwargs)

    return PerViewAttnProcessor


def check_self_attention(attn: Any, name: str) -> None:
    """Refuse attention layers with features the set mixer does not implement."""
    unsupported = [flag for flag in ("spatial_norm", "group_norm", "norm_q", "norm_k")
                   if getattr(attn, flag, None) is not None]
    if getattr(attn, "residual_connection", False):
        unsupported.append("residual_connection")
    if getattr(attn, "is_cross_attention", False):
        unsupported.append("cross-attention")
    if unsupported:
        raise RuntimeError(f"{name}: set mixer does not support {', '.join(unsupported)}")


def install_set_mixer(unet: torch.nn.Module) -> list[str]:
    """Give every ``attn1`` of ``unet`` a :class:`SetSelfAttnProcessor`, every other attention the per-view one.

    Returns:
        the processor names that now mix across views (16 for the SD-Turbo UNet).
    """
    modules = dict(unet.named_modules())
    processors: dict[str, Any] = {}
    mixed: list[str] = []
    for name in unet.attn_processors:
        module_name = name.removesuffix(".processor")
        if module_name.endswith("attn1"):
            check_self_attention(modules[module_name], module_name)
            processors[name] = SetSelfAttnProcessor()
            mixed.append(name)
        else:
            processors[name] = per_view_processor_class()()
    unet.set_attn_processor(processors)
    return mixed
