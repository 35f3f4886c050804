"""The report site's index page (``index.html``) body: the leaderboards, the plots, the damage table (on
how many targets each method is worse than the baseline), every target in a table sortable by each
method's gain, and the runs."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from setdiff_bench.reporting.leaderboard import Leaderboard, metric_arrow, metric_decimals, metric_header
from setdiff_bench.reporting.site_html import cell_class, esc, leaderboard_html, number, signed
from setdiff_bench.reporting.site_targets import TargetRecord, target_gain


def targets_table_html(
    records: Sequence[TargetRecord],
    methods: Sequence[str],
    metrics: Sequence[str],
    baseline: str | None,
    *,
    with_pages: bool,
) -> str:
    """Every target as a row: its render thumbnail and link, the baseline's values, and each method's gain
    (or, without a baseline, value) per metric; every numeric column sorts on a click.  The rows start
    sorted by the first method's gain on the first metric, worst first, so damage shows at the top."""
    compared = [m for m in methods if m != baseline]
    head = ['<th class="l">target</th>', '<th class="l">group</th>']
    if baseline:
        head += [
            f'<th class="sortable">{esc(baseline)} {esc(metric_header(m))}{esc(metric_arrow(m, False))}</th>'
            for m in metrics
        ]
        head += [
            f'<th class="sortable">{esc(method)} {esc(metric_header(m))} gain</th>'
            for method in compared
            for m in metrics
        ]
    else:
        head += [
            f'<th class="sortable">{esc(method)} {esc(metric_header(m))}{esc(metric_arrow(m, False))}</th>'
            for method in compared
            for m in metrics
        ]

    def sort_key(record: TargetRecord) -> float:
        if not (baseline and compared and metrics):
            return 0.0
        value = target_gain(record, compared[0], metrics[0], baseline)
        return value if math.isfinite(value) else math.inf

    rows = []
    for record in sorted(records, key=sort_key):
        name = esc(f"{record.scene} / {record.frame}")
        link = (
            f'<a href="targets/{record.slug}.html"><img class="thumb" loading="lazy" alt="" '
            f'src="images/{record.slug}/render.png"> {name}</a>'
            if with_pages
            else name
        )
        cells = [f'<td class="l">{link}</td>', f'<td class="l">{esc(record.group)}</td>']
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
        f"<th>{esc(metric_header(m))} worse</th><th>{esc(metric_header(m))} worst gain</th>" for m in metrics
    )
    return (
        f'<table class="damage"><caption>Targets each method makes worse than {esc(baseline)} (the render)'
        f'</caption><thead><tr><th class="l">Method</th>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
    )


def index_body(
    boards: Sequence[Leaderboard],
    labels: Mapping[str, Path],
    plots: Sequence[Path],
    records: Sequence[TargetRecord],
    methods: Sequence[str],
    metrics: Sequence[str],
    baseline: str | None,
    with_pages: bool,
    staging: Path,
) -> str:
    """The body of ``index.html`` (``staging``: the site folder being written, plot links are relative to it)."""
    parts = ['<h2 id="leaderboards">Leaderboards</h2>']
    parts += [leaderboard_html(board) for board in boards]
    if plots:
        parts.append('<h2 id="plots">Plots</h2><div class="strip">')
        parts += [
            f'<figure><img src="{esc(p.relative_to(staging).as_posix())}" alt="{esc(p.stem)}" '
            f'style="max-width:640px"><figcaption>{esc(p.stem)}</figcaption></figure>'
            for p in plots
        ]
        parts.append("</div>")
    parts.append(f'<h2 id="targets">Targets ({len(records)})</h2>')
    if baseline:
        parts.append(damage_html(records, methods, metrics, baseline))
        parts.append(
            f'<p class="note">Gains are against {esc(baseline)} (its outputs are the render): positive = better, '
            "negative = damage, whatever the metric's direction.  Click a column to sort; the table starts "
            "with the largest loss of the first method.</p>"
        )
    if not with_pages:
        parts.append('<p class="note">No pictures: the site was built without the packet store.</p>')
    parts.append(targets_table_html(records, methods, metrics, baseline, with_pages=with_pages))
    runs = "".join(f"<li>{esc(label)}: <code>{esc(folder)}</code></li>" for label, folder in labels.items())
    parts.append(f"<h2>Runs</h2><ul>{runs}</ul>")
    return "".join(parts)
