"""``setdiff-bench train`` end to end against an in-memory stand-in for the packet store."""

from __future__ import annotations

import hashlib
import json
import sys
import types
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.models.setdiff.checkpoint import read_config, resolve_checkpoint
from setdiff_bench.models.setdiff.files import MANIFEST_FILE
from tests.models.setdiff_fixtures import CLI_TRAIN_CONFIG as CONFIG
from tests.models.setdiff_fixtures import FakeStore, tiny_config_toml, train_argv


@pytest.fixture
def fake_store(monkeypatch: pytest.MonkeyPatch) -> type[FakeStore]:
    module = types.ModuleType("setdiff_bench.packets.store")
    module.PacketStore = FakeStore  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "setdiff_bench.packets.store", module)
    FakeStore.calls = []
    return FakeStore


def test_train_verb(tmp_path: Path, fake_store: type[FakeStore], capsys: pytest.CaptureFixture[str]) -> None:
    config = tmp_path / "tiny.toml"
    config.write_text(CONFIG)
    out = tmp_path / "run"
    code = main(train_argv(config, tmp_path / "packets", out, "--no-progress", "--cpu"))
    assert code == 0
    assert fake_store.calls == [("training_dataset", ("train", 2, 4, 0))]
    printed = capsys.readouterr().out
    assert "trained setdiff to step 2" in printed and "validation: psnr" in printed
    checkpoint = resolve_checkpoint(out)
    assert checkpoint.name == "step-00000002"
    assert read_config(checkpoint).train.steps == 2
    # running again resumes (nothing left to do) and --steps extends the run
    assert main(train_argv(config, "p", out, "--no-progress", "--steps", "3")) == 0
    assert resolve_checkpoint(out).name == "step-00000003"
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    assert [(s["start_step"], s["end_step"]) for s in manifest["sessions"]] == [(0, 2), (2, 3)]
    assert manifest["sessions"][1]["command"].startswith("setdiff-bench train --config")
    assert manifest["steps"] == 3 and manifest["seed"] == 0 and manifest["method"] == "setdiff"
    assert manifest["data"]["scenes"] == ["scene_0003_01"] and manifest["data"]["synthetic_seeds"] == [[3, 1]]
    # the data hash: SHA-256 over the sorted distinct file hashes of the train rows, written out by hand
    expected = hashlib.sha256("\n".join(["a" * 64, "b" * 64, "d" * 64]).encode()).hexdigest()
    assert manifest["data"]["data_sha256"] == expected
    assert manifest["data"]["datasets"] == ["synthetic"] and manifest["data"]["resolutions"] == [[32, 32]]
    assert manifest["validation"]["psnr"] > 0


def test_train_verb_errors(
    tmp_path: Path, fake_store: type[FakeStore], capsys: pytest.CaptureFixture[str]
) -> None:
    code = main(train_argv(tmp_path / "missing.toml", "p", tmp_path))
    assert code == 2
    assert "config file not found" in capsys.readouterr().err
    bad = tmp_path / "bad.toml"
    bad.write_text(tiny_config_toml(model={"preset": "tiny", "unknown_key": 1}))
    assert main(train_argv(bad, "p", tmp_path / "o")) == 2
    assert "unknown keys ['unknown_key']" in capsys.readouterr().err
