"""Memory available to a computation, and the check that a job fits before it starts.

A job that needs more memory than a machine has is otherwise ended by the kernel's out-of-memory killer
(a bare ``Killed``, nothing of the run kept) or by a CUDA allocation error deep inside a model.  Callers
estimate what a job needs (e.g. :meth:`setdiff_bench.enhancers.setdiff.ModelEnhancer.memory_bytes`),
and :func:`check_memory` turns a job that cannot fit into one line *before* anything is written.

Available memory: on CUDA the device's free memory (``torch.cuda.mem_get_info``); on the CPU the
system's available memory (``psutil``), capped by the process's cgroup limit where one is set (containers
report the host's memory otherwise).  ``SETDIFF_MEMORY_LIMIT`` (bytes, or with a ``K``/``M``/``G``
suffix, powers of 1024) caps it further — to keep headroom for other jobs on a shared machine, and in tests.
"""

from __future__ import annotations

import os
from pathlib import Path

from setdiff_bench.errors import MemoryNeedError, UsageError

#: Float32 channels one loaded view holds per pixel: RGB (3), C-map (3), alpha (1) -- a packet's or a
#: stream session's ``ViewSet``.  The memory estimate and the service's per-session bound count with it.
VIEW_CHANNELS = 3 + 3 + 1
#: Bytes per float32 element.
FLOAT32_BYTES = 4

#: Environment variable that caps the memory this process may plan to use (bytes or ``2G``, ``512M``...).
MEMORY_LIMIT_ENV = "SETDIFF_MEMORY_LIMIT"
_SUFFIXES = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}
#: cgroup v2 and v1 files holding the memory limit and current use of this process's container.
_CGROUP_FILES = (
    ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),
    ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"),
)


def parse_bytes(text: str, where: str = MEMORY_LIMIT_ENV) -> int:
    """``"3G"`` → 3·1024³; a plain integer is bytes.

    Raises:
        UsageError: (naming ``where``) not a positive size.
    """
    value = text.strip().upper().removesuffix("B").removesuffix("I")
    number, suffix = (value[:-1], value[-1]) if value[-1:] in _SUFFIXES and value[-1:] else (value, "")
    try:
        size = float(number) * _SUFFIXES[suffix]
    except ValueError:
        size = -1.0
    if not size > 0:
        raise UsageError(f"not a memory size: {text!r} (bytes, or a number with K, M, G)", where)
    return int(size)


def format_bytes(size: float) -> str:
    """``3.9 GB`` / ``812 MB`` / ``64 KB`` (powers of 1024, as the limits are written)."""
    if size >= 1 << 30:
        return f"{size / (1 << 30):.1f} GB"
    return f"{size / (1 << 20):.0f} MB" if size >= 1 << 20 else f"{size / (1 << 10):.0f} KB"


def _cgroup_headroom() -> int | None:
    for limit_file, usage_file in _CGROUP_FILES:
        try:
            limit_text = Path(limit_file).read_text().strip()
            usage = int(Path(usage_file).read_text().strip())
        except (OSError, ValueError):
            continue
        if limit_text == "max" or not limit_text.isdigit() or int(limit_text) >= 1 << 60:
            return None
        return max(0, int(limit_text) - usage)
    return None


def available_bytes(device: str = "cpu") -> int:
    """Memory this process can still allocate on ``device`` (see the module docstring), in bytes."""
    import torch

    if str(device).startswith("cuda"):
        free, _ = torch.cuda.mem_get_info(torch.device(device))
        available = int(free)
    else:
        import psutil

        available = int(psutil.virtual_memory().available)
        headroom = _cgroup_headroom()
        if headroom is not None:
            available = min(available, headroom)
    limit = os.environ.get(MEMORY_LIMIT_ENV)
    if limit:
        available = min(available, parse_bytes(limit))
    return available


def check_memory(
    needed: int, device: str, what: str, advice: str, path: str | os.PathLike[str] | None
) -> None:
    """Raise :class:`MemoryNeedError` (one line: needed, available, ``advice``) when ``needed`` bytes do not
    fit in :func:`available_bytes` of ``device``.

    Args:
        what: the job, e.g. ``"enhancing packet P (16 views of 576x1024) with setdiff"``.
        advice: what to change, e.g. ``"use fewer views per set (-o targets_per_set=4)"``.
        path: the file or folder the job reads (named first in the line).
    """
    available = available_bytes(device)
    if needed > available:
        raise MemoryNeedError(
            f"{what} needs about {format_bytes(needed)} on {device}, {format_bytes(available)} available; "
            f"{advice}",
            path,
        )
