"""The one-line description of a weights file whose tensor names do not fit the model."""

from __future__ import annotations

from setdiff_bench.errors import key_mismatch


def test_agreeing_names_give_none_whatever_the_order() -> None:
    assert key_mismatch(["a", "b"], ("b", "a")) is None


def test_missing_and_unexpected_are_counted_and_sorted_with_examples() -> None:
    text = key_mismatch(["w3", "w1", "w2", "b"], ["b", "x", "w9"], examples=2)
    assert text == "3 missing (e.g. ['w1', 'w2']), 2 unexpected (e.g. ['w9', 'x'])"
    assert key_mismatch(["a"], []) == "1 missing (e.g. ['a']), 0 unexpected (e.g. [])"
