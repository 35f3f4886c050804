"""Shared by the training-pair recipe tests: the capture's recorded frames, a ``prepare --pairs`` call with
tiny fits, and the written packets read back from the index."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pandas as pd
import pytest

import setdiff_bench.packets.fits as fits_module
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


def spy_fits(monkeypatch: pytest.MonkeyPatch, *, views: bool = False) -> list[dict[str, Any]]:
    """Record each fit that ``prepare`` makes (the real fit still runs): the frames loaded for it, its PLY,
    iterations and ``stop_after``; with ``views``, also the views it was given (names, camera centres ``(3,)``
    and rotations ``(3, 3)``, whether masked, images ``(3, H, W)``)."""
    calls: list[dict[str, Any]] = []
    load, fit = fits_module.load_fit_views, fits_module.fit_views_to_ply

    def load_spy(scene: Any, names: list[str], **kwargs: Any) -> Any:
        calls.append({"frames": list(names)})
        return load(scene, names, **kwargs)

    def fit_spy(scene: Any, given: Any, config: Any, out: Path, **kwargs: Any) -> Any:
        calls[-1].update(
            iterations=config.iterations, stop_after=kwargs.get("stop_after"), ply=Path(out).name
        )
        if views:
            calls[-1].update(
                names=[v.name for v in given],
                centres=[v.camera.center.copy() for v in given],
                rotations=[v.camera.R.copy() for v in given],
                masked=[v.mask is not None for v in given],
                images=[v.image.clone() for v in given],
            )
        return fit(scene, given, config, out, **kwargs)

    monkeypatch.setattr(fits_module, "load_fit_views", load_spy)
    monkeypatch.setattr(fits_module, "fit_views_to_ply", fit_spy)
    return calls
