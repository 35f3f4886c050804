"""``setdiff-bench report``: a static HTML site of finished runs, browsed from disk with no network.

Examples::

    setdiff-bench report --runs runs/demo/work/runs --packets runs/demo/work/packets --out runs/report
    setdiff-bench report --runs runs/demo/work/runs/identity runs/demo/work/runs/setdiff \\
        --packets runs/demo/work/packets --out runs/report_setdiff --no-videos
    setdiff-bench report --runs runs/demo/work/runs --packets runs/demo/work/packets --out runs/videos \\
        --video-only

The site (``<out>/index.html``; open it in a browser) holds the leaderboard of each dataset and evaluation
profile (the tables of ``setdiff-bench leaderboard``, with the paper's reported rows, marked "(paper)",
where the dataset's layout has them; ``--no-reported`` leaves them out), each method's cost (ms per frame,
peak memory), the dataset's plots, each method's gain per scene with paired bootstrap intervals, and every
target: a table of each method's gain or loss against the render (the ``--baseline`` run, ``identity``),
sortable by any column so damage is easy to find, linking to a page per target with render | each method |
ground truth, a before/after slider, error maps and metrics.  ``videos.html`` plays render | method | ground
truth per camera sequence (WebM, VP9).  Pictures are JPEG (``--jpeg-quality``) unless ``--lossless``.
Pictures and videos need ``--packets``, the store the runs were made on (checked against the index hash the
runs recorded).  ``--video-only`` writes ``<out>/videos/`` alone.  The site is built beside ``--out`` and
replaces it whole when complete; see docs/report.md.
"""

from __future__ import annotations

import argparse
import shlex
from pathlib import Path

VERB = "report"
HELP = "a static HTML site of finished runs: leaderboards, plots, per-target pictures and sliders, videos"
DESCRIPTION = __doc__


def add_arguments(parser: argparse.ArgumentParser) -> None:
    # the settings' defaults (a light module: no heavy import at every CLI start)
    from setdiff_bench.reporting.site import SiteSettings

    defaults = SiteSettings()
    parser.add_argument(
        "--runs",
        required=True,
        nargs="+",
        action="extend",
        type=Path,
        metavar="RUN",
        help="run folders, or folders of runs",
    )
    parser.add_argument(
        "--packets",
        type=Path,
        default=None,
        help="packet store the runs were made on (pictures, videos; default: the store the runs' "
        "manifests name, when it exists here)",
    )
    parser.add_argument("--out", required=True, type=Path, help="site folder (replaced whole)")
    parser.add_argument(
        "--baseline",
        default=defaults.baseline,
        metavar="METHOD",
        help="method gains are measured against; its outputs are the render (default identity)",
    )
    parser.add_argument("--split", default="test", help="split of the targets to show (train, test, all)")
    parser.add_argument(
        "--fps",
        type=float,
        default=defaults.fps,
        help="frames per second of the videos (default %(default)s)",
    )
    parser.add_argument(
        "--max-width",
        type=int,
        default=defaults.max_width,
        help="pictures and videos wider than this many pixels are scaled down (0: full size; default 768)",
    )
    parser.add_argument(
        "--video-width",
        type=int,
        default=defaults.video_width,
        help="the widest panel of a video frame in pixels (render, method, ground truth side by side; "
        "0: the pictures' width; default %(default)s)",
    )
    parser.add_argument(
        "--lossless",
        action="store_true",
        help="pictures as lossless PNG (every pixel as scored; several times larger) instead of JPEG",
    )
    parser.add_argument(
        "--jpeg-quality",
        type=int,
        default=defaults.pictures.quality,
        help="JPEG quality of the pictures, 1-100 (default %(default)s)",
    )
    parser.add_argument(
        "--no-reported",
        action="store_true",
        help="leave the paper's reported rows out of the leaderboards (shown by default where the "
        "dataset's layout has them, marked (paper))",
    )
    parser.add_argument(
        "--bootstrap-resamples",
        type=int,
        default=defaults.bootstrap.resamples,
        help="resamples of the per-scene paired bootstrap intervals (default %(default)s)",
    )
    parser.add_argument(
        "--bootstrap-seed",
        type=int,
        default=defaults.bootstrap.seed,
        help="seed of those resamples (default %(default)s)",
    )
    videos = parser.add_mutually_exclusive_group()
    videos.add_argument("--no-videos", action="store_true", help="leave the videos out")
    videos.add_argument("--video-only", action="store_true", help="write only <out>/videos/*.webm")


def run(args: argparse.Namespace) -> int:
    # lazy: every verb module loads at each CLI start (--help too); what the verb needs loads when it runs
    from setdiff_bench.errors import UsageError
    from setdiff_bench.reporting.bootstrap import BootstrapSettings
    from setdiff_bench.reporting.site import PictureSettings, SiteSettings, build_site

    if not args.fps > 0:
        raise UsageError(f"needs a positive frame rate, got {args.fps}", "--fps")
    if args.max_width < 0:
        raise UsageError(f"needs a width >= 0, got {args.max_width}", "--max-width")
    if args.video_width < 0:
        raise UsageError(f"needs a width >= 0, got {args.video_width}", "--video-width")
    if not 1 <= args.jpeg_quality <= 100:
        raise UsageError(f"needs a quality of 1-100, got {args.jpeg_quality}", "--jpeg-quality")
    if args.bootstrap_resamples < 1:
        raise UsageError(
            f"needs at least 1 resample, got {args.bootstrap_resamples}", "--bootstrap-resamples"
        )
    command = "setdiff-bench " + shlex.join(
        ["report", "--runs", *map(str, args.runs), "--out", str(args.out)]
        + (["--packets", str(args.packets)] if args.packets else [])
    )
    settings = SiteSettings(
        baseline=args.baseline,
        split=None if args.split == "all" else args.split,
        fps=args.fps,
        max_width=args.max_width or None,
        videos=not args.no_videos,
        command=command,
        pictures=PictureSettings(lossless=args.lossless, quality=args.jpeg_quality),
        with_reported=not args.no_reported,
        bootstrap=BootstrapSettings(resamples=args.bootstrap_resamples, seed=args.bootstrap_seed),
        video_width=args.video_width or None,
    )
    summary = build_site(
        args.runs, args.out, packets=args.packets, settings=settings, video_only=args.video_only
    )
    for note in summary.notes:
        print(f"note: {note}")
    if args.video_only:
        print(f"{len(summary.videos)} videos in {args.out / 'videos'}")
    else:
        print(
            f"site: {args.out / 'index.html'} ({summary.targets} targets, {summary.pages} pages, "
            f"{len(summary.videos)} videos)"
        )
    return 0
