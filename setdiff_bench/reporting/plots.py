"""Metric-vs-distance plots (matplotlib, Agg): nuScenes time buckets (the paper's per-offset figure), lane
shift (Para-Lane single/double, synthetic lane +1/+2) and DL3DV's view count (n3/n6/n9).

Each point is a method's mean of per-image values over the targets of one group, with an error bar
of ±1 standard error of that mean (``std / sqrt(n)``, ddof 1).  The x position of a group comes from
its name: ``10-11s`` → the bucket's start offset 10 s (label "10–11 s"); ``single``/``double`` → 1/2
lanes, ``lane+K`` → K, ``interp`` → 0; ``nK`` → K fit views.  Groups without a position are left out of that plot.

:func:`plot_refit_steps` draws the ``X 3D`` / ``X 3D+`` rows (``run --refit``, docs/refit.md) against the refit
model's steps: one panel per group and metric, plus the warp error when the runs scored it.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import atomic_path
from setdiff_bench.reporting.leaderboard import higher_is_better, metric_header

_BUCKET = re.compile(r"^(\d+(?:\.\d+)?)-(\d+(?:\.\d+)?)s$")
_LANE = re.compile(r"^lane\+(\d+)$")
_VIEWS = re.compile(r"^n(\d+)$")
LANE_NAMES = {"interp": 0, "single": 1, "double": 2}


def time_bucket(group: str) -> tuple[float, str] | None:
    """``"10-11s"`` → ``(10.0, "10–11 s")``; ``None`` for other names."""
    match = _BUCKET.match(group)
    if not match:
        return None
    return float(match.group(1)), f"{match.group(1)}–{match.group(2)} s"


def lane_shift(group: str) -> tuple[float, str] | None:
    """``single``/``double``/``lane+K``/``interp`` → ``(lanes, label)``; ``None`` for other names."""
    if group in LANE_NAMES:
        lanes = LANE_NAMES[group]
    elif (match := _LANE.match(group)) is not None:
        lanes = int(match.group(1))
    else:
        return None
    return float(lanes), f"{lanes:+d}" if lanes else "0"


def view_count(group: str) -> tuple[float, str] | None:
    """``"n3"`` (the 3DGS fitted on 3 views, DL3DV's groups) → ``(3.0, "3")``; ``None`` for other names."""
    match = _VIEWS.match(group)
    if not match:
        return None
    return float(match.group(1)), match.group(1)


def mean_and_error(values: np.ndarray) -> tuple[float, float, int]:
    """``(mean, standard error of the mean, count)`` of the finite ``values`` (error ``std / sqrt(n)``, ddof 1;
    0 for one value; mean NaN for none)."""
    values = values[np.isfinite(values)]
    sem = float(values.std(ddof=1) / np.sqrt(len(values))) if len(values) > 1 else 0.0
    return (float(values.mean()) if len(values) else np.nan), sem, len(values)


def group_summary(
    images: pd.DataFrame, metric: str, position: Callable[[str], tuple[float, str] | None]
) -> pd.DataFrame:
    """Per (method, group with a position): x, label, mean, standard error, count of ``metric``."""
    records = []
    for (method, group), rows in images.groupby(["method", "group"], sort=True):
        where = position(str(group))
        if where is None:
            continue
        mean, sem, count = mean_and_error(rows[metric].to_numpy(dtype=np.float64))
        records.append(
            {
                "method": method,
                "group": group,
                "x": where[0],
                "label": where[1],
                "mean": mean,
                "sem": sem,
                "count": count,
            }
        )
    return pd.DataFrame.from_records(
        records, columns=["method", "group", "x", "label", "mean", "sem", "count"]
    )


def error_bar_caption(summary: pd.DataFrame) -> str:
    """What the points and bars of a plot are, with the number of targets behind each point."""
    counts = summary.loc[summary["count"] > 0, "count"]
    n = f"n = {counts.min()}" if counts.min() == counts.max() else f"n = {counts.min()}–{counts.max()}"
    return (
        f"points: mean over the targets of a group ({n} per point); error bars: ±1 standard error of the mean"
    )


def plot_metric_by_group(
    images: pd.DataFrame,
    out: str | Path,
    *,
    position: Callable[[str], tuple[float, str] | None],
    xlabel: str,
    metrics: Sequence[str] = ("psnr", "ssim", "lpips"),
    title: str = "",
    methods: Sequence[str] | None = None,
) -> Path:
    """One panel per metric, one line per method, x = group position; saved as PNG at ``out``.

    Args:
        images: per-target rows of runs (``metrics.parquet`` columns).
        out: the PNG to write (atomically).
        position: group name → ``(x, tick label)`` or ``None``.
        xlabel: axis label.
        metrics: metric columns, one panel each.
        methods: methods to draw, in legend order (default: all, sorted).

    Raises:
        UsageError: no group of ``images`` has a position, or a metric column is missing.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    missing = [m for m in metrics if m not in images.columns]
    if missing:
        raise UsageError(f"no metric column(s) {', '.join(missing)} in the runs")
    methods = list(methods) if methods is not None else sorted(images["method"].unique())
    frame = images[images["method"].isin(methods)]
    summaries = {metric: group_summary(frame, metric, position) for metric in metrics}
    if all(s.empty for s in summaries.values()):
        raise UsageError(
            f"no group of these runs has a position on the {xlabel!r} axis "
            f"(groups: {', '.join(sorted(images['group'].unique()))})"
        )
    figure, axes = plt.subplots(1, len(metrics), figsize=(4.2 * len(metrics), 3.4), squeeze=False)
    for axis, metric in zip(axes[0], metrics):
        summary = summaries[metric]
        for method in methods:
            own = summary[summary["method"] == method].sort_values("x")
            if own.empty:
                continue
            axis.errorbar(own["x"], own["mean"], yerr=own["sem"], marker="o", capsize=3, label=method)
        ticks = summary.drop_duplicates("x").sort_values("x")
        axis.set_xticks(ticks["x"].to_numpy(), ticks["label"].tolist())
        arrow = "↑" if higher_is_better(metric) else "↓"
        axis.set_title(f"{metric_header(metric)} {arrow}")
        axis.set_xlabel(xlabel)
        axis.grid(alpha=0.3)
    axes[0][0].legend(fontsize="small")
    return _save(figure, out, title, error_bar_caption(pd.concat(list(summaries.values()))), 0.06)


def _save(figure: Any, out: str | Path, title: str, caption: str, bottom: float) -> Path:
    """Title ``figure``, put ``caption`` under its panels (``bottom``: the share of its height kept for it) and
    write it as PNG at ``out``, atomically; the figure is closed."""
    import matplotlib.pyplot as plt

    if title:
        figure.suptitle(title)
    figure.text(0.5, 0.01, caption, ha="center", va="bottom", fontsize="small")
    figure.tight_layout(rect=(0.0, bottom, 1.0, 1.0))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out) as tmp:
        figure.savefig(tmp, dpi=120, format="png", metadata={"Software": "setdiff-bench"})
    plt.close(figure)
    return out


def plot_time_buckets(images: pd.DataFrame, out: str | Path, **kwargs: object) -> Path:
    """Metric vs nuScenes time bucket (seconds after the start of the scene): the paper's per-offset figure."""
    return plot_metric_by_group(images, out, position=time_bucket, xlabel="time after scene start", **kwargs)  # type: ignore[arg-type]


def plot_lane_shift(images: pd.DataFrame, out: str | Path, **kwargs: object) -> Path:
    """Metric vs lateral lane shift of the target from the fitted lane."""
    return plot_metric_by_group(images, out, position=lane_shift, xlabel="lane shift", **kwargs)  # type: ignore[arg-type]


def plot_view_count(images: pd.DataFrame, out: str | Path, **kwargs: object) -> Path:
    """Metric vs the number of views the 3DGS was fitted on (DL3DV's sparse-view groups, paper Table 4)."""
    return plot_metric_by_group(images, out, position=view_count, xlabel="fit views", **kwargs)  # type: ignore[arg-type]


def refit_curves(images: pd.DataFrame) -> pd.DataFrame:
    """Per run: the refit curve it belongs to and its x position, for :func:`plot_refit_steps`.

    A ``run --refit`` run is a point of the curve ``"<X> 3D"`` (scored with ``identity``) or ``"<X> 3D+"``
    (scored with ``X``), ``X`` the refit's enhancer (with its schedule in brackets when the runs hold more than
    one), at x = the refit model's steps.  A run without a refit is the curve's point at x = 0 (a refit of 0 steps is the
    fit itself): the one named ``identity`` for every ``3D`` curve, the one named ``X`` for ``X 3D+``.

    Returns:
        Columns ``run``, ``enhancer`` (``X``, with the schedule when there are several), ``kind`` (``3D`` or
        ``3D+``) and ``x``, one row per (run, curve): a 0-step run may open several curves; empty when no run
        scores a refit.
    """
    columns = ["run", "enhancer", "kind", "x"]
    if "refit_steps" not in images.columns:
        return pd.DataFrame(columns=columns)
    refitted = images.dropna(subset=["refit_steps"]).drop_duplicates("run")
    plain = images[images["refit_steps"].isna()].groupby("method")["run"].unique()
    schedules = refitted["refit_schedule"].nunique() > 1
    records = []
    for row in refitted.itertuples():
        kind = "3D" if row.run_method == "identity" else "3D+"
        enhancer = f"{row.refit_method}" + (f" ({row.refit_schedule})" if schedules else "")
        records.append({"run": row.run, "enhancer": enhancer, "kind": kind, "x": float(row.refit_steps)})
        origin = "identity" if kind == "3D" else str(row.refit_method)
        runs = plain.get(origin, [])
        records.extend({"run": run, "enhancer": enhancer, "kind": kind, "x": 0.0} for run in runs)
    return pd.DataFrame.from_records(records, columns=columns).drop_duplicates()


def plot_refit_steps(
    images: pd.DataFrame,
    out: str | Path,
    *,
    sequences: pd.DataFrame | None = None,
    metrics: Sequence[str] = ("psnr", "ssim", "lpips"),
    title: str = "",
) -> Path:
    """Metric vs refit steps (:func:`refit_curves`): one row of panels per metric (and one for the warp error
    when ``sequences`` hold it for these runs), one column per group; points are means over the group's targets
    (warp: over the runs' sequences) with ±1 standard error; saved as PNG at ``out``.

    Raises:
        UsageError: no run of ``images`` is a refit (``run --refit``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    curves = refit_curves(images)
    if curves.empty:
        raise UsageError("no run here scores a refit (`run --refit`): nothing to plot against refit steps")
    refit_groups = sorted(images.dropna(subset=["refit_steps"])["group"].unique())
    panels = [(metric, group) for metric in metrics for group in refit_groups]
    warp = None
    if sequences is not None and not sequences.empty and "warp" in sequences.columns:
        warp = sequences[sequences["run"].isin(curves["run"]) & sequences["scene"].isin(images["scene"])]
        warp = warp if warp["warp"].notna().any() else None
    rows = len(metrics) + (warp is not None)
    figure, axes = plt.subplots(
        rows, len(refit_groups), figsize=(4.0 * len(refit_groups), 3.0 * rows), squeeze=False
    )

    # one colour per enhancer (and schedule), solid for X 3D, dashed for X 3D+
    colours = {enhancer: f"C{i % 10}" for i, enhancer in enumerate(sorted(curves["enhancer"].unique()))}

    def draw(axis, values_of) -> None:  # type: ignore[no-untyped-def]
        for (enhancer, kind), points in curves.groupby(["enhancer", "kind"], sort=True):
            summary = [
                (x, *mean_and_error(values_of(runs["run"]))) for x, runs in points.groupby("x", sort=True)
            ]
            summary = [point for point in summary if point[3]]  # steps with a finite value
            if summary:
                plus = kind == "3D+"
                axis.errorbar(
                    [point[0] for point in summary],
                    [point[1] for point in summary],
                    yerr=[point[2] for point in summary],
                    marker="s" if plus else "o",
                    linestyle="--" if plus else "-",
                    color=colours[enhancer],
                    capsize=3,
                    label=f"{enhancer} {kind}",
                )
        axis.set_xticks(sorted(curves["x"].unique()))
        axis.set_xlabel("refit steps")
        axis.grid(alpha=0.3)

    for index, (metric, group) in enumerate(panels):
        axis = axes[index // len(refit_groups)][index % len(refit_groups)]
        in_group = images[images["group"] == group]
        draw(
            axis,
            lambda runs, rows=in_group, metric=metric: rows[rows["run"].isin(runs)][metric].to_numpy(
                np.float64
            ),
        )
        arrow = "↑" if higher_is_better(metric) else "↓"
        axis.set_title(f"{group}: {metric_header(metric)} {arrow}")
    if warp is not None:
        for column in range(len(refit_groups)):
            axis = axes[-1][column]
            if column:
                axis.axis("off")
                continue
            draw(axis, lambda runs: warp[warp["run"].isin(runs)]["warp"].to_numpy(np.float64))
            axis.set_title("warp error ↓ (per sequence)")
    axes[0][0].legend(fontsize="small")
    caption = "mean over targets (warp: sequences), ±1 s.e.;\n0 steps: the fit itself"
    return _save(figure, out, title, caption, 0.05)


#: Plots :func:`write_plots` makes per dataset: (file suffix, plotting function).
PLOTS: dict[str, tuple[str, Callable[..., Path]]] = {
    "dl3dv": ("view_count", plot_view_count),
    "nuscenes": ("time_buckets", plot_time_buckets),
    "paralane": ("lane_shift", plot_lane_shift),
    "synthetic": ("lane_shift", plot_lane_shift),
}


def write_plots(
    dataset: str,
    images: pd.DataFrame,
    out: str | Path,
    *,
    split: str | None = "test",
    metrics: Sequence[str] = ("psnr", "ssim", "lpips"),
    sequences: pd.DataFrame | None = None,
    refit_steps: bool = True,
) -> list[Path]:
    """The dataset's standard plots (:data:`PLOTS`) into ``out``, and with ``refit_steps``
    ``<dataset>_refit_steps.png`` (:func:`plot_refit_steps`, with the warp error of ``sequences``) when some run
    scores a refit; ``[]`` when there is nothing to plot."""
    frame = images[images["dataset"] == dataset] if "dataset" in images.columns else images
    if split is not None and not frame.empty:
        frame = frame[frame["split"] == split]
    if frame.empty:
        return []
    written = []
    if dataset in PLOTS:
        suffix, plot = PLOTS[dataset]
        written.append(plot(frame, Path(out) / f"{dataset}_{suffix}.png", metrics=metrics, title=dataset))
    if refit_steps and not refit_curves(frame).empty:
        runs = (
            sequences if sequences is None or sequences.empty else sequences[sequences["dataset"] == dataset]
        )
        written.append(
            plot_refit_steps(
                frame,
                Path(out) / f"{dataset}_refit_steps.png",
                sequences=runs,
                metrics=metrics,
                title=dataset,
            )
        )
    return written
