"""The protocol model: the validated contents of a protocol file (:class:`Protocol` and its parts:
:class:`ImageSpec`, :class:`ReferenceSpec`, :class:`PacketSpec`, :class:`GroupSpec`) and a leaderboard's table
shape (:class:`Layout`, :class:`Block`).  :mod:`.parser` builds them from TOML; the package docstring describes
each table of the file."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from setdiff_bench.errors import ProtocolError

from .rules import RULES, GroupFrames
from .scene_split import SceneSplit

if TYPE_CHECKING:
    from setdiff_bench.types import Scene

SPLITS = ("train", "test")
MaskSource = Literal["dataset", "foreground", "none"]
POOLED = ""  # block key of a leaderboard's pooled block (every group)


@dataclass(frozen=True)
class ImageSpec:
    """Working resolution and mask source.

    Attributes:
        resolution: ``(height, width)`` in pixels, or ``None`` for the scene's own size.
        resize: ``"crop"`` (centre-crop to the working aspect ratio, then resize) or ``"stretch"``.
        masks: ``"dataset"``, ``"foreground"`` or ``"none"`` (module docstring).
        downscale: with ``"native"``, the scene's own size divided by this integer (rounded).
    """

    resolution: tuple[int, int] | None
    resize: Literal["crop", "stretch"]
    masks: MaskSource
    downscale: int = 1


@dataclass(frozen=True)
class ReferenceSpec:
    """Eq. 2 and how many references a packet takes.

    Attributes:
        alpha, beta: Eq. 2 weights (0.8, 0.2 in the paper).
        aggregate: ``"mean"`` (or ``"max"``) of a candidate's scores over the packet's targets.
        count: N per packet, by scene split (``{"train": 6, "test": 8}``).
    """

    alpha: float
    beta: float
    aggregate: Literal["mean", "max"]
    count: Mapping[str, int]


@dataclass(frozen=True)
class PacketSpec:
    """Packet sizes.

    Attributes:
        views: N + M stored per packet, by scene split.  When a group has fewer reference candidates
            than N, the packet takes all of them and more targets, keeping N + M = views.
        train_views: ``(min, max)`` set size the training loader draws (paper: 8, varied up to 12).
    """

    views: Mapping[str, int]
    train_views: tuple[int, int]


@dataclass(frozen=True)
class Block:
    """A leaderboard column block: one group (or every group pooled, ``key == POOLED``) with a display label."""

    key: str
    label: str


@dataclass(frozen=True)
class Layout:
    """The leaderboard table shape of one dataset (a protocol's ``[leaderboard]`` table).

    Attributes:
        blocks: column blocks in order; ``None`` = one block per group found (natural order).
        metrics: image metrics per block.
        sequence_metrics: per-sequence metrics shown in the pooled block when runs have them.
        reported_tables: ``table`` ids of ``protocols/reported`` mixed in by ``with_reported``.
        title: caption text.
    """

    blocks: tuple[Block, ...] | None
    metrics: tuple[str, ...] = ("psnr", "ssim", "lpips")
    sequence_metrics: tuple[str, ...] = ()
    reported_tables: tuple[str, ...] = ()
    title: str = ""


@dataclass(frozen=True)
class GroupSpec:
    """One evaluation group.

    Attributes:
        name: group name (``level1``, ``single``, ``10-11s``, ``n3``, ``lane+1``).
        rule: a key of :data:`setdiff_bench.protocols.rules.RULES`.
        params: the rule's validated parameters.
        fit_key: names the 3DGS fitted for this group (fits are shared by groups with the same key).
        scenes: ``Scene.metadata`` filter (key → accepted values); empty = every scene.
    """

    name: str
    rule: str
    params: Mapping[str, Any]
    fit_key: str
    scenes: Mapping[str, tuple[Any, ...]] = field(default_factory=dict)

    def applies_to(self, scene: Scene) -> bool:
        """Whether this group is evaluated on ``scene`` (its ``scenes`` filter)."""
        return all(scene.metadata.get(key) in values for key, values in self.scenes.items())

    def select(self, scene: Scene) -> GroupFrames:
        """Fit frames and targets of this group in ``scene`` (unfiltered: see :meth:`applies_to`)."""
        return RULES[self.rule].select(scene, self.params)


@dataclass(frozen=True)
class Protocol:
    """A validated protocol file (module docstring)."""

    name: str
    dataset: str
    description: str
    path: Path
    loader_options: Mapping[str, Any]
    split: SceneSplit
    images: ImageSpec
    references: ReferenceSpec
    packets: PacketSpec
    cmap_clip: float
    groups: tuple[GroupSpec, ...]
    evaluation: tuple[str, ...] = ("paper",)
    leaderboard: Layout | None = None

    def group(self, name: str) -> GroupSpec:
        for group in self.groups:
            if group.name == name:
                return group
        raise ProtocolError(
            f"protocol {self.name!r} has no group {name!r}; groups: {', '.join(g.name for g in self.groups)}",
            self.path,
        )

    def references_for(self, split: str) -> int:
        return int(self.references.count[split])

    def views_for(self, split: str) -> int:
        return int(self.packets.views[split])
