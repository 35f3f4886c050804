"""The report site's target pages (``targets/<target>.html``) and their pictures
(``images/<target>/*.jpg``, or ``*.png`` when lossless: :mod:`.site_pictures`): render, each method and ground
truth side by side, a before/after slider per method, error maps |image − GT| on one scale, the target's
metrics and gains, and its sequence's videos; plus the thumbnail the targets table shows."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from setdiff_bench.reporting.leaderboard import metric_decimals, metric_header
from setdiff_bench.reporting.site._html import (
    SLIDER_SCRIPT,
    cell_class,
    esc,
    metric_label,
    metric_unit,
    number,
    page,
    signed,
    video_players,
)
from setdiff_bench.reporting.site._pictures import pooled_error_map, write_picture, write_thumbnail
from setdiff_bench.reporting.site._settings import PictureSettings
from setdiff_bench.reporting.site._targets import TargetRecord, target_gain
from setdiff_bench.reporting.site._video import VideoRecord, slug
from setdiff_bench.reporting.targets import ERROR_MAP_FULL_SCALE, TargetImages, error_map


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
    suffix: str = ".jpg",
    size: tuple[int, int] | None = None,
    error_pool: int = 1,
) -> str:
    """The page of one target: pictures, sliders, error maps, metrics (images under ``../images``, files
    ending in ``suffix``) and the ``videos`` of its camera sequence (under ``../videos``).  ``size``: the
    pictures' ``(width, height)``; error maps stored smaller are shown at it (pixels kept square).
    ``error_pool``: the error maps' pixel covers ``error_pool × error_pool`` pixels (its largest error)."""
    folder = f"../images/{record.slug}"
    shown = [m for m in methods if m != baseline]
    render_label = f"3DGS render (= {baseline})" if baseline in record.values else "3DGS render"

    def figure(src: str, caption: str, shown_at: str = "") -> str:
        return (
            f'<figure><img src="{folder}/{src}" alt="{esc(caption)}"{shown_at}>'
            f"<figcaption>{esc(caption)}</figcaption></figure>"
        )

    at_size = (
        f' width="{size[0]}" height="{size[1]}" style="image-rendering:pixelated"' if size is not None else ""
    )

    def psnr_of(method: str) -> str:
        value = record.values.get(method, {}).get(metrics[0]) if metrics else None
        if value is None:
            return ""
        unit = metric_unit(metrics[0])
        return f" — {metric_header(metrics[0])} {value:.{metric_decimals(metrics[0])}f}" + (
            f" {unit}" if unit else ""
        )

    pictures = (
        figure(f"render{suffix}", render_label + (psnr_of(baseline) if baseline else ""))
        + "".join(figure(f"{slug(m)}{suffix}", m + psnr_of(m)) for m in shown)
        + figure(f"gt{suffix}", "ground truth")
    )
    errors = figure(f"render.err{suffix}", "|render − GT|", at_size) + "".join(
        figure(f"{slug(m)}.err{suffix}", f"|{m} − GT|", at_size) for m in shown
    )
    sliders = "".join(
        f'<div class="cmpwrap"><div>render ◀ ▶ {esc(m)}</div><div class="cmp" data-method="{esc(m)}">'
        f'<img class="after" src="{folder}/{slug(m)}{suffix}" alt="{esc(m)}">'
        f'<img class="before" src="{folder}/render{suffix}" alt="render">'
        f'<input type="range" min="0" max="100" value="50" aria-label="render / {esc(m)}"></div></div>'
        for m in shown
    )
    head = "".join(f"<th>{esc(metric_label(m))}</th>" for m in metrics)
    gains = (
        "".join(f"<th>{esc(metric_label(m, ' gain', arrow=False))}</th>" for m in metrics) if baseline else ""
    )
    rows = []
    for method in [m for m in methods if m in record.values]:
        values = record.values[method]
        cells = "".join(
            f"<td>{number(values.get(m, float('nan')), metric_decimals(m))}</td>" for m in metrics
        )
        if baseline:
            for m in metrics:
                value = target_gain(record, method, m, baseline)
                cells += f"<td{cell_class(value)}>{signed(value, metric_decimals(m))}</td>"
        rows.append(f'<tr><td class="l">{esc(method)}</td>{cells}</tr>')
    nav = " ".join(
        f'<a href="{r.slug}.html">{label}</a>'
        for r, label in ((previous, "◀ previous"), (following, "next ▶"))
        if r is not None
    )
    body = (
        f"<p>{nav} · dataset {esc(record.dataset)} · packet {esc(record.key.packet_id)} target "
        f'{record.key.view}</p><div class="strip">{pictures}</div>'
        f'<h2>Before / after</h2><p class="note">Drag a slider: the render on the left of it, the method\'s '
        f"output on the right.</p>{sliders}"
        f'<h2>Error maps</h2><p class="note">Mean absolute RGB error against the ground truth; black = '
        f"none, brightest = {ERROR_MAP_FULL_SCALE:g} (on a 0–1 scale) or more, the same scale in every map."
        + (
            f"  Each pixel of a map is the largest error of the {error_pool}×{error_pool} pixels it covers."
            if error_pool > 1
            else ""
        )
        + f'</p><div class="strip">{errors}</div>'
        f'<h2>Metrics</h2><table><thead><tr><th class="l">Method</th>{head}{gains}</tr></thead>'
        f"<tbody>{''.join(rows)}</tbody></table>"
    )
    if videos:
        position = videos[0].sequence.targets.index(record.key) + 1
        body += (
            f"<h2>Its sequence: {esc(videos[0].sequence.title)}</h2><p class='note'>This target is frame "
            f"{position} of {len(videos[0].sequence.targets)}; render | method | ground truth.</p>"
            + video_players(videos, "../videos/")
        )
    title = f"{record.scene} / {record.group} / {record.frame}"
    return page(title, body, root="../", script=SLIDER_SCRIPT, command=command)


#: File name of a target's thumbnail in its picture folder (always JPEG: it is only a preview).
THUMBNAIL_FILE = "thumb.jpg"


def write_target_images(
    images: TargetImages,
    record: TargetRecord,
    methods: Sequence[str],
    folder: Path,
    settings: PictureSettings | None = None,
) -> tuple[int, int]:
    """The pictures of one target page (render, each method, ground truth, and their error maps, as
    ``settings`` says, default JPEG, where error maps are :func:`pooled_error_map` at half size; full size
    when lossless) and the targets table's thumbnail of the render (:data:`THUMBNAIL_FILE`).

    Returns:
        The pictures' ``(width, height)``, for the page to show the error maps at.
    """
    settings = settings or PictureSettings()
    errors = error_map if settings.lossless else pooled_error_map
    folder.mkdir(parents=True, exist_ok=True)
    render, truth = images.render(record.key), images.ground_truth(record.key)
    write_picture(folder / "render", render, settings)
    write_picture(folder / "gt", truth, settings)
    write_picture(folder / "render.err", errors(render, truth), settings, error_map=True)
    write_thumbnail(folder / THUMBNAIL_FILE, render)
    for method in methods:
        output = images.output(method, record.key)
        write_picture(folder / slug(method), output, settings)
        write_picture(folder / f"{slug(method)}.err", errors(output, truth), settings, error_map=True)
    return render.shape[1], render.shape[0]
