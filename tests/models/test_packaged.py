"""Shipped models: intact files, loading by name, training scenes disjoint from the demo's test scenes, and
``weights export`` / ``verify`` on a training run."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
import torch

from setdiff_bench.cli.main import main
from setdiff_bench.errors import CheckpointError, UsageError
from setdiff_bench.models.setdiff.checkpoint import (
    load_model,
    mark_latest,
    read_config,
    resolve_checkpoint,
    save_checkpoint,
    step_folder,
)
from setdiff_bench.models.setdiff.files import MANIFEST_FILE
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.models.setdiff.manifest import record_training_session, synthetic_scene_seeds
from setdiff_bench.models.setdiff.packaged import packaged_models, packaged_root, verify
from setdiff_bench.pipeline.demo import SHIPPED_MODELS, check_unseen, evaluation_scene_indices
from setdiff_bench.pipeline.presets import DEMO_PRESETS
from tests.models.setdiff_fixtures import make_packet, perturbed_model

SHIPPED = packaged_models()


def test_every_shipped_model_matches_its_manifest_hashes() -> None:
    assert "tiny_autoencoder" in SHIPPED
    for model in SHIPPED.values():
        files = model.manifest["files"]
        assert set(files) == {p.name for p in model.folder.iterdir() if p.is_file()} - {MANIFEST_FILE}
        for name, expected in files.items():  # hashed here with hashlib, independently of verify()
            assert hashlib.sha256((model.folder / name).read_bytes()).hexdigest() == expected, (
                model.name,
                name,
            )
        assert verify(model) == []
        assert model.size_bytes() <= 15e6


@pytest.mark.parametrize("method", sorted(SHIPPED_MODELS))
def test_shipped_enhancers_load_by_name_and_were_trained_on_other_scenes(method: str) -> None:
    name = SHIPPED_MODELS[method]
    if name not in SHIPPED:
        pytest.fail(f"{name} is not shipped in {packaged_root()}")
    assert resolve_checkpoint(name) == SHIPPED[name].folder
    _, config = load_model(name, method=method)
    assert config.model.method == method
    manifest = SHIPPED[name].manifest
    assert manifest["steps"] == manifest["export"]["checkpoint_step"] > 0
    assert all(s["command"].startswith("setdiff-bench train --config") for s in manifest["sessions"])
    trained = {tuple(pair) for pair in manifest["data"]["synthetic_seeds"]}
    assert trained == {synthetic_scene_seeds(s) for s in manifest["data"]["scenes"]}
    for preset in DEMO_PRESETS.values():  # the demo's test scenes, from the protocol's split, seed 0
        tested = {(0, index) for index in evaluation_scene_indices(preset, 0)}
        assert tested and not (trained & tested), (name, preset.name)
    # the autoencoder the tiny models freeze was trained on training scenes only, too
    autoencoder = SHIPPED["tiny_autoencoder"].manifest
    assert not {synthetic_scene_seeds(s) for s in autoencoder["train_scenes"]} & {(0, 2), (0, 4)}


def test_demo_refuses_shipped_models_that_saw_a_test_scene() -> None:
    if not all(name in SHIPPED for name in SHIPPED_MODELS.values()):
        pytest.fail("the shipped enhancers are missing")
    trained = SHIPPED[SHIPPED_MODELS["setdiff"]].manifest["data"]["synthetic_seeds"][0]
    with pytest.raises(UsageError, match="was trained on scene"):
        check_unseen([tuple(trained)])
    assert set(check_unseen([(0, 2), (0, 4)])) == set(SHIPPED_MODELS)


def test_scene_seeds_are_parsed_from_synthetic_names_only() -> None:
    assert synthetic_scene_seeds("scene_0007_12") == (7, 12)
    assert synthetic_scene_seeds("euvs/level1/scene_0000_01") == (0, 1)
    assert synthetic_scene_seeds("scene-0061") is None and synthetic_scene_seeds("street_00") is None


#: What every session of the runs below records alike: ``train --config tiny_setdiff`` with seed 0.
TINY_SESSION: dict[str, Any] = {
    "command": "setdiff-bench train --config tiny_setdiff",
    "method": "setdiff",
    "config_name": "tiny_setdiff",
    "seed": 0,
    "wall_seconds": 1.0,
}


def _training_run(folder: Path, steps: int, finished: int, keep: int = 1) -> Path:
    """A training output folder as ``train`` leaves it: checkpoints (the ``keep`` newest; each step's output
    head moved by another random step), ``latest`` and ``manifest.json``."""
    model, config = perturbed_model()
    generator = torch.Generator().manual_seed(5)
    for step in range(1, finished + 1):
        with torch.no_grad():
            model.unet.conv_out.weight.add_(
                0.01 * torch.randn(model.unet.conv_out.weight.shape, generator=generator)
            )
        checkpoint = save_checkpoint(step_folder(folder, step), model, config, step=step)
        mark_latest(folder, checkpoint, keep=keep)
    data = {
        "split": "train",
        "packets": 1,
        "views": 2,
        "scenes": ["scene_0000_01"],
        "synthetic_seeds": [[0, 1]],
        "data_sha256": "0" * 64,
    }
    record_training_session(
        folder,
        **TINY_SESSION,
        steps=steps,
        start_step=0,
        end_step=finished,
        data=data,
        validation={"psnr": 20.0},
    )
    return folder


def test_export_then_verify_and_load(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _training_run(tmp_path / "run", steps=2, finished=2)
    assert (
        main(["weights", "export", str(run), "--name", "my_setdiff", "--to", str(tmp_path / "shipped")]) == 0
    )
    folder = tmp_path / "shipped" / "my_setdiff"
    assert sorted(p.name for p in folder.iterdir()) == ["config.json", MANIFEST_FILE, "model.safetensors"]
    exported = packaged_models(tmp_path / "shipped")["my_setdiff"]
    assert exported.kind == "enhancer" and verify(exported) == []
    assert exported.manifest["export"]["checkpoint_step"] == 2 and exported.manifest["validation"] == {
        "psnr": 20.0
    }
    packet = make_packet(1, 2)
    original, _ = load_model(run)
    loaded, _ = load_model(folder)
    assert torch.equal(enhance_packet(loaded, packet), enhance_packet(original, packet))
    # a changed byte is found
    weights = folder / "model.safetensors"
    data = bytearray(weights.read_bytes())
    data[-1] ^= 1
    weights.write_bytes(bytes(data))
    assert verify(exported) == [f"{weights}: SHA-256 differs from the manifest"]


def test_export_refuses_an_unfinished_run(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _training_run(tmp_path / "run", steps=3, finished=2)
    assert main(["weights", "export", str(run), "--name", "x", "--to", str(tmp_path / "shipped")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "step 2 of 3" in err
    assert not (tmp_path / "shipped").exists()


def test_list_and_verify_cli(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["weights", "list"]) == 0
    listed = capsys.readouterr().out
    assert all(name in listed for name in SHIPPED)
    rows = {line.split()[0]: line for line in listed.splitlines()[1:]}
    for name in ("tiny_setdiff", "tiny_difix"):  # the training data, for the out-of-distribution warning
        assert "  synthetic at 256×144 / " in rows[name]
    assert main(["weights", "verify"]) == 0
    assert f"{len(SHIPPED)} shipped model(s) intact" in capsys.readouterr().out
    assert main(["weights", "verify", "no_such_model"]) == 2
    assert "no shipped model 'no_such_model'" in capsys.readouterr().err


def test_unknown_checkpoint_names_the_shipped_models(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="shipped models: "):
        resolve_checkpoint(tmp_path / "nothing")


def test_training_manifest_refuses_other_data(tmp_path: Path) -> None:
    run = _training_run(tmp_path / "run", steps=2, finished=2)
    manifest = json.loads((run / MANIFEST_FILE).read_text())
    other = {**manifest["data"], "data_sha256": "1" * 64}
    with pytest.raises(CheckpointError, match="other data"):
        record_training_session(
            run, **TINY_SESSION, steps=2, start_step=2, end_step=2, data=other, validation=None
        )
    assert pd.Series(
        [s["end_step"] for s in json.loads((run / MANIFEST_FILE).read_text())["sessions"]]
    ).tolist() == [2]


def test_export_sets_the_guidance_scale(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    run = _training_run(tmp_path / "run", steps=2, finished=2)
    shipped = tmp_path / "shipped"
    command = ["weights", "export", str(run), "--name", "cfg1", "--to", str(shipped), "--guidance-scale", "1"]
    assert main(command) == 0
    folder = shipped / "cfg1"
    exported = packaged_models(shipped)["cfg1"]
    assert verify(exported) == [] and exported.manifest["export"]["guidance_scale"] == 1.0
    assert read_config(folder).model.guidance_scale == 1.0
    assert read_config(resolve_checkpoint(run)).model.guidance_scale == 2.0
    weights = "model.safetensors"
    assert (folder / weights).read_bytes() == (resolve_checkpoint(run) / weights).read_bytes()
    # the exported default is what the original model gives when told the scale explicitly
    packet = make_packet(1, 2)
    original, _ = load_model(run)
    loaded, _ = load_model(folder)
    assert torch.equal(enhance_packet(loaded, packet), enhance_packet(original, packet, guidance_scale=1.0))
    assert not torch.equal(enhance_packet(loaded, packet), enhance_packet(original, packet))


@pytest.mark.parametrize("scale", ["0", "-1", "nan"])
def test_export_refuses_a_bad_guidance_scale(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], scale: str
) -> None:
    run = _training_run(tmp_path / "run", steps=2, finished=2)
    command = ["weights", "export", str(run), "--name", "x", "--to", str(tmp_path / "shipped")]
    assert main([*command, f"--guidance-scale={scale}"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--guidance-scale" in err
    assert not (tmp_path / "shipped").exists()


def test_export_averages_the_newest_checkpoints(tmp_path: Path) -> None:
    run = _training_run(tmp_path / "run", steps=3, finished=3, keep=3)
    shipped = tmp_path / "shipped"
    assert main(["weights", "export", str(run), "--name", "avg", "--to", str(shipped), "--average", "2"]) == 0
    exported = packaged_models(shipped)["avg"]
    assert verify(exported) == [] and exported.manifest["export"]["averaged_steps"] == [2, 3]
    states = [load_model(step_folder(run, step))[0].state_dict() for step in (2, 3)]
    averaged, _ = load_model(shipped / "avg")
    moved = 0
    for name, tensor in averaged.state_dict().items():
        a, b = states[0][name], states[1][name]
        if a.is_floating_point():
            assert torch.allclose(tensor.double(), (a.double() + b.double()) / 2, atol=1e-7, rtol=0), name
            moved += int(not torch.equal(a, b))
        else:
            assert torch.equal(tensor, a)
    assert moved == 1  # only the output head differs between the steps; it is the mean of the two
    head = averaged.unet.conv_out.weight
    assert not torch.equal(head, states[0]["unet.conv_out.weight"]) and not torch.equal(
        head, states[1]["unet.conv_out.weight"]
    )


@pytest.mark.parametrize(("average", "problem"), [("1", "2 or more"), ("4", "it keeps steps 1, 2, 3")])
def test_export_refuses_an_impossible_average(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], average: str, problem: str
) -> None:
    run = _training_run(tmp_path / "run", steps=3, finished=3, keep=3)
    argv = ["weights", "export", str(run), "--name", "x", "--to", str(tmp_path / "shipped")]
    assert main([*argv, "--average", average]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and problem in err
    assert not (tmp_path / "shipped").exists()


def test_export_refuses_to_replace_a_shipped_model_without_to_or_force(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The `weights --help` example names `--name tiny_setdiff`: without `--to` it would write into the
    package and replace the shipped model; it is refused in one line and the shipped files stay as they are."""
    run = _training_run(tmp_path / "run", steps=2, finished=2)
    shipped = packaged_root() / "tiny_setdiff"
    before = {path.name: path.read_bytes() for path in shipped.iterdir()}
    assert main(["weights", "export", str(run), "--name", "tiny_setdiff"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        "setdiff-bench weights: error: --name: 'tiny_setdiff' is a shipped model: exporting would replace it "
        "in the package; give --to DIR to export elsewhere, or --force to replace it"
    )
    assert {path.name: path.read_bytes() for path in shipped.iterdir()} == before
    assert main(["weights", "export", str(run), "--name", "tiny_setdiff", "--to", str(tmp_path / "out")]) == 0
    assert (tmp_path / "out" / "tiny_setdiff" / "manifest.json").is_file()
