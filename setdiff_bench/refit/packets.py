"""Packets of the current model, in memory: what an enhancer sees inside a refit loop.

A refit update hands the enhancer a :class:`~setdiff_bench.types.Packet` built as ``prepare`` builds one
(:mod:`setdiff_bench.packets.worker`), from the model being refitted instead of the fit on disk: the targets'
RGB (on the 8-bit grid, as a stored packet's PNG), C-maps and alphas and the references' C-maps and alphas
rendered in one call each, the references' clean captures at the working resolution, everything normalised
into the first target's frame at unit extent (:func:`setdiff_bench.geometry.normalize_packet`).  Nothing is
written.  Targets carry no ground truth: a refit's target views are built from cameras alone
(:func:`target_view` drops a recorded target's capture and mask paths before anything could read them).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.evaluation.scoring import quantize
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.geometry import normalize_packet
from setdiff_bench.io.images import to_tensor_chw
from setdiff_bench.packets.jobs import PacketJob
from setdiff_bench.packets.worker import capture_image
from setdiff_bench.packets.working_view import ViewJob
from setdiff_bench.types import Packet, ViewSet


def target_view(view: ViewJob) -> ViewJob:
    """A target view without its capture and mask: cameras and names are all a refit may know of a target."""
    return dataclasses.replace(view, image_path=None, mask_path=None, invert_mask=False)


class ReferenceCaptures:
    """The clean captures of reference views at the working resolution ``(3, H, W)``, read once per frame."""

    def __init__(self, resolution: tuple[int, int]) -> None:
        self.resolution = resolution
        self._images: dict[str, torch.Tensor] = {}

    def __call__(self, view: ViewJob) -> torch.Tensor:
        if view.frame not in self._images:
            if view.image_path is None:
                raise ValueError(f"reference {view.frame!r} has no capture")
            self._images[view.frame] = to_tensor_chw(capture_image(view, self.resolution))
        return self._images[view.frame]


def current_packet(
    job: PacketJob,
    model: GaussianModel,
    targets: Sequence[Camera],
    references: Sequence[ViewJob],
    captures: ReferenceCaptures,
    backend: str,
) -> Packet:
    """The packet of ``job`` with its targets at ``targets`` (world cameras at the working resolution, in
    ``job.targets`` order and names) and ``references`` (fit frames), rendered from ``model``.

    Returns:
        A :class:`Packet` named by ``job``'s key: references ``(N, 3, H, W)`` clean captures, targets
        ``(M, 3, H, W)`` renders on the 8-bit grid, C-maps and alphas of both, normalised cameras.
    """
    options = dict(backend=backend, cmap_bound=job.cmap_bound, cmap_center=job.cmap_center)
    with torch.no_grad():
        refs = render(model, [v.camera for v in references], **options)
        out = render(model, list(targets), **options)
    cameras = [v.camera for v in references] + list(targets)
    cmaps = torch.cat([refs.cmap.float().cpu(), out.cmap.float().cpu()])
    alphas = torch.cat([refs.alpha.float().cpu(), out.alpha.float().cpu()])
    normalised = normalize_packet(cameras, cmaps, len(references), alphas=alphas)
    n = len(references)
    reference_set = ViewSet(
        names=tuple(v.frame for v in references),
        images=torch.stack([captures(v) for v in references]),
        cmaps=normalised.cmaps[:n],
        alphas=alphas[:n],
        cameras=normalised.cameras[:n],
        timestamps_us=tuple(v.timestamp_us for v in references),
    )
    target_set = ViewSet(
        names=tuple(v.frame for v in job.targets),
        images=quantize(out.rgb.float().cpu()),
        cmaps=normalised.cmaps[n:],
        alphas=alphas[n:],
        cameras=normalised.cameras[n:],
        timestamps_us=tuple(v.timestamp_us for v in job.targets),
    )
    return Packet.from_key(
        job,
        reference_set,
        target_set,
        scale=normalised.scale,
        metadata={
            "fit_key": job.fit_key,
            "recipe": "refit",
            "reference_scores": tuple(float(v.overlap_score or 0.0) for v in references),
        },
    )
