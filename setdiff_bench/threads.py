"""Scoped torch intra-op thread count.

The tile rasteriser and the tiny networks run many small ops, which gain nothing from OpenMP threads
and slow down badly when threads are oversubscribed on a busy machine; callers pin the count for a
block of work and get the previous value back afterwards, even on an exception.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch


@contextlib.contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run the block with ``torch.set_num_threads(count)``; restore the previous count on exit."""
    previous = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)
