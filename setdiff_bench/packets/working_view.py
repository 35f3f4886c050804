"""A packet's view at the working resolution: which window of the capture, which camera, which mask.

* **Working resolution** ``(H, W)``: the protocol's ``[images] resolution``, or the scene's own image size
  divided by ``downscale`` for ``"native"`` (:func:`scene_resolution`).
* **Crop and resize.**  A frame's camera and image are centre-cropped to the working aspect ratio
  (``resize = "crop"``; a no-op for 16:9 captures at 576×1024; ``"stretch"`` keeps the whole image) and
  then resized; ``K`` follows through :meth:`Camera.cropped` and :meth:`Camera.resized`.  Images shrink
  with ``INTER_AREA`` and grow with ``INTER_LINEAR``; masks use nearest neighbour (as the EUVS metric
  script; :func:`setdiff_bench.packets.worker.resample`).
* **Masks** of targets follow the protocol's ``masks`` rule (:func:`mask_source`); references have none.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import ProtocolError
from setdiff_bench.protocols import Protocol
from setdiff_bench.types import Frame, Scene


@dataclass(frozen=True)
class Crop:
    """Pixel window ``[left, left + width) × [top, top + height)`` of the source image."""

    left: int
    top: int
    width: int
    height: int


@dataclass(frozen=True)
class ViewJob:
    """One view of a packet, as the worker needs it.

    Attributes:
        frame, sensor, traversal, timestamp_us: from the loader's :class:`Frame`.
        image_path: the capture, or ``None`` for a view on a novel trajectory (rendered, no ground truth).
        mask_path: the mask file, or ``None`` (all pixels evaluated).
        invert_mask: the mask file marks what to ignore (Para-Lane foreground masks).
        crop: window of the source image kept before resizing.
        camera: world-frame camera at the working resolution.
        overlap_score: Eq. 2 score for a reference, ``None`` for a target.
    """

    frame: str
    sensor: str
    traversal: str
    timestamp_us: int | None
    image_path: Path | None
    mask_path: Path | None
    invert_mask: bool
    crop: Crop
    camera: Camera
    overlap_score: float | None = None


def crop_window(width: int, height: int, resolution: tuple[int, int], mode: str) -> Crop:
    """The centred window of a ``width × height`` image with the aspect ratio of ``resolution`` (H, W)."""
    if mode == "stretch":
        return Crop(0, 0, width, height)
    out_h, out_w = resolution
    if width * out_h > height * out_w:  # too wide: keep the full height
        crop_w = min(width, max(1, round(height * out_w / out_h)))
        return Crop((width - crop_w) // 2, 0, crop_w, height)
    crop_h = min(height, max(1, round(width * out_h / out_w)))
    return Crop(0, (height - crop_h) // 2, width, crop_h)


def working_camera(camera: Camera, crop: Crop, resolution: tuple[int, int]) -> Camera:
    """``camera`` after cropping to ``crop`` and resizing to ``resolution`` (H, W)."""
    if (crop.left, crop.top, crop.width, crop.height) != (0, 0, camera.width, camera.height):
        camera = camera.cropped(crop.left, crop.top, crop.width, crop.height)
    if (camera.height, camera.width) != tuple(resolution):
        camera = camera.resized(resolution[1], resolution[0])
    return camera


def scene_resolution(protocol: Protocol, scene: Scene) -> tuple[int, int]:
    """The working ``(height, width)``: the protocol's, or the scene's own for ``"native"``."""
    if protocol.images.resolution is not None:
        return protocol.images.resolution
    sizes = sorted({(f.camera.height, f.camera.width) for f in scene.frames})
    if len(sizes) != 1:
        raise ProtocolError(
            f'resolution = "native" needs one image size per scene; scene {scene.name!r} has '
            f"{', '.join(f'{w}x{h}' for h, w in sizes)}",
            protocol.path,
        )
    height, width = sizes[0]
    scale = protocol.images.downscale
    return max(1, round(height / scale)), max(1, round(width / scale))


def mask_source(protocol: Protocol, frame: Frame) -> tuple[Path | None, bool]:
    """``(mask file or None, invert)`` of a target under the protocol's mask rule."""
    if protocol.images.masks == "dataset":
        return frame.mask_path, False
    if protocol.images.masks == "foreground":
        path = frame.metadata.get("foreground_mask_path")
        return (Path(path), True) if path else (None, False)
    return None, False


def view_job(
    protocol: Protocol, frame: Frame, resolution: tuple[int, int], *, target: bool, score: float | None = None
) -> ViewJob:
    """The :class:`ViewJob` of a recorded ``frame`` at ``resolution`` (a target gets its mask, a reference
    its Eq. 2 ``score``)."""
    crop = crop_window(frame.camera.width, frame.camera.height, resolution, protocol.images.resize)
    mask, invert = mask_source(protocol, frame) if target else (None, False)
    return ViewJob(
        frame=frame.name,
        sensor=frame.sensor,
        traversal=frame.traversal,
        timestamp_us=frame.timestamp_us,
        image_path=frame.image_path,
        mask_path=mask,
        invert_mask=invert,
        crop=crop,
        camera=working_camera(frame.camera, crop, resolution),
        overlap_score=score,
    )
