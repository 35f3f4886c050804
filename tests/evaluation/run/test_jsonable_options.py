"""A run's options as JSON: the shared sorted walk of :func:`setdiff_bench.io.jsonable.jsonable` with leaves
made JSON-safe (expected values written by hand)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from setdiff_bench.evaluation.run import jsonable_options
from setdiff_bench.io.jsonable import jsonable


@dataclass
class Inner:
    weight: float = float("nan")
    where: tuple[object, ...] = field(default_factory=lambda: (1, Path("/models/a")))


def test_options_leaves_are_json_safe_and_keys_sorted() -> None:
    options = {"z": 1, "a": [Inner(), 2.5, float("inf"), None, True], 3: "s"}
    expected = {"3": "s", "a": [{"weight": "nan", "where": [1, "/models/a"]}, 2.5, "inf", None, True], "z": 1}
    assert jsonable_options(options) == expected
    assert json.dumps(jsonable_options(options), allow_nan=False)  # nothing JSON lacks a form for


def test_plain_jsonable_keeps_leaves_as_they_are() -> None:
    path = Path("/models/a")
    assert jsonable({"b": (path, 1.5), "a": {"y": 2, "x": None}}) == {
        "a": {"x": None, "y": 2},
        "b": [path, 1.5],
    }
