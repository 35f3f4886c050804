"""The report site's index page (``index.html``) body: the leaderboards, the plots with their captions, the
per-scene breakdown with paired intervals, the damage table (on how many targets each method is worse than
the baseline), every target in a table sortable by any column (target and group by name, the rest by
value), and the runs."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from setdiff_bench.reporting.leaderboard import Leaderboard, metric_decimals, metric_header
from setdiff_bench.reporting.plots import PLOTS
from setdiff_bench.reporting.site._html import cell_class, esc, leaderboard_html, metric_label, number, signed
from setdiff_bench.reporting.site._targets import TargetRecord, target_gain


def targets_table_html(
    records: Sequence[TargetRecord],
    methods: Sequence[str],
    metrics: Sequence[str],
    baseline: str | None,
    *,
    with_pages: bool,
    thumbnail: str = "thumb.jpg",
) -> str:
    """Every target as a row: its thumbnail (``images/<target>/<thumbnail>``) and link, its group, the
    baseline's values, and each method's gain (or, without a baseline, value) per metric.  Every column sorts
    on a click (target and group by name, in natural order; the rest by value).  The rows start sorted by
    the first compared method's gain on the first metric, largest loss first, and that column is marked
    (``asc``, ``aria-sort``), so damage shows at the top and the reader sees why."""
    compared = [m for m in methods if m != baseline]
    sorted_by = (compared[0], metrics[0]) if baseline and compared and metrics else None

    def numeric(label: str, method: str, metric: str) -> str:
        if (method, metric) == sorted_by:
            return f'<th class="sortable asc" aria-sort="ascending">{esc(label)}</th>'
        return f'<th class="sortable">{esc(label)}</th>'

    head = [
        '<th class="l sortable" data-type="text">target</th>',
        '<th class="l sortable" data-type="text">group</th>',
    ]
    if baseline:
        head += [numeric(f"{baseline} {metric_label(m)}", baseline, m) for m in metrics]
        head += [
            numeric(f"{method} {metric_label(m, ' gain', arrow=False)}", method, m)
            for method in compared
            for m in metrics
        ]
    else:
        head += [numeric(f"{method} {metric_label(m)}", method, m) for method in compared for m in metrics]

    def sort_key(record: TargetRecord) -> float:
        if sorted_by is None or baseline is None:
            return 0.0
        value = target_gain(record, sorted_by[0], sorted_by[1], baseline)
        return value if math.isfinite(value) else math.inf

    rows = []
    for record in sorted(records, key=sort_key):
        name = f"{record.scene} / {record.frame}"
        link = (
            f'<a href="targets/{record.slug}.html"><img class="thumb" loading="lazy" alt="" '
            f'src="images/{record.slug}/{esc(thumbnail)}"> {esc(name)}</a>'
            if with_pages
            else esc(name)
        )
        cells = [
            f'<td class="l" data-v="{esc(name)}">{link}</td>',
            f'<td class="l" data-v="{esc(record.group)}">{esc(record.group)}</td>',
        ]
        if baseline:
            for m in metrics:
                value = record.values.get(baseline, {}).get(m, float("nan"))
                cells.append(f'<td data-v="{value}">{number(value, metric_decimals(m))}</td>')
            for method in compared:
                for m in metrics:
                    value = target_gain(record, method, m, baseline)
                    cells.append(
                        f'<td data-v="{value}"{cell_class(value)}>{signed(value, metric_decimals(m))}</td>'
                    )
        else:
            for method in compared:
                for m in metrics:
                    value = record.values.get(method, {}).get(m, float("nan"))
                    cells.append(f'<td data-v="{value}">{number(value, metric_decimals(m))}</td>')
        rows.append(f"<tr>{''.join(cells)}</tr>")
    return (
        f'<table class="sortable targets"><thead><tr>{"".join(head)}</tr></thead>'
        f"<tbody>{''.join(rows)}</tbody></table>"
    )


def sort_note(methods: Sequence[str], metrics: Sequence[str], baseline: str | None) -> str:
    """What the targets table is sorted by when the page opens, in words."""
    compared = [m for m in methods if m != baseline]
    if not (baseline and compared and metrics):
        return "The table opens in target order; click a column header to sort by it (again: the other way)."
    return (
        f"The table opens sorted by {compared[0]}'s {metric_header(metrics[0])} gain, largest loss first "
        "(the column marked ▲); click any column header to sort by it (again: the other way)."
    )


def plot_caption(dataset: str, metrics: Sequence[str]) -> str:
    """The caption of ``dataset``'s plot (:data:`~setdiff_bench.reporting.plots.PLOTS`): what the axes and
    points are, with the metrics' units and directions."""
    _, plot = PLOTS[dataset]
    what = (plot.__doc__ or "").strip().split("\n")[0].rstrip(".")
    panels = ", ".join(metric_label(m) for m in metrics)
    return (
        f"{dataset}: {what}.  One panel per metric ({panels}; ↑ higher is better, ↓ lower is better), one "
        "line per method; each point is the mean over the targets of a group, its bar ±1 standard error of "
        "that mean (the number of targets is printed under the panels)."
    )


def damage_html(
    records: Sequence[TargetRecord], methods: Sequence[str], metrics: Sequence[str], baseline: str
) -> str:
    """Per method and metric: on how many targets it is worse than the baseline, and its worst loss."""
    rows = []
    for method in methods:
        if method == baseline:
            continue
        cells = [f'<td class="l">{esc(method)}</td>']
        for m in metrics:
            gains = np.array([target_gain(r, method, m, baseline) for r in records], dtype=float)
            gains = gains[np.isfinite(gains)]
            worse = int((gains < 0).sum())
            worst = float(gains.min()) if len(gains) else float("nan")
            cells.append(
                f"<td>{worse} / {len(gains)}</td><td{cell_class(worst)}>{signed(worst, metric_decimals(m))}</td>"
            )
        rows.append(f"<tr>{''.join(cells)}</tr>")
    head = "".join(
        f"<th>{esc(metric_header(m))} worse</th><th>{esc(metric_label(m, ' worst gain', arrow=False))}</th>"
        for m in metrics
    )
    return (
        f'<table class="damage"><caption>Targets each method makes worse than {esc(baseline)} (the render)'
        f'</caption><thead><tr><th class="l">Method</th>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
    )


def index_body(
    boards: Sequence[Leaderboard],
    labels: Mapping[str, Path],
    plots: Sequence[tuple[Path, str]],
    records: Sequence[TargetRecord],
    methods: Sequence[str],
    metrics: Sequence[str],
    baseline: str | None,
    with_pages: bool,
    staging: Path,
    *,
    scenes: str = "",
    thumbnail: str = "thumb.jpg",
) -> str:
    """The body of ``index.html``.

    Args:
        plots: ``(plot file, caption)`` pairs (:func:`plot_caption`; files under ``staging``, the site folder
            being written: links are relative to it).
        scenes: the per-scene breakdown's HTML (:func:`~setdiff_bench.reporting.site._scenes.scene_table_html`),
            or ``""`` for none.
        thumbnail: file name of each target's thumbnail in ``images/<target>/``.
    """
    parts = ['<h2 id="leaderboards">Leaderboards</h2>']
    parts += [leaderboard_html(board) for board in boards]
    if plots:
        parts.append('<h2 id="plots">Plots</h2><div class="strip">')
        for path, caption in plots:
            parts.append(
                f'<figure><img src="{esc(path.relative_to(staging).as_posix())}" alt="{esc(caption)}" '
                f'style="max-width:640px"><figcaption class="long">{esc(caption)}</figcaption></figure>'
            )
        parts.append("</div>")
    if scenes:
        parts.append(f'<h2 id="scenes">Per scene</h2>{scenes}')
    parts.append(f'<h2 id="targets">Targets ({len(records)})</h2>')
    if baseline:
        parts.append(damage_html(records, methods, metrics, baseline))
        parts.append(
            f'<p class="note">Gains are against {esc(baseline)} (its outputs are the render): positive = better, '
            "negative = damage, whatever the metric's direction.</p>"
        )
    parts.append(f'<p class="note">{esc(sort_note(methods, metrics, baseline))}</p>')
    if not with_pages:
        parts.append('<p class="note">No pictures: the site was built without the packet store.</p>')
    parts.append(
        targets_table_html(records, methods, metrics, baseline, with_pages=with_pages, thumbnail=thumbnail)
    )
    runs = "".join(f"<li>{esc(label)}: <code>{esc(folder)}</code></li>" for label, folder in labels.items())
    parts.append(f"<h2>Runs</h2><ul>{runs}</ul>")
    return "".join(parts)
