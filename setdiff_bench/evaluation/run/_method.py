"""``run_method``: one enhancer over one packet store, the orchestration (plan, claim, enhance, score, merge).

Output layout, resume, shards and warp error: the package's docstring (:mod:`setdiff_bench.evaluation.run`).
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
from setdiff_bench.evaluation.preflight import check_packets_fit, warn_out_of_distribution
from setdiff_bench.evaluation.run._folder import (
    check_folder,
    claim_folder,
    fragment_path,
    record_enhancer,
)
from setdiff_bench.evaluation.run._merge import merge_finished, merge_run
from setdiff_bench.evaluation.run._packet import run_packet, target_ref
from setdiff_bench.evaluation.run._result import RunResult, skipped_metrics, target_rows
from setdiff_bench.evaluation.run._settings import (
    RunSettings,
    check_run_name,
    refit_costs,
)
from setdiff_bench.evaluation.scoring import resolve_metrics
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.shards import Shard
from setdiff_bench.packets.store import PacketStore


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
    refits = refit_costs(settings, store.index, selection)  # every manifest there before any work
    identity = settings.identity(
        index_sha256, model_files, {key: cost["manifest_sha256"] for key, cost in refits.items()}
    )
    check_folder(out, identity)
    if merge_only:
        return replace(
            merge_finished(store, out, settings, specs, selection, refits),
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
        merge_run(store, out, settings, specs, selection, refits)
        merged = True
    skipped = skipped_metrics(store, selection, settings, specs)
    return RunResult(out, len(todo), len(mine) - len(todo), remaining, merged, skipped)


def _open_store(packets: str | os.PathLike[str] | PacketStore) -> PacketStore:
    if isinstance(packets, str | os.PathLike):
        return PacketStore(packets)
    return packets
