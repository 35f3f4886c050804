"""One enhancer over one packet store → enhanced images, per-target metrics, a manifest.

Output folder (``--out``)::

    run.json                      the run's settings; a resumed run must match them
    enhancer.json                 the options the enhancer reported when it was built
    images/<protocol>/<group>/<scene>/<frame stem>.png   enhanced targets, 8-bit (round to nearest)
    fragments/<packet id>.parquet one packet's rows, written atomically after its images
    metrics.parquet               every target's row (merged when every selected packet has a fragment)
    sequences.parquet             warp error per time-ordered sequence (sequence protocols only)
    manifest.json                 method and config, versions, git revision, device, timing, index hash

``metrics.parquet`` has one row per target: ``dataset, protocol, group, split, scene, frame, sensor,
timestamp_us, packet_id, view, method``, one float column per image metric (``psnr, ssim, lpips`` with
the default ``standard`` preset, masks applied), ``ms_per_frame`` (the enhancer's wall time for the
packet divided by its targets; excludes I/O and scoring), ``peak_memory_mb`` (CUDA: most memory allocated
while enhancing the packet; CPU: the process's peak resident memory), and the enhanced image's path and
SHA-256.
Rows are sorted by packet id and target position, so the file depends only on the results.

Resume and shards.  A packet is done when its fragment exists (fragments are written last, atomically),
so a killed run restarted with the same command enhances only the rest.  Nothing is written before the
first packet has been enhanced and scored (``run.json`` included), so a run that fails on bad input
before that leaves no folder behind.  ``--shard i/n`` (0 ≤ i < n) takes every n-th packet of the sorted
selection starting at i; shards may run at the same time, on any machines, into the same folder on a
shared filesystem.  Nothing needs a file lock (``flock`` is often missing on network filesystems):
every file a shard writes is its own (images, its packets' fragments) or has one possible content
(``run.json`` is created once with an atomic hard link; ``enhancer.json`` and the merged files are
written by atomic rename and depend only on the settings and the fragments).  A shard that finds every
fragment present merges them; on a network filesystem, whose directory listings may lag behind other
machines, end with ``run --merge`` (the same command plus ``--merge``), which merges or refuses, in one
line, while a fragment is missing.  One run and any sharding give the same ``metrics.parquet`` up to the
timing columns.  Everything written is deterministic except timing and memory — ``ms_per_frame``,
``peak_memory_mb`` and the manifest's ``timing`` block — so an interrupted-and-resumed run matches an uninterrupted one byte for
byte in ``images/`` and in every other column (compare with :func:`comparable_metrics`).

Targets without ground truth (novel trajectories, ``prepare --trajectory``) are enhanced and written like
any other; their image metrics are null in ``metrics.parquet`` (warp error is computed on them with the flow
of their 3DGS renders, :mod:`.sequences`), named
in :attr:`RunResult.skipped_metrics` (``run`` prints them in one line) and in the manifest's ``skipped`` entry
(present only when something was skipped, so runs on packets with ground truth are unchanged).  FID / KID
(``--inception``) score them without ground truth.

Warp error (``warp``: ``auto`` = on for the protocols in :data:`SEQUENCE_PROTOCOLS`) is computed at
merge time per (protocol, scene, sensor) sequence of targets sorted by timestamp, across groups (a
camera's 10–15 s targets form one sequence), from the written 8-bit images and the ground truth.  The
ground truth's flow and occlusion mask are cached (``warp_cache``, keyed by the ground-truth files'
SHA-256), so scoring a second method on the same store does not recompute optical flow.

The package's modules are private; this face exports what other code uses.  The run contract
(``_settings``: :class:`RunSettings`), the orchestration (``_method``: :func:`run_method`), the run folder's claim
and resume (``_folder``), one packet's images and fragment (``_packet``), the per-target rows (``_rows``), the
manifest (``_manifest``), the merge (``_merge``) and what a call did (``_result``: :class:`RunResult`); warp error
per sequence (``_sequences``).
"""

from __future__ import annotations

from setdiff_bench.evaluation.run._folder import claimed_label, fragment_path
from setdiff_bench.evaluation.run._method import run_method
from setdiff_bench.evaluation.run._result import RunResult, SkippedMetrics
from setdiff_bench.evaluation.run._rows import TIMING_COLUMNS, comparable_metrics
from setdiff_bench.evaluation.run._settings import (
    RUN_FORMAT,
    SEQUENCE_PROTOCOLS,
    RunSettings,
    WarpMode,
    jsonable_options,
    warp_enabled,
)

__all__ = [
    "RUN_FORMAT",
    "SEQUENCE_PROTOCOLS",
    "TIMING_COLUMNS",
    "RunResult",
    "RunSettings",
    "SkippedMetrics",
    "WarpMode",
    "claimed_label",
    "comparable_metrics",
    "fragment_path",
    "jsonable_options",
    "run_method",
    "warp_enabled",
]
