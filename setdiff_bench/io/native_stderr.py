"""Keep C libraries from printing a failure a second time on the process's stderr, or at all.

libpng reports a corrupt or truncated PNG by printing ``libpng error: <what>`` straight to file
descriptor 2, even though OpenImageIO also returns the same problem through ``geterror()``, which
the toolkit turns into its one-line :class:`~setdiff_bench.errors.ImageError`.  The CLI promises a
single stderr line per error, so image opens and decodes run inside :func:`native_stderr_filtered`:
file descriptor 2 is pointed at a temporary file for the duration, then restored, and every line the
libraries wrote is written back except libpng's error lines (warnings and anything else pass
through unchanged).  Python's own ``sys.stderr`` is flushed first and is unaffected.
:func:`native_stderr_silenced` drops every line: FFmpeg's notes on a video container's codec tag
(``reporting.video``) and grpc core's own log of a bind failure that the server reports in one line
(``serve.server``).

Done by hand because no maintained library exposes a hook for libpng's messages through
OpenImageIO's Python bindings.  A lock serialises the redirection, so threads reading images at the
same time cannot restore each other's descriptor.
"""

from __future__ import annotations

import contextlib
import os
import sys
import tempfile
import threading
from collections.abc import Iterator
from typing import IO

#: Lines dropped from the captured output: they repeat an error the caller raises itself.
DROPPED_PREFIXES = ("libpng error:",)

_LOCK = threading.RLock()


@contextlib.contextmanager
def native_stderr_filtered(dropped: tuple[str, ...] | None = DROPPED_PREFIXES) -> Iterator[None]:
    """Capture file descriptor 2 during the block; re-emit what was written minus the lines that start with
    one of ``dropped`` (default: libpng's error lines; ``None``: every line)."""
    with _LOCK:
        with contextlib.suppress(AttributeError, OSError, ValueError):
            sys.stderr.flush()
        try:
            saved = os.dup(2)
        except OSError:  # no descriptor 2 to redirect: nothing can be printed there anyway
            yield
            return
        try:
            with tempfile.TemporaryFile() as capture:
                os.dup2(capture.fileno(), 2)
                try:
                    yield
                finally:
                    os.dup2(saved, 2)
                    if dropped is not None:
                        _replay(capture, dropped)
        finally:
            os.close(saved)


@contextlib.contextmanager
def native_stderr_silenced() -> Iterator[None]:
    """Silence file descriptor 2 during the block (C code that logs what the caller reports itself)."""
    with native_stderr_filtered(None):
        yield


def _replay(capture: IO[bytes], dropped: tuple[str, ...]) -> None:
    """Write the captured bytes back to descriptor 2, without the dropped lines."""
    try:
        capture.seek(0)
        text = capture.read().decode("utf-8", errors="replace")
    except OSError:
        return
    kept = [line for line in text.splitlines(keepends=True) if not line.startswith(dropped)]
    if kept:
        with contextlib.suppress(OSError):
            os.write(2, "".join(kept).encode("utf-8", errors="replace"))
