"""EUVS DINOv2 masked cosine and Final_Score, with a small random network of the hub interface."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from setdiff_bench.errors import WeightsError
from setdiff_bench.metrics.dinov2 import (
    final_score,
    load_dinov2,
    masked_cosine,
    preprocess_image,
    preprocess_mask,
)


class PatchNet(torch.nn.Module):
    """14x14 patch embedding without bias: ``get_intermediate_layers`` returns patch tokens only (hub semantics)."""

    def __init__(self) -> None:
        super().__init__()
        torch.manual_seed(0)
        self.embed = torch.nn.Conv2d(3, 8, 14, stride=14, bias=False)

    def get_intermediate_layers(self, x: torch.Tensor, n: int = 1) -> tuple[torch.Tensor]:
        return (self.embed(x).flatten(2).transpose(1, 2),)


def test_constant_images_give_the_hand_computed_cosine():
    net = PatchNet()
    render = np.full((518, 518, 3), (255, 0, 51), np.uint8)
    truth = np.full((518, 518, 3), (0, 255, 102), np.uint8)
    # every patch of a constant image embeds to sum_c v_c * S_c, S_c = spatial sum of the filter weights
    s = net.embed.weight.detach().double().sum(dim=(2, 3))  # (8, 3)
    v1 = (torch.tensor([255, 0, 51]) / 255.0 - 0.5) / 0.5
    v2 = (torch.tensor([0, 255, 102]) / 255.0 - 0.5) / 0.5
    f1, f2 = s @ v1.double(), s @ v2.double()
    expected = float(f1 @ f2 / (f1.norm() * f2.norm()))
    value = masked_cosine(net, render, truth, np.ones((518, 518), bool))
    assert value == pytest.approx(expected, abs=1e-5)


def test_first_patch_token_is_dropped_as_the_official_slice_does():
    net = PatchNet()
    rng = np.random.default_rng(0)
    truth = rng.integers(0, 256, (518, 518, 3), dtype=np.uint8)
    render = truth.copy()
    render[:14, :14] = 255 - render[:14, :14]  # only the first patch differs
    assert masked_cosine(net, render, truth, np.ones((518, 518), bool)) == pytest.approx(1.0, abs=1e-6)
    render[:14, 14:28] = 255 - render[:14, 14:28]  # the second patch differs too
    assert masked_cosine(net, render, truth, np.ones((518, 518), bool)) < 0.9999


def test_resize_crop_geometry_and_empty_mask_gives_zero():
    # 1920x1080: shorter side -> 518, long side int(518*1920/1080) = 920, crop left round(402/2) = 201
    image = np.zeros((1080, 1920, 3), np.uint8)
    assert preprocess_image(image).shape == (1, 3, 518, 518)
    mask = np.zeros((1080, 1920), bool)
    mask[:, :200] = True  # resized columns j with floor(j*1920/920) < 200 are j <= 95 < 201: cropped away
    assert not preprocess_mask(mask).any()
    assert masked_cosine(PatchNet(), image, image, mask) == 0.0
    mask[:, 900:1000] = True
    assert preprocess_mask(mask).any()


def test_final_score_weights():
    # 0.25*0.8 + 0.15*20 + 0.35*(1-0.2) + 0.25*0.9 = 0.2 + 3 + 0.28 + 0.225
    assert final_score(0.8, 20.0, 0.2, 0.9) == pytest.approx(3.705)


def test_missing_weights_are_one_clear_error(tmp_path):
    with pytest.raises(WeightsError, match="--dinov2 DIR"):
        load_dinov2(tmp_path / "absent")
    with pytest.raises(WeightsError, match=r"model\.safetensors"):
        (tmp_path / "config.json").write_text("{}")
        load_dinov2(tmp_path)
    (tmp_path / "model.safetensors").write_bytes(b"")
    (tmp_path / "config.json").write_text('{"model_type": "vit"}')
    with pytest.raises(WeightsError, match="expected 'dinov2'"):
        load_dinov2(tmp_path)


def test_transformers_folder_adapter_returns_patch_tokens(tmp_path):
    from transformers import Dinov2Config, Dinov2Model

    torch.manual_seed(0)
    config = Dinov2Config(
        hidden_size=8,
        num_hidden_layers=1,
        num_attention_heads=2,
        intermediate_size=16,
        image_size=518,
        patch_size=14,
    )
    Dinov2Model(config).save_pretrained(tmp_path, safe_serialization=True)
    model = load_dinov2(tmp_path)
    x = preprocess_image(np.full((518, 518, 3), 128, np.uint8))
    tokens = model.get_intermediate_layers(x, n=1)[0]
    assert tokens.shape == (1, 37 * 37, 8)
    with torch.no_grad():
        full = model.model(pixel_values=x).last_hidden_state
    assert torch.allclose(tokens, full[:, 1:])
