"""``resolve_device``: the one ``--device`` resolution (``auto`` → CUDA when available, else the CPU)."""

from __future__ import annotations

import pytest
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.runtime.devices import resolve_device

needs_no_cuda = pytest.mark.skipif(torch.cuda.is_available(), reason="checks the CPU-only answers")


@needs_no_cuda
def test_auto_is_cpu_without_cuda() -> None:
    assert resolve_device("auto") == "cpu"
    assert resolve_device(None) == "cpu"
    assert resolve_device("") == "cpu"


def test_auto_follows_cuda_availability() -> None:
    assert resolve_device("auto") == ("cuda" if torch.cuda.is_available() else "cpu")
    assert resolve_device("cpu") == "cpu"


@needs_no_cuda
@pytest.mark.parametrize("text", ["cuda", "cuda:1"])
def test_cuda_without_cuda_is_one_line_usage_error(text: str) -> None:
    with pytest.raises(UsageError, match="CUDA is not available") as info:
        resolve_device(text)
    assert info.value.path == "--device" and len(str(info.value).splitlines()) == 1


def test_unknown_device_names_the_flag() -> None:
    with pytest.raises(UsageError, match="unknown device 'gpu'") as info:
        resolve_device("gpu")
    assert info.value.path == "--device"
