"""Loading a local diffusers-format folder (tiny networks saved the way the SD-Turbo repo is laid out)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch

from setdiff_bench.errors import WeightsError
from setdiff_bench.models.setdiff.config import model_config_from_dict
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.presets import SD_TURBO_SCHEDULE
from tests.models.setdiff_fixtures import SD_TURBO_SCHEDULER_JSON, write_diffusers_folder


def test_loads_unet_vae_and_learned_null_text(tmp_path: Path) -> None:
    unet, vae = write_diffusers_folder(tmp_path, text=False)
    model = SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    for name, tensor in unet.state_dict().items():
        assert torch.equal(model.unet.state_dict()[name], tensor), name
    vae_state = model.codec.vae.state_dict()
    for name, tensor in vae.state_dict().items():
        if name.startswith("encoder.") or name.startswith("quant_conv"):
            assert torch.equal(vae_state[name], tensor), name
    # LoRA wraps decoder layers: the base weights are kept as base_layer
    assert torch.equal(
        vae_state["decoder.conv_in.base_layer.weight"], vae.state_dict()["decoder.conv_in.weight"]
    )
    assert model.text_embedding.requires_grad and torch.count_nonzero(model.text_embedding) == 0


def test_encodes_the_fixed_prompt_once(tmp_path: Path) -> None:
    write_diffusers_folder(tmp_path, text=True)
    model = SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    from transformers import AutoTokenizer, CLIPTextModel

    tokenizer = AutoTokenizer.from_pretrained(tmp_path / "tokenizer", local_files_only=True)
    encoder = CLIPTextModel.from_pretrained(tmp_path / "text_encoder", local_files_only=True)
    ids = tokenizer(
        "remove degradation", padding="max_length", max_length=77, truncation=True, return_tensors="pt"
    ).input_ids
    with torch.no_grad():
        expected = encoder(ids).last_hidden_state
    assert not model.text_embedding.requires_grad
    torch.testing.assert_close(model.text_embedding.data, expected)


def test_missing_parts_and_mismatches(tmp_path: Path) -> None:
    with pytest.raises(WeightsError, match="no unet/"):
        SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    write_diffusers_folder(tmp_path, text=False)
    with pytest.raises(WeightsError, match="block_out_channels"):
        SetDiffModel(
            model_config_from_dict(
                {"preset": "tiny", "pretrained": str(tmp_path), "unet": {"block_out_channels": [32, 96]}}
            )
        )
    schedule = {**SD_TURBO_SCHEDULER_JSON, "beta_end": 0.02}
    (tmp_path / "scheduler" / "scheduler_config.json").write_text(json.dumps(schedule))
    with pytest.raises(WeightsError, match="beta_end"):
        SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    assert SD_TURBO_SCHEDULE["beta_end"] == SD_TURBO_SCHEDULER_JSON["beta_end"]


def test_training_from_pretrained_resumes_with_frozen_prompt(tmp_path: Path) -> None:
    """The resolved text-embedding choice is saved, so a resumed run has the same trainable parameters."""
    import dataclasses

    from setdiff_bench.models.setdiff.checkpoint import load_model, read_config
    from setdiff_bench.models.setdiff.train import train
    from tests.models.setdiff_fixtures import make_sample, tiny_config

    write_diffusers_folder(tmp_path / "sd", text=True)
    config = tiny_config(pretrained=str(tmp_path / "sd"))
    config = dataclasses.replace(config, train=dataclasses.replace(config.train, steps=1))
    first = train(config, [make_sample(1, 1)], tmp_path / "run", progress=False)
    assert read_config(first.checkpoint).model.learn_text_embedding is False
    prompt = load_model(first.checkpoint)[0].text_embedding.detach().clone()
    config = dataclasses.replace(config, train=dataclasses.replace(config.train, steps=2))
    second = train(config, [make_sample(1, 1)], tmp_path / "run", progress=False)
    assert second.step == 2
    resumed, _ = load_model(second.checkpoint)
    assert torch.equal(resumed.text_embedding.detach(), prompt)
