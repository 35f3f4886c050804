"""``"module:attr"`` references: the one lazy import behind the method, dataset and metric registries.

Registries name their functions as ``"module:attr"`` strings so that listing them imports nothing heavy;
:func:`load_attribute` imports one when it is used, and turns every way that can fail into the project's
one-line error naming the reference.
"""

from __future__ import annotations

import importlib
from typing import Any

from setdiff_bench.errors import SetDiffBenchError, UsageError


def load_attribute(
    reference: str, what: str, *, error: type[SetDiffBenchError] = UsageError, path: str | None = None
) -> Any:
    """Import ``module`` and return its attribute ``attr`` for a ``"module:attr"`` reference.

    Args:
        reference: ``"package.module:attr"`` (exactly one colon, both sides non-empty, an absolute module).
        what: what the reference is for, starting the message (e.g. ``"method 'setdiff' factory"``).
        error: the :class:`SetDiffBenchError` subclass raised on failure.
        path: the file, entry point or argument the reference came from, if any (the error's path).

    Raises:
        error: the reference is not ``"module:attr"``, its module cannot be imported, or the module has
            no such attribute; one line naming ``what`` and the reference.
    """
    module_name, sep, attr = str(reference).partition(":")
    module_name, attr = module_name.strip(), attr.strip()
    if not sep or not module_name or module_name.startswith(".") or not attr or ":" in attr:
        raise error(f"{what}: {reference!r} is not 'module:attr'", path)
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise error(f"{what}: cannot import {module_name} for {reference!r} ({exc})", path) from None
    try:
        return getattr(module, attr)
    except AttributeError:
        raise error(f"{what}: {module_name} has no {attr!r} (from {reference!r})", path) from None


def lazy_face(package: str, exports: dict[str, str]) -> tuple[Any, Any]:
    """``__getattr__`` and ``__dir__`` for a package face whose names load on first use (PEP 562), as diffusers'
    ``_import_structure``: ``exports`` maps each public name to the private module (``"_settings"``) that defines
    it, so importing the face (e.g. for a verb's ``--help``) imports none of them, and a name imports only its
    own module.

    Usage, in ``package/__init__.py``: ``__getattr__, __dir__ = lazy_face(__name__, _EXPORTS)``.
    """

    def __getattr__(name: str) -> Any:
        module = exports.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{package}.{module}"), name)
        setattr(importlib.import_module(package), name, value)  # loaded once
        return value

    def __dir__() -> list[str]:
        return sorted(exports)

    return __getattr__, __dir__
