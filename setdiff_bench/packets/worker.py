"""One packet, worker side: render, normalise and write a :class:`~setdiff_bench.packets.plan.PacketJob`.

:func:`build_packet` runs in a spawned worker process (``prepare --workers K``) or in-process.  It renders
the targets (RGB, C-map ``(M, 3, H, W)``, alpha ``(M, 1, H, W)``) and the references' C-maps and alphas
``(N, ·, H, W)`` from the fit, reads the references' captures and the targets' ground truth and masks at
the working resolution ``(H, W)`` (cropped and resized as :mod:`setdiff_bench.packets.plan` says, then
resampled to the pinhole camera when the capture is distorted), normalises the packet into its first
target's frame at unit extent (:func:`setdiff_bench.geometry.normalize_packet`) and writes it
(:func:`setdiff_bench.packets.writer.write_packet`).

Process-global caches: the last fit read (one model per process: jobs arrive grouped by fit) and up to
:data:`_REFERENCE_CACHE_SIZE` reference renders of that model, reused by every packet that shares them.
"""

from __future__ import annotations

import time
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch

from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.geometry import normalize_packet
from setdiff_bench.io.images import read_mask, read_rgb, to_numpy_hwc
from setdiff_bench.packets.jobs import PacketJob
from setdiff_bench.packets.working_view import Crop, ViewJob
from setdiff_bench.packets.writer import PacketHeader, ViewContent, write_packet
from setdiff_bench.runtime.threads import set_process_threads
from setdiff_bench.types import key_fields
from setdiff_bench.undistort import is_distorted, undistort_image, undistortion_maps


@dataclass
class JobStats:
    """What building one packet took: its views and the seconds spent rendering, reading and writing."""

    packet_id: str
    views: int
    render_s: float
    read_s: float
    write_s: float


_MODELS: dict[tuple[Path, int, int, str], Any] = {}
_REFERENCE_RENDERS: OrderedDict[tuple[Any, ...], tuple[torch.Tensor, torch.Tensor]] = OrderedDict()
_REFERENCE_CACHE_SIZE = 64  # views; 64 × (4 × 576 × 1024) float32 ≈ 600 MB at the real datasets' size


def _model(path: Path, device: str) -> Any:
    """The fit at ``path``, cached per process; the key includes the file's size and mtime, so a PLY
    replaced between two in-process ``prepare`` calls is read again instead of rendering the old one."""
    stat = path.stat() if path.is_file() else None
    key = (path, stat.st_size if stat else -1, stat.st_mtime_ns if stat else -1, device)
    if key not in _MODELS:
        _MODELS.clear()  # jobs arrive grouped by fit: keep one model per process
        _REFERENCE_RENDERS.clear()
        _MODELS[key] = read_ply(path).to(device)
    return _MODELS[key]


def _reference_geometry(
    model: Any, references: Sequence[Any], options: dict[str, Any], height: int, width: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame C-maps ``(N, 3, H, W)`` and alphas ``(N, 1, H, W)`` of the references, cached per process.

    A scene's fit frames serve as references of many packets; their renders do not depend on the
    packet (normalisation is applied afterwards), so each is rendered once per process and model.
    """
    keys = [
        (
            id(model),
            v.frame,
            repr(v.camera.K.tolist()),
            repr(v.camera.w2c.tolist()),
            repr(options["cmap_bound"]),
            repr(tuple(np.asarray(options["cmap_center"]).tolist())),
        )
        for v in references
    ]
    missing = [i for i, key in enumerate(keys) if key not in _REFERENCE_RENDERS]
    if missing:
        out = render(model, [references[i].camera for i in missing], **options)
        for j, i in enumerate(missing):
            _REFERENCE_RENDERS[keys[i]] = (out.cmap[j].float().cpu(), out.alpha[j].float().cpu())
            while len(_REFERENCE_RENDERS) > _REFERENCE_CACHE_SIZE:
                _REFERENCE_RENDERS.popitem(last=False)
    if not references:
        return torch.zeros(0, 3, height, width), torch.zeros(0, 1, height, width)
    for key in keys:
        _REFERENCE_RENDERS.move_to_end(key)
    return (
        torch.stack([_REFERENCE_RENDERS[key][0] for key in keys]),
        torch.stack([_REFERENCE_RENDERS[key][1] for key in keys]),
    )


def resample(
    image: np.ndarray, crop: Crop, resolution: tuple[int, int], *, nearest: bool = False
) -> np.ndarray:
    """Crop ``image`` ``(H, W[, C])`` to ``crop`` and resize to ``resolution`` (H, W) (rules in packets.plan)."""
    window = image[crop.top : crop.top + crop.height, crop.left : crop.left + crop.width]
    out_h, out_w = resolution
    if window.shape[:2] == (out_h, out_w):
        return np.ascontiguousarray(window)
    if nearest:
        interpolation = cv2.INTER_NEAREST
    elif out_h <= window.shape[0] and out_w <= window.shape[1]:
        interpolation = cv2.INTER_AREA
    else:
        interpolation = cv2.INTER_LINEAR
    return cv2.resize(np.ascontiguousarray(window), (out_w, out_h), interpolation=interpolation)


def capture_image(view: ViewJob, resolution: tuple[int, int]) -> np.ndarray:
    """The capture of ``view`` at the working resolution, ``(H, W, 3)`` float32 in [0, 1]."""
    assert view.image_path is not None, "a novel-trajectory view has no capture"
    image = resample(read_rgb(view.image_path), view.crop, resolution)
    if is_distorted(view.camera):  # the renderer draws the pinhole camera: resample the capture to it
        image = undistort_image(image, view.camera)[0]
    return np.clip(image, 0.0, 1.0).astype(np.float32)


def _mask(view: ViewJob, resolution: tuple[int, int]) -> np.ndarray:
    covered = (
        undistortion_maps(view.camera)[2] if is_distorted(view.camera) else np.ones(resolution, dtype=bool)
    )
    if view.mask_path is None:
        return covered
    keep = read_mask(view.mask_path)
    if view.invert_mask:
        keep = ~keep
    keep = resample(keep.astype(np.uint8), view.crop, resolution, nearest=True)
    if is_distorted(view.camera):
        keep = (
            undistort_image(keep, view.camera)[0][..., 0]
            if keep.ndim == 3
            else undistort_image(keep, view.camera)[0]
        )
    return keep.astype(bool) & covered


def build_packet(job: PacketJob, root: Path, backend: str, device: str) -> JobStats:
    """Render, normalise and write one packet (runs in a worker process or in-process)."""
    views = (*job.references, *job.targets)
    cameras = [v.camera for v in views]
    start = time.perf_counter()
    model = _model(job.fit_path, device if backend == "torch" else "cuda")
    options = dict(backend=backend, cmap_bound=job.cmap_bound, cmap_center=job.cmap_center)
    with torch.no_grad():
        size = (job.targets[0].camera.height, job.targets[0].camera.width)
        ref_cmap, ref_alpha = _reference_geometry(model, job.references, options, *size)
        out = render(model, [v.camera for v in job.targets], **options)
    rgb = out.rgb.float().cpu()
    cmap = torch.cat([ref_cmap, out.cmap.float().cpu()])
    alpha = torch.cat([ref_alpha, out.alpha.float().cpu()])
    normalised = normalize_packet(cameras, cmap, len(job.references), alphas=alpha)
    rendered = time.perf_counter()
    contents = []
    for i, view in enumerate(views):
        is_target = i >= len(job.references)
        contents.append(
            ViewContent(
                frame=view.frame,
                sensor=view.sensor,
                traversal=view.traversal,
                timestamp_us=view.timestamp_us,
                camera=normalised.cameras[i],
                camera_world=view.camera,
                image=to_numpy_hwc(rgb[i - len(job.references)])
                if is_target
                else capture_image(view, job.resolution),
                cmap=to_numpy_hwc(normalised.cmaps[i]),
                alpha=alpha[i, 0].numpy(),
                gt=capture_image(view, job.resolution) if is_target and view.image_path is not None else None,
                mask=_mask(view, job.resolution) if is_target and view.image_path is not None else None,
                overlap_score=view.overlap_score,
            )
        )
    read = time.perf_counter()
    header = PacketHeader(
        **key_fields(job),
        fit_key=job.fit_key,
        scale=normalised.scale,
        recipe=job.recipe,
        cmap_half=job.cmap_half,
    )
    n = len(job.references)
    write_packet(root, header, contents[:n], contents[n:])
    done = time.perf_counter()
    return JobStats(job.packet_id, len(views), rendered - start, read - rendered, done - read)


def init_worker(threads: int) -> None:
    """A spawned worker's initialiser: ``threads`` torch intra-op threads."""
    set_process_threads(threads)


def build_many(jobs: Sequence[PacketJob], root: Path, backend: str, device: str) -> list[JobStats]:
    """One worker batch: :func:`build_packet` of each job, in order."""
    return [build_packet(job, root, backend, device) for job in jobs]
