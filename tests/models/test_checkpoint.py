"""Checkpoints: exact round trip, clear errors for other configurations and broken files."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from setdiff_bench.errors import CheckpointError
from setdiff_bench.models.setdiff.checkpoint import load_model, mark_latest, save_checkpoint, step_folder
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.model import SetDiffModel
from tests.models.setdiff_fixtures import make_packet, perturbed_model


def test_round_trip_is_bit_identical(tmp_path: Path) -> None:
    model, config = perturbed_model()
    packet = make_packet(2, 3)
    before = enhance_packet(model, packet)
    save_checkpoint(tmp_path / "ckpt", model, config)
    loaded, saved = load_model(tmp_path / "ckpt")
    assert saved.model == model.config and saved.model.learn_text_embedding is True
    assert torch.equal(enhance_packet(loaded, packet), before)
    reference_state, loaded_state = model.state_dict(), loaded.state_dict()
    assert reference_state.keys() == loaded_state.keys()
    assert all(torch.equal(reference_state[k], loaded_state[k]) for k in reference_state)
    assert any("lora_B" in k for k in loaded_state)


def test_training_folder_resolves_to_latest(tmp_path: Path) -> None:
    model, config = perturbed_model()
    for step in (1, 2, 3):
        folder = save_checkpoint(step_folder(tmp_path, step), model, config, step=step)
        mark_latest(tmp_path, folder, keep=2)
    assert sorted(p.name for p in (tmp_path / "checkpoints").iterdir()) == ["step-00000002", "step-00000003"]
    assert (tmp_path / "latest").read_text().strip() == "checkpoints/step-00000003"
    loaded, _ = load_model(tmp_path)
    assert isinstance(loaded, SetDiffModel)


def test_other_configuration_is_refused(tmp_path: Path) -> None:
    model, config = perturbed_model()
    save_checkpoint(tmp_path / "ckpt", model, config)
    other = dataclasses.replace(config, model=dataclasses.replace(config.model, vae_lora_rank=8))
    with pytest.raises(CheckpointError, match="another configuration: model vae_lora_rank"):
        load_model(tmp_path / "ckpt", expected=other)
    with pytest.raises(CheckpointError, match="trained as method 'setdiff', not 'difix'"):
        load_model(tmp_path / "ckpt", method="difix")


def test_inference_settings_do_not_block_loading(tmp_path: Path) -> None:
    model, config = perturbed_model()
    save_checkpoint(tmp_path / "ckpt", model, config)
    other = dataclasses.replace(
        config, model=dataclasses.replace(config.model, guidance_scale=3.0, cfg_batched=False)
    )
    load_model(tmp_path / "ckpt", expected=other)


def test_weights_that_do_not_fit_are_refused(tmp_path: Path) -> None:
    model, config = perturbed_model()
    save_checkpoint(tmp_path / "ckpt", model, config)
    # config.json says one thing, the weights another
    small, small_config = perturbed_model({"skip_connections": True, "geometry_channels": [8, 8, 8, 8, 8]})
    save_checkpoint(tmp_path / "other", small, small_config)
    (tmp_path / "ckpt" / "model.safetensors").write_bytes(
        (tmp_path / "other" / "model.safetensors").read_bytes()
    )
    with pytest.raises(CheckpointError, match="shape"):
        load_model(tmp_path / "ckpt")
    (tmp_path / "ckpt" / "model.safetensors").write_bytes(b"not a safetensors file")
    with pytest.raises(CheckpointError, match="cannot read weights"):
        load_model(tmp_path / "ckpt")


def test_missing_checkpoint(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="not found"):
        load_model(tmp_path / "nothing")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CheckpointError, match="not a checkpoint"):
        load_model(tmp_path / "empty")


def test_save_leaves_no_partial_folder(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    model, config = perturbed_model()

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(torch, "save", broken)
    optimizer = torch.optim.AdamW(model.trainable_parameters())
    with pytest.raises(OSError, match="disk full"):
        save_checkpoint(tmp_path / "ckpt", model, config, optimizer=optimizer, step=1)
    assert list(tmp_path.iterdir()) == []
