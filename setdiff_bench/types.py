"""The shared vocabulary of the data path: Camera, Frame, Scene, ViewSet, PacketKey, TargetRef, Packet.

Shapes follow docs/architecture.md: images are float32 ``(V, 3, H, W)`` in [0, 1]; C-maps
``(V, 3, H, W)`` in the packet's normalised frame; alphas ``(V, 1, H, W)`` in [0, 1]; masks
bool ``(V, 1, H, W)`` (True = evaluate).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any, Self

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import DatasetError

__all__ = [
    "PACKET_KEY_FIELDS",
    "Frame",
    "Packet",
    "PacketKey",
    "Scene",
    "TargetRef",
    "TrainingSample",
    "ViewSet",
]


def tensor_summary(value: torch.Tensor | np.ndarray | None) -> str:
    """``"(3, 3, 32, 48) float32"``: an array's shape and dtype, for short reprs (``"None"`` for none)."""
    if value is None:
        return "None"
    dtype = str(value.dtype).removeprefix("torch.")
    return f"{tuple(value.shape)} {dtype}"


def names_summary(names: Sequence[str], shown: int = 3) -> str:
    """``"['a.jpg', 'b.jpg', ... 'z.jpg']"``: the first ``shown`` - 1 names and the last, for short reprs."""
    if len(names) <= shown:
        return repr(list(names))
    head = ", ".join(repr(name) for name in names[: shown - 1])
    return f"[{head}, ... {names[-1]!r}]"


@dataclass(frozen=True)
class Frame:
    """One captured image of a scene.

    Attributes:
        name: key unique within the scene (usually the image file name relative to its folder).
        image_path: absolute path of the image file.
        camera: the camera, project convention (OpenCV axes, world-to-camera).
        timestamp_us: capture time in integer microseconds, or ``None`` when unknown.
        sensor: camera channel (``CAM_FRONT``, ``front_left``, ...), ``""`` when there is one camera.
        traversal: traversal, lane or clip identifier (``"lane0"``, ``"clip_1"``), ``""`` when unknown.
        mask_path: evaluation mask (255 = keep, 0 = ignore), or ``None``.
        split: the dataset's own designation (``"train"``/``"test"``) where it defines one, else ``None``.
        metadata: loader-specific extras (e.g. nuScenes ``sample_data`` token, ``is_key_frame``).
    """

    name: str
    image_path: Path
    camera: Camera
    timestamp_us: int | None = None
    sensor: str = ""
    traversal: str = ""
    mask_path: Path | None = None
    split: str | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Scene:
    """A scene as a loader returns it: frames sorted deterministically, plus optional sparse points.

    Attributes:
        dataset: dataset key (``euvs``, ``paralane``, ``nuscenes``, ``dl3dv``, ``synthetic``, ...).
        name: scene name, unique in the dataset.
        root: the scene folder (or dataset root for table-based datasets).
        frames: every frame, sorted by the loader's documented order.
        points3d: ``(P, 3)`` float64 sparse points in world coordinates (SfM, LiDAR), or ``None``.
        points_rgb: ``(P, 3)`` uint8 colours of ``points3d``, or ``None``.
        metadata: dataset-level extras (e.g. EUVS level, lane order).
    """

    dataset: str
    name: str
    root: Path
    frames: tuple[Frame, ...]
    points3d: np.ndarray | None = None
    points_rgb: np.ndarray | None = None
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        seen: set[str] = set()
        for frame in self.frames:
            if frame.name in seen:
                raise DatasetError(f"duplicate frame name {frame.name!r} in scene {self.name!r}", self.root)
            seen.add(frame.name)

    def __repr__(self) -> str:
        return (
            f"Scene({self.dataset!r}, {self.name!r}, {len(self.frames)} frames "
            f"{names_summary(self.frame_names)}, sensors {list(self.sensors)}, points3d "
            f"{tensor_summary(self.points3d)}, root {str(self.root)!r})"
        )

    def frame(self, name: str) -> Frame:
        """The frame called ``name``."""
        for frame in self.frames:
            if frame.name == name:
                return frame
        raise DatasetError(f"scene {self.name!r} has no frame {name!r}", self.root)

    @property
    def frame_names(self) -> tuple[str, ...]:
        return tuple(frame.name for frame in self.frames)

    @property
    def sensors(self) -> tuple[str, ...]:
        """Distinct camera channels, in order of first appearance."""
        return tuple(dict.fromkeys(frame.sensor for frame in self.frames))

    @property
    def traversals(self) -> tuple[str, ...]:
        """Distinct traversals / lanes, in order of first appearance."""
        return tuple(dict.fromkeys(frame.traversal for frame in self.frames))

    def select(self, names: Sequence[str]) -> tuple[Frame, ...]:
        """Frames in the order of ``names``."""
        by_name = {frame.name: frame for frame in self.frames}
        missing = [name for name in names if name not in by_name]
        if missing:
            raise DatasetError(f"scene {self.name!r} has no frames {missing[:5]}", self.root)
        return tuple(by_name[name] for name in names)


@dataclass
class ViewSet:
    """The views of one role (references or targets) in a packet, stacked.

    Attributes:
        names: ``V`` frame names.
        images: ``(V, 3, H, W)`` float32 in [0, 1]: clean captures for references, 3DGS renders for targets.
        cmaps: ``(V, 3, H, W)`` float32 C-maps (Eq. 1) in the packet's normalised frame.
        alphas: ``(V, 1, H, W)`` float32 accumulated opacity of the render.
        cameras: ``V`` cameras in the packet's normalised frame.
        timestamps_us: ``V`` capture times (``None`` where unknown).
    """

    names: tuple[str, ...]
    images: torch.Tensor
    cmaps: torch.Tensor
    alphas: torch.Tensor
    cameras: tuple[Camera, ...]
    timestamps_us: tuple[int | None, ...] = ()

    def __len__(self) -> int:
        return len(self.names)

    def __repr__(self) -> str:
        return (
            f"ViewSet({len(self)} views {names_summary(self.names)}, images {tensor_summary(self.images)}, "
            f"cmaps {tensor_summary(self.cmaps)}, alphas {tensor_summary(self.alphas)})"
        )

    @property
    def K(self) -> torch.Tensor:
        """``(V, 3, 3)`` float32 intrinsics."""
        return torch.from_numpy(np.stack([c.K for c in self.cameras])).float()

    @property
    def w2c(self) -> torch.Tensor:
        """``(V, 4, 4)`` float32 normalised world-to-camera matrices."""
        return torch.from_numpy(np.stack([c.w2c for c in self.cameras])).float()

    def subset(self, indices: Sequence[int]) -> ViewSet:
        """The views at ``indices``, in that order."""
        idx = list(indices)
        return ViewSet(
            names=tuple(self.names[i] for i in idx),
            images=self.images[idx],
            cmaps=self.cmaps[idx],
            alphas=self.alphas[idx],
            cameras=tuple(self.cameras[i] for i in idx),
            timestamps_us=tuple(self.timestamps_us[i] for i in idx) if self.timestamps_us else (),
        )


@dataclass(frozen=True)
class PacketKey:
    """Which packet: the one declaration of a packet's identity.

    Everything that names a packet extends it — the plan's ``PacketJob``, the store's ``PacketHeader``,
    one target view's :class:`TargetRef`, a :class:`Packet` with its views — and its fields are the key columns of
    the packet index and of a run's ``metrics.parquet`` (:data:`setdiff_bench.io.run_layout.KEY_COLUMNS`).

    Attributes:
        packet_id: unique id in its store.
        dataset, protocol, group, split, scene: where the packet comes from.
    """

    packet_id: str
    dataset: str
    protocol: str
    group: str
    split: str
    scene: str

    @property
    def key(self) -> PacketKey:
        """Only the key (an object that extends :class:`PacketKey` carries more)."""
        return PacketKey(**key_fields(self))

    @classmethod
    def from_row(cls, row: Mapping[str, Any], **extra: Any) -> Self:
        """``cls`` built from the key columns of an index or run row, plus ``extra`` fields."""
        return cls(**{name: str(row[name]) for name in PACKET_KEY_FIELDS}, **extra)


#: The key's field names, in declaration order.
PACKET_KEY_FIELDS: tuple[str, ...] = tuple(f.name for f in fields(PacketKey))


def key_fields(keyed: PacketKey | Packet) -> dict[str, str]:
    """``{field: value}`` of the packet key of a :class:`PacketKey` (or anything extending it) or a :class:`Packet`."""
    return {name: getattr(keyed, name) for name in PACKET_KEY_FIELDS}


@dataclass(frozen=True)
class TargetRef(PacketKey):
    """Where one target view comes from: its packet's key and its frame, enough to find a file produced
    for it by external code."""

    frame: str


@dataclass(frozen=True)
class Packet(PacketKey):
    """N clean references + M rendered targets of one scene, normalised into the first target's frame.

    Ground truth and masks are not here: they stay with the runner and never reach an enhancer.  A packet is
    its :class:`PacketKey` (the first six fields, :attr:`key`) extended by its views; it is frozen like the key,
    so a packet with other views is ``dataclasses.replace(packet, references=..., targets=...)``.

    Attributes:
        references: the N reference views (clean images).
        targets: the M target views (3DGS renders).
        scale: the factor world units were multiplied by during normalisation.
    """

    references: ViewSet
    targets: ViewSet
    scale: float = 1.0
    metadata: Mapping[str, Any] = field(default_factory=dict)

    @classmethod
    def from_key(
        cls,
        key: PacketKey,
        references: ViewSet,
        targets: ViewSet,
        scale: float = 1.0,
        metadata: Mapping[str, Any] | None = None,
    ) -> Packet:
        """A packet named by ``key`` (any :class:`PacketKey`, e.g. a store's ``PacketHeader``)."""
        return cls(
            **key_fields(key),
            references=references,
            targets=targets,
            scale=scale,
            metadata={} if metadata is None else metadata,
        )

    def __repr__(self) -> str:
        where = "/".join((self.dataset, self.protocol, self.group, self.split, self.scene))
        return (
            f"Packet({self.packet_id!r}, {where}, {len(self.references)} references "
            f"{names_summary(self.references.names)} + {len(self.targets)} targets "
            f"{names_summary(self.targets.names)}, {self.height}x{self.width} px, scale {self.scale:g})"
        )

    @property
    def height(self) -> int:
        return int(self.targets.images.shape[-2])

    @property
    def width(self) -> int:
        return int(self.targets.images.shape[-1])


@dataclass
class TrainingSample:
    """One training example: a packet plus what only the trainer may see.

    Attributes:
        packet: references (clean) and targets (renders) with C-maps and normalised cameras.
        target_gt: ``(M, 3, H, W)`` float32 ground-truth images of the targets, in [0, 1].
        target_masks: ``(M, 1, H, W)`` bool, True where the loss is evaluated.
    """

    packet: Packet
    target_gt: torch.Tensor
    target_masks: torch.Tensor

    def __repr__(self) -> str:
        return (
            f"TrainingSample({self.packet!r}, target_gt {tensor_summary(self.target_gt)}, "
            f"target_masks {tensor_summary(self.target_masks)})"
        )
