"""CUDA paths (skipped without a GPU): bf16 inference close to float32, and bf16 training under accelerate."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest
import torch

from setdiff_bench.models.setdiff.checkpoint import load_model, save_checkpoint
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.train import train
from tests.models.setdiff_fixtures import make_packet, make_sample, tiny_config

pytestmark = [pytest.mark.gpu, pytest.mark.skipif(not torch.cuda.is_available(), reason="needs CUDA")]


def test_bf16_inference_matches_float32(tmp_path: Path) -> None:
    config = tiny_config(skip_connections=True)
    torch.manual_seed(0)
    save_checkpoint(tmp_path / "ckpt", SetDiffModel(config.model), config)
    packet = make_packet(3, 4, size=(64, 64))
    reference, _ = load_model(tmp_path / "ckpt")
    expected = enhance_packet(reference, packet)
    fast, _ = load_model(tmp_path / "ckpt", device="cuda", dtype=torch.bfloat16)
    output = enhance_packet(fast, packet)
    assert output.device.type == "cpu" and output.dtype == torch.float32
    assert float((output - expected).abs().mean()) < 2e-2


def test_bf16_training_step(tmp_path: Path) -> None:
    config = tiny_config(skip_connections=True)
    config = dataclasses.replace(
        config, train=dataclasses.replace(config.train, steps=2, mixed_precision="bf16")
    )
    result = train(config, [make_sample(2, 2)], tmp_path, device="cuda", progress=False)
    assert result.step == 2 and all(torch.isfinite(torch.tensor(list(result.losses.values()))))
