"""Checking a weights file's tensors against the network that will read them, before any is loaded.

Every reader of third-party or trained weights (FID Inception-v3, LPIPS, SetDiff checkpoints) refuses a file
whose names, shapes, dtypes or values do not fit, in one line naming the first problem.  The check is here
once; each reader words its own line from the :class:`StateDictProblem` (its users know the file by name).
``torch.nn.Module.load_state_dict`` reports only names and shapes, all at once, and only after the load
began; it says nothing of dtypes or NaNs.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import torch

ProblemKind = Literal["missing", "unexpected", "shape", "dtype", "non_finite"]


@dataclass(frozen=True)
class StateDictProblem:
    """The first way a state dict does not fit its network.

    Attributes:
        kind: ``missing`` / ``unexpected`` (names), ``shape``, ``dtype`` (not float32), ``non_finite``.
        names: the offending names, sorted (``missing`` / ``unexpected``: all of them; else the one tensor).
        found, expected: the tensor's shape (``shape``) or dtype (``dtype``); ``None`` for the other kinds.
        missing, unexpected: every missing and every unexpected name (both kinds at once, for readers that
            report the two together).
    """

    kind: ProblemKind
    names: list[str]
    found: Any = None
    expected: Any = None
    missing: tuple[str, ...] = ()
    unexpected: tuple[str, ...] = ()


def _is_finite(value: torch.Tensor | np.ndarray) -> bool:
    if isinstance(value, torch.Tensor):
        return not value.is_floating_point() or bool(torch.isfinite(value).all())
    return not np.issubdtype(value.dtype, np.floating) or bool(np.isfinite(value).all())


def _is_float32(value: torch.Tensor | np.ndarray) -> bool:
    return value.dtype == (torch.float32 if isinstance(value, torch.Tensor) else np.float32)


def state_dict_problem(
    expected: Mapping[str, Sequence[int]],
    state: Mapping[str, torch.Tensor | np.ndarray],
    *,
    optional: Callable[[str], bool] | None = None,
    float32: bool = False,
    finite: bool = False,
) -> StateDictProblem | None:
    """``None`` when ``state`` fits ``expected`` (name → shape), else its first problem, checked in this order:
    missing names (``optional`` ones may be absent), unexpected names, then per tensor in ``expected``'s order
    its shape, with ``float32`` its dtype, with ``finite`` its values (no NaN or infinity)."""
    missing = tuple(sorted(n for n in expected if n not in state and not (optional and optional(n))))
    unexpected = tuple(sorted(set(state) - set(expected)))
    if missing:
        return StateDictProblem("missing", list(missing), missing=missing, unexpected=unexpected)
    if unexpected:
        return StateDictProblem("unexpected", list(unexpected), missing=missing, unexpected=unexpected)
    for name, shape in expected.items():
        if name not in state:
            continue
        value = state[name]
        if tuple(value.shape) != tuple(shape):
            return StateDictProblem("shape", [name], tuple(value.shape), tuple(shape))
        if float32 and not _is_float32(value):
            return StateDictProblem("dtype", [name], value.dtype, "float32")
        if finite and not _is_finite(value):
            return StateDictProblem("non_finite", [name])
    return None


def shapes_of(state: Mapping[str, torch.Tensor]) -> dict[str, tuple[int, ...]]:
    """Name → shape of a module's ``state_dict()`` (the ``expected`` of :func:`state_dict_problem`)."""
    return {name: tuple(tensor.shape) for name, tensor in state.items()}
