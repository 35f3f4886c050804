"""The scoped torch thread count."""

from __future__ import annotations

import pytest
import torch

from setdiff_bench.threads import torch_threads


def test_count_inside_and_restored_after_an_exception() -> None:
    before = torch.get_num_threads()
    target = 1 if before != 1 else 2
    with pytest.raises(RuntimeError), torch_threads(target):
        assert torch.get_num_threads() == target
        raise RuntimeError("inside")
    assert torch.get_num_threads() == before
