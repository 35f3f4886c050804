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

Beyond the paper (``ModelConfig.set_attention``, per resolution level): ``view`` restricts a layer's
self-attention to each view's own tokens (a plain UNet layer), and ``knn`` lets each token attend to its
own view's tokens, the ``k`` reference tokens nearest to its C-map surface point in 3D (other views'
references only; tokens without a surface point get none) and one learned "no match" key/value
(``set_no_match_key`` / ``set_no_match_value``, zero-initialised), all under one softmax — T·(L + k + 1)
pairs instead of T².  ``full`` (the default) is the paper's joint attention, computed exactly as before.
The C-map bias comes in two forms: ``cmap_distance`` (−s·min(d², cap), d in packet units) and
``cmap_relative`` (d divided by the query token's footprint, :func:`relative_distance_bias`).

Written here because diffusers ships no processor for joint attention across batch items.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import torch
import torch.nn.functional as F
from torch import nn

NUM_VIEWS_KEY = "num_views"
POINTS_KEY = "token_points"
NUM_REFERENCES_KEY = "num_references"
BIAS_PARAMETER = "set_bias_log_scale"
#: Initial strength s of the C-map distance bias (logits −s·d², d in packet units).
BIAS_INITIAL_SCALE = 2.0
#: Squared distances are capped here (packet units²): beyond it a token is simply "elsewhere".
BIAS_DISTANCE_CAP = 4.0
#: Initial strength s of the relative bias (logits −s·r², r = distance / the query token's footprint): the
#: logit falls by 1 two footprints away.
RELATIVE_BIAS_INITIAL_SCALE = 0.25
#: Squared relative distances are capped here (footprints²): eight token footprints away is "elsewhere".
RELATIVE_BIAS_CAP = 64.0
#: The learned "no match" key and value of a ``knn`` layer (each ``(heads · head_dim,)``, zero-initialised).
NO_MATCH_KEY = "set_no_match_key"
NO_MATCH_VALUE = "set_no_match_value"
#: What a set-mixing layer attends to: the whole set (the paper), its own view, or its own view plus the
#: k nearest reference tokens in 3D and a learned "no match" key.
SetAttention = Literal["full", "view", "knn"]
#: Most elements (sets × queries × keys) of one block of the distance bias: 16 Mi float32 = 64 MiB (each set
#: of the 256×144 driving demo is one block, as before blocking existed).  The bias is built and applied
#: block by block over queries (:func:`biased_attention`), never as T × T.
BIAS_BLOCK_ELEMENTS = 1 << 24


def set_kwargs(
    num_views: int, points: torch.Tensor | None = None, num_references: int | None = None
) -> dict[str, Any]:
    """The ``cross_attention_kwargs`` of a UNet call whose batch is ``(B·num_views)`` in "(b v)" order.

    Args:
        points: ``(B·V, 4, h, w)`` per latent cell: the C-map surface point × validity (3) and the
            validity (1) — for the C-map distance attention bias; ``(B·V, 5, h, w)`` adds the cell's
            footprint × validity (packet units, :func:`pool_token_geometry`) for the relative bias;
            ``None`` = no points.
        num_references: N, the references at the start of each set (``knn`` layers fetch from them only);
            ``None`` = not given (a ``knn`` layer then refuses to run).
    """
    if num_views < 1:
        raise ValueError(f"a set needs at least one view, got {num_views}")
    kwargs: dict[str, Any] = {NUM_VIEWS_KEY: int(num_views)}
    if points is not None:
        kwargs[POINTS_KEY] = points
    if num_references is not None:
        if not 0 <= num_references <= num_views:
            raise ValueError(f"num_references must be in [0, {num_views}], got {num_references}")
        kwargs[NUM_REFERENCES_KEY] = int(num_references)
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
    geometry = pool_token_geometry(points, tokens)
    return geometry.points, geometry.valid


@dataclass
class TokenGeometry:
    """The C-map geometry of the tokens of one UNet level.

    Attributes:
        points: ``(S, T, 3)`` mean surface point of each token's cells that have one (packet units).
        valid: ``(S, T)`` bool, more than half the token's area has a surface point.
        coverage: ``(S, T)`` float in [0, 1], the share of the token's area that has one.
        footprint: ``(S, T)`` the token's side at its surface (depth × the token's angular size, packet
            units), or ``None`` when the points came without it.
    """

    points: torch.Tensor
    valid: torch.Tensor
    coverage: torch.Tensor
    footprint: torch.Tensor | None

    def grouped(self, sets: int) -> TokenGeometry:
        """Views merged into their sets: ``(S·V, L, ...)`` → ``(S, V·L, ...)``."""
        footprint = None if self.footprint is None else self.footprint.reshape(sets, -1)
        return TokenGeometry(
            self.points.reshape(sets, -1, 3),
            self.valid.reshape(sets, -1),
            self.coverage.reshape(sets, -1),
            footprint,
        )


def pool_token_geometry(points: torch.Tensor, tokens: int) -> TokenGeometry:
    """Latent-cell points ``(B·V, 4 or 5, h, w)`` → the :class:`TokenGeometry` of a level with ``tokens``
    tokens per view.  Channel 4, when present, is the cell's footprint × validity; a token's footprint
    is its valid cells' mean footprint × the cells per token side (``h / token rows``)."""
    cells_h = int(points.shape[-2])
    h, w = token_grid(cells_h, int(points.shape[-1]), tokens)
    pooled = F.adaptive_avg_pool2d(points.float(), (h, w))
    coverage = pooled[:, 3:4]
    safe = coverage.clamp_min(1e-6)
    xyz = (pooled[:, :3] / safe).flatten(2).transpose(1, 2)
    footprint = None
    if points.shape[1] > 4:
        footprint = (pooled[:, 4] / safe[:, 0] * (cells_h / h)).flatten(1)
    return TokenGeometry(xyz, (coverage > 0.5).flatten(1), coverage.flatten(1), footprint)


def relative_distance_bias(
    geometry: TokenGeometry, scale: torch.Tensor, rows: slice | None = None
) -> torch.Tensor:
    """Scale-free attention logits ``(S, 1, Q, T)``: ``−s·[c_q c_k·min(r², cap) + (1 − c_q c_k)·cap]`` with
    ``r = ‖p_q − p_k‖ / f_q`` (``f_q`` the query token's footprint) and ``c`` the tokens' surface coverage.

    Scaling the scene (points and camera translations) scales distances and footprints alike, so the bias
    does not change.  Tokens with little surface (low render alpha) are handled by their coverage: a
    query without any gets the constant row ``−s·cap`` (no effect: it attends by content alone), a key
    without any counts as "elsewhere" (the cap), partial coverage interpolates linearly.

    Args:
        geometry: the tokens of S sets (``footprint`` required).
        rows: the queries (``None`` = all T).
    """
    if geometry.footprint is None:
        raise RuntimeError("the relative C-map bias needs token footprints (5-channel points)")
    rows = slice(None) if rows is None else rows
    points = geometry.points
    footprint = geometry.footprint[:, rows, None].clamp_min(1e-12)
    relative = (torch.cdist(points[:, rows], points) / footprint).square().clamp(max=RELATIVE_BIAS_CAP)
    weight = geometry.coverage[:, rows, None] * geometry.coverage[:, None, :]
    return (-scale * (weight * relative + (1.0 - weight) * RELATIVE_BIAS_CAP))[:, None]


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
    """``softmax(QKᵀ/√d + distance_bias)·V`` (:func:`row_biased_attention` with :func:`distance_bias`).

    Args:
        query, key, value: ``(B, heads, T, d)``.
        points: ``(B, T, 3)`` token surface points; valid: ``(B, T)`` bool; scale: the bias strength.

    Returns:
        ``(B, heads, T, d)``.
    """
    return row_biased_attention(query, key, value, functools.partial(distance_bias, points, valid, scale))


def row_biased_attention(
    query: torch.Tensor,
    key: torch.Tensor,
    value: torch.Tensor,
    bias_rows: Callable[[slice | None], torch.Tensor],
) -> torch.Tensor:
    """``softmax(QKᵀ/√d + bias)·V``, computed blockwise over queries so that no ``T × T`` tensor is
    ever held: each block of queries gets its rows of the bias (``bias_rows(rows)`` → ``(B, 1, Q, T)``;
    ``None`` = all rows) as the additive mask of a fused SDPA kernel (which never materialises the
    attention matrix), so peak memory grows linearly with T.  Each query's softmax runs over all keys,
    so the result equals the unblocked one.

    Args:
        query, key, value: ``(B, heads, T, d)``.

    Returns:
        ``(B, heads, T, d)``.
    """
    sets, _, total, _ = query.shape
    block = bias_block_rows(sets, total)
    if block >= total:
        bias = bias_rows(None).to(query.dtype)
        return F.scaled_dot_product_attention(query, key, value, attn_mask=bias)
    # Written into one preallocated output: collecting per-block outputs between the large bias blocks
    # fragments the CPU heap (glibc kept 2 GB for a 16-view 576×1024 set).  Autograd tracks the
    # in-place writes, so training through this path works as the unblocked one.
    output = query.new_empty(*query.shape[:3], value.shape[-1])
    for start in range(0, total, block):
        rows = slice(start, min(start + block, total))
        bias = bias_rows(rows).to(query.dtype)
        output[:, :, rows] = F.scaled_dot_product_attention(query[:, :, rows], key, value, attn_mask=bias)
    return output


def pair_bias(
    geometry: TokenGeometry,
    query_index: torch.Tensor,
    key_index: torch.Tensor,
    scale: torch.Tensor,
    relative: bool,
) -> torch.Tensor:
    """The C-map bias of chosen token pairs, elementwise: query tokens ``query_index`` ``(S, Q, 1)`` against
    key tokens ``key_index`` ``(S, Q, K)`` (indices into T) → ``(S, Q, K)``, the same values as
    :func:`distance_bias` (``relative = False``) or :func:`relative_distance_bias` give those pairs."""

    def gathered(x: torch.Tensor, index: torch.Tensor) -> torch.Tensor:  # (S, T, ...) at (S, Q, K)
        flat = index.reshape(index.shape[0], -1)
        if x.ndim == 3:
            return torch.gather(x, 1, flat[..., None].expand(-1, -1, x.shape[-1])).reshape(
                *index.shape, x.shape[-1]
            )
        return torch.gather(x, 1, flat).reshape(index.shape)

    difference = gathered(geometry.points, query_index) - gathered(geometry.points, key_index)
    squared = difference.square().sum(-1)
    if relative:
        if geometry.footprint is None:
            raise RuntimeError("the relative C-map bias needs token footprints (5-channel points)")
        footprint = gathered(geometry.footprint, query_index).clamp_min(1e-12)
        ratio = (squared / footprint.square()).clamp(max=RELATIVE_BIAS_CAP)
        weight = gathered(geometry.coverage, query_index) * gathered(geometry.coverage, key_index)
        return -scale * (weight * ratio + (1.0 - weight) * RELATIVE_BIAS_CAP)
    both = gathered(geometry.valid, query_index) & gathered(geometry.valid, key_index)
    capped = squared.clamp(max=BIAS_DISTANCE_CAP)
    return -scale * torch.where(both, capped, torch.full_like(capped, BIAS_DISTANCE_CAP))


def nearest_reference_keys(
    geometry: TokenGeometry, rows: slice, candidates: torch.Tensor, neighbours: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """For the query tokens ``rows`` of S sets, the ``neighbours`` candidate tokens nearest in 3D.

    Args:
        geometry: the sets' tokens (``(S, T, ...)``).
        rows: the queries.
        candidates: ``(C,)`` token indices the keys may come from (e.g. the other references' tokens).

    Returns:
        ``index`` ``(S, Q, k)`` (into T; k = min(neighbours, C)) and ``found`` ``(S, Q, k)`` bool: False
        where the query or the candidate has no surface point (those slots are masked out).
    """
    count = min(neighbours, int(candidates.numel()))
    sets = geometry.points.shape[0]
    queries = geometry.points[:, rows]
    if count == 0:
        empty = torch.zeros((sets, queries.shape[1], 0), dtype=torch.long, device=queries.device)
        return empty, empty.bool()
    distance = torch.cdist(queries.float(), geometry.points[:, candidates].float())
    distance.masked_fill_(~geometry.valid[:, None, candidates], math.inf)  # keys without a surface point
    nearest, order = distance.topk(count, dim=-1, largest=False)
    return candidates[order], torch.isfinite(nearest) & geometry.valid[:, rows, None]


def nearest_reference_attention(
    query: torch.Tensor,
    key: torch.Tensor,
    value: torch.Tensor,
    geometry: TokenGeometry | None,
    *,
    num_views: int,
    num_references: int,
    neighbours: int,
    no_match_key: torch.Tensor,
    no_match_value: torch.Tensor,
    bias_scale: torch.Tensor | None = None,
    relative: bool = False,
) -> torch.Tensor:
    """Each token attends, under one softmax, to its own view's L tokens, the ``neighbours`` reference
    tokens of the *other* views nearest to its surface point (:func:`nearest_reference_keys`) and a
    learned "no match" key.  Computed per view in blocks of queries (as :func:`row_biased_attention`).

    Args:
        query, key, value: ``(S, heads, V·L, d)`` — S sets of V views of L tokens, references first.
        geometry: the tokens' :class:`TokenGeometry` (grouped by set), or ``None`` (no geometry: no
            neighbours, own view and "no match" only).
        num_references: N; neighbours come from views ``[0, N)``.
        no_match_key, no_match_value: ``(heads·d,)`` the learned extra key and value.
        bias_scale: the C-map bias strength, added to the own-view and neighbour logits (``None`` = none).
        relative: the bias is :func:`relative_distance_bias`'s, else :func:`distance_bias`'s.

    Returns:
        ``(S, heads, V·L, d)``.
    """
    sets, heads, total, head_dim = query.shape
    tokens = total // num_views
    device = query.device
    factor = 1.0 / math.sqrt(head_dim)
    spare_key = no_match_key.to(query.dtype).reshape(heads, head_dim)
    spare_value = no_match_value.to(value.dtype).reshape(heads, head_dim)
    all_index = torch.arange(total, device=device)
    set_index = torch.arange(sets, device=device)[:, None, None]
    # (S, T, h·d): each token's keys / values of all heads in one row, gathered by token index
    token_keys = key.transpose(1, 2).reshape(sets, total, heads * head_dim)
    token_values = value.transpose(1, 2).reshape(sets, total, heads * head_dim)
    # per query: its logits over L + k + 1 keys and its k gathered keys and values (each head), and its
    # distances to every candidate (the N·L reference tokens at most)
    per_query = max(heads * (tokens + 2 * neighbours * head_dim + neighbours + 1), num_references * tokens)
    block = max(1, min(tokens, BIAS_BLOCK_ELEMENTS // max(1, sets * per_query)))
    output = query.new_empty(*query.shape[:3], value.shape[-1])
    for view in range(num_views):
        own = slice(view * tokens, (view + 1) * tokens)
        own_keys, own_values = key[:, :, own], value[:, :, own]
        is_candidate = all_index < num_references * tokens
        is_candidate[own] = False
        candidates = all_index[is_candidate]
        for start in range(own.start, own.stop, block):
            rows = slice(start, min(start + block, own.stop))
            q = query[:, :, rows]
            own_logits = q @ own_keys.transpose(-1, -2) * factor  # (S, h, Q, L)
            if geometry is not None:
                index, found = nearest_reference_keys(geometry, rows, candidates, neighbours)
            else:
                index = torch.zeros((sets, q.shape[2], 0), dtype=torch.long, device=device)
                found = index.bool()
            near_keys, near_values = (
                rows_of[set_index, index].reshape(*index.shape, heads, head_dim).permute(0, 3, 1, 2, 4)
                for rows_of in (token_keys, token_values)
            )  # (S, h, Q, k, d)
            near_logits = (q.unsqueeze(-2) @ near_keys.transpose(-1, -2)).squeeze(-2) * factor  # (S, h, Q, k)
            if bias_scale is not None and geometry is not None:
                query_index = all_index[rows].expand(sets, -1)[..., None]
                own_index = all_index[own].expand(sets, q.shape[2], -1)
                own_logits = own_logits + pair_bias(geometry, query_index, own_index, bias_scale, relative)[
                    :, None
                ].to(own_logits.dtype)
                near_logits = near_logits + pair_bias(geometry, query_index, index, bias_scale, relative)[
                    :, None
                ].to(near_logits.dtype)
            near_logits = near_logits.masked_fill(~found[:, None], -math.inf)
            spare_logits = (q * spare_key[None, :, None]).sum(-1, keepdim=True) * factor  # (S, h, Q, 1)
            weights = torch.softmax(torch.cat([own_logits, near_logits, spare_logits], dim=-1), dim=-1)
            own_w, near_w, spare_w = weights.split([tokens, index.shape[-1], 1], dim=-1)
            mixed = own_w @ own_values + (near_w.unsqueeze(-2) @ near_values).squeeze(-2)
            output[:, :, rows] = mixed + spare_w * spare_value[None, :, None]
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


def add_bias_parameters(unet: torch.nn.Module, names: list[str], initial: float = BIAS_INITIAL_SCALE) -> None:
    """Give each set-mixing ``attn1`` a learnable log-strength of the distance bias (saved with the UNet),
    starting at ``log(initial)``."""
    modules = dict(unet.named_modules())
    for name in names:
        module = modules[name.removesuffix(".processor")]
        if not hasattr(module, BIAS_PARAMETER):
            module.register_parameter(BIAS_PARAMETER, nn.Parameter(torch.tensor(math.log(initial))))


def is_no_match_parameter(name: str) -> bool:
    """Whether a state-dict key is a ``knn`` layer's "no match" key or value (present only with ``knn``)."""
    return name.rsplit(".", 1)[-1] in (NO_MATCH_KEY, NO_MATCH_VALUE)


def add_no_match_parameters(unet: torch.nn.Module, names: list[str]) -> None:
    """Give each ``knn`` set-mixing ``attn1`` its learned "no match" key and value (zeros, saved with the UNet)."""
    modules = dict(unet.named_modules())
    for name in names:
        module = modules[name.removesuffix(".processor")]
        width = module.to_k.out_features
        for parameter in (NO_MATCH_KEY, NO_MATCH_VALUE):
            if not hasattr(module, parameter):
                module.register_parameter(parameter, nn.Parameter(torch.zeros(width)))


class SetSelfAttnProcessor:
    """Joint self-attention over the union of all V views' tokens (replaces ``attn1`` processors).

    Args:
        attention: what each token attends to (:data:`SetAttention`): ``full`` (the paper), ``view`` or ``knn``.
        neighbours: k, the nearest reference tokens a ``knn`` layer adds.
        relative_bias: the layer's C-map bias (when it has one) is :func:`relative_distance_bias`, else
            :func:`distance_bias`.
    """

    def __init__(
        self, attention: SetAttention = "full", neighbours: int = 16, relative_bias: bool = False
    ) -> None:
        if attention not in ("full", "view", "knn"):
            raise ValueError(f"set attention must be 'full', 'view' or 'knn', got {attention!r}")
        if neighbours < 1:
            raise ValueError(f"neighbours must be >= 1, got {neighbours}")
        self.attention, self.neighbours, self.relative_bias = attention, int(neighbours), bool(relative_bias)

    def __call__(
        self,
        attn: Any,
        hidden_states: torch.Tensor,
        encoder_hidden_states: torch.Tensor | None = None,
        attention_mask: torch.Tensor | None = None,
        temb: torch.Tensor | None = None,
        num_views: int | None = None,
        token_points: torch.Tensor | None = None,
        num_references: int | None = None,
        **kwargs: Any,
    ) -> torch.Tensor:
        """``hidden_states`` ``(B·V, L, C)`` → ``(B·V, L, C_out)``, attending across the V views of each set
        (or as :attr:`attention` restricts it).

        With ``token_points`` and a layer that has the bias parameter, the logits get the C-map
        distance bias (:func:`distance_bias` or :func:`relative_distance_bias`)."""
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
        groups = batch_views if self.attention == "view" else sets
        heads = attn.heads
        query = attn.to_q(hidden_states)
        key = attn.to_k(hidden_states)
        value = attn.to_v(hidden_states)
        head_dim = query.shape[-1] // heads

        def to_heads(x: torch.Tensor) -> torch.Tensor:
            """(B·V, L, h·d) → (G, h, T, d): G sets of V·L tokens ("(b v)" order), or B·V views of L."""
            return x.reshape(groups, -1, heads, head_dim).transpose(1, 2)

        query, key, value = to_heads(query), to_heads(key), to_heads(value)
        log_scale = getattr(attn, BIAS_PARAMETER, None)
        scale = None if token_points is None or log_scale is None else log_scale.exp()
        if self.attention == "knn":
            if num_references is None:
                raise RuntimeError("a 'knn' set-mixing layer needs cross_attention_kwargs['num_references']")
            geometry = (
                None if token_points is None else pool_token_geometry(token_points, tokens).grouped(sets)
            )
            mixed = nearest_reference_attention(
                query,
                key,
                value,
                geometry,
                num_views=num_views,
                num_references=num_references,
                neighbours=self.neighbours,
                no_match_key=getattr(attn, NO_MATCH_KEY),
                no_match_value=getattr(attn, NO_MATCH_VALUE),
                bias_scale=scale,
                relative=self.relative_bias,
            )
        elif scale is not None and token_points is not None and self.relative_bias:
            geometry = pool_token_geometry(token_points, tokens).grouped(groups)
            mixed = row_biased_attention(
                query, key, value, functools.partial(relative_distance_bias, geometry, scale)
            )
        elif scale is not None and token_points is not None:
            points, valid = pool_token_points(token_points, tokens)
            mixed = biased_attention(
                query, key, value, points.reshape(groups, -1, 3), valid.reshape(groups, -1), scale
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
            num_references: int | None = None,
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


def level_attention(attention: Sequence[str], level: int) -> str:
    """The set attention of resolution ``level`` (0 = full latent grid) from a per-level list; levels
    past its end are ``full``."""
    return attention[level] if level < len(attention) else "full"


def install_set_mixer(
    unet: torch.nn.Module,
    attention: Sequence[str] = (),
    *,
    neighbours: int = 16,
    relative_bias: bool = False,
) -> list[str]:
    """Give every ``attn1`` of ``unet`` a :class:`SetSelfAttnProcessor`, every other attention the per-view one.

    Args:
        attention: the :data:`SetAttention` of each resolution level, level 0 first (missing levels:
            ``full``); ``knn`` layers get their "no match" parameters (:func:`add_no_match_parameters`).
        neighbours: k of the ``knn`` layers.
        relative_bias: biased layers use :func:`relative_distance_bias`.

    Returns:
        the processor names that now mix across views (16 for the SD-Turbo UNet).
    """
    modules = dict(unet.named_modules())
    levels = len(unet.down_blocks)
    processors: dict[str, Any] = {}
    mixed: list[str] = []
    nearest: list[str] = []
    for name in unet.attn_processors:
        module_name = name.removesuffix(".processor")
        if module_name.endswith("attn1"):
            check_self_attention(modules[module_name], module_name)
            kind = level_attention(attention, mixer_level(name, levels))
            processors[name] = SetSelfAttnProcessor(kind, neighbours, relative_bias)  # type: ignore[arg-type]
            mixed.append(name)
            if kind == "knn":
                nearest.append(name)
        else:
            processors[name] = per_view_processor_class()()
    unet.set_attn_processor(processors)
    add_no_match_parameters(unet, nearest)
    return mixed
