"""One packet of a run: enhance and score it, write its 8-bit images, then (last) its fragment."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from setdiff_bench.enhancers.base import Enhancer
from setdiff_bench.evaluation.packet_scoring import score_packet
from setdiff_bench.evaluation.run._folder import fragment_path
from setdiff_bench.evaluation.run._rows import write_rows
from setdiff_bench.evaluation.run._settings import RunSettings
from setdiff_bench.evaluation.scoring import to_uint8_hwc
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.images import write_png
from setdiff_bench.io.run_layout import KEY_COLUMNS, image_relative
from setdiff_bench.metrics.registry import MetricSpec
from setdiff_bench.packets.store import PacketStore, timestamp_or_none
from setdiff_bench.types import TargetRef


def target_ref(row: Mapping[str, Any]) -> TargetRef:
    return TargetRef.from_row(row, frame=str(row["frame"]))


def run_packet(
    store: PacketStore,
    out: Path,
    packet_id: str,
    enhancer: Enhancer,
    specs: Sequence[MetricSpec],
    settings: RunSettings,
    claim: Callable[[], None],
) -> None:
    """Enhance and score one packet, then write its images and (last) its fragment.

    Everything that can fail on bad input (reading, enhancing, checking, scoring) happens before the
    first write, in :func:`~setdiff_bench.evaluation.packet_scoring.score_packet` (the one implementation
    of the shape check, the 8-bit rounding and the scoring); ``claim()`` is called right before it.
    """
    rows = store.rows(packet_id)
    targets = rows[rows["role"] == "target"].sort_values("view").to_dict("records")
    result = score_packet(
        enhancer, store, packet_id, metrics=specs, device=settings.device, batch_size=settings.batch_size
    )
    enhanced, scores, elapsed_ms = result.enhanced, result.scores, result.elapsed_ms
    claim()
    records = []
    for position, row in enumerate(targets):
        ref = target_ref(row)
        relative = image_relative(ref)
        write_png(out / relative, to_uint8_hwc(enhanced[position]))
        records.append(
            {
                **{key: row[key] for key in KEY_COLUMNS if key in row},
                "method": settings.label,
                "timestamp_us": timestamp_or_none(row.get("timestamp_us")),
                "sensor": str(row.get("sensor") or ""),
                "image": relative,
                "image_sha256": sha256_file(out / relative),
            }
        )
    per_frame = elapsed_ms / max(1, len(targets))
    scored = result.has_ground_truth
    for position, record in enumerate(records):
        for spec in specs:  # null, not NaN, where there was nothing to compare with
            unscored = scored is not None and not scored[position]
            record[spec.name] = None if unscored else float(scores[spec.name][position])
        record["ms_per_frame"] = per_frame
        record["peak_memory_mb"] = result.peak_memory_mb
    write_rows(fragment_path(out, packet_id), records, [spec.name for spec in specs])
