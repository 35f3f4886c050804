"""FID and KID of a run's enhanced targets against the recorded frames of the same scenes.

Distribution metrics need no ground truth: they compare the set of enhanced images with a set of real
ones.  The real set is the **recorded frames** of the same scenes — the clean captures the run's
packets carry as references (chosen by Eq. 2 from the frames the fit saw), each counted once per
scene.  One row per leaderboard block, pooling the block's scenes (a scene alone gives a few dozen
frames: too few for FID, enough for KID, which is unbiased at any size):

``<run>/distribution.parquet``::

    method, dataset, protocol, group, split   the block
    scenes             scenes pooled
    enhanced           distinct enhanced targets (a target seen in several packets counts once)
    recorded           distinct recorded frames
    fid                Fréchet Inception Distance (null with fewer than 2 images on a side)
    kid, kid_std       KID (unbiased MMD², cubic kernel) and its standard deviation over subsets
    kid_subsets, kid_subset_size    how KID was estimated (subset size null: the whole sets once)

and ``<run>/distribution.json`` (the Inception file's SHA-256, the KID settings, the table's
columns).  Features: :mod:`setdiff_bench.metrics.inception`; formulas: :mod:`setdiff_bench.metrics.distribution`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.io.images import read_rgb, to_tensor_chw
from setdiff_bench.io.run_layout import METRICS_FILE, image_relative
from setdiff_bench.metrics.distribution import KID_SUBSET_SIZE, KID_SUBSETS, fid, kid
from setdiff_bench.metrics.inception import inception_features
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.types import TargetRef

DISTRIBUTION_FILE = "distribution.parquet"
DISTRIBUTION_INFO_FILE = "distribution.json"
BLOCK_COLUMNS = ("method", "dataset", "protocol", "group", "split")
COLUMNS = (
    *BLOCK_COLUMNS,
    "scenes",
    "enhanced",
    "recorded",
    "fid",
    "kid",
    "kid_std",
    "kid_subsets",
    "kid_subset_size",
)


@dataclass(frozen=True)
class DistributionSettings:
    """How FID / KID are computed.

    Attributes:
        kid_subsets: random subset pairs when both sets exceed ``kid_subset_size``.
        kid_subset_size: features per KID subset.
        seed: seed of the KID subset draws.
        batch_size: images per Inception call.
    """

    kid_subsets: int = KID_SUBSETS
    kid_subset_size: int = KID_SUBSET_SIZE
    seed: int = 0
    batch_size: int = 16


def _image(path: Path) -> torch.Tensor:
    return to_tensor_chw(read_rgb(path))


def block_sets(run: Path, store: PacketStore) -> dict[tuple[str, ...], tuple[list[Path], list[Path], int]]:
    """Per block ``(method, dataset, protocol, group, split)``: the enhanced images (run folder), the recorded
    frames (packet references of the same packets' scenes) and how many scenes — paths, each once.

    Raises:
        UsageError: the run has no ``metrics.parquet`` (not finished) or its packets are not in ``store``.
    """
    metrics_path = run / METRICS_FILE
    if not metrics_path.is_file():
        raise UsageError(f"not a finished run (no {METRICS_FILE})", run)
    rows = pd.read_parquet(metrics_path)
    index = store.index
    missing = sorted(set(rows["packet_id"]) - set(index["packet_id"]))
    if missing:
        raise UsageError(
            f"packet {missing[0]!r} of run {run} is not in this store; pass the run's own --packets",
            store.root,
        )
    references = index[index["role"] == "ref"]
    out: dict[tuple[str, ...], tuple[list[Path], list[Path], int]] = {}
    for block, part in rows.groupby(list(BLOCK_COLUMNS), sort=True):
        enhanced: dict[tuple[str, str], Path] = {}
        for row in part.sort_values(["packet_id", "view"]).to_dict("records"):
            key = (str(row["scene"]), str(row["frame"]))
            enhanced.setdefault(key, run / image_relative(TargetRef.from_row(row, frame=str(row["frame"]))))
        recorded: dict[tuple[str, str], Path] = {}
        chosen = references[references["packet_id"].isin(set(part["packet_id"]))]
        for row in chosen.sort_values(["packet_id", "view"]).to_dict("records"):
            key = (str(row["scene"]), str(row["frame"]))
            if key not in recorded:
                recorded[key] = store.file_path(pd.Series(row), "image")
        scenes = len(set(part["scene"]))
        out[tuple(str(v) for v in block)] = (list(enhanced.values()), list(recorded.values()), scenes)
    return out


def score_distribution(
    run: str | Path,
    packets: str | Path | PacketStore,
    model: torch.nn.Module,
    settings: DistributionSettings | None = None,
    *,
    weights_sha256: str | None = None,
    weights_file: str | None = None,
    progress: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """FID and KID of every block of a finished run (module docstring); writes and returns the table.

    Args:
        run: the run folder (``metrics.parquet``, ``images/``).
        packets: the store the run was made from.
        model: maps ``(B, 3, H, W)`` RGB in [0, 1] to ``(B, D)`` features
            (:func:`setdiff_bench.metrics.inception.load_inception`).
        settings: KID subsets, seed, batch size.
        weights_sha256: the Inception file's SHA-256, recorded in ``distribution.json``.
        weights_file: the Inception file's name (no folder: a record names no path of the machine), recorded
            in ``distribution.json`` as ``inception_file`` beside the hash; the leaderboard's caption shows it.
        progress: called with one line per block scored.
    """
    settings = settings or DistributionSettings()
    run = Path(run)
    store = packets if isinstance(packets, PacketStore) else PacketStore(packets)
    blocks = block_sets(run, store)
    cache: dict[Path, np.ndarray] = {}

    def features(paths: list[Path]) -> np.ndarray:
        todo = [p for p in paths if p not in cache]
        if todo:
            computed = inception_features(model, (_image(p) for p in todo), batch_size=settings.batch_size)
            cache.update(zip(todo, computed, strict=True))
        return np.stack([cache[p] for p in paths]) if paths else np.zeros((0, 1))

    records: list[dict[str, Any]] = []
    for block, (enhanced, recorded, scenes) in blocks.items():
        a, b = features(enhanced), features(recorded)
        record: dict[str, Any] = dict(zip(BLOCK_COLUMNS, block, strict=True))
        record.update(scenes=scenes, enhanced=len(enhanced), recorded=len(recorded))
        if len(enhanced) >= 2 and len(recorded) >= 2:
            estimate = kid(
                a, b, subsets=settings.kid_subsets, subset_size=settings.kid_subset_size, seed=settings.seed
            )
            record.update(
                fid=fid(a, b),
                kid=estimate.mean,
                kid_std=estimate.std,
                kid_subsets=estimate.subsets,
                kid_subset_size=estimate.subset_size,
            )
        else:
            record.update(fid=None, kid=None, kid_std=None, kid_subsets=None, kid_subset_size=None)
        records.append(record)
        if progress is not None:
            fid_text = "n/a" if record["fid"] is None else f"{record['fid']:.2f}"
            kid_text = "n/a" if record["kid"] is None else f"{record['kid']:.4f}"
            progress(
                f"{'/'.join(block)}: FID {fid_text}, KID {kid_text} "
                f"({len(enhanced)} enhanced vs {len(recorded)} recorded frames, {scenes} scenes)"
            )
    table = pd.DataFrame.from_records(records, columns=list(COLUMNS))
    for column in ("scenes", "enhanced", "recorded", "kid_subsets", "kid_subset_size"):
        table[column] = table[column].astype("Int64")
    for column in ("fid", "kid", "kid_std"):
        table[column] = table[column].astype("float64")
    with atomic_path(run / DISTRIBUTION_FILE) as tmp:
        table.to_parquet(tmp, index=False)
    info = {
        "inception_sha256": weights_sha256,
        "inception_file": None if weights_file is None else Path(weights_file).name,
        "settings": asdict(settings),
        "columns": list(COLUMNS),
        "reference_set": "the recorded frames the run's packets carry as references, once per scene",
    }
    write_text_atomic(run / DISTRIBUTION_INFO_FILE, json.dumps(info, indent=2) + "\n")
    return table
