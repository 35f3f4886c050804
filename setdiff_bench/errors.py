"""One exception family for every user-facing failure.

The CLI turns any :class:`SetDiffBenchError` into a single line ``<path>: <problem>`` on stderr and
exit code 2, with no traceback.  Subclasses only say which stage failed; the message always names
the file (or the argument) and the problem.
"""

from __future__ import annotations

from collections.abc import Iterable
from os import PathLike


class SetDiffBenchError(Exception):
    """A user-facing error: bad input, missing file, inconsistent data.

    Args:
        problem: what is wrong, in one line (no trailing period needed).
        path: the file, folder or argument the problem is in; ``None`` when there is none.
    """

    def __init__(self, problem: str, path: str | PathLike[str] | None = None) -> None:
        self.problem = " ".join(str(problem).split())
        self.path = None if path is None else str(path)
        super().__init__(self.one_line())

    def one_line(self) -> str:
        """The message the CLI prints: ``path: problem`` (or just the problem)."""
        return f"{self.path}: {self.problem}" if self.path else self.problem


class UsageError(SetDiffBenchError):
    """A command-line argument or option combination is invalid."""


class DatasetError(SetDiffBenchError):
    """A dataset on disk is missing files, malformed or inconsistent."""


class CameraError(SetDiffBenchError):
    """A camera has non-finite values, a non-rotation, or non-positive focal lengths."""


class ImageError(SetDiffBenchError):
    """An image file cannot be read or has the wrong size or channel count."""


class PlyError(SetDiffBenchError):
    """A Gaussian PLY file is malformed."""


class PacketError(SetDiffBenchError):
    """A packet store index or file is missing, corrupt or inconsistent."""


class ProtocolError(SetDiffBenchError):
    """A protocol TOML file is invalid or does not fit the dataset."""


class WeightsError(SetDiffBenchError):
    """Model or metric weights are missing, unsafe, or of the wrong shape."""


class CheckpointError(SetDiffBenchError):
    """A checkpoint is missing, unsafe, or belongs to another configuration."""


class MemoryNeedError(SetDiffBenchError):
    """The work asked for needs more memory than the device has available (checked before it starts)."""


def key_mismatch(expected: Iterable[str], found: Iterable[str], examples: int = 3) -> str | None:
    """``None`` when the two name sets agree, else ``"N missing (e.g. [...]), M unexpected (e.g. [...])"``.

    For the one-line error of a weights file whose tensor names do not fit the model that reads it.
    """
    missing = sorted(set(expected) - set(found))
    unexpected = sorted(set(found) - set(expected))
    if not missing and not unexpected:
        return None
    return (
        f"{len(missing)} missing (e.g. {missing[:examples]}), "
        f"{len(unexpected)} unexpected (e.g. {unexpected[:examples]})"
    )
