"""Which rows a leaderboard averages: the dataset's rows scored under the table's profile, of its split and
methods, checked for the metric columns asked and for duplicates (:func:`select_rows`; the errors
:func:`~setdiff_bench.reporting.leaderboard.aggregate.build_leaderboard` raises about its arguments)."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.run_layout import TARGET_COLUMNS
from setdiff_bench.loaders import DATASETS
from setdiff_bench.metrics.registry import METRICS
from setdiff_bench.protocols import Layout
from setdiff_bench.protocols.profiles import DEFAULT_PROFILE, PROFILE_COLUMN, get_profile
from setdiff_bench.reporting.leaderboard.columns import LeaderboardError


def select_rows(
    dataset: str,
    images: pd.DataFrame,
    reported: pd.DataFrame | None,
    *,
    split: str | None,
    metrics: Sequence[str] | None,
    methods: Sequence[str] | None,
    layout: Layout,
    profile: str,
) -> tuple[pd.DataFrame, tuple[str, ...]]:
    """The rows of ``dataset`` a table averages (its profile, split and methods) and its image metric columns,
    checked: :func:`build_leaderboard`'s arguments and errors."""
    metric_names = tuple(metrics or layout.metrics)
    frame = images if len(images) else pd.DataFrame(columns=["dataset"])
    present = sorted(set(frame["dataset"]))
    no_reported = reported is None or not len(reported)
    if dataset not in present and dataset not in DATASETS and no_reported:
        raise UsageError(
            f"unknown dataset {dataset!r}; choose from {', '.join(DATASETS)}"
            + name_list("runs found for", present),
            "--dataset",
        )
    frame = frame[frame["dataset"] == dataset]
    spec = get_profile(profile)
    frame = profile_rows(frame, profile, dataset if no_reported else None)
    if (
        metrics is None and profile != DEFAULT_PROFILE
    ):  # the profile's metrics (+ the DINOv2 columns when scored)
        metric_names = spec.metrics + tuple(
            m
            for m, s in METRICS.items()
            if s.scope == "profile" and m in frame.columns and frame[m].notna().any()
        )
    unknown_metrics = [m for m in metric_names if m not in METRICS]
    if unknown_metrics:
        raise UsageError(
            f"unknown metric(s) {', '.join(unknown_metrics)}; known: {', '.join(METRICS)}", "--metrics"
        )
    if profile != DEFAULT_PROFILE and reported is not None and len(reported):
        raise LeaderboardError(
            f"the paper's reported numbers use the {DEFAULT_PROFILE} profile; they cannot share "
            f"a table with profile {profile} (drop --with-reported)"
        )
    if split is not None and len(frame) and spec.scenes == "split":  # "all": the profile averages every scene
        splits = sorted(set(frame["split"]))
        frame = frame[frame["split"] == split]
        if not len(frame) and no_reported:
            raise LeaderboardError(
                f"no {dataset} results of split {split!r}" + name_list("splits with results", splits)
            )
    if methods is not None and len(frame):
        unknown = sorted(set(methods) - set(frame["method"]))
        if unknown:
            raise LeaderboardError(
                f"no {dataset} runs of method(s) {', '.join(unknown)}"
                + name_list("methods with runs", sorted(set(frame["method"])))
            )
        frame = frame[frame["method"].isin(list(methods))]
    if not len(frame) and no_reported:
        raise LeaderboardError(
            f"no {dataset} results{f' of split {split}' if split else ''} to tabulate"
            + name_list("runs found for", present)
        )
    missing_columns = [m for m in metric_names if len(frame) and m not in frame.columns]
    if missing_columns:
        raise LeaderboardError(
            f"runs have no column(s) {', '.join(missing_columns)} "
            f"(they were scored with other metrics; pass --metrics)"
        )
    check_duplicates(frame)
    return frame, metric_names


def profile_rows(frame: pd.DataFrame, profile: str, dataset: str | None = None) -> pd.DataFrame:
    """The rows scored under ``profile``: plain run rows are ``paper``; a ``paper`` table written by
    ``setdiff-bench evaluate`` is used only where no plain run rows exist (they hold the same numbers).

    Raises:
        LeaderboardError: (only when ``dataset`` is given) ``frame`` holds rows of ``dataset`` but none were
            scored under ``profile`` — the runs need ``setdiff-bench evaluate`` first.
    """
    if PROFILE_COLUMN not in frame.columns:
        chosen = frame if profile == DEFAULT_PROFILE else frame.iloc[0:0]
    else:
        plain = frame[PROFILE_COLUMN].isna()
        if profile == DEFAULT_PROFILE and plain.any():
            chosen = frame[plain]
        else:
            chosen = frame[frame[PROFILE_COLUMN].fillna(DEFAULT_PROFILE) == profile]
    mine = frame["dataset"] == dataset if dataset is not None and "dataset" in frame.columns else None
    if mine is not None and mine.any() and not (chosen["dataset"] == dataset).any():
        raise LeaderboardError(
            f"no {dataset} results scored under profile {profile!r}: score the runs with "
            f"`setdiff-bench evaluate RUN --profile {profile}` first"
        )
    return chosen


def check_duplicates(frame: pd.DataFrame) -> None:
    if not len(frame):
        return
    keys = ["method", *TARGET_COLUMNS]
    duplicated = frame[frame.duplicated(keys, keep=False)]
    if len(duplicated):
        first = duplicated.iloc[0]
        runs = sorted(duplicated[(duplicated[keys] == first[keys]).all(axis=1)]["run"].unique())
        raise LeaderboardError(
            f"method {first['method']!r} has {len(duplicated)} duplicate rows, e.g. "
            f"{first['scene']}/{first['frame']} ({first['group']}) in runs {', '.join(runs)}; "
            "keep one run per method"
        )


def name_list(what: str, names: Sequence[str]) -> str:
    """``"; <what>: a, b"`` for an error message, or nothing when ``names`` is empty."""
    return f"; {what}: {', '.join(names)}" if len(names) else ""
