"""How the report site stores its pictures: JPEG (small; the default) or lossless PNG, half-size error maps
that keep every error visible, thumbnails for the targets table, and the poster frames of the videos.

A site of a large benchmark is mostly pictures: per target the render, the ground truth, every method's
output and an error map per image.  As lossless PNG the sparse demo's 676 targets at 256×144 made a site of
353 MB; as JPEG (pictures at quality 90, 4:4:4; error maps at half size, quality 85, 4:2:0) with video
panels at 192 px the site is 76.9 MB, its pictures 71 KB per target (docs/report.md, "Size and time", gives
the commands).  ``--lossless`` (:attr:`PictureSettings.lossless`) keeps PNG for readers who must see every
pixel as scored.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from setdiff_bench.errors import UsageError
from setdiff_bench.io.images import write_png
from setdiff_bench.reporting.site._settings import DEFAULT_JPEG_QUALITY, PictureSettings
from setdiff_bench.reporting.targets import error_map

__all__ = [
    "ERROR_MAP_POOL",
    "THUMBNAIL_HEIGHT",
    "pooled_error_map",
    "thumbnail",
    "write_jpeg",
    "write_picture",
    "write_thumbnail",
]

#: Error maps are written at 1 / this of the pictures' width and height, each pixel the largest error of the
#: block it covers (pages show them at the pictures' size).
ERROR_MAP_POOL = 2
#: Height in pixels of the targets table's thumbnails (shown 40 px high: sharp on 2x displays).
THUMBNAIL_HEIGHT = 80
#: JPEG quality of those thumbnails.
THUMBNAIL_QUALITY = 80


def write_jpeg(
    path: str | Path, image: np.ndarray, quality: int = DEFAULT_JPEG_QUALITY, *, full_chroma: bool = True
) -> Path:
    """Write an 8-bit RGB ``(H, W, 3)`` image as a baseline JPEG, with 4:4:4 chroma (``full_chroma``: thin
    coloured edges keep their colour) or 4:2:0 (chroma at half resolution; about a third smaller).

    Written directly (the site is built in a staging folder that is renamed into place whole).

    Raises:
        UsageError: an image that is not 8-bit RGB, or one the encoder refuses.
    """
    path = Path(path)
    array = np.asarray(image)
    if array.dtype != np.uint8 or array.ndim != 3 or array.shape[2] != 3:
        raise UsageError(f"a JPEG needs an 8-bit (H, W, 3) image, got {array.dtype} {array.shape}", path)
    parameters = [
        cv2.IMWRITE_JPEG_QUALITY,
        int(quality),
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
        cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444 if full_chroma else cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
    ]
    ok, encoded = cv2.imencode(".jpg", cv2.cvtColor(array, cv2.COLOR_RGB2BGR), parameters)
    if not ok:
        raise UsageError("the JPEG encoder refused the image", path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(encoded.tobytes())
    return path


def write_picture(
    path_without_suffix: Path, image: np.ndarray, settings: PictureSettings, *, error_map: bool = False
) -> Path:
    """Write ``image`` (8-bit RGB) as ``<path_without_suffix><settings.suffix>`` (an ``error_map`` at the
    error maps' quality); returns the file.  (Error maps are passed at the size they are stored:
    :func:`pooled_error_map` for JPEG sites, full size for lossless ones.)"""
    path = path_without_suffix.with_name(path_without_suffix.name + settings.suffix)
    if settings.lossless:
        write_png(path, image, atomic=False)
        return path
    if error_map:
        return write_jpeg(path, image, settings.error_quality, full_chroma=False)
    return write_jpeg(path, image, settings.quality)


def thumbnail(image: np.ndarray, height: int = THUMBNAIL_HEIGHT) -> np.ndarray:
    """``image`` scaled down (area averaging) to ``height`` pixels, keeping its aspect; unchanged when it is
    not taller."""
    rows, columns = image.shape[:2]
    if rows <= height:
        return image
    width = max(1, round(columns * height / rows))
    return cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)


def pooled_error_map(image: np.ndarray, truth: np.ndarray, pool: int = ERROR_MAP_POOL) -> np.ndarray:
    """The error map of ``image`` against ``truth`` (:func:`~setdiff_bench.reporting.targets.error_map`: mean
    absolute RGB error on its colour scale) at ``1 / pool`` of their size, each pixel the **largest** error of
    the ``pool × pool`` block it covers, so a single wrong pixel stays as bright as at full size (averaging
    would dim it).  Sides that do not divide by ``pool`` are padded by repeating the edge."""
    if image.shape != truth.shape:
        raise UsageError(f"image {image.shape} and ground truth {truth.shape} differ in size")
    error = np.abs(image.astype(np.float32) - truth.astype(np.float32)).mean(axis=2)  # (H, W), 0-255
    if pool > 1:
        rows, columns = error.shape
        padded = np.pad(error, ((0, -rows % pool), (0, -columns % pool)), mode="edge")
        blocks = padded.reshape(padded.shape[0] // pool, pool, padded.shape[1] // pool, pool)
        error = blocks.max(axis=(1, 3))
    grey = np.repeat(error[:, :, None], 3, axis=2)  # every channel the error: error_map's mean is the error
    return error_map(grey, np.zeros_like(grey))


def write_thumbnail(path: str | Path, image: np.ndarray) -> Path:
    """The targets table's preview of ``image``: :func:`thumbnail`, as a JPEG at quality 80, chroma 4:2:0."""
    return write_jpeg(path, thumbnail(image), THUMBNAIL_QUALITY, full_chroma=False)
