"""A run's ``manifest.json``: method and config, store, metrics, device, versions, git revision, timing."""

from __future__ import annotations

import contextlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa

from setdiff_bench.enhancers.base import available_methods
from setdiff_bench.evaluation.run._settings import RUN_FORMAT, RunSettings, jsonable_options
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.run_layout import ENHANCER_FILE, IMAGES_DIR, METRICS_FILE, SEQUENCES_FILE
from setdiff_bench.metrics.registry import MetricSpec
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.runtime.provenance import device_description, git_revision, package_versions


def run_manifest(
    store: PacketStore,
    out: Path,
    settings: RunSettings,
    specs: Sequence[MetricSpec],
    frame: pd.DataFrame,
    sequences: pa.Table | None,
    fragments_sha256: str,
    refits: Mapping[str, Mapping[str, Any]] | None = None,
) -> dict[str, Any]:
    """The run's ``manifest.json``; ``refits`` (``run --refit``: :func:`refit_costs` as ``run_method`` read and
    recorded them in ``run.json``) become its ``refit`` section."""
    methods = available_methods()
    spec = methods.get(settings.method)
    enhancer_info: dict[str, Any] = {}
    with contextlib.suppress(OSError, json.JSONDecodeError):
        enhancer_info = json.loads((out / ENHANCER_FILE).read_text())
    timing = frame.drop_duplicates("packet_id")[["packet_id", "ms_per_frame"]]
    per_frame = frame["ms_per_frame"].to_numpy(dtype=np.float64)
    per_packet_ms = (frame.groupby("packet_id")["ms_per_frame"].sum()).to_numpy(dtype=np.float64)
    peak = (
        frame["peak_memory_mb"].to_numpy(dtype=np.float64)
        if "peak_memory_mb" in frame.columns
        else np.array([], dtype=np.float64)
    )
    manifest: dict[str, Any] = {
        "format": RUN_FORMAT,
        "method": {
            # the name every table shows (``run --name``, else the registry name) and the registry name
            "name": settings.label,
            "id": settings.method,
            "factory": spec.factory if spec else None,
            "source": spec.source if spec else None,
            "options": jsonable_options(dict(settings.options)),
            "enhancer": enhancer_info,
        },
        "packets": {
            "root": str(Path(store.root).resolve()),
            "index_sha256": sha256_file(Path(store.root) / INDEX_FILE),
            "split": settings.split,
            "packets": int(frame["packet_id"].nunique()),
            "targets": len(frame),
            "datasets": sorted(frame["dataset"].unique().tolist()),
            "protocols": sorted(frame["protocol"].unique().tolist()),
            "groups": sorted(frame["group"].unique().tolist()),
        },
        "metrics": {
            "image": {
                s.name: {
                    "function": s.function,
                    "kwargs": jsonable_options(dict(s.kwargs)),
                    "higher_is_better": s.higher_is_better,
                }
                for s in specs
            },
            "quantization": "8-bit, rint(clip(x, 0, 1) * 255) / 255, as the written PNG",
            "masks": "protocol masks from the packet store (True = evaluate)",
            "warp": None
            if sequences is None
            else {
                "sequences": sequences.num_rows,
                "flow_method": settings.flow_method,
                "scale": "MSE on the 0-255 scale (setdiff_bench.metrics.warp.PAPER_SCALE)",
                "grouping": "(protocol, scene, sensor), targets sorted by timestamp across groups"
                + (
                    "; targets without ground truth: (protocol, scene, sensor, group), flow from their 3DGS renders"
                    if "flow_source" in sequences.column_names
                    and "render" in set(sequences.column("flow_source").to_pylist())
                    else ""
                ),
            },
        },
        "device": {**device_description(settings.device), "requested": settings.device},
        "batch_size": settings.batch_size,
        "versions": package_versions(),
        "git": git_revision(),
        "timing": {
            "frames": len(frame),
            "packets": len(timing),
            "enhance_ms_total": float(per_packet_ms.sum()),
            "ms_per_frame_mean": float(per_frame.mean()) if len(per_frame) else None,
            "ms_per_frame_median": float(np.median(per_frame)) if len(per_frame) else None,
            "ms_per_frame_max": float(per_frame.max()) if len(per_frame) else None,
            "peak_memory_mb": float(np.nanmax(peak)) if len(peak) and not np.isnan(peak).all() else None,
            "peak_memory": "CUDA: most memory torch allocated in one packet's enhance(); CPU: the peak "
            "resident memory of the process that enhanced (model included)",
            "note": "enhancer wall time only (no I/O, no scoring); the first packet of each call includes "
            "one-off warm-up (the median is robust to it); timing differs between runs",
        },
        "fragments_sha256": fragments_sha256,
        "outputs": {
            "metrics": METRICS_FILE,
            "sequences": SEQUENCES_FILE if sequences is not None else None,
            "images": f"{IMAGES_DIR}/<protocol>/<group>/<scene>/<frame stem>.png",
        },
    }
    if settings.refit is not None:  # an X 3D run: what the refits its packets were cut from cost
        manifest["refit"] = {
            "fits": {key: dict(cost) for key, cost in (refits or {}).items()},
            "note": "wall_s: the whole refit of one scene's fit (steps, updates, the enhancer inside them); "
            "from each <scene>/<fit_key>.refit.json of run --refit",
        }
    return manifest
