"""A static HTML site of finished runs, browsed from the file system: no server, no network, no CDN.

Pages (every stylesheet and script inline, every link relative)::

    index.html                 leaderboards (one per dataset and evaluation profile, blocks = groups, and the
                               cost block: ms per frame, peak memory), the dataset's plots, and every target in a
                               table sortable by each method's gain or loss against the render
    videos.html                render | method | ground truth per camera sequence (WebM, VP9)
    targets/<target>.html      render | each method | ground truth, a before/after slider per method,
                               error maps |image − GT|, the target's metrics
    images/<target>/*.png      the pictures those pages show
    plots/*.png, videos/*.webm

The tables come from :func:`setdiff_bench.reporting.leaderboard.build_leaderboard` (the same aggregation,
refusals and bold-best as ``setdiff-bench leaderboard``), the plots from
:func:`setdiff_bench.reporting.plots.write_plots`.  The *baseline* (default ``identity``: its outputs are the
3DGS render) is what gains are measured against: per target, ``method − baseline`` for metrics where higher
is better and ``baseline − method`` where lower is, so a negative gain is damage in every column.

Pictures and videos need the packet store the runs were made on (``packets``; its ``index.parquet`` must be
the one the runs recorded); without one the site has the tables, plots and per-target metrics only.  The
site is built in a staging folder beside ``out`` and renamed into place when complete.
"""

from __future__ import annotations

import html
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.evaluation.profiles import DEFAULT_PROFILE, PROFILE_COLUMN
from setdiff_bench.io.atomic import sha256_file, staged_folder
from setdiff_bench.io.images import write_png
from setdiff_bench.io.run_layout import RUN_FILE
from setdiff_bench.loaders.common import natural_key
from setdiff_bench.metrics.registry import METRICS
from setdiff_bench.packets.index import INDEX_FILE
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.reporting.leaderboard import (
    Leaderboard,
    build_leaderboard,
    find_runs,
    higher_is_better,
    load_runs,
    metric_arrow,
    metric_decimals,
    metric_header,
    profile_rows,
)
from setdiff_bench.reporting.plots import write_plots
from setdiff_bench.reporting.targets import ERROR_MAP_FULL_SCALE, TargetImages, TargetKey, error_map
from setdiff_bench.reporting.video import VideoRecord, slug, target_sequences, write_videos

DEFAULT_BASELINE = "identity"
TARGET_KEY = ["packet_id", "view"]


@dataclass(frozen=True)
class SiteSettings:
    """What :func:`build_site` writes.

    Attributes:
        baseline: the method gains are measured against (its outputs are the render; ``identity``).
        split: targets of this split (``None``: all).
        fps: frames per second of the videos.
        max_width: pictures and videos wider than this are scaled down (``None``: full size).
        videos: write the sequence videos.
        command: the command that built the site, shown at the foot of each page.
    """

    baseline: str = DEFAULT_BASELINE
    split: str | None = "test"
    fps: float = 4.0
    max_width: int | None = 768
    videos: bool = True
    command: str | None = None


@dataclass
class SiteSummary:
    """What a build wrote: the site folder, its pages, videos, and notes (things left out, and why)."""

    out: Path
    pages: int = 0
    targets: int = 0
    videos: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------- inputs
def run_folders(paths: Sequence[str | Path]) -> dict[str, Path]:
    """Method label → run folder of every finished run under ``paths`` (each a run folder or a folder of
    runs).  The label is the run's method; a method found twice is labelled ``method (folder name)``.

    Raises:
        UsageError: a path that is not a folder, or no finished run at all.
    """
    folders: list[Path] = []
    for path in paths:
        for folder in find_runs(path):
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
        return str(json.loads((folder / RUN_FILE).read_text(encoding="utf-8"))["method"])
    except (OSError, ValueError, KeyError):
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


def image_metrics(frame: pd.DataFrame) -> list[str]:
    """The per-image metric columns of ``frame``, in the registry's order."""
    return [
        name
        for name, spec in METRICS.items()
        if spec.scope in ("image", "profile") and name in frame.columns and frame[name].notna().any()
    ]


def gain(metric: str, value: float, baseline: float) -> float:
    """``value`` against ``baseline`` with the sign of "better": positive helps, negative damages."""
    return value - baseline if higher_is_better(metric) else baseline - value


# ---------------------------------------------------------------------- HTML pieces
STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1d2330;background:#fafbfc}
header{background:#1d2330;color:#fff;padding:10px 24px}header a{color:#9cc3ff;margin-right:16px}
header h1{font-size:20px;margin:4px 0}main{padding:8px 24px 40px}h2{margin-top:28px;font-size:18px}
table{border-collapse:collapse;margin:8px 0;font-size:13px;background:#fff}
th,td{border:1px solid #d8dde6;padding:3px 7px;text-align:right;white-space:nowrap}
th{background:#eef1f6}td.l,th.l{text-align:left}caption{text-align:left;font-weight:600;padding:4px 0}
th.sortable{cursor:pointer}th.sortable:after{content:" \\2195";color:#889}
th.asc:after{content:" \\2191"}th.desc:after{content:" \\2193"}
.good{background:#e3f5e6}.bad{background:#fbe1e1}.note{color:#555;font-size:12px;max-width:1100px}
.strip{display:flex;flex-wrap:wrap;gap:8px}figure{margin:0;background:#fff;border:1px solid #d8dde6;padding:4px}
figcaption{font-size:12px;text-align:center}img.thumb{height:40px;vertical-align:middle}
.cmp{position:relative;display:inline-block;line-height:0;border:1px solid #d8dde6}
.cmp img{display:block;max-width:100%}.cmp .before{position:absolute;top:0;left:0}
.cmp input{position:absolute;left:0;bottom:4px;width:100%;margin:0;line-height:normal}
.cmpwrap{display:inline-block;margin:0 12px 12px 0;font-size:12px}
video{background:#000;max-width:100%}.videos{display:flex;flex-wrap:wrap;gap:8px}
footer{color:#777;font-size:12px;padding:12px 24px;border-top:1px solid #d8dde6}
"""

SORT_SCRIPT = """
document.querySelectorAll("table.sortable").forEach(function (table) {
  table.querySelectorAll("th.sortable").forEach(function (th, unused) {
    th.addEventListener("click", function () {
      var column = Array.prototype.indexOf.call(th.parentNode.children, th);
      var down = !th.classList.contains("asc");
      table.querySelectorAll("th.sortable").forEach(function (o) { o.classList.remove("asc", "desc"); });
      th.classList.add(down ? "asc" : "desc");
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      rows.sort(function (a, b) {
        var x = parseFloat(a.cells[column].dataset.v), y = parseFloat(b.cells[column].dataset.v);
        if (isNaN(x) && isNaN(y)) { return 0; }
        if (isNaN(x)) { return 1; }
        if (isNaN(y)) { return -1; }
        return down ? x - y : y - x;
      });
      rows.forEach(function (row) { body.appendChild(row); });
    });
  });
});
"""

SLIDER_SCRIPT = """
document.querySelectorAll(".cmp").forEach(function (box) {
  var before = box.querySelector(".before"), slider = box.querySelector("input");
  function show() { before.style.clipPath = "inset(0 " + (100 - slider.value) + "% 0 0)"; }
  slider.addEventListener("input", show);
  show();
});
"""


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def page(title: str, body: str, *, root: str = "", script: str = "", command: str | None = None) -> str:
    """A complete HTML page: ``title``, a navigation bar (links relative to ``root``), ``body``, and
    ``script`` inline at the end."""
    foot = f"<footer>Built by <code>{_e(command)}</code></footer>" if command else ""
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta name="viewport" content="width=device-width"><title>{_e(title)}</title>'
        f"<style>{STYLE}</style></head><body><header><h1>{_e(title)}</h1>"
        f'<a href="{root}index.html">Results</a><a href="{root}index.html#targets">Targets</a>'
        f'<a href="{root}videos.html">Videos</a></header><main>{body}</main>{foot}'
        + (f"<script>{script}</script>" if script else "")
        + "</body></html>\n"
    )


def leaderboard_html(board: Leaderboard) -> str:
    """``board`` as an HTML table: blocks (groups) as column groups, best values bold, notes below."""
    multi = len(board.columns) > 1
    head = [f'<th class="l" rowspan="{2 if multi else 1}">{_e(board.row_header)}</th>']
    metric_cells = [
        f"<th>{_e(metric_header(m) + metric_arrow(m, False))}</th>"
        for _, metrics in board.columns
        for m in metrics
    ]
    if multi:
        blocks = "".join(f'<th colspan="{len(ms)}">{_e(block.label)}</th>' for block, ms in board.columns)
        header = f"<tr>{head[0]}{blocks}</tr><tr>{''.join(metric_cells)}</tr>"
    else:
        header = f"<tr>{head[0]}{''.join(metric_cells)}</tr>"
    rows = []
    for index, row in enumerate(board.rows):
        label = row.label + (" (paper)" if row.source == "reported" else "")
        cells = [f'<td class="l">{_e(label)}</td>']
        for cell in board.cells():
            text = board.display(row, cell)
            if text is None:
                cells.append("<td>–</td>")
            elif index in board.best.get(cell, set()):
                cells.append(f"<td><b>{_e(text)}</b></td>")
            else:
                cells.append(f"<td>{_e(text)}</td>")
        rows.append(f"<tr>{''.join(cells)}</tr>")
    notes = "".join(f'<p class="note">{_e(note)}</p>' for note in board.notes)
    return (
        f'<table class="board"><caption>{_e(board.title)}</caption><thead>{header}</thead>'
        f"<tbody>{''.join(rows)}</tbody></table>{notes}"
    )


def _number(value: float, decimals: int) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.{decimals}f}"


def _signed(value: float, decimals: int) -> str:
    return "–" if not math.isfinite(value) else f"{value:+.{decimals}f}"


def _cell_class(value: float) -> str:
    if not math.isfinite(value) or value == 0:
        return ""
    return ' class="good"' if value > 0 else ' class="bad"'


# ---------------------------------------------------------------------- the targets
@dataclass(frozen=True)
class TargetRecord:
    """One target's identity and every method's metric values."""

    key: TargetKey
    dataset: str
    scene: str
    group: str
    frame: str
    slug: str
    values: dict[str, dict[str, float]]  # method label → metric → value


def target_records(
    frame: pd.DataFrame, labels: Mapping[str, Path], metrics: Sequence[str]
) -> list[TargetRecord]:
    """The targets of ``frame`` (per-image rows of the runs, one split and profile), in natural order."""
    by_run = {str(folder): label for label, folder in labels.items()}
    records = []
    ordered = frame.sort_values(["dataset", "scene", "group", "packet_id", "view"], kind="stable")
    for (packet_id, view), rows in ordered.groupby(TARGET_KEY, sort=False):
        first = rows.iloc[0]
        values = {
            by_run[str(row["run"])]: {m: float(row[m]) for m in metrics if pd.notna(row[m])}
            for _, row in rows.iterrows()
            if str(row["run"]) in by_run
        }
        name = f"{packet_id}__{int(view)}"  # packet ids are unique in a store (they name the protocol)
        records.append(
            TargetRecord(
                TargetKey(str(packet_id), int(view)),
                str(first["dataset"]),
                str(first["scene"]),
                str(first["group"]),
                str(first["frame"]),
                slug(name),
                values,
            )
        )
    return sorted(
        records, key=lambda r: (r.dataset, natural_key(r.scene), natural_key(r.group), natural_key(r.frame))
    )


def target_gain(record: TargetRecord, method: str, metric: str, baseline: str) -> float:
    """``method``'s gain over ``baseline`` on ``metric`` for this target (NaN when either is missing)."""
    mine = record.values.get(method, {}).get(metric)
    base = record.values.get(baseline, {}).get(metric)
    if mine is None or base is None:
        return float("nan")
    return gain(metric, mine, base)


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
            f'<th class="sortable">{_e(baseline)} {_e(metric_header(m))}{_e(metric_arrow(m, False))}</th>'
            for m in metrics
        ]
        head += [
            f'<th class="sortable">{_e(method)} {_e(metric_header(m))} gain</th>'
            for method in compared
            for m in metrics
        ]
    else:
        head += [
            f'<th class="sortable">{_e(method)} {_e(metric_header(m))}{_e(metric_arrow(m, False))}</th>'
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
        name = _e(f"{record.scene} / {record.frame}")
        link = (
            f'<a href="targets/{record.slug}.html"><img class="thumb" loading="lazy" alt="" '
            f'src="images/{record.slug}/render.png"> {name}</a>'
            if with_pages
            else name
        )
        cells = [f'<td class="l">{link}</td>', f'<td class="l">{_e(record.group)}</td>']
        if baseline:
            for m in metrics:
                value = record.values.get(baseline, {}).get(m, float("nan"))
                cells.append(f'<td data-v="{value}">{_number(value, metric_decimals(m))}</td>')
            for method in compared:
                for m in metrics:
                    value = target_gain(record, method, m, baseline)
                    cells.append(
                        f'<td data-v="{value}"{_cell_class(value)}>{_signed(value, metric_decimals(m))}</td>'
                    )
        else:
            for method in compared:
                for m in metrics:
                    value = record.values.get(method, {}).get(m, float("nan"))
                    cells.append(f'<td data-v="{value}">{_number(value, metric_decimals(m))}</td>')
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
        cells = [f'<td class="l">{_e(method)}</td>']
        for m in metrics:
            gains = np.array([target_gain(r, method, m, baseline) for r in records], dtype=float)
            gains = gains[np.isfinite(gains)]
            worse = int((gains < 0).sum())
            worst = float(gains.min()) if len(gains) else float("nan")
            cells.append(
                f"<td>{worse} / {len(gains)}</td><td{_cell_class(worst)}>{_signed(worst, metric_decimals(m))}</td>"
            )
        rows.append(f"<tr>{''.join(cells)}</tr>")
    head = "".join(
        f"<th>{_e(metric_header(m))} worse</th><th>{_e(metric_header(m))} worst gain</th>" for m in metrics
    )
    return (
        f'<table class="damage"><caption>Targets each method makes worse than {_e(baseline)} (the render)'
        f'</caption><thead><tr><th class="l">Method</th>{head}</tr></thead><tbody>{"".join(rows)}</tbody></table>'
    )


def target_page(
    record: TargetRecord,
    methods: Sequence[str],
    metrics: Sequence[str],
    baseline: str | None,
    *,
    previous: TargetRecord | None,
    following: TargetRecord | None,
    command: str | None,
    videos: Sequence[VideoRecord] = (),
) -> str:
    """The page of one target: pictures, sliders, error maps, metrics (images under ``../images``) and the
    ``videos`` of its camera sequence (under ``../videos``)."""
    folder = f"../images/{record.slug}"
    shown = [m for m in methods if m != baseline]
    render_label = f"3DGS render (= {baseline})" if baseline in record.values else "3DGS render"

    def figure(src: str, caption: str) -> str:
        return f'<figure><img src="{folder}/{src}" alt="{_e(caption)}"><figcaption>{_e(caption)}</figcaption></figure>'

    def psnr_of(method: str) -> str:
        value = record.values.get(method, {}).get(metrics[0]) if metrics else None
        return (
            f" — {metric_header(metrics[0])} {value:.{metric_decimals(metrics[0])}f}"
            if value is not None
            else ""
        )

    pictures = (
        figure("render.png", render_label + (psnr_of(baseline) if baseline else ""))
        + "".join(figure(f"{slug(m)}.png", m + psnr_of(m)) for m in shown)
        + figure("gt.png", "ground truth")
    )
    errors = figure("render.err.png", "|render − GT|") + "".join(
        figure(f"{slug(m)}.err.png", f"|{m} − GT|") for m in shown
    )
    sliders = "".join(
        f'<div class="cmpwrap"><div>render ◀ ▶ {_e(m)}</div><div class="cmp" data-method="{_e(m)}">'
        f'<img class="after" src="{folder}/{slug(m)}.png" alt="{_e(m)}">'
        f'<img class="before" src="{folder}/render.png" alt="render">'
        f'<input type="range" min="0" max="100" value="50" aria-label="render / {_e(m)}"></div></div>'
        for m in shown
    )
    head = "".join(f"<th>{_e(metric_header(m))}{_e(metric_arrow(m, False))}</th>" for m in metrics)
    gains = "".join(f"<th>{_e(metric_header(m))} gain</th>" for m in metrics) if baseline else ""
    rows = []
    for method in [m for m in methods if m in record.values]:
        values = record.values[method]
        cells = "".join(
            f"<td>{_number(values.get(m, float('nan')), metric_decimals(m))}</td>" for m in metrics
        )
        if baseline:
            for m in metrics:
                value = target_gain(record, method, m, baseline)
                cells += f"<td{_cell_class(value)}>{_signed(value, metric_decimals(m))}</td>"
        rows.append(f'<tr><td class="l">{_e(method)}</td>{cells}</tr>')
    nav = " ".join(
        f'<a href="{r.slug}.html">{label}</a>'
        for r, label in ((previous, "◀ previous"), (following, "next ▶"))
        if r is not None
    )
    body = (
        f"<p>{nav} · dataset {_e(record.dataset)} · packet {_e(record.key.packet_id)} target "
        f'{record.key.view}</p><div class="strip">{pictures}</div>'
        f'<h2>Before / after</h2><p class="note">Drag a slider: the render on the left of it, the method\'s '
        f"output on the right.</p>{sliders}"
        f'<h2>Error maps</h2><p class="note">Mean absolute RGB error against the ground truth; black = '
        f"none, brightest = {ERROR_MAP_FULL_SCALE:g} (on a 0–1 scale) or more, the same scale in every map."
        f'</p><div class="strip">{errors}</div>'
        f'<h2>Metrics</h2><table><thead><tr><th class="l">Method</th>{head}{gains}</tr></thead>'
        f"<tbody>{''.join(rows)}</tbody></table>"
    )
    if videos:
        position = videos[0].sequence.targets.index(record.key) + 1
        body += (
            f"<h2>Its sequence: {_e(videos[0].sequence.title)}</h2><p class='note'>This target is frame "
            f"{position} of {len(videos[0].sequence.targets)}; render | method | ground truth.</p>"
            + video_players(videos, "../videos/")
        )
    title = f"{record.scene} / {record.group} / {record.frame}"
    return page(title, body, root="../", script=SLIDER_SCRIPT, command=command)


def write_target_images(
    images: TargetImages, record: TargetRecord, methods: Sequence[str], folder: Path
) -> None:
    """The pictures of one target page: render, each method, ground truth, and their error maps."""
    folder.mkdir(parents=True, exist_ok=True)
    render, truth = images.render(record.key), images.ground_truth(record.key)
    write_png(folder / "render.png", render, atomic=False)
    write_png(folder / "gt.png", truth, atomic=False)
    write_png(folder / "render.err.png", error_map(render, truth), atomic=False)
    for method in methods:
        output = images.output(method, record.key)
        write_png(folder / f"{slug(method)}.png", output, atomic=False)
        write_png(folder / f"{slug(method)}.err.png", error_map(output, truth), atomic=False)


def video_players(videos: Sequence[VideoRecord], folder: str) -> str:
    """One player per video (files under the relative ``folder``), side by side."""
    players = "".join(
        f'<figure><video src="{folder}{_e(v.path.name)}" controls loop muted playsinline '
        f'preload="metadata" title="{_e(v.method)}"></video><figcaption>render | {_e(v.method)} | '
        f"ground truth — {v.frames} frames</figcaption></figure>"
        for v in videos
    )
    return f'<div class="videos">{players}</div>'


def videos_page(records: Sequence[VideoRecord], note: str, command: str | None) -> str:
    """``videos.html``: one row per sequence, one player per method."""
    by_sequence: dict[str, list[VideoRecord]] = {}
    for record in records:
        by_sequence.setdefault(record.sequence.title, []).append(record)
    sections = []
    for title, videos in by_sequence.items():
        sections.append(f"<h2>{_e(title)}</h2>" + video_players(videos, "videos/"))
    body = f'<p class="note">{_e(note)}</p>' + ("".join(sections) or "<p>No videos in this report.</p>")
    return page("Videos", body, command=command)


# ---------------------------------------------------------------------- the site
def build_site(
    runs: Sequence[str | Path],
    out: str | Path,
    *,
    packets: str | Path | None = None,
    settings: SiteSettings = SiteSettings(),
    video_only: bool = False,
) -> SiteSummary:
    """Write the site of the runs under ``runs`` to ``out`` (replacing it whole when complete).

    Args:
        runs: run folders, or folders of runs.
        out: the site folder.
        packets: the packet store the runs were made on (pictures, videos); ``None``: the store the runs'
            manifests name if it exists here, else tables and metrics only.
        settings: baseline, split, video rate and picture size.
        video_only: write only ``videos/`` (needs a store).

    Raises:
        UsageError: no runs, a store the runs were not made on, ``video_only`` without a store, or a baseline
            method given that no run has.
        LeaderboardError: runs that cannot be tabulated (a method missing targets another has).
    """
    labels = run_folders(runs)
    if settings.baseline and settings.baseline != DEFAULT_BASELINE and settings.baseline not in labels:
        raise UsageError(f"no run of the baseline method {settings.baseline!r} (runs: {', '.join(labels)})")
    baseline = settings.baseline if settings.baseline in labels else None
    if packets is None:
        packets = recorded_store(labels)
    store = open_store(packets, labels) if packets is not None else None
    if video_only and store is None:
        raise UsageError("videos need the packet store the runs were made on (packets)")
    images, sequences = load_runs(list(labels.values()))
    plain = profile_rows(images, DEFAULT_PROFILE)
    if settings.split is not None:
        plain = plain[plain["split"] == settings.split]
    if plain.empty:
        raise UsageError(f"the runs have no targets of split {settings.split!r}")
    methods = list(labels)
    metrics = image_metrics(plain)
    summary = SiteSummary(Path(out))
    boards = [] if video_only else _boards(images, sequences, settings)  # refusals before anything is written
    records = target_records(plain, labels, metrics)
    pictures = TargetImages(store, labels, max_width=settings.max_width) if store is not None else None
    compared = [m for m in methods if m != baseline] or methods
    with staged_folder(out) as staging:
        video_records: list[VideoRecord] = []
        video_note = (
            "Each video: the 3DGS render | the method | the ground truth, one camera's targets in order."
        )
        if pictures is not None and (settings.videos or video_only):
            video_records = write_videos(
                pictures, target_sequences(plain), compared, staging / "videos", fps=settings.fps
            )
        elif pictures is None:
            video_note = "No videos: the site was built without the packet store the runs were made on."
            summary.notes.append(
                "no pictures or videos: pass the packet store the runs were made on (--packets)"
            )
        else:
            video_note = "Videos were not asked for."
        summary.videos = [Path(out) / "videos" / r.path.name for r in video_records]
        if video_only:
            return summary
        (staging / "targets").mkdir()
        by_target: dict[TargetKey, list[VideoRecord]] = {}
        for video in video_records:
            for key in video.sequence.targets:
                by_target.setdefault(key, []).append(video)
        if pictures is not None:
            for i, record in enumerate(records):
                write_target_images(
                    pictures, record, [m for m in methods if m != baseline], staging / "images" / record.slug
                )
                page_text = target_page(
                    record,
                    methods,
                    metrics,
                    baseline,
                    previous=records[i - 1] if i else None,
                    following=records[i + 1] if i + 1 < len(records) else None,
                    command=settings.command,
                    videos=by_target.get(record.key, []),
                )
                (staging / "targets" / f"{record.slug}.html").write_text(page_text, encoding="utf-8")
            summary.pages += len(records)
        summary.targets = len(records)
        plots = []
        for dataset in sorted(set(plain["dataset"])):
            plots += write_plots(dataset, plain, staging / "plots", split=settings.split)
        index = _index_body(
            boards, labels, plots, records, methods, metrics, baseline, pictures is not None, staging
        )
        if baseline is None:
            summary.notes.append(
                f"no {settings.baseline} run: the targets table shows values, not gains against the render"
            )
        (staging / "index.html").write_text(
            page("setdiff-bench report", index, script=SORT_SCRIPT, command=settings.command),
            encoding="utf-8",
        )
        (staging / "videos.html").write_text(
            videos_page(video_records, video_note, settings.command), encoding="utf-8"
        )
        summary.pages += 2
    return summary


def _boards(images: pd.DataFrame, sequences: pd.DataFrame, settings: SiteSettings) -> list[Leaderboard]:
    """A leaderboard per dataset and evaluation profile present in the runs."""
    boards = []
    profiles = (
        sorted(set(images[PROFILE_COLUMN].fillna(DEFAULT_PROFILE)), key=lambda p: (p != DEFAULT_PROFILE, p))
        if PROFILE_COLUMN in images.columns
        else [DEFAULT_PROFILE]
    )
    for dataset in sorted(set(images["dataset"])):
        for profile in profiles:
            rows = profile_rows(images, profile)
            rows = rows[rows["dataset"] == dataset]
            if settings.split is not None:
                rows = rows[rows["split"] == settings.split]
            if rows.empty:
                continue
            boards.append(
                build_leaderboard(dataset, rows, sequences, split=settings.split, profile=profile, cost=True)
            )
    return boards


def _index_body(
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
    parts = ['<h2 id="leaderboards">Leaderboards</h2>']
    parts += [leaderboard_html(board) for board in boards]
    if plots:
        parts.append('<h2 id="plots">Plots</h2><div class="strip">')
        parts += [
            f'<figure><img src="{_e(p.relative_to(staging).as_posix())}" alt="{_e(p.stem)}" '
            f'style="max-width:640px"><figcaption>{_e(p.stem)}</figcaption></figure>'
            for p in plots
        ]
        parts.append("</div>")
    parts.append(f'<h2 id="targets">Targets ({len(records)})</h2>')
    if baseline:
        parts.append(damage_html(records, methods, metrics, baseline))
        parts.append(
            f'<p class="note">Gains are against {_e(baseline)} (its outputs are the render): positive = better, '
            "negative = damage, whatever the metric's direction.  Click a column to sort; the table starts "
            "with the largest loss of the first method.</p>"
        )
    if not with_pages:
        parts.append('<p class="note">No pictures: the site was built without the packet store.</p>')
    parts.append(targets_table_html(records, methods, metrics, baseline, with_pages=with_pages))
    runs = "".join(f"<li>{_e(label)}: <code>{_e(folder)}</code></li>" for label, folder in labels.items())
    parts.append(f"<h2>Runs</h2><ul>{runs}</ul>")
    return "".join(parts)
