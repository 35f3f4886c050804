"""``benchmarks/diagnose_set_usage.py``'s attention weights of a ``knn`` set-mixing layer against the layer's own
computation: with one-hot values, :func:`nearest_reference_attention`'s output *is* its weight matrix."""

from __future__ import annotations

from types import SimpleNamespace

import torch

from benchmarks.diagnose_set_usage import knn_weights
from setdiff_bench.models.setdiff import set_mixer

SETS, HEADS, VIEWS, REFERENCES = 2, 2, 3, 2
ROWS, COLUMNS = 2, 3  # one latent cell per token
TOKENS = ROWS * COLUMNS
TOTAL = VIEWS * TOKENS
HEAD_DIM = TOTAL  # the layer's values are one-hot over the tokens


def token_points(generator: torch.Generator) -> torch.Tensor:
    """``(S·V, 5, 2, 3)``: xyz·valid, valid, footprint·valid; one reference token without a surface point."""
    xyz = torch.randn(SETS * VIEWS, 3, ROWS, COLUMNS, generator=generator)
    valid = torch.ones(SETS * VIEWS, 1, ROWS, COLUMNS)
    valid[1, 0, 0, 2] = 0.0
    footprint = 0.5 + torch.rand(SETS * VIEWS, 1, ROWS, COLUMNS, generator=generator)
    return torch.cat([xyz * valid, valid, footprint * valid], dim=1)


def test_knn_weights_equal_the_layers_own_attention() -> None:
    generator = torch.Generator().manual_seed(3)
    query = torch.randn(SETS, HEADS, TOTAL, HEAD_DIM, generator=generator)
    key = torch.randn(SETS, HEADS, TOTAL, HEAD_DIM, generator=generator)
    no_match_key = torch.randn(HEADS * HEAD_DIM, generator=generator)
    points = token_points(generator)
    scale = torch.tensor(0.7)
    geometry = set_mixer.pool_token_geometry(points, TOKENS).grouped(SETS)
    one_hot = torch.eye(TOTAL).expand(SETS, HEADS, TOTAL, TOTAL)
    expected = set_mixer.nearest_reference_attention(
        query,
        key,
        one_hot,
        geometry,
        num_views=VIEWS,
        num_references=REFERENCES,
        neighbours=2,
        no_match_key=no_match_key,
        no_match_value=torch.zeros(HEADS * HEAD_DIM),
        bias_scale=scale,
        relative=True,
    ).mean(dim=(0, 1))
    logits = query @ key.transpose(-1, -2) / HEAD_DIM**0.5
    logits = logits + set_mixer.relative_distance_bias(geometry, scale)
    actual = knn_weights(
        SimpleNamespace(neighbours=2),
        SimpleNamespace(**{set_mixer.NO_MATCH_KEY: no_match_key}),
        logits,
        query,
        {"token_points": points, "num_references": REFERENCES},
        SETS,
        VIEWS,
        TOKENS,
    )
    torch.testing.assert_close(actual, expected, rtol=1e-5, atol=1e-6)
    # every row misses the "no match" key's share; a target token reaches at most k = 2 reference tokens per set
    assert bool((actual.sum(-1) < 1).all())
    assert int((actual[TOKENS * REFERENCES :, : TOKENS * REFERENCES] > 0).sum(-1).max()) <= 2 * SETS
