"""Training-pair recipes: training packets from any capture, without ground truth at a shifted pose (issue 41).

A recipe degrades the 3DGS of a recorded capture on purpose, so that recorded frames become targets whose
render shows the artifacts of a novel view while their capture is the ground truth (the data curation of
Difix3D+ (Wu et al., CVPR 2025) and Fixer).  ``prepare --pairs sparse:4,underfit:0.5,cross-camera`` writes,
instead of the protocol's groups, per recipe and fit:

=================  ================================================  ==========================================
recipe             fit frames (what the degraded 3DGS sees)          targets (recorded, with ground truth)
=================  ================================================  ==========================================
``sparse:N``       every N-th recorded frame (positions 0, N, 2N…)   the frames between them
``underfit:F``     every recorded frame, fit stopped after           the recorded frames (each packet's
                   ``round(F × iterations)`` of its schedule         references exclude its own targets)
``cross-camera:C`` the recorded frames of camera C (default: the     the other cameras' recorded frames
                   camera with most frames, ties by name)
``cycle:S``        renders of the scene's fit at the recorded        the recorded frames (each packet's
                   cameras shifted S metres sideways (none of the    references exclude its own targets)
                   recorded frames)
=================  ================================================  ==========================================

*Recorded frames* are the frames the protocol fits on (each group's ``fit`` selection, in scene order): a
single-trajectory capture as a user has it, e.g. the synthetic benchmark's lane-0 front camera.  References
are chosen by Eq. 2 among the recorded frames the degraded fit saw, exactly as protocol groups choose them
(:func:`setdiff_bench.packets.plan.plan_recipe_pairs`).

Parameters and their ranges: ``N`` an integer ≥ 2 (default 4); ``F`` a fraction with 0.25 ≤ F ≤ 0.75 (the
25–75 % of Difix3D+; default 0.5); ``C`` a camera (sensor) name of the capture; ``S`` a shift in metres
(scene units) with 1 ≤ |S| ≤ 6 (Difix3D+'s 1–6 m; default 2), along each camera's own right axis (OpenCV
+x: lateral for a forward-facing camera), negative to the left.  The group of a recipe's packets is its
label (``sparse4``, ``underfit50``, ``cross-camera`` / ``cross-camera-front``, ``cycle2m`` / ``cycle-1.5m``),
and its fit key ``<protocol fit key>@<label>`` (``lane0@sparse4``; for the default camera
``lane0@cross-camera-front``).

Cycle reconstruction (Difix3D+): the scene's own fit A (``<fit key>.ply``, made with ``--fit`` as the
protocol makes it when missing, else reused) is rendered at the recorded cameras shifted sideways, a second 3DGS B is fitted on those renders
alone (full masks; :mod:`setdiff_bench.packets.cycle`), and B rendered back at the recorded cameras gives
the targets' renders.  B saw none of the recorded frames, so every recorded frame but a packet's own
targets is a reference candidate, as in ``underfit``.  With ``--fits DIR``, B is looked up as
``<fit key>@cycle<S>m.ply`` like every recipe fit, and A is not needed.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

from setdiff_bench.errors import UsageError
from setdiff_bench.types import Frame

RecipeKind = Literal["sparse", "underfit", "cross-camera", "cycle"]
#: The recipes ``--pairs`` knows, in the order of the module docstring.
RECIPES: tuple[RecipeKind, ...] = ("sparse", "underfit", "cross-camera", "cycle")
#: Defaults: every 4th frame; half the iterations; a 2 m shift to the right.
DEFAULT_EVERY = 4
DEFAULT_FRACTION = 0.5
DEFAULT_SHIFT_M = 2.0
#: The range of ``underfit``'s fraction (Difix3D+ stops at 25–75 % of the iterations).
FRACTION_RANGE = (0.25, 0.75)
#: The range of ``cycle``'s shift magnitude |S| in metres (Difix3D+ shifts by 1–6 m).
SHIFT_RANGE_M = (1.0, 6.0)
OPTION = "--pairs"


@dataclass(frozen=True)
class PairRecipe:
    """One parsed recipe of ``--pairs``.

    Attributes:
        kind: ``sparse``, ``underfit``, ``cross-camera`` or ``cycle``.
        every: ``sparse``: fit on every ``every``-th recorded frame.
        fraction: ``underfit``: the share of the fit's iterations run (0.25–0.75).
        camera: ``cross-camera``: the camera fitted on; ``None``: the camera with most recorded frames.
        shift: ``cycle``: the sideways shift in metres (scene units) along each camera's right axis
            (OpenCV +x), 1 ≤ |shift| ≤ 6; negative: to the left.
    """

    kind: RecipeKind
    every: int | None = None
    fraction: float | None = None
    camera: str | None = None
    shift: float | None = None

    @property
    def label(self) -> str:
        """The group name of its packets: ``sparse4``, ``underfit50``, ``cross-camera[-<camera>]``,
        ``cycle2m`` (``cycle-1.5m`` to the left)."""
        if self.kind == "sparse":
            return f"sparse{self.every}"
        if self.kind == "underfit":
            assert self.fraction is not None
            return f"underfit{self.fraction * 100:g}"
        if self.kind == "cycle":
            assert self.shift is not None
            return f"cycle{self.shift:g}m"
        return "cross-camera" if self.camera is None else f"cross-camera-{self.camera}"


def parse_pairs(texts: Sequence[str]) -> tuple[PairRecipe, ...]:
    """Parse ``--pairs`` values: comma-separated ``name[:parameter]`` (the option may also be repeated).

    Raises:
        UsageError: an unknown recipe, a parameter that does not parse or is out of range, or the same
            recipe twice (``sparse:4`` and ``sparse:4``; ``sparse`` and ``sparse:4``; ``cycle`` and
            ``cycle:2.0``).
    """
    recipes = [parse_recipe(part.strip()) for text in texts for part in text.split(",") if part.strip()]
    if texts and not recipes:
        raise UsageError("no recipe given; recipes: " + ", ".join(RECIPES), OPTION)
    labels = [r.label for r in recipes]
    twice = sorted({label for label in labels if labels.count(label) > 1})
    if twice:
        raise UsageError(f"recipe {twice[0]} given twice", OPTION)
    return tuple(recipes)


def parse_recipe(text: str) -> PairRecipe:
    """One ``name[:parameter]`` (module docstring); ``UsageError`` naming ``--pairs`` otherwise."""
    name, _, parameter = text.partition(":")
    if name not in RECIPES:
        raise UsageError(f"unknown recipe {name!r}; recipes: {', '.join(RECIPES)}", OPTION)
    if name == "sparse":
        if not parameter:
            return PairRecipe("sparse", every=DEFAULT_EVERY)
        if not re.fullmatch(r"\d+", parameter) or int(parameter) < 2:
            raise UsageError(f"sparse:{parameter}: the frame step must be an integer >= 2", OPTION)
        return PairRecipe("sparse", every=int(parameter))
    if name == "underfit":
        if not parameter:
            return PairRecipe("underfit", fraction=DEFAULT_FRACTION)
        try:
            fraction = float(parameter)
        except ValueError:
            fraction = math.nan
        low, high = FRACTION_RANGE
        if not low <= fraction <= high:  # NaN fails too
            raise UsageError(
                f"underfit:{parameter}: the share of the fit's iterations must be a number from {low} to {high}",
                OPTION,
            )
        return PairRecipe("underfit", fraction=fraction)
    if name == "cycle":
        return PairRecipe("cycle", shift=_shift(parameter))
    if parameter and not re.fullmatch(r"[A-Za-z0-9_.+-]+", parameter):
        raise UsageError(f"cross-camera:{parameter}: not a camera name", OPTION)
    return PairRecipe("cross-camera", camera=parameter or None)


def _shift(parameter: str) -> float:
    """``cycle``'s shift in metres: ``parameter`` (1 ≤ |S| ≤ 6) or the default; ``UsageError`` otherwise."""
    if not parameter:
        return DEFAULT_SHIFT_M
    try:
        shift = float(parameter)
    except ValueError:
        shift = math.nan
    low, high = SHIFT_RANGE_M
    if not low <= abs(shift) <= high:  # NaN and infinities fail too
        raise UsageError(
            f"cycle:{parameter}: the sideways shift must be a number of metres from {low:g} to {high:g} "
            "(negative: to the left)",
            OPTION,
        )
    return shift


@dataclass(frozen=True)
class RecipeFrames:
    """What a recipe makes of one scene's recorded frames.

    Attributes:
        fit: the frames the degraded 3DGS is fitted on (recorded order); for ``cycle`` the recorded frames
            whose shifted cameras it is fitted at (renders of the scene's fit, never these captures).
        targets: the recorded frames rendered from it (recorded order).
        fit_suffix: ``@<label>`` with the camera resolved for ``cross-camera`` (the fit key's suffix).
        stop_fraction: ``underfit``'s share of the iterations; ``None`` for a full fit.
        disjoint: whether fit frames and targets are disjoint (``False`` for ``underfit`` and ``cycle``:
            each packet's references then exclude its own targets).
        cycle_shift: ``cycle``'s sideways shift in metres; ``None`` for the other recipes.
    """

    fit: tuple[Frame, ...]
    targets: tuple[Frame, ...]
    fit_suffix: str
    stop_fraction: float | None
    disjoint: bool
    cycle_shift: float | None = None


def recipe_frames(recipe: PairRecipe, recorded: Sequence[Frame], where: str) -> RecipeFrames:
    """Split ``recorded`` (the protocol's fit frames of one scene, recorded order) as ``recipe`` says.

    Args:
        recipe: the parsed recipe.
        recorded: the recorded frames, in scene order.
        where: the scene, for messages (``scene 'street_00'``).

    Raises:
        UsageError: fewer than 2 recorded frames; ``cross-camera`` on a capture with one camera, or with a
            camera it does not have.
    """
    frames = tuple(recorded)
    if len(frames) < 2:
        raise UsageError(
            f"recipe {recipe.label} needs at least 2 recorded frames; {where} has {len(frames)}", OPTION
        )
    if recipe.kind == "sparse":
        assert recipe.every is not None
        fit = frames[:: recipe.every]
        kept = {f.name for f in fit}
        return RecipeFrames(
            fit, tuple(f for f in frames if f.name not in kept), f"@{recipe.label}", None, True
        )
    if recipe.kind == "underfit":
        return RecipeFrames(frames, frames, f"@{recipe.label}", recipe.fraction, False)
    if recipe.kind == "cycle":
        return RecipeFrames(frames, frames, f"@{recipe.label}", None, False, cycle_shift=recipe.shift)
    counts = Counter(f.sensor for f in frames)
    if len(counts) < 2:
        only = next(iter(counts)) or "unnamed"
        raise UsageError(
            f"recipe cross-camera needs recorded frames of several cameras; {where} has one ({only})", OPTION
        )
    camera = recipe.camera
    if camera is None:
        camera = min(counts, key=lambda sensor: (-counts[sensor], sensor))
    elif camera not in counts:
        raise UsageError(
            f"recipe {recipe.label}: {where} has no camera {camera!r}; cameras: {', '.join(sorted(counts))}",
            OPTION,
        )
    fit = tuple(f for f in frames if f.sensor == camera)
    targets = tuple(f for f in frames if f.sensor != camera)
    return RecipeFrames(fit, targets, f"@cross-camera-{camera}", None, True)
