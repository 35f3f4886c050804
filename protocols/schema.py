"""Typed access to one TOML table, with errors that name the file and the dotted key.

``tomllib`` parses the file; this checks types, ranges and unknown keys, so every mistake in a
protocol file becomes one :class:`~setdiff_bench.errors.ProtocolError` line such as
``protocols/euvs.toml: packets.test_views: expected an integer >= 2, got 'x'``.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

from setdiff_bench.errors import ProtocolError

_MISSING = object()


class Table:
    """A TOML table being read: remembers its file and dotted key path.

    Args:
        data: the parsed table.
        path: the TOML file (named in errors).
        prefix: dotted key of this table (``""`` for the document root).
    """

    def __init__(self, data: Mapping[str, Any], path: Path, prefix: str = "") -> None:
        if not isinstance(data, Mapping):
            raise ProtocolError(f"{prefix or 'document'}: expected a table, got {type(data).__name__}", path)
        self.data = dict(data)
        self.path = path
        self.prefix = prefix

    # ------------------------------------------------------------------ helpers
    def key(self, name: str) -> str:
        """Dotted key of ``name`` in this table."""
        return f"{self.prefix}.{name}" if self.prefix else name

    def error(self, name: str, problem: str) -> ProtocolError:
        """A :class:`ProtocolError` for key ``name``."""
        return ProtocolError(f"{self.key(name)}: {problem}", self.path)

    def has(self, name: str) -> bool:
        return name in self.data

    def raw(self, name: str, default: Any = _MISSING) -> Any:
        if name not in self.data:
            if default is _MISSING:
                raise self.error(name, "missing required key")
            return default
        return self.data[name]

    def check_keys(self, allowed: Iterable[str]) -> None:
        """Raise for the first key not in ``allowed`` (typos must not be ignored silently)."""
        allowed = set(allowed)
        for name in self.data:
            if name not in allowed:
                raise self.error(name, f"unknown key; expected one of {', '.join(sorted(allowed))}")

    # ------------------------------------------------------------------ typed getters
    def string(self, name: str, default: Any = _MISSING, *, choices: Sequence[str] | None = None) -> str:
        value = self.raw(name, default)
        if not isinstance(value, str) or not value:
            raise self.error(name, f"expected a non-empty string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.error(name, f"expected one of {', '.join(choices)}, got {value!r}")
        return value

    def integer(self, name: str, default: Any = _MISSING, *, minimum: int | None = None) -> int:
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, int) or (minimum is not None and value < minimum):
            bound = f" >= {minimum}" if minimum is not None else ""
            raise self.error(name, f"expected an integer{bound}, got {value!r}")
        return value

    def number(
        self,
        name: str,
        default: Any = _MISSING,
        *,
        minimum: float | None = None,
        maximum: float | None = None,
    ) -> float:
        value = self.raw(name, default)
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.error(name, f"expected a number, got {value!r}")
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise self.error(name, f"expected a number in [{minimum}, {maximum}], got {value!r}")
        return float(value)

    def boolean(self, name: str, default: Any = _MISSING) -> bool:
        value = self.raw(name, default)
        if not isinstance(value, bool):
            raise self.error(name, f"expected true or false, got {value!r}")
        return value

    def strings(self, name: str, default: Any = _MISSING) -> tuple[str, ...]:
        """A non-empty list of non-empty strings (a single string is accepted as a list of one)."""
        value = self.raw(name, default)
        if isinstance(value, str):
            value = [value]
        if not isinstance(value, list) or not value or not all(isinstance(v, str) and v for v in value):
            raise self.error(name, f"expected a non-empty list of strings, got {value!r}")
        return tuple(value)

    def numbers(self, name: str, length: int, default: Any = _MISSING) -> tuple[float, ...]:
        value = self.raw(name, default)
        if (
            not isinstance(value, list)
            or len(value) != length
            or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
        ):
            raise self.error(name, f"expected a list of {length} numbers, got {value!r}")
        return tuple(float(v) for v in value)

    def integers(self, name: str, default: Any = _MISSING, *, minimum: int | None = None) -> tuple[int, ...]:
        value = self.raw(name, default)
        ok = (
            isinstance(value, list)
            and value
            and all(
                isinstance(v, int) and not isinstance(v, bool) and (minimum is None or v >= minimum)
                for v in value
            )
        )
        if not ok:
            bound = f" >= {minimum}" if minimum is not None else ""
            raise self.error(name, f"expected a non-empty list of integers{bound}, got {value!r}")
        return tuple(value)

    def table(self, name: str, default: Any = _MISSING) -> Table:
        value = self.raw(name, default)
        if not isinstance(value, Mapping):
            raise self.error(name, f"expected a table, got {value!r}")
        return Table(value, self.path, self.key(name))

    def tables(self, name: str) -> list[Table]:
        """An array of tables (``[[name]]``), at least one."""
        value = self.raw(name)
        if not isinstance(value, list) or not value or not all(isinstance(v, Mapping) for v in value):
            raise self.error(name, "expected an array of tables ([[...]]) with at least one entry")
        return [Table(v, self.path, f"{self.key(name)}[{i}]") for i, v in enumerate(value)]
