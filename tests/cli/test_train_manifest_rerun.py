"""Issue 45, defect 3: a no-op rerun of a finished ``train`` keeps the manifest's validation scores."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from setdiff_bench.cli.main import main
from setdiff_bench.models.setdiff.files import MANIFEST_FILE, VALIDATION_FILE
from tests.cli.conftest import IndexedFakeStore
from tests.models.setdiff_fixtures import CLI_TRAIN_CONFIG as CONFIG
from tests.models.setdiff_fixtures import train_argv


def test_noop_rerun_keeps_validation(
    tmp_path: Path,
    train_store: type[IndexedFakeStore],
    capsys: pytest.CaptureFixture[str],
) -> None:
    config = tmp_path / "tiny.toml"
    config.write_text(CONFIG)
    out = tmp_path / "ckpt"
    argv = train_argv(config, tmp_path / "packets", out, "--no-progress", "--device", "cpu", "--steps", "2")
    assert main(argv) == 0
    first = json.loads((out / MANIFEST_FILE).read_text())
    assert first["validation"] is not None and first["validation"]["psnr"] > 0
    assert main(argv) == 0  # finished: nothing to train, nothing scored
    capsys.readouterr()
    manifest = json.loads((out / MANIFEST_FILE).read_text())
    assert [(s["start_step"], s["end_step"]) for s in manifest["sessions"]] == [(0, 2), (2, 2)]
    lines = (out / VALIDATION_FILE).read_text().splitlines()
    assert manifest["validation"] == json.loads(lines[-1]) == first["validation"]
