"""Loading a local diffusers-format folder (tiny networks saved the way the SD-Turbo repo is laid out)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from diffusers import AutoencoderKL, UNet2DConditionModel

from setdiff_bench.errors import WeightsError
from setdiff_bench.models.setdiff.config import SD_TURBO_SCHEDULE, TINY_UNET, TINY_VAE, model_config_from_dict
from setdiff_bench.models.setdiff.model import SetDiffModel

# The scheduler_config.json of stabilityai/sd-turbo (shared/reference/model.md §4.3).
SD_TURBO_SCHEDULER_JSON = {
    "_class_name": "EulerDiscreteScheduler", "beta_start": 0.00085, "beta_end": 0.012,
    "beta_schedule": "scaled_linear", "clip_sample": False, "interpolation_type": "linear",
    "num_train_timesteps": 1000, "prediction_type": "epsilon", "sample_max_value": 1.0,
    "set_alpha_to_one": False, "sigma_max": None, "sigma_min": None, "skip_prk_steps": True,
    "steps_offset": 1, "timestep_spacing": "trailing", "timestep_type": "discrete",
    "trained_betas": None, "use_karras_sigmas": False,
}


def write_folder(root: Path, *, text: bool) -> tuple[UNet2DConditionModel, AutoencoderKL]:
    torch.manual_seed(3)
    unet = UNet2DConditionModel.from_config(dict(TINY_UNET))
    vae = AutoencoderKL.from_config(dict(TINY_VAE))
    unet.save_pretrained(root / "unet")
    vae.save_pretrained(root / "vae")
    (root / "scheduler").mkdir(parents=True)
    (root / "scheduler" / "scheduler_config.json").write_text(json.dumps(SD_TURBO_SCHEDULER_JSON))
    if text:
        from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer

        vocab = {"<|startoftext|>": 0, "<|endoftext|>": 1}
        for letter in "abcdefghijklmnopqrstuvwxyz":
            vocab[letter] = len(vocab)
            vocab[letter + "</w>"] = len(vocab)
        (root / "raw").mkdir()
        (root / "raw" / "vocab.json").write_text(json.dumps(vocab))
        (root / "raw" / "merges.txt").write_text("#version: 0.2\n")
        CLIPTokenizer(str(root / "raw" / "vocab.json"), str(root / "raw" / "merges.txt")).save_pretrained(
            root / "tokenizer")
        encoder = CLIPTextModel(CLIPTextConfig(vocab_size=len(vocab), hidden_size=32, intermediate_size=64,
                                               num_hidden_layers=1, num_attention_heads=2, max_position_embeddings=77,
                                               bos_token_id=0, eos_token_id=1, pad_token_id=1))
        encoder.save_pretrained(root / "text_encoder")
    return unet, vae


def test_loads_unet_vae_and_learned_null_text(tmp_path: Path) -> None:
    unet, vae = write_folder(tmp_path, text=False)
    model = SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    for name, tensor in unet.state_dict().items():
        assert torch.equal(model.unet.state_dict()[name], tensor), name
    vae_state = model.codec.vae.state_dict()
    for name, tensor in vae.state_dict().items():
        if name.startswith("encoder.") or name.startswith("quant_conv"):
            assert torch.equal(vae_state[name], tensor), name
    # LoRA wraps decoder layers: the base weights are kept as base_layer
    assert torch.equal(vae_state["decoder.conv_in.base_layer.weight"], vae.state_dict()["decoder.conv_in.weight"])
    assert model.text_embedding.requires_grad and torch.count_nonzero(model.text_embedding) == 0


def test_encodes_the_fixed_prompt_once(tmp_path: Path) -> None:
    write_folder(tmp_path, text=True)
    model = SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    from transformers import AutoTokenizer, CLIPTextModel

    tokenizer = AutoTokenizer.from_pretrained(tmp_path / "tokenizer", local_files_only=True)
    encoder = CLIPTextModel.from_pretrained(tmp_path / "text_encoder", local_files_only=True)
    ids = tokenizer("remove degradation", padding="max_length", max_length=77, truncation=True,
                    return_tensors="pt").input_ids
    with torch.no_grad():
        expected = encoder(ids).last_hidden_state
    assert not model.text_embedding.requires_grad
    torch.testing.assert_close(model.text_embedding.data, expected)


def test_missing_parts_and_mismatches(tmp_path: Path) -> None:
    with pytest.raises(WeightsError, match="no unet/"):
        SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    write_folder(tmp_path, text=False)
    with pytest.raises(WeightsError, match="block_out_channels"):
        SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path),
                                             "unet": {"block_out_channels": [32, 96]}}))
    schedule = {**SD_TURBO_SCHEDULER_JSON, "beta_end": 0.02}
    (tmp_path / "scheduler" / "scheduler_config.json").write_text(json.dumps(schedule))
    with pytest.raises(WeightsError, match="beta_end"):
        SetDiffModel(model_config_from_dict({"preset": "tiny", "pretrained": str(tmp_path)}))
    assert SD_TURBO_SCHEDULE["beta_end"] == SD_TURBO_SCHEDULER_JSON["beta_end"]
