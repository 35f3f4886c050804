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

This module is the orchestration (:func:`run_method`) and the face of the concepts it uses, each in a
module of its own and re-exported here: the run contract (:mod:`.run_settings`), the run folder's claim and
resume (:mod:`.run_folder`), one packet's images and fragment (:mod:`.run_packet`), the per-target rows
(:mod:`.run_rows`), warp error per sequence (:mod:`.sequences`), the manifest (:mod:`.run_manifest`), the
merge (:mod:`.run_merge`) and what a call did (:mod:`.run_result`).
"""

from __future__ import annotations

import os
from dataclasses import replace
from pathlib import Path

from setdiff_bench.enhancers.base import (
    ChecksTargets,
    Enhancer,
    available_methods,
    create_enhancer,
)
from setdiff_bench.errors import PacketError, UsageError
from setdiff_bench.evaluation.packet_scoring import EnhancerOutputError
from setdiff_bench.evaluation.preflight import check_packets_fit, warn_out_of_distribution
from setdiff_bench.evaluation.run_folder import (
    check_folder,
    claim_folder,
    claimed_label,
    fragment_path,
    record_enhancer,
)
from setdiff_bench.evaluation.run_merge import merge_finished, merge_run
from setdiff_bench.evaluation.run_packet import run_packet, target_ref
from setdiff_bench.evaluation.run_result import RunResult, SkippedMetrics, skipped_metrics, target_rows
from setdiff_bench.evaluation.run_rows import TIMING_COLUMNS, comparable_metrics, row_schema
from setdiff_bench.evaluation.run_settings import (
    RUN_FORMAT,
    SEQUENCE_PROTOCOLS,
    RunSettings,
    WarpMode,
    check_run_name,
    warp_enabled,
)
from setdiff_bench.evaluation.scoring import resolve_metrics
from setdiff_bench.evaluation.sequences import SEQUENCE_SCHEMA
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.shards import Shard
from setdiff_bench.packets.store import PacketStore, timestamp_or_none

__all__ = [
    "RUN_FORMAT",
    "SEQUENCE_PROTOCOLS",
    "SEQUENCE_SCHEMA",
    "TIMING_COLUMNS",
    "EnhancerOutputError",
    "RunResult",
    "RunSettings",
    "Shard",
    "SkippedMetrics",
    "WarpMode",
    "claimed_label",
    "comparable_metrics",
    "fragment_path",
    "merge_run",
    "row_schema",
    "run_method",
    "skipped_metrics",
    "timestamp_or_none",
    "warp_enabled",
]


# ---------------------------------------------------------------------- the run
def run_method(
    packets: str | os.PathLike[str] | PacketStore,
    out: str | os.PathLike[str],
    settings: RunSettings,
    *,
    shard: Shard = Shard(),
    progress: bool | None = True,
    enhancer: Enhancer | None = None,
    verify: bool = True,
    merge_only: bool = False,
) -> RunResult:
    """Enhance and score every packet of ``settings.split`` in this shard; merge when all are done.

    Args:
        packets: a packet store folder or an open :class:`~setdiff_bench.packets.store.PacketStore`.
        out: the run folder (created; a folder holding a run with other settings is refused).
        settings: method, options and scoring choices.
        shard: which packets this call enhances.
        progress: a tqdm bar over the packets on stderr (a widget in a notebook); ``False``: none; ``None``:
            only when stderr is a terminal or in a notebook (the CLI's default; ``--no-progress`` gives
            ``False``).
        enhancer: an already built enhancer to use instead of building ``settings.method`` (tests,
            notebooks); its ``name`` must equal ``settings.method``.
        verify: re-hash every file of the packets to enhance before starting (seconds for a store of
            thousands of files), so that a corrupt file stops the run at once.
        merge_only: enhance nothing; merge every shard's fragments, or raise :class:`UsageError` naming
            what is missing.

    Raises:
        SetDiffBenchError: bad store, unknown method or option, an output of the wrong shape, ...
    """
    from tqdm.auto import tqdm

    store = _open_store(packets)
    out = Path(out)
    if settings.batch_size < 1:
        raise UsageError(f"batch size must be >= 1, got {settings.batch_size}", "--batch-size")
    specs = resolve_metrics(settings.metrics, option="RunSettings.metrics")  # the CLI checks --metrics
    selection = store.packet_ids(settings.split)
    if not selection:
        splits = sorted(set(store.index["split"]))
        raise UsageError(
            f"no packets of split {settings.split or 'any'!r} in the store; splits: {', '.join(splits)}",
            store.root,
        )
    if settings.method not in available_methods() and enhancer is None:
        raise UsageError(
            f"unknown method {settings.method!r}; available: {', '.join(sorted(available_methods()))}",
            parameter="method",
        )
    check_run_name(settings, available_methods())
    index_sha256 = sha256_file(Path(store.root) / INDEX_FILE)
    spec = available_methods().get(settings.method)
    model_files = spec.model_files(settings.options) if spec is not None else {}
    identity = settings.identity(index_sha256, model_files)
    check_folder(out, identity)
    if merge_only:
        return replace(
            merge_finished(store, out, settings, specs, selection),
            skipped_metrics=skipped_metrics(store, selection, settings, specs),
        )
    mine = shard.select(selection)
    todo = [pid for pid in mine if not fragment_path(out, pid).is_file()]
    targets = target_rows(store, selection)
    if todo and verify and hasattr(store, "verify"):
        # every file of the packets to enhance against the index's SHA-256, before any work: a corrupt
        # file is reported at once, not when the run reaches it
        problems = store.verify(todo)  # "packet_id: relative path: missing | SHA-256 mismatch"
        if problems:
            _, relative, what = problems[0].split(": ", 2)
            what = "packet file missing" if what == "missing" else what
            more = f", {len(problems) - 1} more problem(s) in other files" if len(problems) > 1 else ""
            raise PacketError(
                f"{what} (found by the check before any work{more}); run `setdiff-bench prepare` "
                "again to rewrite the packets, or pass --no-verify",
                Path(store.root) / relative,
            )
    if todo:
        if enhancer is None:
            enhancer = create_enhancer(
                settings.method, optional={"device": settings.device}, **settings.options
            )
        elif enhancer.name != settings.method:
            raise UsageError(f"enhancer {enhancer.name!r} given for method {settings.method!r}")
        if isinstance(enhancer, ChecksTargets):
            todo_set = set(todo)
            enhancer.check_targets([target_ref(row) for row in targets if row["packet_id"] in todo_set])
        check_packets_fit(enhancer, store.index, todo, Path(store.root))
        warn_out_of_distribution(enhancer, store.index, todo)
        built = enhancer
        claimed = False

        def claim() -> None:
            """Write run.json / enhancer.json just before the first results (a run that fails earlier leaves
            nothing behind, so a corrected command is not refused as 'other settings')."""
            nonlocal claimed
            if not claimed:
                claim_folder(out, identity)
                record_enhancer(out, built)
                claimed = True

        bar = tqdm(
            todo,
            desc=f"{settings.label} [{shard}]",
            unit="packet",
            disable=None if progress is None else not progress,
        )
        for packet_id in bar:
            run_packet(store, out, packet_id, enhancer, specs, settings, claim)
    remaining = sum(not fragment_path(out, pid).is_file() for pid in selection)
    merged = False
    if remaining == 0:
        merge_run(store, out, settings, specs, selection)
        merged = True
    skipped = skipped_metrics(store, selection, settings, specs)
    return RunResult(out, len(todo), len(mine) - len(todo), remaining, merged, skipped)


def _open_store(packets: str | os.PathLike[str] | PacketStore) -> PacketStore:
    if isinstance(packets, str | os.PathLike):
        return PacketStore(packets)
    return packets
