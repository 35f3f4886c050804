"""A static HTML site of finished runs, browsed from the file system: no server, no network, no CDN.

Pages (every stylesheet and script inline, every link relative)::

    index.html                 leaderboards (one per dataset and evaluation profile, blocks = groups, the
                               cost block: ms per frame, peak memory, and the paper's reported rows where the
                               dataset's layout has them), the dataset's plots, each method's gain per scene
                               with paired bootstrap intervals, and every target in a table sortable by any
                               column (opening sorted, and marked so, by the first method's loss)
    videos.html                render | method | ground truth per camera sequence (WebM, VP9, with posters)
    targets/<target>.html      render | each method | ground truth, a before/after slider per method,
                               error maps |image − GT|, the target's metrics
    images/<target>/*.jpg      the pictures those pages show (``*.png`` with ``lossless``) and thumb.jpg
    plots/*.png, videos/*.webm, videos/*.jpg (the videos' posters)

The tables come from :func:`setdiff_bench.reporting.leaderboard.build_leaderboard` (the same aggregation,
refusals and bold-best as ``setdiff-bench leaderboard``), the plots from
:func:`setdiff_bench.reporting.plots.write_plots`.  The *baseline* (default ``identity``: its outputs are the
3DGS render) is what gains are measured against: per target, ``method − baseline`` for metrics where higher
is better and ``baseline − method`` where lower is, so a negative gain is damage in every column.

Pictures and videos need the packet store the runs were made on (``packets``; its ``index.parquet`` must be
the one the runs recorded); without one the site has the tables, plots and per-target metrics only.  The
site is built in a staging folder beside ``out`` and renamed into place when complete.

Modules, along the data path: :mod:`.site_runs` (the runs and their packet store), :mod:`.site_targets`
(per-target records and gains), :mod:`.site_pictures` (JPEG or PNG pictures, thumbnails), :mod:`.site_html`
(style, scripts, page frame, units, leaderboard tables, video players), :mod:`.site_scenes` (the per-scene
breakdown), :mod:`.site_target_pages` (a target's page and pictures), :mod:`.site_index` (``index.html``) and
this module (:func:`build_site`, which writes them all).

The package's modules are private (``_site`` builds, ``_settings``, ``_runs``, ``_targets``, ``_pictures``,
``_html``, ``_index``, ``_scenes``, ``_target_pages``, ``_video``: the sequences' videos); this face exports what other code uses.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from setdiff_bench.runtime.lazy import lazy_face

#: Public name → the private module that defines it; each loads on first use (``report --help`` imports none).
_EXPORTS = {
    "DEFAULT_PANEL_WIDTH": "_settings",
    "PictureSettings": "_settings",
    "SiteSettings": "_settings",
    "TargetRecord": "_targets",
    "VideoError": "_video",
    "build_site": "_site",
    "pooled_error_map": "_pictures",
    "run_folders": "_runs",
    "side_by_side": "_video",
    "target_sequences": "_video",
    "write_jpeg": "_pictures",
    "write_target_images": "_target_pages",
    "write_video": "_video",
}

__all__ = [
    "DEFAULT_PANEL_WIDTH",
    "PictureSettings",
    "SiteSettings",
    "TargetRecord",
    "VideoError",
    "build_site",
    "pooled_error_map",
    "run_folders",
    "side_by_side",
    "target_sequences",
    "write_jpeg",
    "write_target_images",
    "write_video",
]  # = sorted(_EXPORTS)
__getattr__, __dir__ = lazy_face(__name__, _EXPORTS)

if TYPE_CHECKING:  # for type checkers and IDEs
    from setdiff_bench.reporting.site._pictures import pooled_error_map, write_jpeg
    from setdiff_bench.reporting.site._runs import run_folders
    from setdiff_bench.reporting.site._settings import DEFAULT_PANEL_WIDTH, PictureSettings, SiteSettings
    from setdiff_bench.reporting.site._site import build_site
    from setdiff_bench.reporting.site._target_pages import write_target_images
    from setdiff_bench.reporting.site._targets import TargetRecord
    from setdiff_bench.reporting.site._video import VideoError, side_by_side, target_sequences, write_video
