"""PacketStore: packets on disk (index + PNG/EXR files), read as :class:`~setdiff_bench.types.Packet`.

Layout and index columns: :mod:`setdiff_bench.packets.index`.  Files per view:

* ``*_rgb.png`` — 8-bit RGB: the clean capture (references) or the 3DGS render (targets), at the
  protocol's working resolution;
* ``*_cmap.exr`` — 4 channels ``X, Y, Z, A`` through OpenImageIO, **float32** by default: X, Y, Z
  is the Eq. 1 C-map (alpha-weighted, not divided) in the packet's normalised frame, A the render's
  accumulated alpha (needed to divide or to re-transform an Eq. 1 map).  Why float32: the maps carry
  geometry, and half's 11-bit significand is off by up to 2⁻¹¹ of a coordinate's magnitude — a
  ~5e-4 rad direction error, about 0.4 px once a point is reprojected into another 576×1024 view —
  so reprojection (warp metrics, reprojection baselines, the frame tests) would see quantisation
  error.  The price is size: ZIP-compressed float32 maps are ~3.5× larger than half (measured,
  benchmarks/results/prepare.json); ``prepare(cmap_precision="half")`` stores half where disk is
  the constraint (the model's conditioning does not need more);
* ``tgt_*_gt.png`` — 8-bit ground truth (the capture), ``tgt_*_mask.png`` — 8-bit, 255 = evaluate
  (all 255 when the protocol uses no masks).  A target on a novel trajectory (``prepare --trajectory``)
  has neither: its ``gt`` / ``mask`` columns are null (:meth:`PacketStore.has_ground_truth`), and
  ``run`` scores such targets only by what needs no ground truth (FID / KID).

Writes are atomic: a packet is assembled in a temporary folder, its fragment index written last,
then renamed into place; an interrupted write (SIGKILL) leaves only a ``.tmp-*`` folder that the next
run removes.  Files are not fsynced one by one (it tripled the write time): after a power loss a
torn file would fail its SHA-256 check, which ``prepare`` runs before skipping a packet, so it is
rewritten.  :meth:`PacketStore.verify` re-hashes every file, and every file a packet is loaded from is
checked against its SHA-256 before it is decoded (a file changed after ``prepare`` is an error, never
a silently different input or ground truth; hashing costs a few ms next to decoding).
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import PacketError, SetDiffBenchError, UsageError
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.images import read_exr, read_mask, read_rgb, to_tensor_chw
from setdiff_bench.packets.index import INDEX_FILE, SCENE_SPLITS, NoGroundTruthError, merge_index, read_rows
from setdiff_bench.packets.training_dataset import PacketTrainingDataset
from setdiff_bench.packets.writer import (
    file_problems,
)
from setdiff_bench.types import Packet, PacketKey, ViewSet

__all__ = ["PacketStore", "row_camera", "target_has_ground_truth", "timestamp_or_none"]


class PacketStore:
    """A prepared packet store (``setdiff-bench prepare ... --out ROOT``).

    Args:
        root: the store folder holding ``index.parquet``.

    Raises:
        PacketError: no index, or an unreadable one.
    """

    def __init__(self, root: str | os.PathLike[str]) -> None:
        self.root = Path(root)
        index_file = self.root / INDEX_FILE
        if not index_file.is_file():
            raise PacketError(
                "no index.parquet here; create the store with `setdiff-bench prepare`",
                self.root,
                parameter="packets",
            )
        self.index: pd.DataFrame = read_rows(index_file).to_pandas()
        self._rows: dict[str, pd.DataFrame] = {
            pid: rows for pid, rows in self.index.groupby("packet_id", sort=True)
        }

    def __len__(self) -> int:
        return len(self._rows)

    def __repr__(self) -> str:
        return f"PacketStore({str(self.root)!r}, packets={len(self)})"

    # ------------------------------------------------------------------ listing
    def packet_ids(self, split: str | None = None) -> list[str]:
        """Packet ids in sorted order.

        Args:
            split: ``"train"`` or ``"test"`` (the packets of the protocol's train or test scenes; ``[]`` when the
                store holds none), another split this store's index holds, or ``None`` / ``"all"``: every packet.

        Raises:
            UsageError: (naming ``split``) a split that is no split name and not in this store, e.g. a typo
                (``"tset"``), naming the valid ones.
        """
        if split is None or split == "all":
            return list(self._rows)
        chosen = [pid for pid, rows in self._rows.items() if rows["split"].iloc[0] == split]
        if not chosen and split not in SCENE_SPLITS:
            present = sorted({str(rows["split"].iloc[0]) for rows in self._rows.values()})
            valid = list(dict.fromkeys([*SCENE_SPLITS, *present, "all"]))
            raise UsageError(
                f"unknown split; valid splits: {', '.join(valid)} (this store holds: {', '.join(present) or 'none'})",
                split,
                parameter="split",
            )
        return chosen

    def rows(self, packet_id: str) -> pd.DataFrame:
        """The index rows of one packet (references first, then targets, each by position)."""
        if packet_id not in self._rows:
            raise PacketError(f"no packet {packet_id!r} in the index", self.root / INDEX_FILE)
        return self._rows[packet_id]

    # ------------------------------------------------------------------ loading
    def load_packet(
        self, packet_id: str, references: Sequence[int] | None = None, targets: Sequence[int] | None = None
    ) -> Packet:
        """A packet without ground truth: references (clean) and targets (renders) with C-maps and cameras.

        Args:
            packet_id: an id from :meth:`packet_ids`.
            references, targets: positions to load, in that order (default: all, stored order).
        """
        rows = self.rows(packet_id)
        refs, tgts = rows[rows["role"] == "ref"], rows[rows["role"] == "target"]
        first = rows.iloc[0]
        return Packet.from_key(
            PacketKey.from_row(first),
            references=self._view_set(_pick(refs, references)),
            targets=self._view_set(_pick(tgts, targets)),
            scale=float(first["scale"]),
            metadata={
                "fit_key": first["fit_key"],
                "recipe": first["recipe"],
                "reference_scores": tuple(float(s) for s in _pick(refs, references)["overlap_score"]),
            },
        )

    def has_ground_truth(self, packet_id: str) -> np.ndarray:
        """``(M,)`` bool: which of the packet's targets (stored order) have ground truth and a mask.

        Targets on a novel trajectory (``prepare --trajectory``) have neither.
        """
        rows = self.rows(packet_id)
        return target_has_ground_truth(rows[rows["role"] == "target"])

    def load_ground_truth(
        self, packet_id: str, targets: Sequence[int] | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """``(gt (M, 3, H, W) float32 in [0, 1], masks (M, 1, H, W) bool)`` of the packet's targets.

        Raises:
            NoGroundTruthError: a chosen target has no ground truth (a novel-trajectory view; check
                :meth:`has_ground_truth` first).
        """
        rows = _pick(self.rows(packet_id)[lambda r: r["role"] == "target"], targets)
        without = rows[~target_has_ground_truth(rows)]
        if len(without):
            raise NoGroundTruthError(
                f"packet {packet_id!r} target {without['frame'].iloc[0]!r} has no ground truth "
                "(a novel-trajectory view); only metrics that need none apply to it",
                self.root / INDEX_FILE,
            )
        gts, masks = [], []
        for _, row in rows.iterrows():
            size = (int(row["height"]), int(row["width"]))
            gts.append(to_tensor_chw(read_rgb(self._file(row, "gt"), size)))
            masks.append(torch.from_numpy(read_mask(self._file(row, "mask"), size))[None])
        return torch.stack(gts), torch.stack(masks)

    def iter_packets(self, split: str | None = None) -> Iterator[Packet]:
        """Every packet (optionally of one split), in id order."""
        for packet_id in self.packet_ids(split):
            yield self.load_packet(packet_id)

    def training_dataset(
        self, split: str = "train", min_views: int = 8, max_views: int = 12, seed: int = 0
    ) -> PacketTrainingDataset:
        """A torch ``Dataset`` of :class:`TrainingSample` over the packets of ``split`` (see the class)
        whose targets all have ground truth (novel-trajectory packets have none to train on)."""
        ids = [pid for pid in self.packet_ids(split) if self.has_ground_truth(pid).all()]
        return PacketTrainingDataset(self, ids, min_views=min_views, max_views=max_views, seed=seed)

    # ------------------------------------------------------------------ integrity
    def verify(self, packet_ids: Sequence[str] | None = None) -> list[str]:
        """Re-hash every file of the given packets (default all); returns one line per problem (empty = OK)."""
        problems = []
        for pid in self.packet_ids() if packet_ids is None else packet_ids:
            problems += [f"{pid}: {p}" for p in file_problems(self.root, self.rows(pid).to_dict("records"))]
        return problems

    def merge(self) -> bool:
        """Rebuild ``index.parquet`` from the packet fragments (see :func:`merge_index`)."""
        return merge_index(self.root)

    def file_path(self, row: pd.Series, column: str) -> Path:
        """The file of an index row's ``column`` (``image``, ``gt``, ``mask``, ``cmap``), verified against its SHA-256."""
        return self._file(row, column)

    # ------------------------------------------------------------------ helpers
    def _file(self, row: pd.Series, column: str) -> Path:
        """The file of ``row[column]``, checked against the index's SHA-256 before anything decodes it
        (a changed file must never be scored silently)."""
        path = self.root / row[column]
        if not path.is_file():
            raise PacketError("packet file missing (run `setdiff-bench prepare` again to rewrite it)", path)
        expected = row[f"{column}_sha256"]
        if sha256_file(path) != expected:
            raise PacketError(
                f"SHA-256 mismatch: the file changed since the index recorded {str(expected)[:12]}… "
                "(run `setdiff-bench prepare` again to rewrite it)",
                path,
            )
        return path

    def _view_set(self, rows: pd.DataFrame) -> ViewSet:
        images, cmaps, alphas, cameras = [], [], [], []
        for _, row in rows.iterrows():
            size = (int(row["height"]), int(row["width"]))
            images.append(to_tensor_chw(read_rgb(self._file(row, "image"), size)))
            exr_path = self._file(row, "cmap")
            cmap = read_exr(exr_path, channels=4)
            if cmap.shape[:2] != size:
                raise PacketError(
                    f"C-map is {cmap.shape[1]}x{cmap.shape[0]}, expected {size[1]}x{size[0]}", exr_path
                )
            chw = to_tensor_chw(cmap)
            cmaps.append(chw[:3])
            alphas.append(chw[3:4])
            cameras.append(row_camera(row, str(self.root / INDEX_FILE)))
        height, width = (int(rows["height"].iloc[0]), int(rows["width"].iloc[0])) if len(rows) else (0, 0)
        empty = torch.zeros(0, 3, height, width)
        return ViewSet(
            names=tuple(rows["frame"]),
            images=torch.stack(images) if images else empty,
            cmaps=torch.stack(cmaps) if cmaps else empty,
            alphas=torch.stack(alphas) if alphas else torch.zeros(0, 1, height, width),
            cameras=tuple(cameras),
            timestamps_us=tuple(timestamp_or_none(t) for t in rows["timestamp_us"]),
        )


def row_camera(row: pd.Series | dict[str, Any], source: str = "", world: bool = False) -> Camera:
    """The normalised (or, with ``world``, the dataset-frame) camera of an index row."""
    K = np.asarray(row["K"], dtype=np.float64).reshape(3, 3)
    w2c = np.asarray(row["w2c_world" if world else "w2c"], dtype=np.float64).reshape(4, 4)
    try:
        return Camera(K, w2c, int(row["width"]), int(row["height"]), source=f"{source} ({row['frame']!r})")
    except SetDiffBenchError as exc:
        raise PacketError(
            f"packet {row['packet_id']!r} view {row['frame']!r}: {exc.problem}", source
        ) from exc


def target_has_ground_truth(rows: pd.DataFrame) -> np.ndarray:
    """``(len(rows),)`` bool: index rows whose ``gt`` and ``mask`` files are recorded (not null)."""
    if not len(rows):
        return np.zeros(0, dtype=bool)
    return np.array(
        [isinstance(g, str) and isinstance(m, str) for g, m in zip(rows["gt"], rows["mask"], strict=True)],
        dtype=bool,
    )


def _pick(rows: pd.DataFrame, positions: Sequence[int] | None) -> pd.DataFrame:
    if positions is None:
        return rows
    count = len(rows)
    bad = [p for p in positions if not 0 <= int(p) < count]
    if bad:
        raise PacketError(f"view position {bad[0]} out of range (the packet has {count} of this role)")
    return rows.iloc[[int(p) for p in positions]]


def timestamp_or_none(value: Any) -> int | None:
    """A ``timestamp_us`` cell as an ``int``, or ``None`` when missing (``None``/NaN/NA)."""
    return None if value is None or pd.isna(value) else int(value)
