"""Training: the tiny model learns, resumes exactly, draws valid sets, and never drops a loss term."""

from __future__ import annotations

import dataclasses
import json
import random
import sys
import types
from pathlib import Path

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from safetensors.torch import load_file

from setdiff_bench.errors import CheckpointError, WeightsError
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.models.setdiff.checkpoint import load_model, resolve_checkpoint
from setdiff_bench.models.setdiff.config import Config
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.inputs import choose_views, training_set
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.train import train
from tests.models.setdiff_fixtures import DIFIX, make_sample, tiny_config


def with_train(config: Config, **changes: object) -> Config:
    return dataclasses.replace(config, train=dataclasses.replace(config.train, **changes))


def overfit(
    tmp_path: Path, refs: int, targets: int, steps: int, decode: int = 1
) -> tuple[torch.Tensor, torch.Tensor]:
    """PSNR of the targets before and after training ``steps`` steps on one sample."""
    config = with_train(
        tiny_config(skip_connections=True, vae_decoder="full"),
        steps=steps,
        min_views=12,
        max_views=12,
        log_every=steps,
        checkpoint_every=steps,
        decode_targets=decode,
    )
    sample = make_sample(refs, targets)
    torch.manual_seed(config.train.seed)
    initial = SetDiffModel(config.model).eval()
    before = psnr(enhance_packet(initial, sample.packet), sample.target_gt)
    result = train(config, [sample], tmp_path, progress=False)
    trained, _ = load_model(result.checkpoint)
    after = psnr(enhance_packet(trained, sample.packet), sample.target_gt)
    return before, after


def test_tiny_model_overfits_one_packet(tmp_path: Path) -> None:
    """Target PSNR rises by >= 10 dB within 200 steps (1 reference, 2 targets, one decoded per step)."""
    before, after = overfit(tmp_path, refs=1, targets=2, steps=200)
    assert bool(((after - before) >= 10.0).all()), (before.tolist(), after.tolist())


@pytest.mark.slow
def test_tiny_model_overfits_larger_set(tmp_path: Path) -> None:
    """3 references + 3 targets, every target decoded each step (~60 s on a loaded 2-core machine)."""
    before, after = overfit(tmp_path, refs=3, targets=3, steps=200, decode=0)
    assert bool(((after - before) >= 10.0).all()), (before.tolist(), after.tolist())


def test_resume_continues_exactly(tmp_path: Path) -> None:
    config = with_train(tiny_config(), steps=4, checkpoint_every=2)
    samples = [make_sample(2, 2, seed=s) for s in range(3)]
    straight = train(config, samples, tmp_path / "straight", progress=False)
    train(with_train(config, steps=2), samples, tmp_path / "split", progress=False)
    resumed = train(config, samples, tmp_path / "split", progress=False)
    assert resumed.step == straight.step == 4
    a = load_file(str(resolve_checkpoint(tmp_path / "straight") / "model.safetensors"))
    b = load_file(str(resolve_checkpoint(tmp_path / "split") / "model.safetensors"))
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    log = [json.loads(line) for line in (tmp_path / "split" / "train_log.jsonl").read_text().splitlines()]
    assert [r["step"] for r in log] == [1, 2, 3, 4]


def test_resume_refuses_another_configuration(tmp_path: Path) -> None:
    config = with_train(tiny_config(), steps=1)
    train(config, [make_sample(1, 1)], tmp_path, progress=False)
    other = with_train(tiny_config(geometry_channels=[8, 8, 8, 8, 8]), steps=2)
    with pytest.raises(CheckpointError, match=r"another configuration.*geometry_channels"):
        train(other, [make_sample(1, 1)], tmp_path, progress=False)


def test_validation_and_logs(tmp_path: Path) -> None:
    config = with_train(tiny_config(), steps=2, validate_every=1, validation_packets=1)
    result = train(
        config, [make_sample(2, 2)], tmp_path, validation=[make_sample(1, 2, seed=9)], progress=False
    )
    assert [r["step"] for r in result.validation] == [1, 2]
    assert {"psnr", "ssim"} <= set(result.validation[-1])
    lines = (tmp_path / "validation.jsonl").read_text().splitlines()
    assert len(lines) == 2
    assert {"latent", "l2", "ssim", "loss"} <= set(result.losses)


def test_lpips_term_is_never_dropped_silently(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """With an LPIPS weight the trainer needs LPIPS weights; missing ones raise WeightsError."""

    def missing(*args: object, **kwargs: object) -> None:
        raise WeightsError("LPIPS trunk weights not found", "vgg16.pth")

    fake = types.ModuleType("setdiff_bench.metrics.lpips")
    fake.load_lpips = missing  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "setdiff_bench.metrics.lpips", fake)
    config = with_train(tiny_config(), steps=1, lpips_weight=1.0)
    with pytest.raises(WeightsError):
        train(config, [make_sample(1, 1)], tmp_path, progress=False)
    assert not (tmp_path / "latest").exists()


def test_difix_trains_on_pairs(tmp_path: Path) -> None:
    config = with_train(tiny_config(**DIFIX), steps=2)
    result = train(config, [make_sample(3, 2)], tmp_path, progress=False)
    model, saved = load_model(result.checkpoint, method="difix")
    assert saved.model.method == "difix"
    assert model.geometry_encoder is None


def test_difix_pairs_use_best_reference() -> None:
    sample = make_sample(3, 2)
    # target 0's camera is closest to reference 0 (same yaw and position offsets, see the fixtures)
    drawn = training_set(
        sample, random.Random(0), min_views=8, max_views=8, use_geometry=False, cmap_clip=0.0, pairs=True
    )
    assert drawn.batch.num_references == 1 and drawn.batch.num_targets == 1
    references = sample.packet.references.images
    chosen = drawn.batch.images[0, 0]
    index = next(i for i in range(3) if torch.equal(references[i], chosen))
    target = next(i for i in range(2) if torch.equal(sample.target_gt[i], drawn.target_gt[0, 0]))
    assert index == target  # reference i sits at yaw 7i+0.15°, x 0.1i+0.05: nearest to target i


@settings(max_examples=60, deadline=None)
@given(
    refs=st.integers(0, 12),
    targets=st.integers(1, 12),
    low=st.integers(2, 10),
    extra=st.integers(0, 6),
    seed=st.integers(0, 10_000),
)
def test_choose_views(refs: int, targets: int, low: int, extra: int, seed: int) -> None:
    high = low + extra
    reference_ids, target_ids = choose_views(
        refs, targets, random.Random(seed), min_views=low, max_views=high
    )
    size = len(reference_ids) + len(target_ids)
    assert size <= min(high, refs + targets)
    assert size >= min(low, refs + targets) or len(target_ids) == targets
    assert len(target_ids) >= 1
    assert refs == 0 or len(reference_ids) >= 1
    assert len(set(reference_ids)) == len(reference_ids) and set(reference_ids) <= set(range(refs))
    assert len(set(target_ids)) == len(target_ids) and set(target_ids) <= set(range(targets))
