"""Scene-level train/test splits for enhancer training.

Scenes are ordered by Python's ``sorted`` on their names (code-point order, the names as the
loader's ``list_scenes`` returns them), over **every** scene of the dataset root, so a scene's split
never depends on which scenes a run selects.  Rules:

``interleaved`` (EUVS, Para-Lane, synthetic: the paper's 60 %/40 % scene split)
    with the test fraction ``p`` as an exact fraction (2/5), the scene at sorted position ``i``
    (0-based) is a test scene iff ``⌊(i + 1)·p⌋ > ⌊i·p⌋``.  Test scenes are spread evenly through
    the sorted list (positions 2, 4, 7, 9, … for p = 2/5), so every level or location prefix is split
    about 60/40, and exactly ``⌊n·p⌋`` of ``n`` scenes are test.
``every_nth`` (nuScenes: "after sorting scene names, every fifth scene is assigned to the test set")
    the scene at 1-based position ``k`` is test iff ``k % every == 0`` (the 5th, 10th, … scenes).
``list`` (DL3DV: the 20 3DGS-Enhancer test hashes in ``protocols/splits/``)
    test iff the name — or its last path component — is in the list file; the rest train.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Literal

SplitRule = Literal["interleaved", "every_nth", "list"]


@dataclass(frozen=True)
class SceneSplit:
    """A scene-level split rule (module docstring).

    Attributes:
        rule: ``interleaved``, ``every_nth`` or ``list``.
        test_fraction: ``interleaved``: the exact test fraction.
        every: ``every_nth``: the period.
        test_names: ``list``: the test scene names (from ``list_file``).
        list_file: ``list``: where the names came from.
    """

    rule: SplitRule
    test_fraction: Fraction | None = None
    every: int | None = None
    test_names: frozenset[str] = frozenset()
    list_file: Path | None = None

    def assign(self, scene_names: Iterable[str]) -> dict[str, str]:
        """``{scene name: "train" | "test"}`` for every name (rule in the module docstring)."""
        ordered = sorted(set(scene_names))
        if self.rule == "interleaved":
            p = self.test_fraction
            assert p is not None
            return {
                name: "test" if math.floor((i + 1) * p) > math.floor(i * p) else "train"
                for i, name in enumerate(ordered)
            }
        if self.rule == "every_nth":
            assert self.every is not None
            return {name: "test" if (i + 1) % self.every == 0 else "train" for i, name in enumerate(ordered)}
        return {
            name: "test" if name in self.test_names or name.rsplit("/", 1)[-1] in self.test_names else "train"
            for name in ordered
        }

    def describe(self) -> str:
        if self.rule == "interleaved":
            return f"interleaved, test fraction {self.test_fraction}"
        if self.rule == "every_nth":
            return f"every {self.every}th sorted scene is test"
        return f"{len(self.test_names)} listed test scenes ({self.list_file.name if self.list_file else '?'})"


def read_split_list(path: Path) -> frozenset[str]:
    """Names in a split file: one per line, blank lines ignored (``OSError`` propagates)."""
    return frozenset(line.strip() for line in path.read_text(encoding="utf-8").splitlines() if line.strip())


def counts(assignment: Mapping[str, str]) -> tuple[int, int]:
    """``(train, test)`` scene counts of an assignment."""
    test = sum(1 for v in assignment.values() if v == "test")
    return len(assignment) - test, test
