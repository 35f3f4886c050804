"""Image bytes of the sensorsim protocol: encode PNG / JPEG replies, decode an upstream renderer's replies.

PNG is written by :func:`setdiff_bench.io.images.write_png` (OpenImageIO, compression 6), the writer of
``run``, so a served PNG is byte for byte the file ``run`` writes for the same pixels.  JPEG is OpenCV's
baseline encoder at the request's ``image_quality`` (1-100; 0 means AlpaSim's 95).
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import cv2
import numpy as np

from setdiff_bench.evaluation.stream import StreamInputError
from setdiff_bench.io.images import write_png
from setdiff_bench.serve.sensorsim import sensorsim_pb2 as pb

#: The formats served (AlpaSim uses these two).
SERVED_FORMATS = {pb.ImageFormat.PNG: "PNG", pb.ImageFormat.JPEG: "JPEG"}
#: JPEG quality when a request leaves ``image_quality`` at 0 (AlpaSim's runtime asks for 95).
DEFAULT_JPEG_QUALITY = 95
#: Where PNGs are staged on their way to bytes (memory-backed where the system has it).
_STAGING = Path("/dev/shm") if Path("/dev/shm").is_dir() and os.access("/dev/shm", os.W_OK) else None


def check_format(image_format: int, image_quality: float, what: str) -> None:
    """Refuse formats other than PNG and JPEG, and JPEG qualities outside 0..100 (one line)."""
    if image_format not in SERVED_FORMATS:
        name = pb.ImageFormat.Name(image_format) if image_format in pb.ImageFormat.values() else image_format
        raise StreamInputError(f"image_format {name} is not served; ask for PNG or JPEG", what)
    if image_format == pb.ImageFormat.JPEG and not (
        math.isfinite(image_quality) and 0 <= image_quality <= 100
    ):
        raise StreamInputError(f"image_quality must be 0..100 for JPEG, got {image_quality:g}", what)


def encode(image: np.ndarray, image_format: int, image_quality: float = 0.0) -> bytes:
    """``(H, W, 3)`` uint8 RGB → PNG or JPEG bytes (call :func:`check_format` first)."""
    if image_format == pb.ImageFormat.PNG:
        with tempfile.TemporaryDirectory(dir=_STAGING) as folder:
            path = Path(folder) / "frame.png"
            write_png(path, image, atomic=False)
            return path.read_bytes()
    quality = round(image_quality) if image_quality > 0 else DEFAULT_JPEG_QUALITY
    ok, data = cv2.imencode(
        ".jpg", np.ascontiguousarray(image[:, :, ::-1]), [cv2.IMWRITE_JPEG_QUALITY, max(1, min(100, quality))]
    )
    if not ok:  # pragma: no cover - OpenCV encodes any uint8 image
        raise StreamInputError("JPEG encoding failed", "image_format")
    return data.tobytes()


def decode(data: bytes, height: int, width: int, what: str) -> np.ndarray:
    """PNG / JPEG bytes → ``(height, width, 3)`` uint8 RGB, refusing anything else (one line)."""
    if not data:
        raise StreamInputError("the upstream renderer returned no image bytes", what)
    image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise StreamInputError(f"the upstream renderer returned {len(data)} bytes that are no image", what)
    if image.shape[:2] != (height, width):
        raise StreamInputError(
            f"the upstream renderer returned a {image.shape[1]}x{image.shape[0]} image for a "
            f"{width}x{height} request",
            what,
        )
    return np.ascontiguousarray(image[:, :, ::-1])
