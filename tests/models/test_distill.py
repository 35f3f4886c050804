"""Guidance distillation: the targets are the teacher's CFG output (recomputed here from the UNet by hand),
a student step runs from the teacher's weights, and the exported student enhances in one UNet pass."""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from setdiff_bench.errors import UsageError
from setdiff_bench.models.setdiff.checkpoint import load_model, save_checkpoint
from setdiff_bench.models.setdiff.config import Config
from setdiff_bench.models.setdiff.distill import check_student_config, distillation_targets
from setdiff_bench.models.setdiff.export import export_enhancer
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.train import train
from tests.models.setdiff_fixtures import geometry_set, make_packet, make_sample, perturbed_model

#: ᾱ at t = 199 of SD-Turbo's scaled-linear schedule (docs/model.md, "SD-Turbo schedule at t = 199").
ALPHA_BAR = 0.7552384


def teacher_folder(tmp_path: Path) -> tuple[Path, Config]:
    """A tiny teacher (Ψ, LoRA and text made non-zero so geometry matters) saved as a checkpoint, CFG 1.5."""
    model, config = perturbed_model({"skip_connections": True, "guidance_scale": 1.5})
    config = replace(config, model=replace(config.model, guidance_scale=1.5))
    with torch.no_grad():
        model.unet.conv_out.weight.mul_(3.0)
    folder = tmp_path / "teacher"
    save_checkpoint(folder, model, config)
    return folder, config


def student_config(teacher: Path, config: Config, **train: object) -> Config:
    return replace(
        config,
        model=replace(config.model, guidance_scale=1.0, geometry_dropout=0.0),
        train=replace(config.train, distill_from=str(teacher), **train),
    )


def test_targets_are_the_teachers_cfg_output(tmp_path: Path) -> None:
    folder, _ = teacher_folder(tmp_path)
    teacher, _ = load_model(folder)
    batch = geometry_set().batch
    targets = distillation_targets(teacher, batch, 1.5, torch.tensor([0, 1]))
    with torch.no_grad():  # by hand: two UNet passes, v = u + s·(c − u), x̂0 = √ᾱ·z − √(1−ᾱ)·v
        images = batch.images[0]
        latents = teacher.encode(images).latents
        g = teacher.geometry_encoder(batch.geometry[0])
        text = teacher.text_embedding.expand(4, -1, -1)
        timestep = torch.full((4,), 199)
        kwargs = {"num_views": 4}
        c = teacher.unet(
            latents + g, timestep, encoder_hidden_states=text, cross_attention_kwargs=kwargs
        ).sample
        u = teacher.unet(latents, timestep, encoder_hidden_states=text, cross_attention_kwargs=kwargs).sample
        x0 = math.sqrt(ALPHA_BAR) * latents - math.sqrt(1 - ALPHA_BAR) * (u + 1.5 * (c - u))
        single = math.sqrt(ALPHA_BAR) * latents - math.sqrt(1 - ALPHA_BAR) * c
    torch.testing.assert_close(targets.target_x0[0], x0[2:], atol=2e-5, rtol=1e-4)
    assert float((x0[2:] - single[2:]).abs().max()) > 1e-3  # guidance does change the output
    enhanced = teacher.enhance(batch, guidance_scale=1.5)  # the inference path
    torch.testing.assert_close(targets.decoded, enhanced, atol=2e-5, rtol=1e-4)


def test_a_student_step_starts_from_the_teacher(tmp_path: Path) -> None:
    folder, config = teacher_folder(tmp_path)
    samples = [make_sample(2, 2, size=(32, 32), seed=s) for s in range(2)]
    frozen = student_config(folder, config, steps=1, learning_rate=0.0)
    result = train(frozen, samples, tmp_path / "still", device="cpu", progress=False)
    teacher_weights = load_file(folder / "model.safetensors")
    student_weights = load_file(result.checkpoint / "model.safetensors")
    assert teacher_weights.keys() == student_weights.keys()
    assert all(
        torch.equal(teacher_weights[k], student_weights[k]) for k in teacher_weights
    )  # lr 0: the teacher
    assert result.losses["latent"] > 0  # one pass is not yet the guided output


def test_student_config_is_checked(tmp_path: Path) -> None:
    folder, config = teacher_folder(tmp_path)
    with pytest.raises(UsageError, match="guidance_scale = 1"):
        check_student_config(
            replace(student_config(folder, config), model=replace(config.model, geometry_dropout=0.0))
        )
    with pytest.raises(UsageError, match="geometry_dropout = 0"):
        check_student_config(
            replace(student_config(folder, config), model=replace(config.model, guidance_scale=1.0))
        )


def count_unet_calls(model) -> list[int]:
    """The batch size of every UNet call the model makes from now on."""
    calls: list[int] = []
    model.unet.register_forward_hook(lambda module, args, output: calls.append(int(args[0].shape[0])))
    return calls


def test_exported_student_runs_one_unet_pass(tmp_path: Path) -> None:
    folder, config = teacher_folder(tmp_path)
    run = train(
        student_config(folder, config, steps=1),
        [make_sample(2, 2, size=(32, 32))],
        tmp_path / "run",
        device="cpu",
        progress=False,
    )
    teacher_weights = load_file(folder / "model.safetensors")
    after = load_file(run.checkpoint / "model.safetensors")
    assert any(not torch.equal(teacher_weights[k], after[k]) for k in teacher_weights)  # it learned
    saved = json.loads((run.checkpoint / "config.json").read_text())
    assert saved["model"]["guidance_scale"] == 1.0 and saved["train"]["distill_from"] == str(folder)
    exported = export_enhancer(run.checkpoint, {"format": "test"}, tmp_path / "student")
    manifest = json.loads((exported / "manifest.json").read_text())
    assert manifest["distillation"]["guidance_scale"] == 1.5
    assert (
        manifest["distillation"]["weights_sha256"]
        == hashlib.sha256((folder / "model.safetensors").read_bytes()).hexdigest()
    )
    packet = make_packet(2, 3, size=(32, 32), seed=5)
    student, _ = load_model(exported)
    calls = count_unet_calls(student)
    enhance_packet(student, packet)
    assert calls == [5]  # one pass over the 5 views, no unconditional branch
    teacher, _ = load_model(folder)
    teacher_calls = count_unet_calls(teacher)
    enhance_packet(teacher, packet)
    assert teacher_calls == [10]  # both CFG branches batched
