"""Writing a packet folder: its PNG / EXR files and fragment index, atomically, and checking that a
written one is complete (every file present and matching its SHA-256, the recipe current).

File formats (8-bit PNG captures, renders, ground truth and masks; 4-channel ``X, Y, Z, A`` EXR C-maps,
float32 or half) and why: :mod:`setdiff_bench.packets.store`; index columns and layout:
:mod:`setdiff_bench.packets.index`.  A packet is assembled in ``packets/.tmp-<id>-*``, its fragment index
written last, then renamed into place; EXR files carry fixed attributes (:data:`EXR_ATTRIBUTES`) so that
identical inputs give byte-identical files.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import PacketError
from setdiff_bench.io.atomic import sha256_file, staged_folder
from setdiff_bench.io.images import write_exr, write_png
from setdiff_bench.packets.index import (
    FILE_COLUMNS,
    INDEX_FILE,
    PACKETS_DIR,
    TEMP_PREFIX,
    read_rows,
    write_rows,
)
from setdiff_bench.types import PacketKey, key_fields

CMAP_CHANNELS = ("X", "Y", "Z", "A")
#: OpenEXR stamps the write time unless a DateTime is given; a fixed one keeps files byte-identical.
EXR_ATTRIBUTES = {"DateTime": "1970:01:01 00:00:00", "Software": "setdiff-bench"}


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
    """The folder of packet ``packet_id`` in the store at ``root``."""
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
    row: dict[str, Any] = {  # any order: write_rows orders the columns by the index SCHEMA
        **key_fields(header),
        "role": role,
        "view": position,
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
    return not file_problems(root, rows)


def file_problems(root: Path, rows: Sequence[dict[str, Any]]) -> list[str]:
    """One line per file of ``rows`` (index rows) that is missing or does not match its SHA-256."""
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
