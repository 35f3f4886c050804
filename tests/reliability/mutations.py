"""Hypothesis strategies that break valid files in structured ways (mutation fuzzing).

Three levels, combined by the fuzz tests:

* bytes: truncation, byte flips, inserted and deleted runs, duplicated runs, and now and then
  random bytes outright (:func:`mutated_bytes`);
* text tokens: a field replaced by a nasty token (NaN, inf, huge or negative numbers, words, empty),
  fields or lines deleted, duplicated, swapped or inserted, the text cut (:func:`mutated_text`);
* JSON trees: a key deleted, a value replaced by a value of another type or an extreme number, a list
  shortened or an element duplicated, anywhere in the tree (:func:`mutated_json`).

Every strategy starts from a valid file, so most inputs get deep into the parser before they break.
"""

from __future__ import annotations

import copy
import math
from typing import Any

from hypothesis import strategies as st

#: Tokens that break numeric fields in interesting ways.
NASTY_TOKENS = (
    "nan",
    "NaN",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e400",
    "-1",
    "0",
    "-0",
    "1e-320",
    "18446744073709551616",
    "-9223372036854775809",
    "99999999999999999999",
    "4294967296",
    "2147483648",
    "abc",
    "1.5.2",
    "0x10",
    "",
    "#",
    "--",
    "1,5",
    "٣",
    "\u00a0",
    "None",
    "true",
)

#: JSON values of every type and extreme magnitudes.
NASTY_VALUES: tuple[Any, ...] = (
    None,
    True,
    False,
    0,
    -1,
    1,
    10**30,
    -(10**30),
    2**63,
    1e308,
    -1e308,
    1e-320,
    math.nan,
    math.inf,
    -math.inf,
    "",
    "x",
    "../../../etc/passwd",
    "/abs/path",
    "a\x00b",
    [],
    [1],
    [[0.0] * 4] * 4,
    {},
    {"token": "x"},
    0.5,
    "1",
)


@st.composite
def mutated_bytes(draw: st.DrawFn, base: bytes, max_ops: int = 3) -> bytes:
    """``base`` changed by 1..``max_ops`` byte-level operations (or, rarely, replaced by random bytes)."""
    if draw(st.integers(0, 19)) == 0:
        return draw(st.binary(max_size=512))
    data = bytearray(base)
    for _ in range(draw(st.integers(1, max_ops))):
        size = len(data)
        op = draw(st.sampled_from(("truncate", "flip", "insert", "delete", "duplicate", "set")))
        at = draw(st.integers(0, max(size - 1, 0)))
        if op == "truncate":
            del data[at:]
        elif op == "flip" and size:
            data[at] ^= draw(st.integers(1, 255))
        elif op == "set" and size:
            data[at] = draw(st.sampled_from((0, 10, 32, 45, 46, 48, 57, 101, 127, 128, 255)))
        elif op == "insert":
            data[at:at] = draw(st.binary(min_size=1, max_size=16))
        elif op == "delete":
            del data[at : at + draw(st.integers(1, 64))]
        elif op == "duplicate":
            length = draw(st.integers(1, 64))
            data[at:at] = data[at : at + length]
    return bytes(data)


@st.composite
def mutated_text(draw: st.DrawFn, base: str, max_ops: int = 3) -> str:
    """``base`` (whitespace-separated fields in lines) changed by 1..``max_ops`` token/line operations."""
    lines = [line.split(" ") for line in base.split("\n")]
    for _ in range(draw(st.integers(1, max_ops))):
        op = draw(
            st.sampled_from(
                (
                    "token",
                    "token",
                    "token",
                    "drop_token",
                    "add_token",
                    "drop_line",
                    "dup_line",
                    "swap_lines",
                    "add_line",
                    "cut",
                )
            )
        )
        row = draw(st.integers(0, max(len(lines) - 1, 0)))
        if not lines:
            lines = [[]]
        fields = lines[row]
        col = draw(st.integers(0, max(len(fields) - 1, 0)))
        if op == "token" and fields:
            fields[col] = draw(
                st.one_of(
                    st.sampled_from(NASTY_TOKENS),
                    st.integers(-(2**70), 2**70).map(str),
                    st.floats(allow_nan=True, allow_infinity=True).map(repr),
                    st.text(alphabet="0123456789.-+eE", max_size=8),
                )
            )
        elif op == "drop_token" and fields:
            del fields[col]
        elif op == "add_token":
            fields.insert(col, draw(st.sampled_from(NASTY_TOKENS)))
        elif op == "drop_line":
            del lines[row]
        elif op == "dup_line":
            lines.insert(row, list(fields))
        elif op == "swap_lines" and len(lines) > 1:
            other = draw(st.integers(0, len(lines) - 1))
            lines[row], lines[other] = lines[other], lines[row]
        elif op == "add_line":
            lines.insert(row, draw(st.lists(st.sampled_from(NASTY_TOKENS), max_size=12)))
        elif op == "cut":
            text = "\n".join(" ".join(f) for f in lines)
            text = text[: draw(st.integers(0, len(text)))]
            lines = [line.split(" ") for line in text.split("\n")]
    return "\n".join(" ".join(f) for f in lines)


def _containers(tree: Any, path: tuple = ()) -> list[tuple]:
    """Paths of every dict and list in ``tree`` (the root is ``()``)."""
    found = []
    if isinstance(tree, dict | list):
        found.append(path)
        items = tree.items() if isinstance(tree, dict) else enumerate(tree)
        for key, value in items:
            found.extend(_containers(value, (*path, key)))
    return found


def _at(tree: Any, path: tuple) -> Any:
    for key in path:
        tree = tree[key]
    return tree


@st.composite
def mutated_json(draw: st.DrawFn, base: Any, max_ops: int = 3) -> Any:
    """A deep copy of ``base`` changed by 1..``max_ops`` tree operations anywhere in it."""
    tree = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, max_ops))):
        containers = _containers(tree)
        if not containers:
            return copy.deepcopy(draw(st.sampled_from(NASTY_VALUES)))
        node = _at(tree, draw(st.sampled_from(containers)))
        keys = list(node) if isinstance(node, dict) else list(range(len(node)))
        op = draw(
            st.sampled_from(("replace", "replace", "replace", "delete", "duplicate", "retype_container"))
        )
        if not keys:
            continue
        key = draw(st.sampled_from(keys))
        if op == "replace":  # (copied: the nasty lists and dicts must not be shared between places)
            node[key] = copy.deepcopy(
                draw(
                    st.one_of(
                        st.sampled_from(NASTY_VALUES),
                        st.integers(-(2**70), 2**70),
                        st.floats(allow_nan=True, allow_infinity=True),
                        st.text(max_size=6),
                    )
                )
            )
        elif op == "delete":
            del node[key]
        elif op == "duplicate" and isinstance(node, list):
            node.insert(key, copy.deepcopy(node[key]))
        elif op == "retype_container":
            value = node[key]
            node[key] = (
                list(value.values())
                if isinstance(value, dict)
                else ({str(i): v for i, v in enumerate(value)} if isinstance(value, list) else [value])
            )
    return tree
