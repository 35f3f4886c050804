"""Fine-tunes (``[train] init_from``) and students may restrict what the set mixer attends to: they start
from the source model's weights (a ``knn`` level's "no match" key and value at zero), any other
architecture difference is refused in one line, and the exported manifest names the source by hash."""

from __future__ import annotations

import hashlib
import json
from dataclasses import replace
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file

from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from setdiff_bench.models.setdiff.config import Config
from setdiff_bench.models.setdiff.export import export_enhancer
from setdiff_bench.models.setdiff.train import train
from tests.models.setdiff_fixtures import make_sample, perturbed_model


def source_folder(tmp_path: Path) -> tuple[Path, Config]:
    """A trained-looking tiny model (full set attention, CFG 1.5) saved as a checkpoint."""
    model, config = perturbed_model({"skip_connections": True, "guidance_scale": 1.5})
    config = replace(config, model=replace(config.model, guidance_scale=1.5))
    folder = tmp_path / "source"
    save_checkpoint(folder, model, config)
    return folder, config


def samples() -> list:
    return [make_sample(2, 2, size=(32, 32), seed=s) for s in range(2)]


def test_a_fine_tune_with_knn_attention_starts_from_the_source(tmp_path: Path) -> None:
    folder, config = source_folder(tmp_path)
    knn = replace(
        config,
        model=replace(config.model, set_attention=("knn",), set_attention_neighbours=4),
        train=replace(config.train, init_from=str(folder), steps=1, learning_rate=0.0),
    )
    run = train(knn, samples(), tmp_path / "knn", device="cpu", progress=False)
    source = load_file(folder / "model.safetensors")
    tuned = load_file(run.checkpoint / "model.safetensors")
    added = sorted(set(tuned) - set(source))
    assert added and all(name.endswith(("set_no_match_key", "set_no_match_value")) for name in added)
    assert set(source) <= set(tuned)
    assert all(torch.equal(source[k], tuned[k]) for k in source)  # lr 0: the source's weights
    assert all(not tuned[k].any() for k in added)  # the new "no match" pair starts at zero
    exported = export_enhancer(run.checkpoint, {"format": "test"}, tmp_path / "exported")
    manifest = json.loads((exported / "manifest.json").read_text())
    assert manifest["initialised_from"] == {
        "model": str(folder),
        "weights_sha256": hashlib.sha256((folder / "model.safetensors").read_bytes()).hexdigest(),
    }


def test_a_fine_tune_of_another_architecture_is_refused(tmp_path: Path) -> None:
    folder, config = source_folder(tmp_path)
    other = replace(
        config,
        model=replace(config.model, skip_connections=False),
        train=replace(config.train, init_from=str(folder), steps=1),
    )
    with pytest.raises(CheckpointError, match="skip_connections"):
        train(other, samples(), tmp_path / "other", device="cpu", progress=False)
    with pytest.raises(UsageError, match="exclude each other"):
        replace(config.train, init_from=str(folder), distill_from=str(folder))


def test_a_student_may_restrict_set_attention(tmp_path: Path) -> None:
    folder, config = source_folder(tmp_path)
    student = replace(
        config,
        model=replace(config.model, guidance_scale=1.0, geometry_dropout=0.0, set_attention=("view",)),
        train=replace(config.train, distill_from=str(folder), steps=1, learning_rate=0.0),
    )
    run = train(student, samples(), tmp_path / "student", device="cpu", progress=False)
    source = load_file(folder / "model.safetensors")
    tuned = load_file(run.checkpoint / "model.safetensors")
    assert source.keys() == tuned.keys() and all(torch.equal(source[k], tuned[k]) for k in source)
    assert run.losses["latent"] > 0  # per-view attention at level 0 is not the teacher's guided output
    manifest = json.loads(
        (
            export_enhancer(run.checkpoint, {"format": "test"}, tmp_path / "exported") / "manifest.json"
        ).read_text()
    )
    assert "folder" not in manifest["distillation"]  # no machine path beyond the config's own name
