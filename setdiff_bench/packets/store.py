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
import shutil
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import PacketError, SetDiffBenchError
from setdiff_bench.geometry import renormalize
from setdiff_bench.io.atomic import sha256_file, staged_folder
from setdiff_bench.io.images import read_exr, read_mask, read_rgb, to_tensor_chw, write_exr, write_png
from setdiff_bench.packets.index import (
    FILE_COLUMNS,
    INDEX_FILE,
    PACKETS_DIR,
    TEMP_PREFIX,
    NoGroundTruthError,
    merge_index,
    read_rows,
    write_rows,
)
from setdiff_bench.types import Packet, PacketKey, TrainingSample, ViewSet

CMAP_CHANNELS = ("X", "Y", "Z", "A")
#: OpenEXR stamps the write time unless a DateTime is given; a fixed one keeps files byte-identical.
EXR_ATTRIBUTES = {"DateTime": "1970:01:01 00:00:00", "Software": "setdiff-bench"}


# ---------------------------------------------------------------------- writing
@dataclass
class ViewContent:
    """One view to write.

    Attributes:
        frame, sensor, traversal, timestamp_us: where it comes from.
        camera: the camera in the packet's normalised frame (working resolution).
        camera_world: the same camera in the dataset's world frame.
        image: ``(H, W, 3)`` float32 in [0, 1] (clean capture or render).
        cmap: ``(H, W, 3)`` float32 normalised Eq. 1 C-map.  alpha: ``(H, W)`` float32.
        gt: ``(H, W, 3)`` float32 ground truth (targets), else ``None``; a target without ground truth
            (a novel-trajectory view) has ``None`` here and in ``mask``: its ``gt`` / ``mask`` index
            columns and their SHA-256 are null, and every other file is hashed as usual.
        mask: ``(H, W)`` bool, True = evaluate (targets with ground truth), else ``None``.
        overlap_score: Eq. 2 score (references), else ``None``.
    """

    frame: str
    sensor: str
    traversal: str
    timestamp_us: int | None
    camera: Camera
    camera_world: Camera
    image: np.ndarray
    cmap: np.ndarray
    alpha: np.ndarray
    gt: np.ndarray | None = None
    mask: np.ndarray | None = None
    overlap_score: float | None = None


@dataclass(frozen=True)
class PacketHeader(PacketKey):
    """Packet-level columns of the index: the packet's key, then how it was made."""

    fit_key: str
    scale: float
    recipe: str
    cmap_half: bool = False


def packet_dir(root: Path, packet_id: str) -> Path:
    return root / PACKETS_DIR / packet_id


def remove_temporaries(root: Path, packet_id: str) -> None:
    """Delete ``.tmp-<packet_id>-*`` folders left by an interrupted write of this packet."""
    folder = root / PACKETS_DIR
    if folder.is_dir():
        for stale in folder.glob(f"{TEMP_PREFIX}{packet_id}-*"):
            shutil.rmtree(stale, ignore_errors=True)


def write_packet(
    root: Path, header: PacketHeader, references: Sequence[ViewContent], targets: Sequence[ViewContent]
) -> list[dict[str, Any]]:
    """Write one packet folder atomically; returns its index rows.

    The folder is built under ``packets/.tmp-<id>-<random>`` (files, then the fragment ``index.parquet``)
    and swapped in as ``packets/<id>`` (replacing an incomplete or outdated one; :func:`staged_folder`).
    """
    base = root / PACKETS_DIR
    base.mkdir(parents=True, exist_ok=True)
    remove_temporaries(root, header.packet_id)
    final = packet_dir(root, header.packet_id)
    with staged_folder(final, prefix=f"{TEMP_PREFIX}{header.packet_id}-", suffix="") as tmp:
        rows = [_write_view(root, tmp, header, "ref", i, v) for i, v in enumerate(references)]
        rows += [_write_view(root, tmp, header, "target", i, v) for i, v in enumerate(targets)]
        write_rows(tmp / INDEX_FILE, rows, atomic=False)
    return rows


def _write_view(
    root: Path, folder: Path, header: PacketHeader, role: str, position: int, view: ViewContent
) -> dict[str, Any]:
    stem = f"{'ref' if role == 'ref' else 'tgt'}_{position:02d}"
    relative = Path(PACKETS_DIR) / header.packet_id
    files: dict[str, str | None] = dict.fromkeys(FILE_COLUMNS)
    write_png(folder / f"{stem}_rgb.png", view.image, atomic=False)
    files["image"] = f"{stem}_rgb.png"
    cmap = np.concatenate([view.cmap, view.alpha[:, :, None]], axis=2).astype(np.float32)
    write_exr(
        folder / f"{stem}_cmap.exr",
        cmap,
        CMAP_CHANNELS,
        half=header.cmap_half,
        attributes=EXR_ATTRIBUTES,
        atomic=False,
    )
    files["cmap"] = f"{stem}_cmap.exr"
    if role == "target" and (view.gt is None) != (view.mask is None):
        raise ValueError(f"target {view.frame!r} needs both ground truth and a mask, or neither")
    if role == "target" and view.gt is not None and view.mask is not None:
        write_png(folder / f"{stem}_gt.png", view.gt, atomic=False)
        write_png(folder / f"{stem}_mask.png", view.mask.astype(bool), atomic=False)
        files["gt"], files["mask"] = f"{stem}_gt.png", f"{stem}_mask.png"
    row: dict[str, Any] = {
        "packet_id": header.packet_id,
        "role": role,
        "view": position,
        "dataset": header.dataset,
        "protocol": header.protocol,
        "group": header.group,
        "split": header.split,
        "scene": header.scene,
        "fit_key": header.fit_key,
        "frame": view.frame,
        "sensor": view.sensor,
        "traversal": view.traversal,
        "timestamp_us": view.timestamp_us,
        "width": view.camera.width,
        "height": view.camera.height,
        "K": [float(v) for v in view.camera.K.reshape(-1)],
        "w2c": [float(v) for v in view.camera.w2c.reshape(-1)],
        "w2c_world": [float(v) for v in view.camera_world.w2c.reshape(-1)],
        "scale": float(header.scale),
        "overlap_score": None if view.overlap_score is None else float(view.overlap_score),
        "recipe": header.recipe,
    }
    for column, name in files.items():
        row[column] = None if name is None else (relative / name).as_posix()
        row[f"{column}_sha256"] = None if name is None else sha256_file(folder / name)
    return row


def packet_is_complete(root: Path, packet_id: str, recipe: str) -> bool:
    """Whether ``packets/<id>`` holds a fragment with this ``recipe`` whose files all match their hashes."""
    fragment = packet_dir(root, packet_id) / INDEX_FILE
    if not fragment.is_file():
        return False
    try:
        rows = read_rows(fragment).to_pylist()
    except PacketError:
        return False
    if not rows or any(r["recipe"] != recipe or r["packet_id"] != packet_id for r in rows):
        return False
    return not _file_problems(root, rows)


def _file_problems(root: Path, rows: Sequence[dict[str, Any]]) -> list[str]:
    problems = []
    for row in rows:
        for column in FILE_COLUMNS:
            relative = row[column]
            if not isinstance(relative, str):  # null (pandas may give None or NaN)
                continue
            path = root / relative
            if not path.is_file():
                problems.append(f"{relative}: missing")
            elif sha256_file(path) != row[f"{column}_sha256"]:
                problems.append(f"{relative}: SHA-256 mismatch")
    return problems


# ---------------------------------------------------------------------- reading
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
        """Packet ids in sorted order; ``split`` (``"train"``/``"test"``) filters by scene split."""
        if split is None:
            return list(self._rows)
        return [pid for pid, rows in self._rows.items() if rows["split"].iloc[0] == split]

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
            problems += [f"{pid}: {p}" for p in _file_problems(self.root, self.rows(pid).to_dict("records"))]
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


# ---------------------------------------------------------------------- training
class PacketTrainingDataset(torch.utils.data.Dataset):
    """Training samples drawn from stored packets: variable set size, random order within roles.

    Item ``index`` of epoch ``e`` (:meth:`set_epoch`) uses ``numpy.random.default_rng([seed, e, index])``:

    1. the set size is uniform in ``[min_views, max_views]`` (capped by the packet's view count);
    2. references and targets keep the packet's proportion (at least one target, and one reference
       when the packet has any);
    3. the chosen references and targets are each randomly permuted (the paper's permutation π);
    4. the subset is re-normalised so its own first target is the identity and its largest pairwise
       camera distance is 1 — the invariant every packet satisfies at inference.

    Only the chosen views' files are read.  ``Packet.scale`` composes both normalisations.
    """

    def __init__(
        self,
        store: PacketStore,
        packet_ids: Sequence[str],
        *,
        min_views: int = 8,
        max_views: int = 12,
        seed: int = 0,
    ) -> None:
        if not 2 <= min_views <= max_views:
            raise ValueError(f"need 2 <= min_views <= max_views, got {min_views}, {max_views}")
        self.store, self.packet_ids = store, list(packet_ids)
        self.min_views, self.max_views, self.seed, self.epoch = min_views, max_views, seed, 0

    def __len__(self) -> int:
        return len(self.packet_ids)

    def set_epoch(self, epoch: int) -> None:
        """Select the epoch whose random draws :meth:`__getitem__` makes."""
        self.epoch = int(epoch)

    def choose(self, index: int) -> tuple[list[int], list[int]]:
        """Reference and target positions of item ``index`` in the current epoch (rules in the class doc)."""
        rows = self.store.rows(self.packet_ids[index])
        n_ref, n_tgt = int((rows["role"] == "ref").sum()), int((rows["role"] == "target").sum())
        rng = np.random.default_rng([self.seed, self.epoch, index])
        total = n_ref + n_tgt
        size = int(rng.integers(min(self.min_views, total), min(self.max_views, total) + 1))
        refs = min(max(round(size * n_ref / total), 1 if n_ref else 0), n_ref, size - 1)
        targets = min(size - refs, n_tgt)
        refs = min(size - targets, n_ref)
        return (
            [int(i) for i in rng.permutation(n_ref)[:refs]],
            [int(i) for i in rng.permutation(n_tgt)[:targets]],
        )

    def __getitem__(self, index: int) -> TrainingSample:
        packet_id = self.packet_ids[index]
        ref_ids, tgt_ids = self.choose(index)
        packet = self.store.load_packet(packet_id, ref_ids, tgt_ids)
        gt, masks = self.store.load_ground_truth(packet_id, tgt_ids)
        packet = renormalize(packet)
        packet.metadata = {
            **packet.metadata,
            "reference_positions": tuple(ref_ids),
            "target_positions": tuple(tgt_ids),
            "epoch": self.epoch,
        }
        return TrainingSample(packet=packet, target_gt=gt, target_masks=masks)
