"""Cycle reconstruction's training views: the ``cycle`` training-pair recipe (issue 41, Difix3D+).

The scene's own fit A is rendered at every recorded camera moved ``S`` metres along its right axis (OpenCV
+x, :func:`~setdiff_bench.packets.trajectory.shifted`: lateral for a forward-facing camera), and those renders
are the only training views of a second 3DGS B (:meth:`setdiff_bench.packets.fits.FitSource.ensure`).  B
rendered back at the recorded cameras shows what a reconstruction from a neighbouring trajectory gets wrong,
while the recorded captures stay its ground truth.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch

from setdiff_bench.gaussians.fit import FitConfig, FitView
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.packets.trajectory import shifted


def cycle_views(
    model: GaussianModel,
    views: Sequence[FitView],
    shift_m: float,
    config: FitConfig,
    *,
    label: str,
    device: str = "cpu",
) -> list[FitView]:
    """The training views of the cycle's second fit: ``model`` rendered at each view's camera shifted sideways.

    Args:
        model: the scene's fit A (world frame).
        views: the recorded frames' fit views (:func:`~setdiff_bench.gaussians.fit.load_fit_views`: pinhole
            cameras at the fit's working scale); only their names and cameras are used, never their images.
        shift_m: metres (scene units) along each camera's right axis (OpenCV +x); negative: to the left.
        config: the fit configuration of B; its ``background`` (RGB in [0, 1]) and, on the CPU, ``tile_size``
            render A as the fit renders.
        label: the recipe label (``cycle2m``); view ``NAME`` becomes ``NAME@<label>``.
        device: ``cpu`` (torch rasteriser) or ``cuda`` (gsplat), as the fit picks.

    Returns:
        One :class:`FitView` per view, in order: the shifted camera (same intrinsics, size and orientation), its
        render ``(3, H, W)`` float32 in [0, 1] on the CPU at full SH degree, and no mask (every pixel counts).
    """
    backend = "gsplat" if torch.device(device).type == "cuda" else "torch"
    options = {"tile_size": config.tile_size} if backend == "torch" else {}
    model = model.to(device)
    out = []
    with torch.no_grad():
        for view in views:
            camera = shifted(view.camera, shift_m)
            rendered = render(
                model, [camera], backend, with_geometry=False, background=config.background, **options
            )
            image = rendered.rgb[0].float().clamp(0.0, 1.0).cpu().contiguous()
            out.append(FitView(f"{view.name}@{label}", camera, image, None))
    return out
