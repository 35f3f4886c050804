"""Numbers read into camera arithmetic: conversion to float64 with a :class:`CameraError` for what is not
numbers, and floating-point overflow turned into one.

Values come from dataset files (poses, intrinsics), so a string, a ragged list or ``1e308`` in a pose is
corrupt data to name, not a numpy warning to print.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import numpy as np

from setdiff_bench.errors import CameraError


@contextlib.contextmanager
def float_errors_raised(source: str) -> Iterator[None]:
    """Turn floating-point overflow and invalid operations in the block into a :class:`CameraError`.

    They only happen for absurd values read from a file (1e308 in a pose); numpy would otherwise print
    a ``RuntimeWarning`` line and carry ``inf``/``NaN`` on.
    """
    try:
        with np.errstate(over="raise", invalid="raise", divide="raise"):
            yield
    except FloatingPointError as error:
        raise CameraError(
            f"camera arithmetic overflowed or became invalid ({error}); values out of range", source
        ) from None


def numeric_array(values: object, what: str, source: str) -> np.ndarray:
    """``values`` as a float64 array; a :class:`CameraError` naming ``what`` when they are not numbers
    (a string, a ragged nested list, an integer too large for a float: values read from dataset files)."""
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise CameraError(f"{what} must be numbers, got {value_preview(values)}", source) from None


def value_preview(values: object, limit: int = 80) -> str:
    text = repr(values)
    return text if len(text) <= limit else text[: limit - 3] + "..."
