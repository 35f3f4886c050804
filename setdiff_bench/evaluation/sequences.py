"""Warp error per time-ordered sequence: the rows of ``sequences.parquet``.

A sequence is one (protocol, scene, sensor) of targets sorted by timestamp across groups; its warp error
(MSE on the 0-255 scale) compares the written 8-bit images, shape (N, 3, H, W) in [0, 1], with the
ground truth's flow and occlusion mask, cached by the ground-truth files' SHA-256.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import torch

from setdiff_bench.errors import PacketError
from setdiff_bench.evaluation.run_settings import RunSettings
from setdiff_bench.evaluation.scoring import default_warp_cache, sequence_warp_error
from setdiff_bench.io.images import read_rgb, to_tensor_chw
from setdiff_bench.packets.store import PacketStore, target_has_ground_truth

SEQUENCE_SCHEMA = pa.schema(
    [
        ("dataset", pa.string()),
        ("protocol", pa.string()),
        ("scene", pa.string()),
        ("sensor", pa.string()),
        ("method", pa.string()),
        ("frames", pa.int32()),
        ("first_frame", pa.string()),
        ("last_frame", pa.string()),
        ("warp", pa.float64()),
    ]
)


def sequence_table(store: PacketStore, out: Path, frame: pd.DataFrame, settings: RunSettings) -> pa.Table:
    """Warp error of every (protocol, scene, sensor) sequence with ≥ 2 time-stamped targets."""
    records = []
    cache = None
    if settings.warp_cache is not None:
        cache = default_warp_cache() if settings.warp_cache == "auto" else Path(settings.warp_cache)
    index = store.index
    targets = index[index["role"] == "target"]
    without = targets[~target_has_ground_truth(targets)]
    if len(without):  # novel-trajectory targets: no ground truth to take flow from (named as skipped)
        unscored = set(zip(without["packet_id"], without["view"].astype(int), strict=True))
        keep = [(p, int(v)) not in unscored for p, v in zip(frame["packet_id"], frame["view"], strict=True)]
        frame = frame[np.asarray(keep, dtype=bool)]
    gt_hashes = (
        dict(zip(zip(targets["packet_id"], targets["view"].astype(int)), targets["gt_sha256"]))
        if "gt_sha256" in targets.columns
        else {}
    )
    for (protocol, scene, sensor), rows in frame.groupby(
        ["protocol", "scene", "sensor"], sort=True, dropna=False
    ):
        if rows["timestamp_us"].isna().any():
            if settings.warp == "on":
                raise PacketError(
                    f"warp error needs timestamps; scene {scene!r} sensor {sensor!r} has targets without one",
                    store.root,
                )
            continue
        rows = rows.sort_values(["timestamp_us", "frame", "packet_id"])
        if len(rows) < 2:
            continue
        frames, gts, masks, hashes = [], [], [], []
        for row in rows.itertuples():
            gt, mask = store.load_ground_truth(row.packet_id, targets=[int(row.view)])
            digest = gt_hashes.get((row.packet_id, int(row.view)))
            hashes.append(digest if isinstance(digest, str) else "")
            size = tuple(gt.shape[-2:])
            frames.append(to_tensor_chw(read_rgb(out / row.image, size)))
            gts.append(gt[0])
            masks.append(mask[0])
        value = sequence_warp_error(
            torch.stack(frames),
            torch.stack(gts),
            torch.stack(masks),
            flow_method=settings.flow_method,
            cache=cache,
            gt_key=",".join(hashes) if all(hashes) else None,
        )
        records.append(
            {
                "dataset": rows["dataset"].iloc[0],
                "protocol": protocol,
                "scene": scene,
                "sensor": sensor,
                "method": settings.method,
                "frames": len(rows),
                "first_frame": rows["frame"].iloc[0],
                "last_frame": rows["frame"].iloc[-1],
                "warp": value,
            }
        )
    return pa.Table.from_pylist(records, schema=SEQUENCE_SCHEMA)
