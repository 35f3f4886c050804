"""Safe path handling for dataset files named inside other files (split lists, JSON tables)."""

from __future__ import annotations

import os
from pathlib import Path

from setdiff_bench.errors import DatasetError


def resolve_inside(root: str | os.PathLike[str], relative: str, *, source: str | os.PathLike[str]) -> Path:
    """Join ``relative`` onto ``root`` and refuse any path that escapes ``root``.

    The check is lexical: absolute paths and ``..`` components that climb out of ``root`` are refused,
    whatever exists on disk.  Symbolic links *inside* the dataset are followed (real setups link
    ``samples/`` to another disk, or Hugging Face snapshots link into ``blobs/``); a link is placed by
    whoever installed the data, whereas a name read from a dataset file is untrusted.

    Args:
        root: the dataset root folder.
        relative: a path read from a dataset file (e.g. a nuScenes ``filename`` field).
        source: the file the path was read from, named in the error.

    Raises:
        DatasetError: empty or absolute paths, NUL bytes, or ``..`` escapes.
    """
    if not isinstance(relative, str) or not relative or "\x00" in relative:
        raise DatasetError(f"invalid path entry {relative!r}", source)
    root_path = Path(os.path.abspath(root))
    if (
        os.path.isabs(relative)
        or relative.startswith(("/", "\\"))
        or (len(relative) > 1 and relative[1] == ":")
    ):
        raise DatasetError(
            f"path {relative!r} is absolute; dataset paths must be relative to {root_path}", source
        )
    candidate = Path(os.path.normpath(root_path / relative.replace("\\", "/")))
    if candidate != root_path and root_path not in candidate.parents:
        raise DatasetError(f"path {relative!r} escapes the dataset root {root_path}", source)
    return candidate
