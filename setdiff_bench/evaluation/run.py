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
any other; their paired metrics (the image metrics, and warp error) are null in ``metrics.parquet``, named
in :attr:`RunResult.skipped_metrics` (``run`` prints them in one line) and in the manifest's ``skipped`` entry
(present only when something was skipped, so runs on packets with ground truth are unchanged).  FID / KID
(``--inception``) score them without ground truth.

Warp error (``warp``: ``auto`` = on for the protocols in :data:`SEQUENCE_PROTOCOLS`) is computed at
merge time per (protocol, scene, sensor) sequence of targets sorted by timestamp, across groups (a
camera's 10–15 s targets form one sequence), from the written 8-bit images and the ground truth.  The
ground truth's flow and occlusion mask are cached (``warp_cache``, keyed by the ground-truth files'
SHA-256), so scoring a second method on the same store does not recompute optical flow.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import torch

from setdiff_bench.enhancers.base import (
    ChecksTargets,
    Enhancer,
    TargetRef,
    available_methods,
    create_enhancer,
)
from setdiff_bench.errors import PacketError, UsageError
from setdiff_bench.evaluation.packet_scoring import EnhancerOutputError as EnhancerOutputError  # re-exported
from setdiff_bench.evaluation.packet_scoring import score_packet
from setdiff_bench.evaluation.preflight import check_packets_fit, warn_out_of_distribution
from setdiff_bench.evaluation.scoring import (
    default_warp_cache,
    resolve_metrics,
    sequence_warp_error,
    to_uint8_hwc,
)
from setdiff_bench.io.atomic import (
    atomic_path,
    is_stale_temporary,
    private_temporary,
    sha256_file,
    write_text_atomic,
)
from setdiff_bench.io.images import read_rgb, to_tensor_chw, write_png
from setdiff_bench.io.names import safe_component
from setdiff_bench.io.run_layout import (
    ENHANCER_FILE,
    FRAGMENTS_DIR,
    IMAGES_DIR,
    KEY_COLUMNS,
    MANIFEST_FILE,
    METRICS_FILE,
    RUN_FILE,
    SEQUENCES_FILE,
    image_relative,
)
from setdiff_bench.metrics.registry import PRESETS, MetricSpec
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.shards import Shard
from setdiff_bench.packets.store import PacketStore, target_has_ground_truth, timestamp_or_none
from setdiff_bench.runtime.provenance import device_description, git_revision, package_versions

RUN_FORMAT = "setdiff-run/1"
#: Protocols whose targets are time-ordered camera sequences: warp error with ``warp="auto"``.
SEQUENCE_PROTOCOLS = frozenset({"nuscenes"})
#: Columns that are measurements of time, not results: excluded from byte-identity comparisons.
TIMING_COLUMNS = ("ms_per_frame", "peak_memory_mb")

WarpMode = Literal["auto", "on", "off"]


@dataclass(frozen=True)
class RunSettings:
    """Everything that decides a run's results (recorded in ``run.json``; a resume must match).

    Attributes:
        method: registry name (``setdiff-bench list methods``).
        options: factory options given by the user (``checkpoint``, ``source`` for ``--from``, plugin options).
        split: ``"train"``/``"test"`` or ``None`` for every packet.
        metrics: image metric names (default: the ``standard`` preset: PSNR, SSIM, LPIPS-alex).
        warp: warp error per sequence: ``auto`` (on for :data:`SEQUENCE_PROTOCOLS`), ``on`` or ``off``.
        flow_method: optical flow for warp error (``deepflow`` or ``dis``).
        device: where the enhancer (if it takes ``device``) and the metrics run.
        batch_size: images per metric call (bounds LPIPS memory); does not change results.
        warp_cache: folder caching the ground truth's flow per sequence (shared by every method; keyed
            by the ground-truth files' SHA-256 and the flow method); ``"auto"`` = the user cache
            (:func:`setdiff_bench.evaluation.scoring.default_warp_cache`), ``None`` = no cache.  Does not change results.
    """

    method: str
    options: Mapping[str, Any] = field(default_factory=dict)
    split: str | None = "test"
    metrics: tuple[str, ...] = PRESETS["standard"]
    warp: WarpMode = "auto"
    flow_method: str = "deepflow"
    device: str = "cpu"
    batch_size: int = 8
    warp_cache: str | None = "auto"

    def identity(self, index_sha256: str, model_files: Mapping[str, str] | None = None) -> dict[str, Any]:
        """The ``run.json`` content: what must not change between a run and its resumption.

        ``model_files`` (``{file: SHA-256}`` from the method's fingerprint, e.g. a checkpoint's weights and
        config) is recorded when the method has one, so that the same ``--checkpoint`` naming other weights
        (retrained, re-exported, a newer shipped model) does not resume into stale results.
        """
        identity = {
            "format": RUN_FORMAT,
            "method": self.method,
            "options": _jsonable(dict(self.options)),
            "split": self.split,
            "metrics": list(self.metrics),
            "warp": self.warp,
            "flow_method": self.flow_method,
            "device": self.device,
            "index_sha256": index_sha256,
        }
        if model_files:
            identity["model_files"] = dict(sorted(model_files.items()))
        return identity


@dataclass(frozen=True)
class SkippedMetrics:
    """Metrics a run could not compute for some targets because they have no ground truth.

    Attributes:
        metrics: metric names skipped (the run's image metrics, then ``warp`` when warp error is on).
        targets: how many selected targets have no ground truth.
        groups: the groups those targets are in, sorted.
    """

    metrics: tuple[str, ...]
    targets: int
    groups: tuple[str, ...]

    def line(self, distribution: bool = False) -> str:
        """The one line ``run`` prints; ``distribution``: FID / KID are being computed (``--inception``)."""
        how = "FID / KID below" if distribution else "FID / KID (--inception FILE)"
        return (
            f"skipped {', '.join(self.metrics)} for {self.targets} target(s) without ground truth "
            f"(groups {', '.join(self.groups)}): novel-trajectory views are scored by {how}"
        )

    def record(self) -> dict[str, Any]:
        """The manifest's ``skipped`` entry."""
        return {
            "metrics": list(self.metrics),
            "targets": self.targets,
            "groups": list(self.groups),
            "reason": "no ground truth (novel-trajectory targets); their metric columns are null",
        }


def skipped_metrics(
    store: PacketStore, selection: Sequence[str], settings: RunSettings, specs: Sequence[MetricSpec]
) -> SkippedMetrics | None:
    """What a run over ``selection`` skips for lack of ground truth (``None`` when every target has it)."""
    rows = pd.DataFrame(_target_rows(store, selection))
    if rows.empty:
        return None
    without = rows[~target_has_ground_truth(rows)]
    if without.empty:
        return None
    metrics = [spec.name for spec in specs]
    if warp_enabled(settings, sorted(rows["protocol"].unique())):
        metrics.append("warp")
    return SkippedMetrics(tuple(metrics), len(without), tuple(sorted(without["group"].unique())))


@dataclass
class RunResult:
    """What one call of :func:`run_method` did.

    Attributes:
        out: the run folder.
        enhanced: packets enhanced by this call.
        skipped: packets of this shard already done.
        remaining: packets of the whole selection still without a fragment (other shards).
        merged: whether ``metrics.parquet`` is complete (written now or already up to date).
        skipped_metrics: the paired metrics not computed for the selection's targets without ground
            truth (``None``: every target has it).
    """

    out: Path
    enhanced: int
    skipped: int
    remaining: int
    merged: bool
    skipped_metrics: SkippedMetrics | None = None

    @property
    def metrics(self) -> pd.DataFrame:
        """The merged per-target table (raises if the run is not merged yet)."""
        if not self.merged:
            raise UsageError(f"run not complete: {self.remaining} packets remain", self.out)
        return pd.read_parquet(self.out / METRICS_FILE)


# ---------------------------------------------------------------------- paths
def fragment_path(out: Path, packet_id: str) -> Path:
    return out / FRAGMENTS_DIR / f"{safe_component(packet_id)}.parquet"


# ---------------------------------------------------------------------- the run
def run_method(
    packets: str | os.PathLike[str] | PacketStore,
    out: str | os.PathLike[str],
    settings: RunSettings,
    *,
    shard: Shard = Shard(),
    progress: bool | None = None,
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
        progress: tqdm bar (``None``: only on a terminal).
        enhancer: an already built enhancer to use instead of building ``settings.method`` (tests,
            notebooks); its ``name`` must equal ``settings.method``.
        verify: re-hash every file of the packets to enhance before starting (seconds for a store of
            thousands of files), so that a corrupt file stops the run at once.
        merge_only: enhance nothing; merge every shard's fragments, or raise :class:`UsageError` naming
            what is missing.

    Raises:
        SetDiffBenchError: bad store, unknown method or option, an output of the wrong shape, ...
    """
    from tqdm import tqdm

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
    index_sha256 = sha256_file(Path(store.root) / INDEX_FILE)
    spec = available_methods().get(settings.method)
    model_files = spec.model_files(settings.options) if spec is not None else {}
    identity = settings.identity(index_sha256, model_files)
    _check_folder(out, identity)
    if merge_only:
        return replace(
            _merge_finished(store, out, settings, specs, selection),
            skipped_metrics=skipped_metrics(store, selection, settings, specs),
        )
    mine = shard.select(selection)
    todo = [pid for pid in mine if not fragment_path(out, pid).is_file()]
    targets = _target_rows(store, selection)
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
            enhancer.check_targets([_target_ref(row) for row in targets if row["packet_id"] in todo_set])
        check_packets_fit(enhancer, store.index, todo, Path(store.root))
        warn_out_of_distribution(enhancer, store.index, todo)
        built = enhancer
        claimed = False

        def claim() -> None:
            """Write run.json / enhancer.json just before the first results (a run that fails earlier leaves
            nothing behind, so a corrected command is not refused as 'other settings')."""
            nonlocal claimed
            if not claimed:
                _claim_folder(out, identity)
                _record_enhancer(out, built)
                claimed = True

        bar = tqdm(
            todo,
            desc=f"{settings.method} [{shard}]",
            unit="packet",
            disable=None if progress is None else not progress,
        )
        for packet_id in bar:
            _run_packet(store, out, packet_id, enhancer, specs, settings, claim)
    remaining = sum(not fragment_path(out, pid).is_file() for pid in selection)
    merged = False
    if remaining == 0:
        merge_run(store, out, settings, specs, selection)
        merged = True
    skipped = skipped_metrics(store, selection, settings, specs)
    return RunResult(out, len(todo), len(mine) - len(todo), remaining, merged, skipped)


def _merge_finished(
    store: PacketStore,
    out: Path,
    settings: RunSettings,
    specs: Sequence[MetricSpec],
    selection: Sequence[str],
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
    merge_run(store, out, settings, specs, selection)
    return RunResult(out, 0, len(selection), 0, True)


def _open_store(packets: str | os.PathLike[str] | PacketStore) -> PacketStore:
    if isinstance(packets, str | os.PathLike):
        return PacketStore(packets)
    return packets


def _check_folder(out: Path, identity: dict[str, Any]) -> None:
    """Refuse, without writing anything, a folder that holds another run or other files."""
    if not out.exists():
        return
    if not out.is_dir():
        raise UsageError("output path exists and is not a folder; choose another --out", out)
    if (out / RUN_FILE).is_file():
        _compare_settings(out, identity)
    elif _has_visible_files(out):
        raise UsageError("output folder is not empty and holds no run.json; choose another --out", out)


def _claim_folder(out: Path, identity: dict[str, Any]) -> None:
    """Create ``out`` with ``run.json``, or check that the run already there has the same settings.

    Lock-free: ``run.json`` is written to a private temporary file and hard-linked into place, which
    fails if the file exists (atomic on local and network filesystems), so shards started together into
    a new folder agree on one ``run.json``, and a shard with other settings is refused.
    """
    out.mkdir(parents=True, exist_ok=True)
    run_file = out / RUN_FILE
    if not run_file.is_file():
        with private_temporary(run_file) as tmp:
            tmp.write_text(json.dumps(identity, indent=2, sort_keys=True) + "\n")
            with contextlib.suppress(FileExistsError):
                os.link(tmp, run_file)
    _compare_settings(out, identity)


def _compare_settings(out: Path, identity: dict[str, Any]) -> None:
    run_file = out / RUN_FILE
    try:
        existing = json.loads(run_file.read_text())
    except (OSError, json.JSONDecodeError) as error:
        raise UsageError(f"unreadable run settings ({error})", run_file) from None
    if existing != identity:
        changed = sorted(k for k in set(existing) | set(identity) if existing.get(k) != identity.get(k))
        if changed == ["model_files"]:
            before = "were not recorded (an older run.json)" if "model_files" not in existing else "differ"
            raise UsageError(
                f"this folder holds a run made with other model files (their SHA-256 {before}): "
                "its results would mix two models; choose another --out",
                out,
            )
        raise UsageError(
            f"this folder holds a run with other settings ({', '.join(changed)} differ); "
            "resume with the same command or choose another --out",
            out,
        )


def _has_visible_files(folder: Path) -> bool:
    """Anything but hidden entries (the lock file, temporary files of killed writes)."""
    return any(not entry.name.startswith(".") for entry in folder.iterdir())


def _record_enhancer(out: Path, enhancer: Enhancer) -> None:
    info = {
        "name": enhancer.name,
        "class": f"{type(enhancer).__module__}.{type(enhancer).__qualname__}",
        "options": _jsonable(dict(getattr(enhancer, "options", {}) or {})),
    }
    path = out / ENHANCER_FILE
    text = json.dumps(info, indent=2, sort_keys=True) + "\n"
    if not path.is_file() or path.read_text() != text:
        write_text_atomic(path, text)


def _target_rows(store: PacketStore, selection: Sequence[str]) -> list[dict[str, Any]]:
    index = store.index
    rows = index[(index["role"] == "target") & index["packet_id"].isin(list(selection))]
    return rows.sort_values(["packet_id", "view"]).to_dict("records")


def _target_ref(row: Mapping[str, Any]) -> TargetRef:
    return TargetRef.from_row(row, frame=str(row["frame"]))


def _run_packet(
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
        ref = _target_ref(row)
        relative = image_relative(ref)
        write_png(out / relative, to_uint8_hwc(enhanced[position]))
        records.append(
            {
                **{key: row[key] for key in KEY_COLUMNS if key in row},
                "method": settings.method,
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
    _write_rows(fragment_path(out, packet_id), records, [spec.name for spec in specs])


# ---------------------------------------------------------------------- tables
def row_schema(metric_names: Sequence[str]) -> pa.Schema:
    """Arrow schema of ``metrics.parquet`` and of fragments."""
    return pa.schema(
        [
            ("dataset", pa.string()),
            ("protocol", pa.string()),
            ("group", pa.string()),
            ("split", pa.string()),
            ("scene", pa.string()),
            ("frame", pa.string()),
            ("sensor", pa.string()),
            ("timestamp_us", pa.int64()),
            ("packet_id", pa.string()),
            ("view", pa.int32()),
            ("method", pa.string()),
            *[(name, pa.float64()) for name in metric_names],
            ("ms_per_frame", pa.float64()),
            ("peak_memory_mb", pa.float64()),
            ("image", pa.string()),
            ("image_sha256", pa.string()),
        ]
    )


def _write_rows(path: Path, records: Sequence[Mapping[str, Any]], metric_names: Sequence[str]) -> None:
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


# ---------------------------------------------------------------------- merging
def warp_enabled(settings: RunSettings, protocols: Sequence[str]) -> bool:
    """Whether warp error is computed for a run over ``protocols``."""
    if settings.warp == "auto":
        return any(protocol in SEQUENCE_PROTOCOLS for protocol in protocols)
    return settings.warp == "on"


def merge_run(
    store: PacketStore,
    out: Path,
    settings: RunSettings,
    specs: Sequence[MetricSpec],
    selection: Sequence[str],
) -> None:
    """Merge every fragment into ``metrics.parquet`` (+ ``sequences.parquet``) and write ``manifest.json``.

    Idempotent: nothing is rewritten when the manifest already records the same fragments.  Lock-free:
    every output depends only on the fragments and is written by atomic rename, so two shards merging
    at once write the same bytes.
    """
    _remove_stale_temporaries(out)
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
        sequences = _sequence_table(store, out, frame, settings)
        with atomic_path(out / SEQUENCES_FILE) as tmp:
            pq.write_table(sequences, tmp, compression="zstd")
    manifest = _manifest(store, out, settings, specs, frame, sequences, fragments_sha256)
    skipped = skipped_metrics(store, selection, settings, specs)
    if skipped is not None:  # only then, so the manifests of runs with ground truth are unchanged
        manifest["skipped"] = skipped.record()
    write_text_atomic(manifest_path, json.dumps(manifest, indent=2, sort_keys=True) + "\n")


def _remove_stale_temporaries(out: Path) -> None:
    """Temporary files of writes killed mid-way (``.<name>.<writer>.<random>.tmp<ext>``), not those of
    another shard's write in progress (:func:`~setdiff_bench.io.atomic.is_stale_temporary`)."""
    for folder in (out / IMAGES_DIR, out / FRAGMENTS_DIR, out):
        if folder.is_dir():
            pattern = "**/.*.tmp*" if folder.name == IMAGES_DIR else ".*.tmp*"
            for stale in folder.glob(pattern):
                with contextlib.suppress(FileNotFoundError):
                    if stale.is_file() and is_stale_temporary(stale):
                        stale.unlink()


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


def _sequence_table(store: PacketStore, out: Path, frame: pd.DataFrame, settings: RunSettings) -> pa.Table:
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


def _manifest(
    store: PacketStore,
    out: Path,
    settings: RunSettings,
    specs: Sequence[MetricSpec],
    frame: pd.DataFrame,
    sequences: pa.Table | None,
    fragments_sha256: str,
) -> dict[str, Any]:
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
    return {
        "format": RUN_FORMAT,
        "method": {
            "name": settings.method,
            "factory": spec.factory if spec else None,
            "source": spec.source if spec else None,
            "options": _jsonable(dict(settings.options)),
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
                    "kwargs": _jsonable(dict(s.kwargs)),
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
                "grouping": "(protocol, scene, sensor), targets sorted by timestamp across groups",
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


def _jsonable(value: Any) -> Any:
    """Options as JSON values (paths and other objects become strings)."""
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, bool | int | str) or value is None:
        return value
    if isinstance(value, float):
        return value if np.isfinite(value) else str(value)
    if hasattr(value, "__dataclass_fields__"):
        return _jsonable(asdict(value))
    return str(value)
