"""The report site's inputs: the finished runs under the folders given (labelled by method) and the packet
store they were made on (checked against the index hash each run recorded), for
:func:`setdiff_bench.reporting.site.build_site`."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path

import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.run_layout import RUN_FILE
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.reporting.leaderboard import find_runs


def run_folders(paths: Sequence[str | Path]) -> dict[str, Path]:
    """Method label → run folder of every finished run under ``paths`` (each a run folder or a folder of
    runs).  The label is the run's display name (``run --name``, recorded in ``run.json``), else its method,
    as in the rows' ``method`` column; a label found twice is labelled ``label (folder name)``.
    Evaluation profiles' tables (``<run>/profiles/<profile>/metrics.parquet``, written by ``evaluate``) are
    not runs here: they hold scores, not images.

    Raises:
        UsageError: a path that is not a folder, or no finished run at all.
    """
    folders: list[Path] = []
    for path in paths:
        for folder in find_runs(path, profiles=False):
            if folder not in folders:
                folders.append(folder)
    if not folders:
        raise UsageError(
            f"no finished run (a folder with metrics.parquet) under {', '.join(map(str, paths))}"
        )
    methods = {folder: _run_method(folder) for folder in folders}
    counts = pd.Series(list(methods.values())).value_counts()
    return {
        (method if counts[method] == 1 else f"{method} ({folder.name})"): folder
        for folder, method in methods.items()
    }


def _run_method(folder: Path) -> str:
    try:
        record = json.loads((folder / RUN_FILE).read_text(encoding="utf-8"))
        return str(record.get("name") or record["method"])
    except (OSError, ValueError, KeyError, AttributeError):
        return str(pd.read_parquet(folder / "metrics.parquet", columns=["method"])["method"].iloc[0])


def open_store(packets: str | Path, runs: Mapping[str, Path]) -> PacketStore:
    """The packet store at ``packets``, checked to be the one every run in ``runs`` was made on (the index
    hash each ``run.json`` recorded).

    Raises:
        UsageError: a run made on another store (its pictures would not match its numbers).
    """
    store = PacketStore(packets)
    digest = sha256_file(Path(packets) / INDEX_FILE)
    for label, folder in runs.items():
        try:
            recorded = json.loads((folder / RUN_FILE).read_text(encoding="utf-8")).get("index_sha256")
        except (OSError, ValueError):
            recorded = None
        if recorded and recorded != digest:
            raise UsageError(
                f"run {label!r} was made on another packet store (index {recorded[:12]}…, this one "
                f"{digest[:12]}…); pass the store the runs were made on",
                packets,
            )
    return store


def recorded_store(runs: Mapping[str, Path]) -> Path | None:
    """The packet store the runs' manifests name, when it exists on this machine (else ``None``)."""
    for folder in runs.values():
        try:
            root = json.loads((folder / "manifest.json").read_text(encoding="utf-8"))["packets"]["root"]
        except (OSError, ValueError, KeyError, TypeError):
            continue
        if (Path(root) / INDEX_FILE).is_file():
            return Path(root)
    return None
