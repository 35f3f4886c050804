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
import math
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

NUM_VIEWS_KEY = "num_views"
POINTS_KEY = "token_points"
BIAS_PARAMETER = "set_bias_log_scale"
#: Initial strength s of the C-map distance bias (logits −s·d², d in packet units).
BIAS_INITIAL_SCALE = 2.0
#: Squared distances are capped here (packet units²): beyond it a token is simply "elsewhere".
BIAS_DISTANCE_CAP = 4.0
#: Most elements (sets × queries × keys) of one block of the distance bias: 16 Mi float32 = 64 MiB (each set
#: of the 256×144 driving demo is one block, as before blocking existed).  The bias is built and applied
#: block by block over queries (:func:`biased_attention`), never as T × T.
BIAS_BLOCK_ELEMENTS = 1 << 24


def set_kwargs(num_views: int, points: torch.Tensor | None = None) -> dict[str, Any]:
    """The ``cross_attention_kwargs`` of a UNet call whose batch is ``(B·num_views)`` in "(b v)" order.

    Args:
        points: ``(B·V, 4, h, w)`` per latent cell: the C-map surface point × validity (3) and the
            validity (1) — for the C-map distance attention bias; ``None`` = no bias.
    """
    if num_views < 1:
        raise ValueError(f"a set needs at least one view, got {num_views}")
    kwargs: dict[str, Any] = {NUM_VIEWS_KEY: int(num_views)}
    if points is not None:
        kwargs[POINTS_KEY] = points
    return kwargs


def token_grid(height: int, width: int, tokens: int) -> tuple[int, int]:
    """The token grid of a UNet level with ``tokens`` tokens whose latent is ``height × width``
    (each UNet downsampler maps a side s to ⌈s/2⌉)."""
    h, w = height, width
    while h * w > tokens:
        h, w = math.ceil(h / 2), math.ceil(w / 2)
    if h * w != tokens:
        raise RuntimeError(f"{tokens} tokens do not match a downsampled {height}x{width} latent grid")
    return h, w


def pool_token_points(points: torch.Tensor, tokens: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Latent-cell points ``(B·V, 4, h, w)`` → per-token mean surface points ``(B·V, L, 3)`` and
    validity ``(B·V, L)`` bool (more than half the token's area has a surface point)."""
    h, w = token_grid(int(points.shape[-2]), int(points.shape[-1]), tokens)
    pooled = F.adaptive_avg_pool2d(points.float(), (h, w))
    coverage = pooled[:, 3:]
    xyz = pooled[:, :3] / coverage.clamp_min(1e-6)
    return xyz.flatten(2).transpose(1, 2), (coverage > 0.5).flatten(1)


def distance_bias(
    points: torch.Tensor, valid: torch.Tensor, scale: torch.Tensor, rows: slice | None = None
) -> torch.Tensor:
    """Additive attention logits ``(B, 1, Q, T)`` = ``−scale · min(‖p_q − p_k‖², cap)``; pairs where either
    token has no surface point get the cap (a query without a point thus gets a constant row: no effect).

    Args:
        points: ``(B, T, 3)`` token surface points (packet units); valid: ``(B, T)`` bool.
        rows: the queries to compute the logits of (``None`` = all T, so Q = T); the keys are always all T.
    """
    rows = slice(None) if rows is None else rows
    squared = torch.cdist(points[:, rows], points).square().clamp(max=BIAS_DISTANCE_CAP)
    both = valid[:, rows, None] & valid[:, None, :]
    squared = torch.where(both, squared, torch.full_like(squared, BIAS_DISTANCE_CAP))
    return (-scale * squared)[:, None]


def bias_block_rows(sets: int, tokens: int) -> int:
    """Queries per block of :func:`biased_attention`: as many as keep one block's bias within
    :data:`BIAS_BLOCK_ELEMENTS` (at least one)."""
    return max(1, BIAS_BLOCK_ELEMENTS // max(1, sets * tokens))


def biased_attention(
    query: torch.Tensor,
    key: torch.Tensor,
    value: torch.Tensor,
    points: torch.Tensor,
    valid: torch.Tensor,
    scale: torch.Tensor,
) -> torch.Tensor:
    """``softmax(QKᵀ/√d + distance_bias)·V``, computed blockwise over queries so that no ``T × T`` tensor is
    ever held: each block of queries gets its rows of :func:`distance_bias` as the additive mask of a
    fused SDPA kernel (which never materialises the attention matrix), so peak memory grows linearly
    with T.  Each query's softmax runs over all keys, so the result equals the unblocked one.

    Args:
        query, key, value: ``(B, heads, T, d)``.
        points: ``(B, T, 3)`` token surface points; valid: ``(B, T)`` bool; scale: the bias strength.

    Returns:
        ``(B, heads, T, d)``.
    """
    sets, _, total, _ = query.shape
    block = bias_block_rows(sets, total)
    if block >= total:
        bias = distance_bias(points, valid, scale).to(query.dtype)
        return F.scaled_dot_product_attention(query, key, value, attn_mask=bias)
    # Written into one preallocated output: collecting per-block outputs between the large bias blocks
    # fragments the CPU heap (glibc kept 2 GB for a 16-view 576×1024 set).  Autograd tracks the
    # in-place writes, so training through this path works as the unblocked one.
    output = query.new_empty(*query.shape[:3], value.shape[-1])
    for start in range(0, total, block):
        rows = slice(start, min(start + block, total))
        bias = distance_bias(points, valid, scale, rows).to(query.dtype)
        output[:, :, rows] = F.scaled_dot_product_attention(query[:, :, rows], key, value, attn_mask=bias)
    return output


def mixer_level(name: str, levels: int) -> int:
    """The resolution level (0 = the full latent grid, each level halves it) of a set-mixing layer named
    as in diffusers' ``UNet2DConditionModel`` with ``levels`` down blocks: ``down_blocks.i`` works at
    level i (it downsamples at its end), ``mid_block`` at the last, ``up_blocks.j`` at ``levels − 1 − j``
    (it upsamples at its end)."""
    block, _, rest = name.partition(".")
    if block == "mid_block":
        return levels - 1
    index = int(rest.split(".", 1)[0])
    if block == "down_blocks":
        return index
    if block == "up_blocks":
        return levels - 1 - index
    raise ValueError(f"{name}: not a down, mid or up block of a UNet")


def biased_layers(names: list[str], levels: int, which: str) -> list[str]:
    """The set-mixing layers that get the distance bias: ``all`` of ``names``, or the ``lowest``-resolution ones."""
    if which == "all":
        return list(names)
    if which != "lowest":
        raise ValueError(f"attention bias layers must be 'all' or 'lowest', got {which!r}")
    deepest = max(mixer_level(name, levels) for name in names)
    return [name for name in names if mixer_level(name, levels) == deepest]


def add_bias_parameters(unet: torch.nn.Module, names: list[str]) -> None:
    """Give each set-mixing ``attn1`` a learnable log-strength of the distance bias (saved with the UNet)."""
    modules = dict(unet.named_modules())
    for name in names:
        module = modules[name.removesuffix(".processor")]
        if not hasattr(module, BIAS_PARAMETER):
            module.register_parameter(
                BIAS_PARAMETER, nn.Parameter(torch.tensor(math.log(BIAS_INITIAL_SCALE)))
            )


class SetSelfAttnProcessor:
    """Joint self-attention over the union of all V views' tokens (replaces ``attn1`` processors)."""

    def __call__(
        self,
        attn: Any,
        hidden_states: torch.Tensor,
        encoder_hidden_states: torch.Tensor | None = None,
        attention_mask: torch.Tensor | None = None,
        temb: torch.Tensor | None = None,
        num_views: int | None = None,
        token_points: torch.Tensor | None = None,
        **kwargs: Any,
    ) -> torch.Tensor:
        """``hidden_states`` ``(B·V, L, C)`` → ``(B·V, L, C_out)``, attending across the V views of each set.

        With ``token_points`` and a layer that has the bias parameter, the logits get the C-map
        distance bias (:func:`distance_bias`)."""
        if num_views is None:
            raise RuntimeError("set mixer called without cross_attention_kwargs={'num_views': V}")
        if encoder_hidden_states is not None or attention_mask is not None:
            raise RuntimeError("set mixer replaces self-attention only: got encoder_hidden_states or a mask")
        if hidden_states.ndim != 3:
            raise RuntimeError(
                f"set mixer expects (B·V, L, C) tokens, got shape {tuple(hidden_states.shape)}"
            )
        batch_views, tokens, _ = hidden_states.shape
        if batch_views % num_views:
            raise RuntimeError(f"UNet batch {batch_views} is not a multiple of the set size {num_views}")
        sets = batch_views // num_views
        heads = attn.heads
        query = attn.to_q(hidden_states)
        key = attn.to_k(hidden_states)
        value = attn.to_v(hidden_states)
        head_dim = query.shape[-1] // heads

        def to_heads(
            x: torch.Tensor,
        ) -> torch.Tensor:  # (B·V, L, h·d) → (B, h, V·L, d); a view in "(b v)" order
            return x.reshape(sets, num_views * tokens, heads, head_dim).transpose(1, 2)

        query, key, value = to_heads(query), to_heads(key), to_heads(value)
        log_scale = getattr(attn, BIAS_PARAMETER, None)
        if token_points is not None and log_scale is not None:
            points, valid = pool_token_points(token_points, tokens)
            mixed = biased_attention(
                query,
                key,
                value,
                points.reshape(sets, num_views * tokens, 3),
                valid.reshape(sets, -1),
                log_scale.exp(),
            )
        else:
            mixed = F.scaled_dot_product_attention(query, key, value)
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

        def __call__(
            self,
            attn: Any,
            hidden_states: torch.Tensor,
            encoder_hidden_states: torch.Tensor | None = None,
            attention_mask: torch.Tensor | None = None,
            temb: torch.Tensor | None = None,
            num_views: int | None = None,
            token_points: torch.Tensor | None = None,
            **kwargs: Any,
        ) -> torch.Tensor:
            return super().__call__(
                attn, hidden_states, encoder_hidden_states, attention_mask, temb, **kwargs
            )

    return PerViewAttnProcessor


def check_self_attention(attn: Any, name: str) -> None:
    """Refuse attention layers with features the set mixer does not implement."""
    unsupported = [
        flag
        for flag in ("spatial_norm", "group_norm", "norm_q", "norm_k")
        if getattr(attn, flag, None) is not None
    ]
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
