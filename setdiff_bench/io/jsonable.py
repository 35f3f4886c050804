"""Plain JSON data from nested settings: the one conversion used where a config is written as JSON."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any


def jsonable(value: Any, leaf: Callable[[Any], Any] | None = None) -> Any:
    """Mappings → dicts with string keys in sorted order, tuples and lists → lists, recursively; every other value
    as it is (``json.dumps`` writes it, or refuses what JSON has no form for), or as ``leaf`` converts it (a run's
    options: :func:`setdiff_bench.evaluation.run.jsonable_options`).  A stable JSON form: the same
    settings give the same text whatever order their tables were built in."""
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, leaf) for k, v in sorted(value.items(), key=lambda item: str(item[0]))}
    if isinstance(value, list | tuple):
        return [jsonable(v, leaf) for v in value]
    return value if leaf is None else leaf(value)
