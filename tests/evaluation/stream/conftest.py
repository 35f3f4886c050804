"""Fixtures of the stream tests: one tiny SetDiff checkpoint per package, one torch thread."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.stream.stream_fixtures import save_tiny_checkpoint


@pytest.fixture(scope="package")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with torch_threads(1):
        return save_tiny_checkpoint(tmp_path_factory.mktemp("ckpt") / "tiny_setdiff")
