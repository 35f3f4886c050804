"""Merging a run: every packet's fragment into ``metrics.parquet`` (+ ``sequences.parquet``) and the manifest.

:func:`merge_run` is idempotent and lock-free (every output depends only on the fragments and is written
by atomic rename); :func:`merge_finished` is ``run --merge``, which merges or names what is missing.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from setdiff_bench.errors import PacketError, UsageError
from setdiff_bench.evaluation.run._folder import fragment_path, remove_stale_temporaries
from setdiff_bench.evaluation.run._manifest import run_manifest
from setdiff_bench.evaluation.run._result import RunResult, skipped_metrics
from setdiff_bench.evaluation.run._rows import row_schema
from setdiff_bench.evaluation.run._sequences import sequence_table
from setdiff_bench.evaluation.run._settings import RunSettings, warp_enabled
from setdiff_bench.io.atomic import atomic_path, sha256_file, write_text_atomic
from setdiff_bench.io.run_layout import MANIFEST_FILE, METRICS_FILE, RUN_FILE, SEQUENCES_FILE
from setdiff_bench.metrics.registry import MetricSpec
from setdiff_bench.packets.store import PacketStore


def merge_run(
    store: PacketStore,
    out: Path,
    settings: RunSettings,
    specs: Sequence[MetricSpec],
    selection: Sequence[str],
    refits: Mapping[str, Mapping[str, Any]] | None = None,
) -> None:
    """Merge every fragment into ``metrics.parquet`` (+ ``sequences.parquet``) and write ``manifest.json``
    (``refits``: the refit costs ``run_method`` recorded, for ``run --refit``).

    Idempotent: nothing is rewritten when the manifest already records the same fragments.  Lock-free:
    every output depends only on the fragments and is written by atomic rename, so two shards merging
    at once write the same bytes.
    """
    remove_stale_temporaries(out)
    paths = [fragment_path(out, pid) for pid in selection]
    digest = hashlib.sha256()
    for path in paths:
        digest.update(f"{path.name}:{sha256_file(path)}\n".encode())
    fragments_sha256 = digest.hexdigest()
    manifest_path = out / MANIFEST_FILE
    if manifest_path.is_file() and (out / METRICS_FILE).is_file():
        with contextlib.suppress(OSError, json.JSONDecodeError):
            if json.loads(manifest_path.read_text()).get("fragments_sha256") == fragments_sha256:
                return
    names = [spec.name for spec in specs]
    tables = []
    for path in paths:
        try:
            tables.append(pq.read_table(path).cast(row_schema(names)))
        except (OSError, pa.ArrowException) as error:
            raise PacketError(
                f"unreadable run fragment ({type(error).__name__}); delete it to redo the packet", path
            ) from None
    merged = pa.concat_tables(tables).sort_by([("packet_id", "ascending"), ("view", "ascending")])
    with atomic_path(out / METRICS_FILE) as tmp:
        pq.write_table(merged, tmp, compression="zstd")
    frame = merged.to_pandas()
    sequences = None
    if warp_enabled(settings, sorted(frame["protocol"].unique())):
        sequences = sequence_table(store, out, frame, settings)
        with atomic_path(out / SEQUENCES_FILE) as tmp:
            pq.write_table(sequences, tmp, compression="zstd")
    manifest = run_manifest(store, out, settings, specs, frame, sequences, fragments_sha256, refits)
    skipped = skipped_metrics(store, selection, settings, specs)
    if skipped is not None:  # only then, so the manifests of runs with ground truth are unchanged
        manifest["skipped"] = skipped.record()
    write_text_atomic(manifest_path, json.dumps(manifest, indent=2, sort_keys=True) + "\n")


def merge_finished(
    store: PacketStore,
    out: Path,
    settings: RunSettings,
    specs: Sequence[MetricSpec],
    selection: Sequence[str],
    refits: Mapping[str, Mapping[str, Any]] | None = None,
) -> RunResult:
    """``--merge``: merge a run whose shards have all finished; one line naming what is missing otherwise."""
    if not (out / RUN_FILE).is_file():
        raise UsageError("no run here to merge (no run.json): run the shards first", out)
    missing = [pid for pid in selection if not fragment_path(out, pid).is_file()]
    if missing:
        shown = ", ".join(missing[:3]) + (", ..." if len(missing) > 3 else "")
        raise UsageError(
            f"run incomplete: {len(missing)} of {len(selection)} packets have no fragment ({shown}); "
            "rerun the shards that hold them (the same command resumes), then merge again",
            out,
        )
    merge_run(store, out, settings, specs, selection, refits)
    return RunResult(out, 0, len(selection), 0, True)
