"""The settings of one refit (:class:`RefitSettings`) and its two schedule presets, declared once.

Light on purpose (no torch): the ``refit`` verb builds its options from these fields at every CLI start.

A schedule is four numbers (docs/refit.md says which paper each preset follows and why):

* ``update_every`` — refit steps between two pseudo-view updates (``0``: one update, before the first step);
* ``pose_fraction`` — how far the ``k``-th update (``k = 1, 2, ...``) moves each pseudo-view along the path from
  its target's nearest training pose to the target: ``min(1, k · pose_fraction)`` of the way;
* ``pseudo_weight`` — the loss weight ``w`` of a pseudo-view step (a real view's is 1);
* ``real_ratio`` — the share ``r`` of steps that take a real training view (the others a pseudo-view).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from fractions import Fraction
from typing import Any, Literal, get_args

from setdiff_bench.errors import UsageError

#: The schedule presets' names (``--schedule``).
Schedule = Literal["progressive", "one-shot"]

#: What each preset sets; every other field keeps the :class:`RefitSettings` default.
SCHEDULE_PRESETS: Mapping[str, Mapping[str, Any]] = {
    # Difix3D+ (Wu et al., CVPR 2025): poses move from the nearest training view toward the targets in steps,
    # each update re-renders and re-fixes them; 0.3 loss weight, 70 % of batches real
    "progressive": {"update_every": 100, "pose_fraction": 0.5, "pseudo_weight": 0.3, "real_ratio": 0.7},
    # 3DGS-Enhancer (Liu et al., NeurIPS 2024): the target views enhanced once, then a fine-tune with them
    "one-shot": {"update_every": 0, "pose_fraction": 1.0, "pseudo_weight": 0.3, "real_ratio": 0.7},
}


@dataclass(frozen=True)
class RefitSettings:
    """How one scene is refitted (module docstring for the schedule).

    Attributes:
        schedule: the preset the schedule numbers came from (recorded in the manifest).
        steps: optimiser steps of the refit (each renders one view, real or pseudo).
        update_every, pose_fraction, pseudo_weight, real_ratio: the schedule (module docstring).
        seed: seeds the order of the real and pseudo-views.
        checkpoint_every: save a resumable checkpoint every this many steps (and after the last one).
        snapshot_every: also write the model every this many steps (``0``: never) where ``prepare --fits`` reads
            it (:func:`setdiff_bench.io.refit_layout.snapshot_folder`); the snapshot at step ``k`` is the PLY a
            refit with ``steps = k`` ends with, so one refit gives the curve of a score against refit steps.
        min_fit_correlation: the fit's renders of its training views must correlate with the captures' detail
            (Pearson correlation of the high-pass images, mean over views) at least this much, else it is refused
            as the fit of another scene (measured on the tiny preset: own fits 0.38 and 0.52, the other scene's
            0.04 and 0.06; docs/refit.md).
    """

    schedule: Schedule = "progressive"
    steps: int = 300
    update_every: int = 100
    pose_fraction: float = 0.5
    pseudo_weight: float = 0.3
    real_ratio: float = 0.7
    seed: int = 0
    checkpoint_every: int = 50
    snapshot_every: int = 0
    min_fit_correlation: float = 0.2

    @classmethod
    def preset(cls, schedule: str, **overrides: Any) -> RefitSettings:
        """The ``schedule`` preset's settings with ``overrides`` (``None`` values ignored), checked.

        Raises:
            UsageError: an unknown schedule or field, or a value out of range (:meth:`check`).
        """
        if schedule not in SCHEDULE_PRESETS:
            raise UsageError(
                f"unknown schedule {schedule!r}; choose one of {', '.join(SCHEDULE_PRESETS)}", "--schedule"
            )
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(overrides) - names)
        if unknown:
            raise UsageError(f"refit settings have no field {unknown[0]!r}")
        given = {k: v for k, v in overrides.items() if v is not None}
        return cls(schedule=schedule, **{**SCHEDULE_PRESETS[schedule], **given}).check()  # type: ignore[arg-type]

    def check(self) -> RefitSettings:
        """``self`` when every value is in range; else :class:`UsageError` naming the option."""
        if self.schedule not in get_args(Schedule):
            raise UsageError(f"unknown schedule {self.schedule!r}", "--schedule")
        rules = (
            (self.steps >= 1, "steps", "must be >= 1"),
            (self.update_every >= 0, "update_every", "must be >= 0 (0: one update before the first step)"),
            (0.0 < self.pose_fraction <= 1.0, "pose_fraction", "must be in (0, 1]"),
            (self.pseudo_weight >= 0.0, "pseudo_weight", "must be >= 0"),
            (
                0.0 <= self.real_ratio < 1.0,
                "real_ratio",
                "must be in [0, 1) (1 would never use a pseudo-view)",
            ),
            (self.checkpoint_every >= 1, "checkpoint_every", "must be >= 1"),
            (self.snapshot_every >= 0, "snapshot_every", "must be >= 0 (0: no snapshots)"),
        )
        for ok, name, problem in rules:
            if not ok:
                raise UsageError(f"{problem}, got {getattr(self, name)!r}", f"--{name.replace('_', '-')}")
        return self

    def update_steps(self) -> list[int]:
        """The refit steps (0-based, each before that step runs) at which the pseudo-views are updated."""
        if self.update_every == 0:
            return [0]
        return list(range(0, self.steps, self.update_every))

    def is_pseudo_step(self, step: int) -> bool:
        """Whether 1-based refit step ``step`` takes a pseudo-view: the steps where
        ``⌊step · (1 − r)⌋`` grows, so exactly ``⌊n · (1 − r)⌋`` of the first ``n`` steps are pseudo, spread
        evenly (exact rational arithmetic on the decimal ``r``, no random draw)."""
        share = 1 - Fraction(str(self.real_ratio))
        return (step * share).__floor__() > ((step - 1) * share).__floor__()

    def snapshot_steps(self) -> list[int]:
        """The steps (1-based: after that many steps) whose model is written as a snapshot."""
        return (
            list(range(self.snapshot_every, self.steps + 1, self.snapshot_every))
            if self.snapshot_every
            else []
        )

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)
