"""One exception family for every user-facing failure.

The CLI turns any :class:`SetDiffBenchError` into a single line ``<path>: <problem>`` on stderr and
exit code 2, with no traceback.  Subclasses only say which stage failed; the message always names
the file (or the argument) and the problem.

An error caused by the value of one parameter names it (``parameter="checkpoint"``): a Python caller reads
``checkpoint='nope': checkpoint not found (...)``, and the CLI, which maps the parameter to the verb's option
through its parser (:func:`setdiff_bench.cli.main.parameter_options`), prints ``--checkpoint nope: checkpoint
not found (...)``.  The library never spells a command-line flag for such an error.
"""

from __future__ import annotations

import shlex
from collections.abc import Iterable, Mapping
from os import PathLike


class SetDiffBenchError(Exception):
    """A user-facing error: bad input, missing file, inconsistent data.

    Args:
        problem: what is wrong, in one line (no trailing period needed).
        path: the file, folder or argument the problem is in; ``None`` when there is none.  With
            ``parameter``, the value given for it (``None`` when the value is missing, or is named in
            ``problem``).
        parameter: the name of the parameter whose value is wrong (``"checkpoint"``, ``"packets"``,
            ``"method"``, ``"source"``, ``"protocol"``, ``"config"``: the keyword of the library's entry points,
            which the CLI's option of the same ``dest`` sets); ``None`` when the problem is not one value's.

    Example::

        >>> error = CheckpointError("checkpoint not found", "nope", parameter="checkpoint")
        >>> error.one_line()
        "checkpoint='nope': checkpoint not found"
        >>> error.one_line({"checkpoint": "--checkpoint"})
        '--checkpoint nope: checkpoint not found'
    """

    def __init__(
        self, problem: str, path: str | PathLike[str] | None = None, *, parameter: str | None = None
    ) -> None:
        self.problem = " ".join(str(problem).split())
        self.path = None if path is None else str(path)
        self.parameter = parameter
        super().__init__(self.one_line())

    def where(self, options: Mapping[str, str] | None = None) -> str | None:
        """What the message names before the problem, or ``None``.

        Args:
            options: how a command line spells each parameter (``{"checkpoint": "--checkpoint"}``; ``""`` for a
                positional argument, shown by its value alone), or ``None`` for a Python caller.  Without
                ``parameter``, or for a parameter the command line does not have, the path as given.

        Returns:
            Python: ``checkpoint='nope'`` (or ``checkpoint``); command line: ``--checkpoint nope`` (or
            ``--checkpoint``); else the path.
        """
        if self.parameter is None:
            return self.path
        if options is None:
            return self.parameter if self.path is None else f"{self.parameter}={self.path!r}"
        if self.parameter not in options:
            return self.path if self.path is not None else self.parameter
        option = options[self.parameter]
        if not option:
            return self.path
        return option if self.path is None else f"{option} {shlex.quote(self.path)}"

    def one_line(self, options: Mapping[str, str] | None = None) -> str:
        """The one-line message ``where: problem`` (or just the problem); ``options`` as for :meth:`where`
        (the CLI passes its verb's, a Python caller none)."""
        where = self.where(options)
        return f"{where}: {self.problem}" if where else self.problem


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


class SetDiffBenchWarning(UserWarning):
    """A toolkit warning: the work goes on, but the user should know.  The CLI shows each as one line
    ``setdiff-bench <verb>: warning: <message>`` on stderr (:func:`setdiff_bench.cli.main.one_line_warnings`)."""


class OutOfDistributionWarning(UserWarning):
    """A model runs on a dataset or an image size it was not trained on (``run``, the stream session and ``serve``
    warn once; the model's manifest says what it was trained on)."""


class DatasetWarning(SetDiffBenchWarning):
    """A dataset on disk is read with a repair: frames skipped, values rounded, files paired by order."""


class FallbackWarning(SetDiffBenchWarning):
    """A slower or weaker path is taken because the preferred one is unavailable (a native library, a
    compiler, enough triangulated points, gradient statistics)."""
