"""Checkpoints are shareable: every file and folder gets the umask's mode (safetensors alone writes 0600)."""

from __future__ import annotations

import os
import stat
from pathlib import Path

from setdiff_bench.models.setdiff.checkpoint import save_checkpoint
from setdiff_bench.models.setdiff.model import SetDiffModel
from tests.models.setdiff_fixtures import tiny_config


def test_checkpoint_files_follow_the_umask(tmp_path: Path) -> None:
    config = tiny_config()
    model = SetDiffModel(config.model)
    previous = os.umask(0o022)
    try:
        folder = save_checkpoint(tmp_path / "run" / "step-1", model, config, step=1)
    finally:
        os.umask(previous)
    paths = [folder, *folder.rglob("*")]
    assert len(paths) >= 4
    for path in paths:
        assert stat.S_IMODE(path.stat().st_mode) == (0o755 if path.is_dir() else 0o644), path
