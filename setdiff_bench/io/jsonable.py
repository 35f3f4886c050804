"""Plain JSON data from nested settings: the one conversion used where a config is written as JSON."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any


def jsonable(value: Any) -> Any:
    """Mappings → dicts with string keys in sorted order, tuples and lists → lists, recursively; every other value
    as it is (``json.dumps`` writes it, or refuses what JSON has no form for).  A stable JSON form: the same
    settings give the same text whatever order their tables were built in."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in sorted(value.items(), key=lambda item: str(item[0]))}
    if isinstance(value, list | tuple):
        return [jsonable(v) for v in value]
    return value
