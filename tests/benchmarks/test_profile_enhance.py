"""The pieces of ``benchmarks/profile_enhance.py`` whose numbers the GPU profile relies on: the token count per
level (hand-derived), the per-view option (an analytic property: a view's output no longer depends on the
other views) and the hooks (they time without changing the output)."""

from __future__ import annotations

import torch

from benchmarks.profile_enhance import (
    BlockTimer,
    all_views_per_call,
    set_attention_only_at,
    tokens_per_level,
    watch_unet,
)
from setdiff_bench.models.setdiff import model as model_module
from tests.models.setdiff_fixtures import residual_model


def test_tokens_per_level_at_the_paper_size() -> None:
    # 576×1024 / 8 = 72×128 latent cells; each level halves both sides
    assert tokens_per_level(576, 1024, 8, 4) == {"L0": 9216, "L1": 2304, "L2": 576, "L3": 144, "mid": 144}
    # odd sides round up, as the UNet's downsamplers do: 144×256/8 = 18×32 → 9×16 → 5×8
    assert tokens_per_level(144, 256, 8, 3) == {"L0": 576, "L1": 144, "L2": 40, "mid": 40}


def _unet_outputs(model: torch.nn.Module, latents: torch.Tensor) -> torch.Tensor:
    with torch.no_grad():
        return model.unet_output(latents, num_views=latents.shape[0])


def test_per_view_attention_makes_views_independent_and_is_undone() -> None:
    model = residual_model(output_mode="direct")
    generator = torch.Generator().manual_seed(0)
    latents = torch.randn(3, model.config.latent_channels, 8, 8, generator=generator)
    changed = latents.clone()
    changed[2] = torch.randn(changed[2].shape, generator=generator)
    mixed = _unet_outputs(model, latents)
    assert not torch.allclose(mixed[0], _unet_outputs(model, changed)[0])  # the set mixer couples the views
    with set_attention_only_at(model, keep=set()):
        alone = _unet_outputs(model, latents)
        assert torch.equal(alone[0], _unet_outputs(model, changed)[0])  # view 0 no longer sees view 2
    assert torch.equal(_unet_outputs(model, latents), mixed)  # processors restored
    levels = {f"L{level}" for level in range(len(model.unet.down_blocks))} | {"mid"}
    with set_attention_only_at(model, keep=levels):
        assert torch.equal(_unet_outputs(model, latents), mixed)  # every level kept: nothing changes


def test_hooks_time_every_block_without_changing_the_output() -> None:
    model = residual_model(output_mode="direct")
    latents = torch.randn(2, model.config.latent_channels, 8, 8, generator=torch.Generator().manual_seed(1))
    plain = _unet_outputs(model, latents)
    timer = BlockTimer(cuda=False)
    watch_unet(timer, model)
    timed = _unet_outputs(model, latents)
    totals = timer.totals()
    timer.remove()
    assert torch.equal(timed, plain)
    assert {f"block:down_blocks.{i}" for i in range(len(model.unet.down_blocks))} <= set(totals)
    assert any(label.startswith("part:set attention (attn1)") for label in totals)
    assert all(ms >= 0 for ms in totals.values())
    assert not model.unet._forward_hooks and not model.unet.down_blocks[0]._forward_pre_hooks


def test_all_views_per_call_lifts_the_chunks_and_restores_them() -> None:
    before = model_module.views_per_chunk(576, 1024)
    with all_views_per_call():
        assert model_module.views_per_chunk(576, 1024) >= 1024
    assert model_module.views_per_chunk(576, 1024) == before == 3
