"""A pseudo-view update: move the pseudo-views' cameras, render packets of the current model, enhance them.

The ``k``-th update (``k = 1, 2, ...``) puts every target's pseudo-view ``t = min(1, k · pose_fraction)`` of the
way from the target's nearest training pose to the target (:mod:`setdiff_bench.refit.poses`).  Each packet of
the plan keeps its targets (names, order); its references are re-chosen by Eq. 2 for the moved cameras among
the fit frames with the protocol's settings (:func:`setdiff_bench.packets.packing.reference_views`) while
``t < 1``, and are the packet's own (as ``prepare`` chose them) at ``t = 1``.  The enhancer sees each packet
exactly as it would in ``run`` (:func:`~setdiff_bench.refit.packets.current_packet`); its output is checked and
put on the 8-bit grid, and replaces the pseudo-views of the loop.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import torch

from setdiff_bench.evaluation.packet_scoring import check_output
from setdiff_bench.evaluation.scoring import quantize
from setdiff_bench.gaussians.fit import FitView
from setdiff_bench.packets.jobs import PacketJob
from setdiff_bench.packets.packing import reference_views
from setdiff_bench.protocols import Protocol
from setdiff_bench.refit.loop import RefitLoop
from setdiff_bench.refit.packets import ReferenceCaptures, current_packet
from setdiff_bench.refit.poses import nearest_poses, pseudo_cameras
from setdiff_bench.refit.settings import RefitSettings
from setdiff_bench.types import Frame


class PseudoViewUpdater:
    """Rebuilds a loop's pseudo-views (module docstring).

    Args:
        protocol: the protocol (its ``[references]`` rule and images settings).
        fit_frames: the fit frames references are chosen among.
        jobs: the plan's packets, targets without ground truth.
        d_max: the scene's largest camera-centre distance (Eq. 2).
        enhancer: the built enhancer.
        backend: renderer.
        settings: the schedule.
        training_views: the loop's real views (nearest poses are taken among their cameras).
    """

    def __init__(
        self,
        protocol: Protocol,
        fit_frames: Sequence[Frame],
        jobs: Sequence[PacketJob],
        d_max: float,
        enhancer: Any,
        backend: str,
        settings: RefitSettings,
        training_views: Sequence[FitView],
    ) -> None:
        self.protocol, self.fit_frames, self.jobs, self.d_max = protocol, list(fit_frames), list(jobs), d_max
        self.enhancer, self.backend, self.settings = enhancer, backend, settings
        self.training = [v.camera for v in training_views]
        self.nearest = [nearest_poses([v.camera for v in job.targets], self.training) for job in self.jobs]
        resolution = self.jobs[0].resolution
        self.captures = ReferenceCaptures(resolution)

    def fraction(self, update: int) -> float:
        """``t`` of the ``update``-th update (1-based)."""
        return min(1.0, update * self.settings.pose_fraction)

    def __call__(self, loop: RefitLoop) -> float:
        """Rebuild ``loop``'s pseudo-views for its next update; returns the seconds spent in ``enhance()``."""
        t = self.fraction(loop.updates_done + 1)
        model = loop.trainer.params.model().detach()
        names, cameras, images, enhance_s = [], [], [], 0.0
        for job, nearest in zip(self.jobs, self.nearest, strict=True):
            moved = pseudo_cameras([v.camera for v in job.targets], self.training, nearest, t)
            references = job.references
            if t < 1.0:
                n_ref, resolution = len(job.references), job.resolution
                references = reference_views(
                    self.protocol, moved, self.fit_frames, n_ref, self.d_max, resolution
                )
            packet = current_packet(job, model, moved, references, self.captures, self.backend)
            tick = time.perf_counter()
            with torch.no_grad():
                output = self.enhancer.enhance(packet)
            enhance_s += time.perf_counter() - tick
            images.append(quantize(check_output(output, packet, self.enhancer.name)))
            names += [v.frame for v in job.targets]
            cameras += moved
        loop.set_pseudo_views(names, cameras, torch.cat(images))
        return enhance_s
