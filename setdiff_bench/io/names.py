"""Names read from data as file-name parts: the one declaration of how a scene, group, protocol or frame name
becomes a safe path component (packet ids, run folders, the ``precomputed`` enhancer's lookup)."""

from __future__ import annotations

import re
from pathlib import PurePosixPath

from setdiff_bench.errors import PacketError

_UNSAFE = re.compile(r"[^A-Za-z0-9.+-]+")


def slug(text: str) -> str:
    """A file-name-safe form of a scene or group name: runs of other characters become ``-``."""
    out = _UNSAFE.sub("-", text).strip("-.")
    return out or "x"


def safe_component(text: str) -> str:
    """A scene / group / protocol name as one path component.

    Names are used as they are unless they are empty, ``.``/``..`` or contain a path separator or NUL;
    those go through the packet-id slug (runs of characters other than ``A-Za-z0-9.+-`` become ``-``).
    """
    if not text or text in {".", ".."} or "/" in text or "\\" in text or "\0" in text:
        return slug(text)
    return text


def frame_relative(frame: str) -> PurePosixPath:
    """A frame name as a relative path without its extension (``CAM_FRONT/a.jpg`` → ``CAM_FRONT/a``).

    Raises:
        PacketError: an absolute name, or one with ``..`` or empty parts (it could escape its folder).
    """
    path = PurePosixPath(frame.replace("\\", "/"))
    if not frame or path.is_absolute() or any(part in {"..", "."} for part in path.parts) or "//" in frame:
        raise PacketError(f"frame name {frame!r} is not a safe relative file name")
    return path.with_suffix("") if path.suffix else path
