"""Safe path handling for dataset files named inside other files (split lists, JSON tables)."""

from __future__ import annotations

import os
from pathlib import Path

from setdiff_bench.errors import DatasetError


def resolve_inside(root: str | os.PathLike[str], relative: str, *, source: str | os.PathLike[str]) -> Path:
    """Join ``relative`` onto ``root`` and refuse any result outside ``root``.

    Args:
        root: the dataset root folder.
        relative: a path read from a dataset file (e.g. a nuScenes ``filename`` field).
        source: the file the path was read from, named in the error.

    Raises:
        DatasetError: absolute paths, ``..`` escapes, or symlinks leading outside ``root``.
    """
    root_path = Path(root).resolve()
    if not isinstance(relative, str) or not relative or "\x00" in relative:
        raise DatasetError(f"invalid path entry {relative!r}", source)
    if os.path.isabs(relative) or relative.startswith(("/", "\\")):
        raise DatasetError(f"path {relative!r} is absolute; dataset paths must be relative to {root_path}", source)
    candidate = (root_path / relative).resolve()
    if candidate != root_path and root_path not in candidate.parents:
        raise DatasetError(f"path {relative!r} escapes the dataset root {root_path}", source)
    return candidate
