"""How paired intervals are drawn (:mod:`setdiff_bench.reporting.paired`): one settings dataclass, with no heavy
imports, so that verbs can build their options from its defaults at every CLI start."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

#: What a bootstrap resample draws: whole scenes (every target of a drawn scene) or single targets.
Unit = Literal["scene", "frame"]


@dataclass(frozen=True)
class BootstrapSettings:
    """How intervals are computed; recorded beside every interval.

    Attributes:
        resamples: number of bootstrap resamples.
        confidence: two-sided level of the percentile interval (0.95: the 2.5th and 97.5th percentiles).
        seed: seed of ``numpy.random.default_rng`` that draws the resamples.
        unit: ``"scene"`` resamples scenes (every target of a drawn scene comes along); ``"frame"`` resamples
            targets independently.
    """

    resamples: int = 10_000
    confidence: float = 0.95
    seed: int = 0
    unit: Unit = "scene"

    def __post_init__(self) -> None:
        if self.resamples < 1:
            raise ValueError(f"resamples must be >= 1, got {self.resamples}")
        if not 0.0 < self.confidence < 1.0:
            raise ValueError(f"confidence must be in (0, 1), got {self.confidence}")

    def describe(self) -> str:
        """``"paired bootstrap over scenes, 95 % percentile interval, 10000 resamples, seed 0"``."""
        over = "scenes" if self.unit == "scene" else "targets (frames)"
        return (
            f"paired bootstrap over {over}, {self.confidence * 100:g} % percentile interval, "
            f"{self.resamples} resamples, seed {self.seed}"
        )
