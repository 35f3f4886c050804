"""One entry point to render Gaussians: RGB, C-map (Eq. 1), depth and alpha from one compositing pass.

The C-map is exactly Eq. 1 of the paper, ``c(u, v) = Σᵢ αᵢ Πⱼ<ᵢ(1 − αⱼ) xᵢ`` over Gaussian centres
``xᵢ`` in world coordinates: *not* divided by alpha, zero where nothing contributes.  Depth is the
same accumulation of camera-space z (gsplat's ``"D"`` mode); divide by ``alpha`` for the expected
depth.  RGB, C-map and depth are 7 feature channels composited with one set of weights.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.backends import cpu_rasterizer, gsplat_backend, torch_ref
from setdiff_bench.gaussians.backends.common import RenderOptions, RenderOutput, clip_centres
from setdiff_bench.gaussians.model import GaussianModel

Backend = Literal["torch", "gsplat"]

__all__ = ["Backend", "camera_tensors", "render"]


def render(
    gaussians: GaussianModel,
    cameras: Sequence[Camera] | Camera,
    backend: Backend = "torch",
    *,
    with_geometry: bool = True,
    sh_degree: int | None = None,
    background: Sequence[float] | None = None,
    cmap_bound: float | None = None,
    cmap_center: Sequence[float] = (0.0, 0.0, 0.0),
    near: float = 0.01,
    far: float = 1e10,
    eps2d: float = 0.3,
    tile_size: int = 8,
) -> RenderOutput:
    """Render Gaussians from one or more cameras of the same size.

    Args:
        gaussians: the model (its device decides where the torch backend runs).
        cameras: one camera or a sequence of cameras with identical width and height.
        backend: ``"torch"`` (pure PyTorch, CPU or GPU, differentiable) or ``"gsplat"`` (CUDA).
        with_geometry: also composite the C-map and depth (same pass, 7 channels instead of 3).
        sh_degree: active SH degree (default: the model's).
        background: RGB added where transmittance remains (default black).
        cmap_bound: if set, Gaussian centres are clipped to the box ``cmap_center ± cmap_bound``
            before compositing the C-map (the paper's "clipped by scene scale"); rendering is unaffected.
        near, far: depth culling planes (scene units).  eps2d: 2D dilation (px²).  tile_size: pixels.

    Returns:
        :class:`RenderOutput` with tensors on the model's device.
    """
    cams = [cameras] if isinstance(cameras, Camera) else list(cameras)
    if not cams:
        raise UsageError("render() needs at least one camera")
    sizes = {(c.height, c.width) for c in cams}
    if len(sizes) != 1:
        raise UsageError(f"all cameras of one render call must share a size, got {sorted(sizes)}")
    options = RenderOptions(
        with_geometry=with_geometry,
        sh_degree=sh_degree,
        background=background,
        cmap_bound=cmap_bound,
        cmap_center=cmap_center,
        near=near,
        far=far,
        eps2d=eps2d,
        tile_size=tile_size,
    )
    if backend == "gsplat":
        return gsplat_backend.render(gaussians, cams, options)
    if backend != "torch":
        raise UsageError(f"unknown render backend {backend!r}; use 'torch' or 'gsplat'")
    return _render_torch(gaussians, cams, options)


def camera_tensors(
    camera: Camera, device: torch.device, dtype: torch.dtype
) -> tuple[torch.Tensor, torch.Tensor]:
    """``(w2c (4, 4), K (3, 3))`` of a camera as tensors (pinhole; distortion is not rendered)."""
    return (
        torch.tensor(np.array(camera.w2c), device=device, dtype=dtype),
        torch.tensor(np.array(camera.K), device=device, dtype=dtype),
    )


def _render_torch(g: GaussianModel, cams: list[Camera], options: RenderOptions) -> RenderOutput:
    device, dtype = g.means.device, g.means.dtype
    height, width = cams[0].height, cams[0].width
    scales, opacities, quats = g.scales, g.opacities, g.quats
    near, far, eps2d = options.near, options.far, options.eps2d
    cmap_points = (
        clip_centres(g.means, options.cmap_bound, options.cmap_center) if options.with_geometry else None
    )
    rgbs, cmaps, depths, alphas, meta = [], [], [], [], []
    for cam in cams:
        w2c, K = camera_tensors(cam, device, dtype)
        proj = torch_ref.project(
            g.means, quats, scales, opacities, w2c, K, width, height, near=near, far=far, eps2d=eps2d
        )
        center = -w2c[:3, :3].T @ w2c[:3, 3]
        colors = g.colors(center, options.sh_degree)
        if options.with_geometry:
            features = torch.cat([colors, cmap_points, proj.depths[:, None]], dim=1)
        else:
            features = colors
        rasterize = cpu_rasterizer.rasterize if cpu_rasterizer.handles(features) else torch_ref.rasterize
        image, alpha = rasterize(proj, features, width, height, tile_size=options.tile_size)
        rgb = image[:3]
        if options.background is not None:
            bg = torch.as_tensor(list(options.background), device=device, dtype=dtype).view(3, 1, 1)
            rgb = rgb + (1.0 - alpha) * bg
        rgbs.append(rgb)
        alphas.append(alpha)
        if options.with_geometry:
            cmaps.append(image[3:6])
            depths.append(image[6:7])
        meta.append({"means2d": proj.means2d, "radii": proj.radii, "visible": proj.visible})
    return RenderOutput(
        rgb=torch.stack(rgbs),
        cmap=torch.stack(cmaps) if options.with_geometry else None,
        depth=torch.stack(depths) if options.with_geometry else None,
        alpha=torch.stack(alphas),
        meta=meta,
    )
