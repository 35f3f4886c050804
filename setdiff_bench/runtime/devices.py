"""``--device``: the one resolution of a device name (``auto`` → CUDA when available, else the CPU)."""

from __future__ import annotations

from setdiff_bench.errors import UsageError


def resolve_device(text: str | None = "auto") -> str:
    """``auto`` (or ``None``/empty) → ``"cuda"`` when CUDA is available, else ``"cpu"``; any other torch device
    name (``cpu``, ``cuda``, ``cuda:1``, ...) is checked and returned unchanged.

    Raises:
        UsageError: (naming ``--device``) the name is not a torch device, or names CUDA where none is available.
    """
    import torch

    name = (text or "auto").strip()
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    try:
        device = torch.device(name)
    except (RuntimeError, ValueError) as exc:
        raise UsageError(f"unknown device {name!r} (auto, cpu, cuda, cuda:N)", "--device") from exc
    if device.type == "cuda" and not torch.cuda.is_available():
        raise UsageError(f"device {name!r} requested but CUDA is not available", "--device")
    return name
