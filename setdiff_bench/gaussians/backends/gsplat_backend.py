"""CUDA rendering through ``gsplat.rasterization`` with the same outputs as the torch backend.

RGB and the C-map go through gsplat as 6 feature channels (``sh_degree=None``; colours are
evaluated from SH by :meth:`GaussianModel.colors`, identical to the torch backend), and
``render_mode="RGB+D"`` appends accumulated depth: one rasterisation pass.  gsplat's conventions
differ from the torch backend in one documented place: it clamps α at 0.999 instead of 0.99.
"""

from __future__ import annotations

import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.errors import UsageError
from setdiff_bench.gaussians.backends.common import RenderOptions, RenderOutput, clip_centres
from setdiff_bench.gaussians.model import GaussianModel


def render(gaussians: GaussianModel, cameras: list[Camera], options: RenderOptions) -> RenderOutput:
    """Render with gsplat; see :func:`setdiff_bench.gaussians.render.render` for the arguments."""
    try:
        import gsplat
    except ImportError as exc:
        raise UsageError(
            "the gsplat backend needs the 'gpu' extra: pip install 'setdiff-bench[gpu]'"
        ) from exc
    if not torch.cuda.is_available():
        raise UsageError("the gsplat backend needs a CUDA GPU; use backend='torch' on the CPU")
    g = gaussians if gaussians.device.type == "cuda" else gaussians.to("cuda")
    device, dtype = g.means.device, torch.float32
    g = g.to(device, dtype)
    height, width = cameras[0].height, cameras[0].width
    viewmats = torch.tensor(np.stack([c.w2c for c in cameras]), device=device, dtype=dtype)
    Ks = torch.tensor(np.stack([c.K for c in cameras]), device=device, dtype=dtype)
    centers = torch.linalg.inv(viewmats)[:, :3, 3]
    colors = torch.stack([g.colors(center, options.sh_degree) for center in centers])  # (C, N, 3)
    if options.with_geometry:
        points = clip_centres(g.means, options.cmap_bound, options.cmap_center)
        features = torch.cat([colors, points.expand(len(cameras), -1, -1)], dim=-1)
        mode = "RGB+D"
    else:
        features, mode = colors, "RGB"
    renders, alphas, meta = gsplat.rasterization(
        g.means,
        g.quats,
        g.scales,
        g.opacities,
        features,
        viewmats,
        Ks,
        width,
        height,
        near_plane=options.near,
        far_plane=options.far,
        eps2d=options.eps2d,
        sh_degree=None,
        packed=False,
        tile_size=16,
        backgrounds=None,
        render_mode=mode,
        rasterize_mode="classic",
    )
    renders = renders.permute(0, 3, 1, 2)  # (C, D, H, W)
    alpha = alphas.permute(0, 3, 1, 2)
    rgb = renders[:, :3]
    if options.background is not None:
        rgb = rgb + (1.0 - alpha) * torch.as_tensor(
            list(options.background), device=device, dtype=dtype
        ).view(1, 3, 1, 1)
    means2d = meta.get("means2d")
    if means2d is not None and means2d.requires_grad:
        means2d.retain_grad()
    per_camera = [
        {
            "means2d": CameraScreenPoints(means2d, i) if means2d is not None else None,
            "radii": meta["radii"][i],
            "visible": (meta["radii"][i] > 0).reshape(len(g), -1).any(-1),
        }
        for i in range(len(cameras))
    ]
    return RenderOutput(
        rgb=rgb,
        cmap=renders[:, 3:6] if options.with_geometry else None,
        depth=renders[:, 6:7] if options.with_geometry else None,
        alpha=alpha,
        meta=per_camera,
    )


class CameraScreenPoints:
    """Camera ``index``'s slice of gsplat's ``(C, N, 2)`` ``means2d``, with a working ``.grad``.

    A slice of a tensor never receives ``.grad`` itself (only the tensor ``retain_grad`` was called
    on does), so the densification statistics read the slice of the full tensor's gradient here.
    """

    def __init__(self, full: torch.Tensor, index: int) -> None:
        self.full = full
        self.index = index

    @property
    def grad(self) -> torch.Tensor | None:
        """``(N, 2)`` gradient of this camera's screen-space centres, or ``None`` before backward."""
        return None if self.full.grad is None else self.full.grad[self.index]

    def detach(self) -> torch.Tensor:
        return self.full[self.index].detach()
