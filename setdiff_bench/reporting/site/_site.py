"""``build_site``: the report site of finished runs, page by page (the package's docstring says what it holds)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import staged_folder
from setdiff_bench.protocols.profiles import DEFAULT_PROFILE, PROFILE_COLUMN
from setdiff_bench.reporting.leaderboard import (
    Leaderboard,
    build_leaderboard,
    dataset_layout,
    load_runs,
    profile_rows,
    reported_for,
)
from setdiff_bench.reporting.plots import write_plots
from setdiff_bench.reporting.site._html import (
    SORT_SCRIPT,
    page,
    videos_page,
)
from setdiff_bench.reporting.site._index import index_body, plot_caption
from setdiff_bench.reporting.site._pictures import ERROR_MAP_POOL
from setdiff_bench.reporting.site._runs import open_store, recorded_store, run_folders
from setdiff_bench.reporting.site._scenes import scene_table_html
from setdiff_bench.reporting.site._settings import DEFAULT_BASELINE, SiteSettings
from setdiff_bench.reporting.site._target_pages import THUMBNAIL_FILE, target_page, write_target_images
from setdiff_bench.reporting.site._targets import (
    image_metrics,
    target_records,
)
from setdiff_bench.reporting.site._video import VideoRecord, target_sequences, write_videos
from setdiff_bench.reporting.targets import TargetImages, TargetKey

#: The metrics the plots draw, one panel each.
PLOT_METRICS = ("psnr", "ssim", "lpips")


@dataclass
class SiteSummary:
    """What a build wrote: the site folder, its pages, videos, and notes (things left out, and why)."""

    out: Path
    pages: int = 0
    targets: int = 0
    videos: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


# ---------------------------------------------------------------------- the site
def build_site(
    runs: Sequence[str | Path],
    out: str | Path,
    *,
    packets: str | Path | None = None,
    settings: SiteSettings | None = None,
    video_only: bool = False,
) -> SiteSummary:
    """Write the site of the runs under ``runs`` to ``out`` (replacing it whole when complete).

    Args:
        runs: run folders, or folders of runs.
        out: the site folder.
        packets: the packet store the runs were made on (pictures, videos); ``None``: the store the runs'
            manifests name if it exists here, else tables and metrics only.
        settings: baseline, split, video rate, picture size and format... (default :class:`SiteSettings`).
        video_only: write only ``videos/`` (needs a store).

    Raises:
        UsageError: no runs, a store the runs were not made on, ``video_only`` without a store, or a baseline
            method given that no run has.
        LeaderboardError: runs that cannot be tabulated (a method missing targets another has).
    """
    settings = settings or SiteSettings()
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
                pictures,
                target_sequences(plain),
                compared,
                staging / "videos",
                fps=settings.fps,
                panel_width=settings.video_width,
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
                size = write_target_images(
                    pictures,
                    record,
                    [m for m in methods if m != baseline],
                    staging / "images" / record.slug,
                    settings.pictures,
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
                    suffix=settings.pictures.suffix,
                    size=size,
                    error_pool=1 if settings.pictures.lossless else ERROR_MAP_POOL,
                )
                (staging / "targets" / f"{record.slug}.html").write_text(page_text, encoding="utf-8")
            summary.pages += len(records)
        summary.targets = len(records)
        plots = [
            (path, plot_caption(dataset, PLOT_METRICS))
            for dataset in sorted(set(plain["dataset"]))
            for path in write_plots(
                dataset,
                plain,
                staging / "plots",
                split=settings.split,
                metrics=PLOT_METRICS,
                refit_steps=False,
            )
        ]
        scenes = (
            scene_table_html(plain, labels, methods, metrics, baseline, settings.bootstrap)
            if baseline
            else ""
        )
        index = index_body(
            boards,
            labels,
            plots,
            records,
            methods,
            metrics,
            baseline,
            pictures is not None,
            staging,
            scenes=scenes,
            thumbnail=THUMBNAIL_FILE,
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
    """A leaderboard per dataset and evaluation profile present in the runs; the default profile's with the
    paper's reported rows where the dataset's layout has them and ``settings.with_reported``."""
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
            reported = None
            if (
                settings.with_reported
                and profile == DEFAULT_PROFILE
                and dataset_layout(dataset).reported_tables
            ):
                reported = reported_for(dataset)
            boards.append(
                build_leaderboard(
                    dataset,
                    rows,
                    sequences,
                    split=settings.split,
                    profile=profile,
                    cost=True,
                    reported=reported,
                )
            )
    return boards
