"""The report site's HTML pieces: the inline stylesheet and scripts (sortable tables, before/after sliders),
the page frame every page shares, a leaderboard as an HTML table, number formatting of values and gains,
and the video players (``videos.html``)."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence

from setdiff_bench.metrics.registry import METRICS
from setdiff_bench.reporting.leaderboard import Leaderboard, metric_arrow, metric_header
from setdiff_bench.reporting.site._video import VideoRecord

STYLE = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;margin:0;color:#1d2330;background:#fafbfc}
header{background:#1d2330;color:#fff;padding:10px 24px}header a{color:#9cc3ff;margin-right:16px}
header h1{font-size:20px;margin:4px 0}main{padding:8px 24px 40px}h2{margin-top:28px;font-size:18px}
table{border-collapse:collapse;margin:8px 0;font-size:13px;background:#fff}
th,td{border:1px solid #d8dde6;padding:3px 7px;text-align:right;white-space:nowrap}
th{background:#eef1f6}td.l,th.l{text-align:left}caption{text-align:left;font-weight:600;padding:4px 0}
th.sortable{cursor:pointer}th.sortable:after{content:" \\2195";color:#889}
th.asc:after{content:" \\25B2";color:#1d2330}th.desc:after{content:" \\25BC";color:#1d2330}
th.asc,th.desc{background:#dfe6f2}
.good{background:#e3f5e6}.bad{background:#fbe1e1}.note{color:#555;font-size:12px;max-width:1100px}
.strip{display:flex;flex-wrap:wrap;gap:8px}figure{margin:0;background:#fff;border:1px solid #d8dde6;padding:4px}
figcaption{font-size:12px;text-align:center}figcaption.long{text-align:left;max-width:640px}
td small{color:#555}img.thumb{height:40px;vertical-align:middle}
.cmp{position:relative;display:inline-block;line-height:0;border:1px solid #d8dde6}
.cmp img{display:block;max-width:100%}.cmp .before{position:absolute;top:0;left:0}
.cmp input{position:absolute;left:0;bottom:4px;width:100%;margin:0;line-height:normal}
.cmpwrap{display:inline-block;margin:0 12px 12px 0;font-size:12px}
video{background:#000;max-width:100%}.videos{display:flex;flex-wrap:wrap;gap:8px}
footer{color:#777;font-size:12px;padding:12px 24px;border-top:1px solid #d8dde6}
"""

SORT_SCRIPT = """
function sortValue(cell, text) {
  return text ? cell.dataset.v : parseFloat(cell.dataset.v);
}
document.querySelectorAll("table.sortable").forEach(function (table) {
  table.querySelectorAll("th.sortable").forEach(function (th) {
    th.addEventListener("click", function () {
      var column = Array.prototype.indexOf.call(th.parentNode.children, th);
      var down = !th.classList.contains("asc");
      var text = th.dataset.type === "text";
      table.querySelectorAll("th.sortable").forEach(function (o) {
        o.classList.remove("asc", "desc"); o.removeAttribute("aria-sort"); });
      th.classList.add(down ? "asc" : "desc");
      th.setAttribute("aria-sort", down ? "ascending" : "descending");
      var body = table.tBodies[0];
      var rows = Array.prototype.slice.call(body.rows);
      rows.sort(function (a, b) {
        var x = sortValue(a.cells[column], text), y = sortValue(b.cells[column], text);
        if (text) {
          var order = x.localeCompare(y, undefined, {numeric: true});
          return down ? order : -order;
        }
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


def esc(text: object) -> str:
    """``text`` escaped for HTML text and attribute values."""
    return html.escape(str(text), quote=True)


def page(title: str, body: str, *, root: str = "", script: str = "", command: str | None = None) -> str:
    """A complete HTML page: ``title``, a navigation bar (links relative to ``root``), ``body``, and
    ``script`` inline at the end."""
    foot = f"<footer>Built by <code>{esc(command)}</code></footer>" if command else ""
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        f'<meta name="viewport" content="width=device-width"><title>{esc(title)}</title>'
        f"<style>{STYLE}</style></head><body><header><h1>{esc(title)}</h1>"
        f'<a href="{root}index.html">Results</a><a href="{root}index.html#targets">Targets</a>'
        f'<a href="{root}videos.html">Videos</a></header><main>{body}</main>{foot}'
        + (f"<script>{script}</script>" if script else "")
        + "</body></html>\n"
    )


def metric_unit(metric: str) -> str:
    """The unit of ``metric``'s values (``MetricSpec.unit``: ``"dB"`` for PSNR), ``""`` for unitless ones."""
    spec = METRICS.get(metric)
    return spec.unit if spec is not None else ""


def metric_label(metric: str, suffix: str = "", *, arrow: bool = True) -> str:
    """A column header: ``"PSNR (dB)↑"``, ``"PSNR gain (dB)"`` with ``suffix=" gain", arrow=False``;
    the unit only where the metric has one."""
    unit = metric_unit(metric)
    return (
        metric_header(metric)
        + suffix
        + (f" ({unit})" if unit else "")
        + (metric_arrow(metric, False) if arrow else "")
    )


def leaderboard_html(board: Leaderboard) -> str:
    """``board`` as an HTML table: blocks (groups) as column groups, best values bold, notes below."""
    multi = len(board.columns) > 1
    head = [f'<th class="l" rowspan="{2 if multi else 1}">{esc(board.row_header)}</th>']
    metric_cells = [f"<th>{esc(metric_label(m))}</th>" for _, metrics in board.columns for m in metrics]
    if multi:
        blocks = "".join(f'<th colspan="{len(ms)}">{esc(block.label)}</th>' for block, ms in board.columns)
        header = f"<tr>{head[0]}{blocks}</tr><tr>{''.join(metric_cells)}</tr>"
    else:
        header = f"<tr>{head[0]}{''.join(metric_cells)}</tr>"
    rows = []
    for index, row in enumerate(board.rows):
        label = row.label + (" (paper)" if row.source == "reported" else "")
        cells = [f'<td class="l">{esc(label)}</td>']
        for cell in board.cells():
            text = board.display(row, cell)
            if text is None:
                cells.append("<td>–</td>")
            elif index in board.best.get(cell, set()):
                cells.append(f"<td><b>{esc(text)}</b></td>")
            else:
                cells.append(f"<td>{esc(text)}</td>")
        rows.append(f"<tr>{''.join(cells)}</tr>")
    notes = "".join(f'<p class="note">{esc(note)}</p>' for note in board.notes)
    return (
        f'<table class="board"><caption>{esc(board.title)}</caption><thead>{header}</thead>'
        f"<tbody>{''.join(rows)}</tbody></table>{notes}"
    )


def number(value: float, decimals: int) -> str:
    """``value`` at ``decimals`` places, or "–" when missing or not finite."""
    return "–" if value is None or not math.isfinite(value) else f"{value:.{decimals}f}"


def signed(value: float, decimals: int) -> str:
    """A gain with its sign at ``decimals`` places, or "–" when not finite."""
    return "–" if not math.isfinite(value) else f"{value:+.{decimals}f}"


def cell_class(value: float) -> str:
    """The ``class`` attribute of a gain's cell: ``good`` above 0, ``bad`` below, none for 0 or NaN."""
    if not math.isfinite(value) or value == 0:
        return ""
    return ' class="good"' if value > 0 else ' class="bad"'


def video_players(videos: Sequence[VideoRecord], folder: str) -> str:
    """One player per video (files under the relative ``folder``), side by side, each showing its poster (the
    first frame) until it plays."""
    players = "".join(
        f'<figure><video src="{folder}{esc(v.path.name)}" poster="{folder}{esc(v.poster.name)}" controls '
        f'loop muted playsinline preload="metadata" title="{esc(v.method)}"></video><figcaption>render | '
        f"{esc(v.method)} | ground truth — {v.frames} frames</figcaption></figure>"
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
        sections.append(f"<h2>{esc(title)}</h2>" + video_players(videos, "videos/"))
    body = f'<p class="note">{esc(note)}</p>' + ("".join(sections) or "<p>No videos in this report.</p>")
    return page("Videos", body, command=command)
