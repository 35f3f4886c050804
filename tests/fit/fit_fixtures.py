"""Helpers shared by the fit tests (a uniquely named module: test folders are not packages)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch


@contextlib.contextmanager
def single_thread() -> Iterator[None]:
    """One torch thread: the rasteriser runs many small ops, which OpenMP slows down badly on a busy machine."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)
