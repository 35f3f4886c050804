"""The scoped torch thread count."""

from __future__ import annotations

import os

import pytest
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.runtime.threads import compute_threads, threads_in_force, torch_threads, verb_threads


def test_count_inside_and_restored_after_an_exception() -> None:
    before = torch.get_num_threads()
    target = 1 if before != 1 else 2
    with pytest.raises(RuntimeError), torch_threads(target):
        assert torch.get_num_threads() == target
        raise RuntimeError("inside")
    assert torch.get_num_threads() == before


def test_compute_threads_is_fixed_per_machine_not_by_omp(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("SETDIFF_THREADS", raising=False)
    monkeypatch.setenv("OMP_NUM_THREADS", "7")
    assert compute_threads() == (os.cpu_count() or 1)
    monkeypatch.setenv("SETDIFF_THREADS", "3")
    assert compute_threads() == 3
    for bad in ("0", "two", "-1"):
        monkeypatch.setenv("SETDIFF_THREADS", bad)
        with pytest.raises(UsageError, match="SETDIFF_THREADS"):
            compute_threads()


def test_verb_threads_sets_and_restores(monkeypatch: pytest.MonkeyPatch) -> None:
    before = torch.get_num_threads()
    target = 1 if before != 1 else 2
    monkeypatch.setenv("SETDIFF_THREADS", str(target))
    with verb_threads() as count:
        assert count == target == torch.get_num_threads()
    assert torch.get_num_threads() == before


def test_threads_in_force_is_the_count_torch_computes_with(monkeypatch: pytest.MonkeyPatch) -> None:
    """Records of a run state the count in force, not the machine's: inside ``torch_threads(k)`` it is k
    whatever ``SETDIFF_THREADS`` says (a demo lane runs with its share of the cores)."""
    monkeypatch.setenv("SETDIFF_THREADS", "4")
    with torch_threads(1):
        assert threads_in_force() == 1 and compute_threads() == 4
    with torch_threads(3):
        assert threads_in_force() == 3
