"""``--shard i/n``: the one parser and selector for splitting work between processes (``prepare``, ``run``)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TypeVar

from setdiff_bench.errors import UsageError

T = TypeVar("T")


@dataclass(frozen=True)
class Shard:
    """``--shard i/n``: items ``i, i+n, i+2n, ...`` of a sorted selection (0 ≤ i < n)."""

    index: int = 0
    count: int = 1

    @classmethod
    def parse(cls, text: str) -> Shard:
        """``"1/4"`` → ``Shard(1, 4)``; a one-line :class:`UsageError` naming ``--shard`` otherwise."""
        head, sep, tail = text.partition("/")
        try:
            index, count = int(head), int(tail)
        except ValueError:
            index, count = -1, 0
        if not sep or count < 1 or not 0 <= index < count:
            raise UsageError(f"shard must be i/n with 0 <= i < n, got {text!r}", "--shard")
        return cls(index, count)

    def select(self, items: Sequence[T]) -> list[T]:
        """This shard's items: ``items[i::n]``."""
        return list(items[self.index :: self.count])

    def __str__(self) -> str:
        return f"{self.index}/{self.count}"
