"""Publish a finished demo run: replace a results folder by the run's outputs, whole and at once.

``setdiff-bench demo`` writes to a scratch folder; the project's published results (e.g.
``results/synthetic/``) change only through :func:`publish`:

* the run must be complete (``demo.json`` is written last) and its demo outputs unchanged since (their
  SHA-256 are in ``demo.json``); files added to the run folder afterwards (an analysis written there
  on purpose) are published too and marked so in the provenance;
* the code must be committed (the recorded git revision is then the code that made every number),
  unless ``allow_dirty``;
* the new folder is built beside the destination, with ``provenance.json`` (revision, command, seed,
  torch threads, versions, and every file with its SHA-256 and origin), then swapped in with one
  ``renameat2(RENAME_EXCHANGE)`` where Linux offers it (else two renames), and the old folder deleted:
  no stale file of an earlier run survives, and a reader never sees a mix.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import sha256_file, staged_folder, write_text_atomic
from setdiff_bench.pipeline.demo import REPORT_FILE, SUMMARY_FILE

#: The provenance manifest written into a published folder.
PROVENANCE_FILE = "provenance.json"


def run_files(run: Path) -> list[Path]:
    """The files a run publishes: every regular, non-hidden file directly in ``run`` (not ``work/``)."""
    return sorted(p for p in run.iterdir() if p.is_file() and not p.name.startswith("."))


def check_run(run: Path, *, allow_dirty: bool = False) -> dict[str, Any]:
    """The run's ``demo.json`` after checking that the run is complete, unchanged and from committed code.

    Raises:
        UsageError: no finished run there, an output changed since the demo, or uncommitted code.
    """
    summary_path = run / SUMMARY_FILE
    if not summary_path.is_file():
        raise UsageError(
            f"no finished demo run here (no {SUMMARY_FILE}; it is written when the demo completes)", run
        )
    try:
        summary = json.loads(summary_path.read_text(encoding="utf-8"))
        recorded: dict[str, str] = summary["files"]
        git = summary["provenance"]["git"]
    except (OSError, json.JSONDecodeError, KeyError, TypeError) as error:
        raise UsageError(
            f"unreadable or pre-provenance demo summary ({type(error).__name__}); rerun the demo",
            summary_path,
        ) from None
    for name, digest in recorded.items():
        path = run / name
        if not path.is_file():
            raise UsageError(f"output {name} of the demo is missing", path)
        if sha256_file(path) != digest:
            raise UsageError(f"output {name} changed after the demo wrote it; rerun the demo", path)
    if git.get("revision") is None:
        raise UsageError("the run records no git revision (not run from a git checkout)", summary_path)
    if git.get("dirty") and not allow_dirty:
        raise UsageError(
            f"the run was made with uncommitted changes on {git['revision'][:12]}; commit and rerun, "
            "or pass --allow-dirty (recorded as dirty)",
            summary_path,
        )
    return summary


def provenance_manifest(
    run: Path, summary: dict[str, Any], files: list[Path], command: str
) -> dict[str, Any]:
    """``provenance.json``: the run's provenance and every published file with its SHA-256 and origin."""
    recorded = summary["files"]
    entries = {}
    for path in files:
        origin = (
            "demo" if path.name in recorded or path.name in (SUMMARY_FILE,) else "added to the run folder"
        )
        entries[path.name] = {"sha256": sha256_file(path), "origin": origin}
    return {
        "run_command": summary["invocation"],
        "published_with": command,
        "published_from": str(run),
        **summary["provenance"],
        "files": entries,
    }


def publish(
    run: str | os.PathLike[str],
    destination: str | os.PathLike[str],
    *,
    command: str,
    allow_dirty: bool = False,
) -> dict[str, Any]:
    """Replace ``destination`` by the files of the finished demo run ``run``; returns the provenance written.

    Args:
        run: the demo's ``--out`` folder.
        destination: the published folder (created if absent, else replaced whole).
        command: the publishing command line (recorded).
        allow_dirty: publish a run made with uncommitted code (recorded as such).

    Raises:
        UsageError: see :func:`check_run`; ``destination`` inside ``run`` or the other way round.
    """
    run, destination = Path(run), Path(destination)
    if not run.is_dir():
        raise UsageError("run folder not found", run)
    if (
        run.resolve() == destination.resolve()
        or destination.resolve().is_relative_to(run.resolve())
        or run.resolve().is_relative_to(destination.resolve())
    ):
        raise UsageError("the published folder and the run folder must be separate", destination)
    summary = check_run(run, allow_dirty=allow_dirty)
    files = run_files(run)
    if (run / REPORT_FILE) not in files:
        raise UsageError(f"the run has no {REPORT_FILE}", run)
    with staged_folder(destination) as staging:
        for path in files:
            shutil.copyfile(path, staging / path.name)
        manifest = provenance_manifest(run, summary, files, command)
        write_text_atomic(staging / PROVENANCE_FILE, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    return manifest
