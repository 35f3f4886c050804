"""The packet store's on-disk index: one Parquet row per view, written per packet and merged.

Store layout::

    <store>/index.parquet                    every view of every complete packet (written last)
    <store>/packets/<packet_id>/index.parquet    the packet's own rows ("fragment"), written last in it
    <store>/packets/<packet_id>/ref_00_rgb.png   clean capture at the working resolution
                               ref_00_cmap.exr   C-map X, Y, Z + alpha A (float32, normalised frame)
                               tgt_00_rgb.png    3DGS render
                               tgt_00_cmap.exr
                               tgt_00_gt.png     captured ground truth
                               tgt_00_mask.png   255 = evaluate, 0 = ignore

A packet folder appears only complete: it is written under ``packets/.tmp-<packet_id>-*`` and
renamed into place.  The top-level index is the concatenation of all fragments, sorted by packet id
then role (references first) then position — so it depends only on which packets exist, not on the
order, shard or worker that wrote them.  Merges need no file lock (see :func:`merge_index`).

Columns (:data:`SCHEMA`): ``packet_id, role ("ref" | "target"), view`` (position within the role),
``dataset, protocol, group, split, scene, fit_key, frame, sensor, traversal, timestamp_us`` (null when
unknown), ``width, height``, ``K`` (9 floats, row-major, pixels at the working resolution), ``w2c``
(16 floats, row-major, normalised: first target = identity, max pairwise centre distance 1),
``w2c_world`` (16 floats, the dataset's world frame), ``scale`` (world units → packet units),
``overlap_score`` (Eq. 2 score of a reference, aggregated over the packet's targets; null for
targets), file paths relative to the store with their SHA-256 (``image, cmap`` for every view;
``gt, mask`` for targets, null for references and for targets without ground truth: the novel-trajectory
views of ``prepare --trajectory``), and ``recipe`` (SHA-256 of everything the packet
was made from; a changed recipe makes ``prepare`` rewrite the packet).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.errors import PacketError
from setdiff_bench.io.atomic import atomic_path, is_stale_temporary
from setdiff_bench.io.names import slug

INDEX_FILE = "index.parquet"
PACKETS_DIR = "packets"
TEMP_PREFIX = ".tmp-"
ROLES = ("ref", "target")
#: The values of the ``split`` column: the protocol's train or test scenes (a store may hold only one).
SCENE_SPLITS = ("train", "test")
FILE_COLUMNS = ("image", "cmap", "gt", "mask")


class NoGroundTruthError(PacketError):
    """A target chosen for ground truth has none: its ``gt`` / ``mask`` columns are null (a novel-trajectory
    view, ``prepare --trajectory``)."""


#: Arrow types of the columns that say which packet, view and frame a row is about: declared once, for the index
#: (in this order) and the run tables that carry some of them (:func:`key_columns`).
KEY_COLUMN_TYPES: dict[str, pa.DataType] = {
    "packet_id": pa.string(),
    "role": pa.string(),
    "view": pa.int32(),
    "dataset": pa.string(),
    "protocol": pa.string(),
    "group": pa.string(),
    "split": pa.string(),
    "scene": pa.string(),
    "fit_key": pa.string(),
    "frame": pa.string(),
    "sensor": pa.string(),
    "traversal": pa.string(),
    "timestamp_us": pa.int64(),
}


def key_columns(*names: str) -> list[tuple[str, pa.DataType]]:
    """``(name, type)`` of the key columns ``names``, in that order (:data:`KEY_COLUMN_TYPES`)."""
    return [(name, KEY_COLUMN_TYPES[name]) for name in names]


SCHEMA = pa.schema(
    [
        *KEY_COLUMN_TYPES.items(),
        ("width", pa.int32()),
        ("height", pa.int32()),
        ("K", pa.list_(pa.float64(), 9)),
        ("w2c", pa.list_(pa.float64(), 16)),
        ("w2c_world", pa.list_(pa.float64(), 16)),
        ("scale", pa.float64()),
        ("overlap_score", pa.float64()),
        ("image", pa.string()),
        ("image_sha256", pa.string()),
        ("cmap", pa.string()),
        ("cmap_sha256", pa.string()),
        ("gt", pa.string()),
        ("gt_sha256", pa.string()),
        ("mask", pa.string()),
        ("mask_sha256", pa.string()),
        ("recipe", pa.string()),
    ]
)


def packet_id(protocol: str, scene: str, group: str, index: int) -> str:
    """``<protocol>__<scene slug>__<group slug>__<index:04d>`` (slugs never contain ``__``)."""
    return f"{slug(protocol)}__{slug(scene)}__{slug(group)}__{index:04d}"


def group_prefix(protocol: str, scene: str, group: str) -> str:
    """The id prefix shared by every packet of one (protocol, scene, group)."""
    return f"{slug(protocol)}__{slug(scene)}__{slug(group)}__"


def write_rows(path: Path, rows: Sequence[dict[str, Any]], *, atomic: bool = True) -> None:
    """Write ``rows`` (dicts with the :data:`SCHEMA` columns) as Parquet, reproducibly.

    ``atomic``: through a temporary file and rename (off inside a folder that is renamed as a whole).
    """
    table = pa.Table.from_pylist(list(rows), schema=SCHEMA)
    with atomic_path(path) if atomic else contextlib.nullcontext(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def read_rows(path: Path) -> pa.Table:
    """Read an index or fragment file; ``PacketError`` if it is unreadable or has other columns."""
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise PacketError(
            f"cannot read packet index ({exc.__class__.__name__}: {str(exc).splitlines()[0]})", path
        ) from exc
    if table.schema.names != SCHEMA.names:
        missing = sorted(set(SCHEMA.names) - set(table.schema.names))
        raise PacketError(f"not a packet index of this version (missing columns {missing[:5]})", path)
    return table.cast(SCHEMA)


def sort_rows(table: pa.Table) -> pa.Table:
    """Rows ordered by packet id, role (``ref`` before ``target``), position."""
    return table.sort_by([("packet_id", "ascending"), ("role", "ascending"), ("view", "ascending")])


def fragment_paths(root: Path) -> list[Path]:
    """Fragments of every complete packet folder under ``root/packets`` (temporary folders skipped)."""
    folder = root / PACKETS_DIR
    if not folder.is_dir():
        return []
    return sorted(
        p / INDEX_FILE
        for p in folder.iterdir()
        if p.is_dir() and not p.name.startswith(".") and (p / INDEX_FILE).is_file()
    )


def merge_index(root: Path) -> bool:
    """Rebuild ``root/index.parquet`` from the packet fragments, without a file lock.

    Nothing is written when the merged bytes would equal the existing file (a resumed run with
    nothing to do leaves the store untouched).  The index is written by atomic rename and depends only
    on the fragments; after writing, the fragments are listed again and the merge is redone if they
    changed (reading only new or rewritten fragments), so of shards merging at once the last to publish
    has seen every fragment written before its own merge.  (On a network filesystem whose listings may lag, run the same ``prepare`` command
    once more without ``--shard`` after all shards: it skips every finished packet and merges.)
    Temporary index files left by killed writers are removed
    (:func:`~setdiff_bench.io.atomic.is_stale_temporary`).

    Returns:
        whether the index file was (re)written.
    """
    for stale in root.glob(f".{Path(INDEX_FILE).stem}.*.tmp*"):
        with contextlib.suppress(FileNotFoundError):
            if is_stale_temporary(stale):
                stale.unlink()
    written = False
    read: dict[tuple[str, int, int], pa.Table] = {}  # fragments already read, by (path, size, mtime)
    while True:
        seen = _signature(fragment_paths(root))
        for entry in seen:
            if entry not in read:
                read[entry] = read_rows(Path(entry[0]))
        tables = [read[entry] for entry in seen]
        merged = sort_rows(pa.concat_tables(tables)) if tables else SCHEMA.empty_table()
        target = root / INDEX_FILE
        unchanged = False
        if target.is_file():
            with contextlib.suppress(PacketError):
                unchanged = read_rows(target).equals(merged)
        if not unchanged:
            write_rows(target, merged.to_pylist())
            written = True
        if _signature(fragment_paths(root)) == seen:
            return written


def _signature(paths: Sequence[Path]) -> list[tuple[str, int, int]]:
    """(path, size, mtime ns) of every fragment: changes when one is added, removed or rewritten."""
    signature = []
    for path in paths:
        with contextlib.suppress(FileNotFoundError):
            stat = path.stat()
            signature.append((str(path), stat.st_size, stat.st_mtime_ns))
    return signature
