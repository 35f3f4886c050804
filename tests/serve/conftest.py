"""Fixtures of the service tests: a tiny random SetDiff checkpoint (fast), test certificates."""

from __future__ import annotations

from pathlib import Path

import pytest

from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.stream.stream_fixtures import save_tiny_checkpoint
from tests.serve.serve_fixtures import Certificates, make_certificates


@pytest.fixture(scope="package")
def checkpoint(tmp_path_factory: pytest.TempPathFactory) -> Path:
    with torch_threads(1):
        return save_tiny_checkpoint(tmp_path_factory.mktemp("ckpt") / "tiny_setdiff")


@pytest.fixture(scope="package")
def certificates(tmp_path_factory: pytest.TempPathFactory) -> Certificates:
    pytest.importorskip("cryptography")
    return make_certificates(tmp_path_factory.mktemp("certs"))
