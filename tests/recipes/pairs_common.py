"""Shared by the training-pair recipe tests: the capture's recorded frames, a ``prepare --pairs`` call with
tiny fits, and the written packets read back from the index."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd

from setdiff_bench.packets.prepare import PrepareSummary, prepare
from setdiff_bench.runtime.threads import torch_threads

#: 3DGS iterations of every fit in these tests.
ITERATIONS = 20
F = "lane0_front_{:03d}.png"
#: The synthetic protocol's recorded frames of ``street_00``: lane 0's front camera minus timestep 2.
RECORDED = [F.format(i) for i in (0, 1, 3, 4)]


def prepare_pairs(root: Path, out: Path, pairs: str, **kwargs: Any) -> PrepareSummary:
    """``prepare synthetic --fit --fit-iterations 20 --pairs PAIRS`` on one torch thread, without progress bars;
    ``kwargs`` are further :func:`prepare` options, over these (``fit=False, fits=DIR``)."""
    options = {"fit": True, "fit_iterations": ITERATIONS, "progress": False, **kwargs}
    with torch_threads(1):
        return prepare("synthetic", root, out, pairs=[pairs], **options)


def packets_of(out: Path) -> dict[str, tuple[list[str], set[str]]]:
    """packet id → (target frames in order, reference frames)."""
    index = pd.read_parquet(out / "index.parquet")
    result = {}
    for pid, rows in index.groupby("packet_id"):
        targets = rows[rows["role"] == "target"].sort_values("view")["frame"].tolist()
        result[str(pid)] = (targets, set(rows[rows["role"] == "ref"]["frame"]))
    return result
