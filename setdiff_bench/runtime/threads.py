"""Torch intra-op thread counts: the one every verb uses, and a scoped override.

Results depend on the thread count: CPU kernels (convolution weight gradients, matrix products, the
compiled rasteriser's reductions) split their sums by thread, so two counts round differently in the
last bits, and training amplifies that (measured on the tiny demo: 1 vs 2 threads changed trained
weights by up to 0.008 and DiFix's leaderboard cells by up to 0.88 dB PSNR).  Every verb therefore runs with
:func:`compute_threads` — ``SETDIFF_THREADS`` when set, else the machine's CPU count — never with
whatever ``OMP_NUM_THREADS`` or the load would give, and the demo records the count it used.

The tile rasteriser and the tiny networks run many small ops, which gain nothing from OpenMP threads
and slow down badly when threads are oversubscribed on a busy machine; callers pin the count for a
block of work with :func:`torch_threads` and get the previous value back afterwards.
"""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator

from setdiff_bench.errors import UsageError

#: Environment variable fixing the torch intra-op thread count of every verb (default: the CPU count).
THREADS_ENV = "SETDIFF_THREADS"


def compute_threads() -> int:
    """The intra-op thread count for this machine: ``$SETDIFF_THREADS``, else ``os.cpu_count()``.

    Raises:
        UsageError: ``SETDIFF_THREADS`` is not a positive integer.
    """
    text = os.environ.get(THREADS_ENV, "").strip()
    if not text:
        return max(1, os.cpu_count() or 1)
    try:
        count = int(text)
    except ValueError:
        count = 0
    if count < 1:
        raise UsageError(f"must be a positive integer, got {text!r}", THREADS_ENV)
    return count


def threads_in_force() -> int:
    """The intra-op thread count this process computes with now, for records of a run: torch's own count
    once torch is imported, else the ``OMP_NUM_THREADS`` torch will read (set by :func:`verb_threads`), else
    :func:`compute_threads`.  Differs from :func:`compute_threads` inside :func:`torch_threads` blocks and in
    processes whose caller set another count (a demo lane runs with its share of the cores)."""
    if "torch" in sys.modules:
        return int(sys.modules["torch"].get_num_threads())
    text = os.environ.get("OMP_NUM_THREADS", "").strip()
    return int(text) if text.isdigit() and int(text) > 0 else compute_threads()


@contextlib.contextmanager
def verb_threads() -> Iterator[int]:
    """Run a verb with :func:`compute_threads` torch threads; yields the count.

    When torch is not imported yet (a fresh process), ``OMP_NUM_THREADS`` is set for the block, which
    torch reads when it starts (so that verbs which never import torch stay fast); otherwise the
    count is set directly.  Either way the previous setting is back afterwards.
    """
    count = compute_threads()
    if "torch" in sys.modules:
        with torch_threads(count):
            yield count
        return
    previous = os.environ.get("OMP_NUM_THREADS")
    os.environ["OMP_NUM_THREADS"] = str(count)
    try:
        yield count
    finally:
        if previous is None:
            os.environ.pop("OMP_NUM_THREADS", None)
        else:
            os.environ["OMP_NUM_THREADS"] = previous


def set_process_threads(count: int) -> None:
    """Set this process's torch intra-op thread count for the rest of its life: the initialiser of a worker
    process (``prepare --workers``, ``synth --jobs``), which does all its work with ``count`` threads."""
    import torch

    torch.set_num_threads(count)


@contextlib.contextmanager
def torch_threads(count: int) -> Iterator[None]:
    """Run the block with ``torch.set_num_threads(count)``; restore the previous count on exit."""
    import torch

    previous = torch.get_num_threads()
    torch.set_num_threads(count)
    try:
        yield
    finally:
        torch.set_num_threads(previous)
