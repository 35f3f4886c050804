"""The per-target rows of a run: the Arrow schema of ``metrics.parquet`` and of the per-packet fragments.

One row per target: the key columns, ``method``, one float column per image metric, the timing columns
(:data:`TIMING_COLUMNS`, which differ between runs) and the enhanced image's path and SHA-256.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.io.atomic import atomic_path
from setdiff_bench.packets.index import key_columns

#: Columns that are measurements of time, not results: excluded from byte-identity comparisons.
TIMING_COLUMNS = ("ms_per_frame", "peak_memory_mb")


def row_schema(metric_names: Sequence[str]) -> pa.Schema:
    """Arrow schema of ``metrics.parquet`` and of fragments."""
    return pa.schema(
        [
            *key_columns(
                "dataset",
                "protocol",
                "group",
                "split",
                "scene",
                "frame",
                "sensor",
                "timestamp_us",
                "packet_id",
                "view",
            ),
            ("method", pa.string()),
            *[(name, pa.float64()) for name in metric_names],
            ("ms_per_frame", pa.float64()),
            ("peak_memory_mb", pa.float64()),
            ("image", pa.string()),
            ("image_sha256", pa.string()),
        ]
    )


def write_rows(path: Path, records: Sequence[Mapping[str, Any]], metric_names: Sequence[str]) -> None:
    schema = row_schema(metric_names)
    clean = [{name: _plain(record.get(name)) for name in schema.names} for record in records]
    table = pa.Table.from_pylist(clean, schema=schema)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def _plain(value: Any) -> Any:
    """numpy scalars → Python scalars (Arrow takes those); NaN floats stay NaN."""
    return value.item() if isinstance(value, np.generic) else value


def comparable_metrics(path: str | os.PathLike[str]) -> pd.DataFrame:
    """``metrics.parquet`` without its timing columns: equal for a resumed and an uninterrupted run."""
    return pd.read_parquet(path).drop(columns=list(TIMING_COLUMNS), errors="ignore")
