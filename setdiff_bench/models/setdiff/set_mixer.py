"""The set mixer: every UNet self-attention (``attn1``) attends over the tokens of all views of a set.

The UNet sees views stacked on the batch axis in "(b v)" order (view-minor: all V views of set 0,
then all of set 1, ...).  In each transformer block the set mixer regroups the self-attention tokens
``(B·V, L, C) → (B, V·L, C)``, runs multi-head attention over the union, and splits the result back,
so every token of any reference or target can attend to every other token of the same set (paper
§3.2, "Set mixer").  There is no view position encoding, so the UNet is permutation-equivariant over
views; V may change from call to call.  Text cross-attention (``attn2``) keeps diffusers' standard
processor.  The pretrained ``to_q/to_k/to_v/to_out`` weights are reused; no new parameters.

V travels through a :class:`SetContext` shared by the model's processors (not a process-global
patch, unlike DiFix3D's ``mv_unet.py``), set around each UNet call with :meth:`SetContext.views`.
This is written here because diffusers ships no processor for joint attention across batch items.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import torch
import torch.nn.functional as F


class SetContext:
    """How many views each set in the current UNet batch has (``None`` outside a call)."""

    def __init__(self) -> None:
        self.num_views: int | None = None

    @contextlib.contextmanager
    def views(self, num_views: int) -> Iterator[None]:
        """Within the block, the UNet batch is ``(B·num_views)`` in "(b v)" order."""
        if num_views < 1:
            raise ValueError(f"a set needs at least one view, got {num_views}")
        previous, self.num_views = self.num_views, int(num_views)
        try:
            yield
        finally:
            self.num_views = previous


class SetSelfAttnProcessor:
    """Joint self-attention over the union of all V views' tokens (replaces ``attn1`` processors)."""

    def __init__(self, context: SetContext) -> None:
        self.context = context

    def __call__(self, attn: Any, hidden_states: torch.Tensor, encoder_hidden_states: torch.Tensor | None = None,
                 attention_mask: torch.Tensor | None = None, temb: torch.Tensor | None = None,
                 **kwargs: Any) -> torch.Tensor:
        """``hidden_states`` ``(B·V, L, C)`` → ``(B·V, L, C_out)``, attending across the V views of each set."""
        num_views = self.context.num_views
        if num_views is None:
            raise RuntimeError("set mixer called outside SetContext.views(...): the number of views is unknown")
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


def install_set_mixer(unet: torch.nn.Module, context: SetContext) -> list[str]:
    """Give every ``attn1`` of ``unet`` a :class:`SetSelfAttnProcessor`; ``attn2`` gets ``AttnProcessor2_0``.

    Returns:
        the processor names that now mix across views (16 for the SD-Turbo UNet).
    """
    from diffusers.models.attention_processor import AttnProcessor2_0

    modules = dict(unet.named_modules())
    processors: dict[str, Any] = {}
    mixed: list[str] = []
    for name in unet.attn_processors:
        module_name = name.removesuffix(".processor")
        if module_name.endswith("attn1"):
            check_self_attention(modules[module_name], module_name)
            processors[name] = SetSelfAttnProcessor(context)
            mixed.append(name)
        else:
            processors[name] = AttnProcessor2_0()
    unet.set_attn_processor(processors)
    return mixed
