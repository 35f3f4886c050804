"""A leaderboard's inputs: the finished run folders under ``--runs`` (unfinished ones left out with a warning),
their per-target and per-sequence rows, and the paper's reported numbers (``protocols/reported/*.csv``)."""

from __future__ import annotations

import json
import warnings
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pandas as pd
import pyarrow as pa

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.distribution_scoring import COLUMNS as DISTRIBUTION_COLUMNS
from setdiff_bench.evaluation.distribution_scoring import DISTRIBUTION_FILE, DISTRIBUTION_INFO_FILE
from setdiff_bench.evaluation.run import claimed_label
from setdiff_bench.io.run_layout import MANIFEST_FILE, METRICS_FILE, PROFILES_DIR, RUN_FILE, SEQUENCES_FILE
from setdiff_bench.protocols import Layout
from setdiff_bench.reporting.leaderboard.columns import LeaderboardError, dataset_layout


class UnfinishedRunWarning(UserWarning):
    """A run folder left out of a table because its run has not finished (shown as one line by the CLI)."""


@dataclass(frozen=True)
class UnfinishedRun:
    """A folder claimed by ``run`` (``run.json``) whose ``manifest.json`` is not written yet: the run is still
    going, was killed, or its shards are unfinished or not merged (``merge_run`` writes the manifest last)."""

    folder: Path
    method: str | None  # the name its rows will carry (run.json's name, else method); None when unreadable

    def problem(self) -> str:
        """What is wrong and what to do (the folder is named beside it)."""
        method = f" (method {self.method})" if self.method else ""
        return (
            f"run incomplete{method}: no {MANIFEST_FILE} yet (still running, killed, or shards unfinished or "
            "not merged); finish it, or run the same `setdiff-bench run` command with --merge"
        )


def survey_runs(runs: str | Path | Sequence[str | Path]) -> tuple[list[Path], list[UnfinishedRun]]:
    """The finished run folders under ``runs`` (one folder, or several searched in turn) and the unfinished
    ones, each sorted and listed once (a run under two of the folders given, e.g. ``runs`` and ``runs/mine``,
    counts once).

    A folder with ``metrics.parquet`` is a finished run unless ``run`` claimed it (``run.json``) and has not
    written its ``manifest.json`` (the last file a run writes, atomically); a claimed folder without the
    manifest is unfinished.  Folders of other writers (evaluation profiles, tables made by hand) have no
    ``run.json`` and count when their ``metrics.parquet`` exists.

    Raises:
        UsageError: a folder of ``runs`` does not exist or is not a folder (named).
    """
    roots = [Path(runs)] if isinstance(runs, str | Path) else [Path(p) for p in runs]
    if not roots:
        raise UsageError("no runs folder given", parameter="runs")
    finished: set[Path] = set()
    unfinished: dict[Path, UnfinishedRun] = {}
    for root in roots:
        if not root.is_dir():
            raise UsageError("runs folder not found", root)
        mine = {}
        for claimed in sorted(root.rglob(RUN_FILE)):
            folder = claimed.parent
            if not (folder / MANIFEST_FILE).is_file() or not (folder / METRICS_FILE).is_file():
                mine[folder.resolve()] = UnfinishedRun(folder, claimed_label(claimed))
        skipped = {run.folder for run in mine.values()}  # with the profile tables inside them
        for path in root.rglob(METRICS_FILE):
            if skipped.isdisjoint(path.parents):
                finished.add(path.parent)
        for key, run in mine.items():
            unfinished.setdefault(key, run)
    return _once(sorted(finished)), sorted(unfinished.values(), key=lambda run: run.folder)


def _once(folders: Sequence[Path]) -> list[Path]:
    """``folders`` without a second spelling of one folder (``runs/x`` and ``./runs/x``), first kept."""
    seen: set[Path] = set()
    kept = []
    for folder in folders:
        key = folder.resolve()
        if key not in seen:
            seen.add(key)
            kept.append(folder)
    return kept


def find_runs(runs: str | Path | Sequence[str | Path], *, profiles: bool = True) -> list[Path]:
    """Every finished run folder (holding ``metrics.parquet``) under ``runs`` (one folder or several), sorted,
    each once; with ``profiles=False``
    without the evaluation profiles' tables inside runs (``<run>/profiles/<profile>/``: scores, no images).

    Unfinished runs (:func:`survey_runs`) are left out, each with an :class:`UnfinishedRunWarning` naming it.

    Raises:
        UsageError: ``runs`` is not a folder.
        LeaderboardError: every run under ``runs`` is unfinished (a table of none would say less).
    """
    finished, unfinished = survey_runs(runs)
    require_finished(finished, unfinished)
    warn_unfinished(unfinished)
    return finished if profiles else [f for f in finished if f.parent.name != PROFILES_DIR]


def require_finished(finished: Sequence[Path], unfinished: Sequence[UnfinishedRun]) -> None:
    """Refuse a runs folder whose every run is unfinished, naming the first.

    Raises:
        LeaderboardError: no finished run and at least one unfinished one.
    """
    if unfinished and not finished:
        first = unfinished[0]
        raise LeaderboardError(first.problem() + _more(len(unfinished) - 1, "unfinished run"), first.folder)


def warn_unfinished(unfinished: Sequence[UnfinishedRun]) -> None:
    """One :class:`UnfinishedRunWarning` per run left out (the CLI prints each as one line)."""
    for run in unfinished:
        warnings.warn(f"{run.folder}: left out, {run.problem()}", UnfinishedRunWarning, stacklevel=3)


def _more(count: int, what: str) -> str:
    return f" (and {count} more {what}{'s' if count > 1 else ''})" if count else ""


def load_runs(runs: str | Path | Sequence[Path]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Per-target rows and per-sequence rows of every run (a ``run`` column names the folder)."""
    folders = find_runs(runs) if isinstance(runs, str | Path) else [Path(p) for p in runs]
    images, sequences = [], []
    for folder in folders:
        try:
            rows = pd.read_parquet(folder / METRICS_FILE).assign(run=str(folder))
            refits = _refits(folder)
            if refits:  # an X 3D run (run --refit): each scene's refit, for --cost and the refit-steps plot
                for column in REFIT_COLUMNS:
                    rows[column] = rows["scene"].map({scene: r[column] for scene, r in refits.items()})
                rows["refit_s"] = rows["refit_s"].astype("float64")
                rows["refit_steps"] = rows["refit_steps"].astype("float64")
            images.append(rows)
            if (folder / SEQUENCES_FILE).is_file():
                sequences.append(pd.read_parquet(folder / SEQUENCES_FILE).assign(run=str(folder)))
        except (OSError, pa.ArrowException) as error:
            raise LeaderboardError(f"unreadable run results ({type(error).__name__})", folder) from None
    image_frame = pd.concat(images, ignore_index=True) if images else pd.DataFrame()
    sequence_frame = pd.concat(sequences, ignore_index=True) if sequences else pd.DataFrame()
    return image_frame, sequence_frame


#: The columns an ``X 3D`` run's rows get from its manifest (``run --refit``): the scene's refit wall seconds
#: (all its fits), the refit model's steps, the refit's enhancer and schedule, and the run's own enhancer
#: (``identity`` scores ``X 3D``, ``X`` scores ``X 3D+``).
REFIT_COLUMNS = ("refit_s", "refit_steps", "refit_method", "refit_schedule", "run_method")


def _refits(folder: Path) -> dict[str, dict[str, object]]:
    """Scene → :data:`REFIT_COLUMNS` of a ``run --refit`` run, from its manifest; ``{}`` for every other run (or
    a manifest that cannot be read: the run's rows still load)."""
    try:
        manifest = json.loads((folder / MANIFEST_FILE).read_text(encoding="utf-8"))
        run_method = str(manifest["method"]["id"]) if "refit" in manifest else ""
        refits: dict[str, dict[str, object]] = {}
        for key, cost in manifest.get("refit", {}).get("fits", {}).items():
            scene = key.rsplit("/", 1)[0]
            entry = refits.setdefault(
                scene,
                {
                    "refit_s": 0.0,
                    # manifests of runs made before the refit's steps were recorded: the steps it ran
                    "refit_steps": float(cost.get("refit_steps", cost["steps"])),
                    "refit_method": str(cost["method"]),
                    "refit_schedule": str(cost["schedule"]),
                    "run_method": run_method,
                },
            )
            entry["refit_s"] = float(entry["refit_s"]) + float(cost["wall_s"])  # type: ignore[arg-type]
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        return {}
    return refits


def run_names(folders: Sequence[Path]) -> dict[Path, set[str]]:
    """Each finished run folder → the names its rows carry (``metrics.parquet``'s ``method`` column: the
    method, or the name ``run --name`` gave it).

    Raises:
        LeaderboardError: a ``metrics.parquet`` that cannot be read.
    """
    names = {}
    for folder in folders:
        try:
            column = pd.read_parquet(Path(folder) / METRICS_FILE, columns=["method"])["method"]
        except (OSError, KeyError, pa.ArrowException) as error:
            raise LeaderboardError(f"unreadable run results ({type(error).__name__})", folder) from None
        names[Path(folder)] = {str(name) for name in column.unique()}
    return names


def load_distribution(folders: Sequence[Path]) -> pd.DataFrame:
    """FID / KID rows of every run folder that has them (``distribution.parquet``, written by
    ``run`` / ``evaluate --inception``), with ``run`` (the folder) and the Inception weights the run used, read
    from ``distribution.json`` beside it: ``inception_sha256`` and ``inception_file`` (the file name, when
    recorded; ``None`` otherwise).  Folders without the file contribute nothing; no folder has one: an empty
    frame with those columns.

    Raises:
        LeaderboardError: a distribution table or its ``distribution.json`` cannot be read, or lacks columns.
    """
    columns = [*DISTRIBUTION_COLUMNS, "run", "inception_sha256", "inception_file"]
    frames = []
    for folder in (Path(p) for p in folders):
        path = folder / DISTRIBUTION_FILE
        if not path.is_file():
            continue
        try:
            table = pd.read_parquet(path)
        except (OSError, pa.ArrowException) as error:
            raise LeaderboardError(f"unreadable FID / KID table ({type(error).__name__})", path) from None
        missing = [c for c in DISTRIBUTION_COLUMNS if c not in table.columns]
        if missing:
            raise LeaderboardError(f"FID / KID table lacks column(s) {', '.join(missing)}", path)
        info: dict[str, object] = {}
        info_path = folder / DISTRIBUTION_INFO_FILE
        if info_path.is_file():
            try:
                info = json.loads(info_path.read_text(encoding="utf-8"))
            except (OSError, ValueError):
                raise LeaderboardError("unreadable FID / KID settings (not JSON)", info_path) from None
            if not isinstance(info, dict):
                raise LeaderboardError("FID / KID settings are not a JSON object", info_path)
        sha, name = info.get("inception_sha256"), info.get("inception_file")
        frames.append(
            table[list(DISTRIBUTION_COLUMNS)].assign(
                run=str(folder),
                inception_sha256=sha if isinstance(sha, str) else None,
                inception_file=name if isinstance(name, str) else None,
            )
        )
    if not frames:
        return pd.DataFrame(columns=columns)
    return pd.concat(frames, ignore_index=True)[columns]


def load_reported(dataset: str | None = None, tables: Iterable[str] | None = None) -> pd.DataFrame:
    """The paper's numbers from ``protocols/reported/*.csv`` (long format).

    Columns: ``table, dataset, section, setting, group, method, method_id, metric, value`` (float),
    ``printed`` (the text as typeset), ``decimals``, ``bold`` (bold in the paper), ``source``
    (``"reported"``).  ``group`` is the protocol group the setting corresponds to (``""`` = all).
    """
    folder = resources.files("setdiff_bench.protocols") / "reported"
    frames = []
    for entry in sorted(folder.iterdir(), key=lambda e: e.name):
        if entry.name.endswith(".csv"):
            with entry.open() as handle:
                frames.append(pd.read_csv(handle, dtype=str, keep_default_na=False))
    frame = pd.concat(frames, ignore_index=True)
    if dataset is not None:
        frame = frame[frame["dataset"] == dataset]
    if tables is not None:
        frame = frame[frame["table"].isin(list(tables))]
    frame = frame.rename(columns={"value": "printed"}).reset_index(drop=True)
    frame["value"] = frame["printed"].astype(float)
    frame["decimals"] = frame["printed"].map(lambda text: len(text.split(".")[1]) if "." in text else 0)
    frame["bold"] = frame["bold"] == "1"
    frame["source"] = "reported"
    return frame


def reported_for(dataset: str, layout: Layout | None = None) -> pd.DataFrame:
    """The reported rows the dataset's layout mixes in (empty when the paper has none)."""
    layout = layout or dataset_layout(dataset)
    if not layout.reported_tables:
        return load_reported(dataset).iloc[0:0]
    return load_reported(dataset, layout.reported_tables)
