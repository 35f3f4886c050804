"""The report site's settings (:class:`SiteSettings`, :class:`PictureSettings`) and their defaults, with no heavy
imports, so that ``setdiff-bench report`` builds its options from them at every CLI start."""

from __future__ import annotations

from dataclasses import dataclass, field

from setdiff_bench.errors import UsageError
from setdiff_bench.reporting.bootstrap import BootstrapSettings

#: The method gains are measured against (its outputs are the 3DGS render).
DEFAULT_BASELINE = "identity"
#: JPEG quality of pictures (1-100) when none is given: artefacts of the methods stay visible at it.
DEFAULT_JPEG_QUALITY = 90
#: JPEG quality of error maps (a colour scale of the error, not the picture itself: a lower quality and
#: 4:2:0 chroma change where the errors show no more than the colour scale's steps do).
DEFAULT_ERROR_MAP_QUALITY = 85
#: Widest panel (render, method or ground truth) of a video frame by default, in pixels: three side by side
#: fit a screen, and the sparse benchmark's 18 videos stay a fifth of its report (docs/report.md).
DEFAULT_PANEL_WIDTH = 192


@dataclass(frozen=True)
class PictureSettings:
    """How pictures are written.

    Attributes:
        lossless: PNG (every pixel as scored, several times larger) instead of JPEG.
        quality: JPEG quality of the pictures (render, outputs, ground truth), 1-100, chroma 4:4:4.
        error_quality: JPEG quality of the error maps, 1-100, chroma 4:2:0.
    """

    lossless: bool = False
    quality: int = DEFAULT_JPEG_QUALITY
    error_quality: int = DEFAULT_ERROR_MAP_QUALITY

    def __post_init__(self) -> None:
        for name, value in (("quality", self.quality), ("error_quality", self.error_quality)):
            if not 1 <= value <= 100:
                raise UsageError(f"JPEG {name} must be 1-100, got {value}")

    @property
    def suffix(self) -> str:
        """The file suffix of pictures: ``.png`` or ``.jpg``."""
        return ".png" if self.lossless else ".jpg"


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
        pictures: JPEG (quality) or lossless PNG pictures.
        with_reported: add the paper's reported rows, marked "(paper)", to the leaderboards of datasets whose
            layout has them (the rows ``leaderboard --with-reported`` adds; never to other profiles' tables).
        bootstrap: resamples, level and seed of the per-scene breakdown's paired intervals.
        video_width: the widest panel of a video frame (render, method, ground truth; ``None``: the
            pictures' width).
    """

    baseline: str = DEFAULT_BASELINE
    split: str | None = "test"
    fps: float = 4.0
    max_width: int | None = 768
    videos: bool = True
    command: str | None = None
    pictures: PictureSettings = field(default_factory=PictureSettings)
    with_reported: bool = True
    bootstrap: BootstrapSettings = field(default_factory=BootstrapSettings)
    video_width: int | None = DEFAULT_PANEL_WIDTH
