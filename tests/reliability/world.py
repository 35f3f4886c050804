"""Inputs shared by the reliability tests, built once per session and copied before any case changes them.

* ``street``: one scene of the packet tests' street world (synthetic layout, COLMAP binary, masks,
  ``scene.json``, a fit PLY under ``street_00/fits/lane0.ply``) — ``prepare``'s input;
* ``store``: the run tests' analytic packet store (one scene, two packets of two references and three
  targets, split ``test``) — ``run``'s input;
* ``train_store``: the same store with split ``train`` — ``train``'s input;
* ``setdiff_run``: a ``train`` output folder holding one tiny SetDiff checkpoint (``latest``,
  ``model.safetensors``, ``optimizer.pt``, ``trainer.json``), built on first use (diffusers import ~5 s).

Also the ``run`` command line the tests give, and small helpers that change one thing in a copy: rewrite
packet index rows, re-hash a packet's files.
"""

from __future__ import annotations

import functools
import shutil
import stat
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pyarrow.parquet as pq
import torch

from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.packets.index import FILE_COLUMNS, INDEX_FILE, PACKETS_DIR, merge_index, write_rows
from setdiff_bench.runtime.threads import torch_threads
from tests.evaluation.run.store_fixtures import StoreSpec, build_store
from tests.packets.packet_fixtures import write_dataset

STREET_SCENE = "street_00"


@dataclass
class World:
    """Pristine session inputs (never modified: a case copies what it changes)."""

    base: Path

    @functools.cached_property
    def street(self) -> Path:
        root = self.base / "street"
        with torch_threads(1):
            write_dataset(root, seeds=(11,))
        return root

    @functools.cached_property
    def store(self) -> Path:
        with torch_threads(1):
            return build_store(self.base / "store", StoreSpec(scenes=("scene_a",)))

    @functools.cached_property
    def train_store(self) -> Path:
        with torch_threads(1):
            return build_store(self.base / "train_store", StoreSpec(scenes=("scene_a",), split="train"))

    @functools.cached_property
    def setdiff_run(self) -> Path:
        """A training output folder of the packaged ``tiny_setdiff`` config after one (fake) step."""
        from setdiff_bench.models.setdiff.checkpoint import mark_latest, save_checkpoint, step_folder
        from setdiff_bench.models.setdiff.config_io import load_config
        from setdiff_bench.models.setdiff.model import SetDiffModel

        out = self.base / "setdiff_run"
        config = load_config("tiny_setdiff")
        with torch_threads(1):
            torch.manual_seed(0)
            model = SetDiffModel(config.model, load_pretrained=False)
            optimizer = torch.optim.AdamW(model.trainable_parameters(), lr=1e-3)
            folder = save_checkpoint(step_folder(out, 1), model, config, optimizer=optimizer, step=1)
        mark_latest(out, folder, keep=1)
        return out

    @property
    def fit_ply(self) -> Path:
        return self.street / STREET_SCENE / "fits" / "lane0.ply"

    @property
    def shared(self) -> list[Path]:
        """The pristine inputs built so far (checked unchanged after every case)."""
        return [
            self.base / name
            for name in ("street", "store", "train_store", "setdiff_run")
            if (self.base / name).exists()
        ]


def run_argv(
    store: Path, out: Path, *extra: str, method: str = "identity", metrics: str = "psnr"
) -> list[str]:
    """``setdiff-bench run`` arguments on ``store`` into ``out``: CPU, no progress, no warp cache, then ``extra``."""
    return [
        "run",
        "--method",
        method,
        "--packets",
        str(store),
        "--out",
        str(out),
        "--device",
        "cpu",
        "--no-progress",
        "--metrics",
        metrics,
        "--warp-cache",
        "none",
        *extra,
    ]


def copy(source: Path, destination: Path) -> Path:
    shutil.copytree(source, destination, symlinks=True)
    return destination


def first_packet(store: Path) -> Path:
    """The packet folder ``run`` enhances first (sorted ids)."""
    return sorted(p for p in (store / PACKETS_DIR).iterdir() if not p.name.startswith("."))[0]


def edit_rows(
    store: Path, packet: Path, edit: Callable[[list[dict[str, Any]]], Iterable[dict[str, Any]]]
) -> None:
    """Rewrite a packet's fragment rows with ``edit`` and merge the store index again."""
    rows = pq.read_table(packet / INDEX_FILE).to_pylist()
    write_rows(packet / INDEX_FILE, list(edit(rows)))
    merge_index(store)


def rehash(store: Path, packet: Path) -> None:
    """Record the current SHA-256 of every file of ``packet`` (as if ``prepare`` had written them)."""

    def update(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
        for row in rows:
            for column in FILE_COLUMNS:
                if row[column]:
                    row[f"{column}_sha256"] = sha256_file(store / row[column])
        return rows

    edit_rows(store, packet, update)


def tree_state(roots: Iterable[Path]) -> dict[str, tuple[str, int, int]]:
    """Every entry under ``roots`` (hidden ones included): path → (kind, size, mtime_ns)."""
    state: dict[str, tuple[str, int, int]] = {}
    for root in roots:
        if not root.exists():
            continue
        for path in [root, *sorted(root.rglob("*"))]:
            try:
                info = path.lstat()
            except FileNotFoundError:  # removed while listing (a writer's temporary file)
                continue
            kind = "dir" if stat.S_ISDIR(info.st_mode) else "file"
            state[str(path)] = (
                kind,
                info.st_size if kind == "file" else 0,
                info.st_mtime_ns if kind == "file" else 0,
            )
    return state
