"""Checks a run makes once its enhancer is built and before it writes anything: will the largest packet fit
in memory, and is the store like the data the enhancer was trained on.

Both read only the packet store's index (views per packet, image size, dataset), so they cost nothing
next to the enhancement they guard.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from setdiff_bench.enhancers.base import Enhancer, EstimatesMemory, KnowsTrainingData
from setdiff_bench.errors import OutOfDistributionWarning
from setdiff_bench.runtime.memory import check_memory

#: What a user can change when a packet does not fit (the options every model enhancer takes).
MEMORY_ADVICE = (
    "use fewer views per set (-o targets_per_set=M, -o max_references=N), a smaller resolution "
    "(the protocol's resolution), or another device (--device)"
)


def packet_shapes(index: pd.DataFrame, packet_ids: Sequence[str]) -> pd.DataFrame:
    """Per packet of ``packet_ids``: ``references``, ``targets``, ``height``, ``width`` (one row each)."""
    rows = index[index["packet_id"].isin(set(packet_ids))]
    grouped = rows.groupby("packet_id", sort=True)
    return pd.DataFrame(
        {
            "references": grouped["role"].apply(lambda roles: int((roles == "ref").sum())),
            "targets": grouped["role"].apply(lambda roles: int((roles != "ref").sum())),
            "height": grouped["height"].max().astype(int),
            "width": grouped["width"].max().astype(int),
        }
    )


def check_packets_fit(
    enhancer: Enhancer, index: pd.DataFrame, packet_ids: Sequence[str], store: Path
) -> None:
    """Raise :class:`~setdiff_bench.errors.MemoryNeedError` (one line) when the enhancer's estimate for the
    largest of ``packet_ids`` exceeds the memory available on its device; no-op for enhancers that do
    not estimate (identity, reproject, plugins)."""
    if not isinstance(enhancer, EstimatesMemory) or not packet_ids:
        return
    shapes = packet_shapes(index, packet_ids)
    needs = [
        enhancer.memory_bytes(int(row.references), int(row.targets), int(row.height), int(row.width))
        for row in shapes.itertuples()
    ]
    worst = max(range(len(needs)), key=needs.__getitem__)
    row = shapes.iloc[worst]
    what = (
        f"enhancing packet {shapes.index[worst]} ({int(row.references)} references + {int(row.targets)} "
        f"targets of {int(row.width)}x{int(row.height)}) with {enhancer.name}"
    )
    check_memory(needs[worst], enhancer.device, what, MEMORY_ADVICE, store)


def warn_out_of_distribution(
    enhancer: Enhancer, index: pd.DataFrame, packet_ids: Sequence[str]
) -> str | None:
    """Warn (:class:`OutOfDistributionWarning`, once) when the packets' datasets or image sizes differ from
    the enhancer's recorded training data; returns the line (``None`` when they match or nothing is
    recorded)."""
    if not isinstance(enhancer, KnowsTrainingData) or not packet_ids:
        return None
    rows = index[index["packet_id"].isin(set(packet_ids))]
    sizes = sorted({(int(h), int(w)) for h, w in zip(rows["height"], rows["width"], strict=True)})
    line = enhancer.out_of_distribution(sorted({str(d) for d in rows["dataset"]}), sizes, "this store")
    if line is not None:
        warnings.warn(line, OutOfDistributionWarning, stacklevel=2)
    return line
