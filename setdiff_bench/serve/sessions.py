"""What a session of the enhancer server holds and shares: its :class:`Session` record (stream, lease,
bytes held, busy count), the bytes its references will hold (read from the request's shapes before
decoding), the FIFO :class:`FairLock` sessions take turns on the model with, and handing memory freed by
closed or expired sessions back to the OS."""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

from setdiff_bench.evaluation.stream import StreamSession
from setdiff_bench.serve import enhancer_pb2 as pb
from setdiff_bench.serve.settings import reference_bytes

#: How many expired session ids are remembered (to answer "expired" rather than "unknown").
EXPIRED_MEMORY = 4096


class FairLock:
    """A FIFO lock: threads acquire it in the order they asked (Python's ``Lock`` promises no order).

    Each session holds its own lock while it waits here, so a session has at most one call waiting:
    FIFO over calls is round-robin over the sessions calling at once -- none waits for more than one
    call of each other session.  ``grants`` records the last owners served and ``arrivals`` the order in
    which each of them had asked (0, 1, 2, ...: increasing when FIFO holds), for tests and measurements.
    """

    def __init__(self, history: int = 4096) -> None:
        self._condition = threading.Condition()
        self._queue: collections.deque[int] = collections.deque()
        self._held = False
        self._asked = 0
        self.grants: collections.deque[str] = collections.deque(maxlen=history)
        self.arrivals: collections.deque[int] = collections.deque(maxlen=history)

    @contextmanager
    def hold(self, owner: str) -> Iterator[None]:
        with self._condition:
            ticket = self._asked
            self._asked += 1
            self._queue.append(ticket)
            while self._held or self._queue[0] != ticket:
                self._condition.wait()
            self._queue.popleft()
            self._held = True
            self.grants.append(owner)
            self.arrivals.append(ticket)
        try:
            yield
        finally:
            with self._condition:
                self._held = False
                self._condition.notify_all()


@dataclass
class Session:
    """One open session: its stream, idle lease (seconds), reference bytes held, the lock its calls take
    turns on, when its last call ended (the service clock) and how many calls are in flight."""

    stream: StreamSession
    idle_timeout: float
    held_bytes: int
    lock: threading.Lock = field(default_factory=threading.Lock)
    last_used: float = 0.0  # the service clock's time at the end of the last call
    busy: int = 0


def _load_malloc_trim() -> Callable[[int], int] | None:
    try:
        import ctypes

        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):  # not glibc: freed memory goes back as that allocator decides
        return None


_MALLOC_TRIM = _load_malloc_trim()


def release_freed_memory() -> None:
    """Hand memory freed by closed or expired sessions back to the OS (glibc keeps freed heap pages in its
    per-thread arenas otherwise, so the server's resident memory would stay at its peak).

    A session is freed by reference counting when it leaves the table (no cycles: tested); no
    ``gc.collect()`` here, which would hold the GIL for 0.1-1 s and stall every other call.  ctypes
    releases the GIL during ``malloc_trim`` (about 10 ms)."""
    if _MALLOC_TRIM is not None:
        _MALLOC_TRIM(0)


def session_bytes(request: pb.StartSessionRequest) -> int:
    """Bytes the session's references will hold, from the request's shapes (before decoding anything)."""
    total = 0
    for view in request.references:
        shape = list(view.rgb.shape)
        if len(shape) == 3 and all(s > 0 for s in shape[:2]):
            total += reference_bytes(int(shape[0]), int(shape[1]))
    return total
