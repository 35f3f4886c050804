"""Warp error per time-ordered sequence: the rows of ``sequences.parquet``.

Two kinds of sequence, told apart by the ``flow_source`` column:

- ``ground_truth``: the targets with ground truth of one (protocol, scene, sensor), sorted by timestamp
  across groups (a nuScenes camera's 10–15 s targets form one sequence).  The flow and occlusion mask come
  from the ground truth, with the protocol's evaluation masks; cached by the ground-truth files' SHA-256.
  ``group`` is null (the sequence spans groups).
- ``render``: the targets without ground truth (novel trajectories, ``prepare --trajectory``) of one
  (protocol, scene, sensor, group), sorted by timestamp.  A trajectory group never mixes with another
  (``shift+3m`` and ``shift+6m`` of one camera are two sequences).  The flow and occlusion mask come from
  the packet's own target images, the 3DGS renders, which a static model draws consistently from frame to
  frame, so the value measures the flicker an enhancer adds on top of the render's own motion.  No
  evaluation mask (such targets have none); cached by the render files' SHA-256 under a key of its own.

Either way the warp error (MSE on the 0–255 scale) compares the written 8-bit images, shape
``(T, 3, H, W)`` in [0, 1], frame t warped back onto frame t−1 by the flow, occluded pixels left out.
A sequence needs at least 2 targets, all time-stamped: without timestamps it is skipped under
``warp="auto"`` and refused under ``warp="on"``.  Rows: ground-truth sequences first, then render
sequences, each sorted by their grouping keys.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import torch

from setdiff_bench.errors import PacketError
from setdiff_bench.evaluation.run._settings import RunSettings
from setdiff_bench.evaluation.scoring import default_warp_cache, sequence_warp_error
from setdiff_bench.io.images import read_rgb, to_tensor_chw
from setdiff_bench.packets.index import key_columns
from setdiff_bench.packets.store import PacketStore, target_has_ground_truth

#: ``flow_source`` of a sequence whose flow comes from the ground truth (targets with ground truth).
FLOW_FROM_GROUND_TRUTH = "ground_truth"
#: ``flow_source`` of a sequence whose flow comes from the 3DGS renders (targets without ground truth).
FLOW_FROM_RENDER = "render"

SEQUENCE_SCHEMA = pa.schema(
    [
        *key_columns("dataset", "protocol", "scene", "sensor"),
        ("method", pa.string()),
        ("frames", pa.int32()),
        ("first_frame", pa.string()),
        ("last_frame", pa.string()),
        ("warp", pa.float64()),
        ("flow_source", pa.string()),
        *key_columns("group"),
    ]
)


def sequence_table(store: PacketStore, out: Path, frame: pd.DataFrame, settings: RunSettings) -> pa.Table:
    """Warp error of every sequence with ≥ 2 time-stamped targets (:data:`SEQUENCE_SCHEMA` rows).

    Args:
        store: the packet store the run read.
        out: the run folder (``frame["image"]`` is relative to it).
        frame: the run's merged per-target rows (``metrics.parquet``).
        settings: the run's settings (``warp``, ``flow_method``, ``warp_cache``, ``method``).

    Raises:
        PacketError: with ``warp="on"``, a sequence with a target that has no timestamp.
    """
    cache = None
    if settings.warp_cache is not None:
        cache = default_warp_cache() if settings.warp_cache == "auto" else Path(settings.warp_cache)
    index = store.index
    targets = index[index["role"] == "target"]
    rows_of = {
        (row["packet_id"], int(row["view"])): row for row in targets.to_dict("records")
    }  # index row of each target
    has_gt = dict(zip(rows_of, target_has_ground_truth(targets), strict=True))
    with_gt = np.array(
        [has_gt.get((p, int(v)), True) for p, v in zip(frame["packet_id"], frame["view"], strict=True)],
        dtype=bool,
    )
    records = []
    keys = ["protocol", "scene", "sensor"]
    for (protocol, scene, sensor), rows in frame[with_gt].groupby(keys, sort=True, dropna=False):
        ordered = _ordered(rows, settings, store, f"scene {scene!r} sensor {sensor!r}")
        if ordered is None:
            continue
        value = _sequence_warp(store, out, ordered, rows_of, settings, cache, FLOW_FROM_GROUND_TRUTH)
        records.append(_record(ordered, protocol, scene, sensor, None, value, settings))
    for (protocol, scene, sensor, group), rows in frame[~with_gt].groupby(
        [*keys, "group"], sort=True, dropna=False
    ):
        ordered = _ordered(rows, settings, store, f"scene {scene!r} sensor {sensor!r} group {group!r}")
        if ordered is None:
            continue
        value = _sequence_warp(store, out, ordered, rows_of, settings, cache, FLOW_FROM_RENDER)
        records.append(_record(ordered, protocol, scene, sensor, group, value, settings))
    return pa.Table.from_pylist(records, schema=SEQUENCE_SCHEMA)


def _ordered(rows: pd.DataFrame, settings: RunSettings, store: PacketStore, what: str) -> pd.DataFrame | None:
    """The sequence's rows by timestamp, then frame and packet; ``None`` when it is not a sequence."""
    if rows["timestamp_us"].isna().any():
        if settings.warp == "on":
            raise PacketError(f"warp error needs timestamps; {what} has targets without one", store.root)
        return None
    if len(rows) < 2:
        return None
    return rows.sort_values(["timestamp_us", "frame", "packet_id"])


def _sequence_warp(
    store: PacketStore,
    out: Path,
    rows: pd.DataFrame,
    rows_of: dict[tuple[str, int], dict[str, Any]],
    settings: RunSettings,
    cache: Path | None,
    flow_source: str,
) -> float:
    """Warp error of the written images, ``(T, 3, H, W)`` in [0, 1], with the flow and occlusion of the ground
    truth and its evaluation masks (:data:`FLOW_FROM_GROUND_TRUTH`), or of the packet's 3DGS renders and no mask
    (:data:`FLOW_FROM_RENDER`); the flow cache is keyed by those files' SHA-256."""
    frames, sources, masks, hashes = [], [], [], []
    for row in rows.itertuples():
        target = rows_of[(row.packet_id, int(row.view))]
        if flow_source == FLOW_FROM_GROUND_TRUTH:
            gt, mask = store.load_ground_truth(row.packet_id, targets=[int(row.view)])
            digest = target.get("gt_sha256")
            sources.append(gt[0])
            masks.append(mask[0])
        else:
            size = (int(target["height"]), int(target["width"]))
            sources.append(to_tensor_chw(read_rgb(store.file_path(pd.Series(target), "image"), size)))
            digest = target["image_sha256"]
        hashes.append(digest if isinstance(digest, str) else "")
        frames.append(to_tensor_chw(read_rgb(out / row.image, tuple(sources[-1].shape[-2:]))))
    return sequence_warp_error(
        torch.stack(frames),
        torch.stack(sources),
        torch.stack(masks) if masks else None,
        flow_method=settings.flow_method,
        cache=cache,
        gt_key=",".join(hashes) if all(hashes) else None,
        flow_source=flow_source,
    )


def _record(
    rows: pd.DataFrame,
    protocol: str,
    scene: str,
    sensor: str,
    group: str | None,
    value: float,
    settings: RunSettings,
) -> dict[str, Any]:
    return {
        "dataset": rows["dataset"].iloc[0],
        "protocol": protocol,
        "scene": scene,
        "sensor": sensor,
        "method": settings.label,
        "frames": len(rows),
        "first_frame": rows["frame"].iloc[0],
        "last_frame": rows["frame"].iloc[-1],
        "warp": value,
        "flow_source": FLOW_FROM_GROUND_TRUTH if group is None else FLOW_FROM_RENDER,
        "group": group,
    }
