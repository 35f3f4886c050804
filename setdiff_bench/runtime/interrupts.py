"""Stop long work at a safe point on SIGINT / SIGTERM, instead of dying mid-step.

A loop that can save its state (training) runs inside :func:`stop_at_safe_point`; at the end of
each unit of work it asks :func:`stop_requested`, saves, and raises :class:`Interrupted`.  A second
signal while the first is pending interrupts at once (the user insists).  Outside the block the
process's previous handlers are back, so Ctrl-C behaves as before everywhere else.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

#: The signals that ask for a stop (Ctrl-C and the usual ``kill`` / job-scheduler signal).
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_pending: list[int] = []  # signals received inside the innermost active block
_depth = 0


class Interrupted(KeyboardInterrupt):
    """Work stopped on a signal after saving its state; ``str()`` says where it was saved."""


def stop_requested() -> bool:
    """Whether a stop signal arrived inside an active :func:`stop_at_safe_point` block."""
    return bool(_pending)


def _handler(signum: int, frame: FrameType | None) -> None:
    del frame
    if _pending:  # a second signal: stop now
        raise KeyboardInterrupt
    _pending.append(signum)


@contextlib.contextmanager
def stop_at_safe_point() -> Iterator[None]:
    """Within the block, SIGINT/SIGTERM only set :func:`stop_requested`; previous handlers restored after.

    Outside the main thread (where Python cannot install handlers) the block does nothing.
    """
    global _depth
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _handler) for sig in STOP_SIGNALS}
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if _depth == 0:
            _pending.clear()
