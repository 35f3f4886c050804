"""Ground-truth capture: render every frame of every drive from the world, with dynamic masks.

One render call per timestep draws the rig's three cameras together (the static world plus the
drive's moving vehicle posed at that timestamp).  Dynamic masks come from a second render of the
vehicle alone: a pixel is dynamic where the vehicle covers it (alpha > 0.3) and is not hidden behind
static surfaces (its expected depth is within 5 % + 0.3 m of the full render's); the mask is dilated
by ``mask_dilation_px`` pixels, as segmentation masks are in practice.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import cv2
import numpy as np
import torch

from setdiff_bench.cameras import Camera
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.synthetic.layout import MovingVehicle
from setdiff_bench.synthetic.rig import CameraSpec, Traversal, rig_camera, timestamp_us
from setdiff_bench.synthetic.soup import quaternion_multiply, yaw_quaternion

DYNAMIC_ALPHA = 0.3


@dataclass
class CapturedFrame:
    """One rendered ground-truth frame.

    Attributes:
        name: ``{traversal}_{camera}_{index:03d}.png``.
        rgb: ``(H, W, 3)`` float32 in [0, 1].
        static_mask: ``(H, W)`` bool, True = static (evaluate), False = moving vehicle.
        depth: ``(H, W)`` float32 expected camera-space depth in metres (0 where alpha < 0.5).
    """

    name: str
    traversal: str
    sensor: str
    index: int
    timestamp_us: int
    camera: Camera
    rgb: np.ndarray
    static_mask: np.ndarray
    depth: np.ndarray

    @property
    def has_dynamic(self) -> bool:
        return not bool(self.static_mask.all())


def frame_name(traversal: str, sensor: str, index: int) -> str:
    return f"{traversal}_{sensor}_{index:03d}.png"


def posed_vehicle(template: GaussianModel, vehicle: MovingVehicle, time_s: float) -> GaussianModel:
    """The vehicle template moved to its pose at ``time_s``: ``x = x_start + speed · t``, heading ``car.yaw``."""
    yaw = vehicle.car.yaw
    c, s = math.cos(yaw), math.sin(yaw)
    rotation = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]], dtype=template.means.dtype)
    position = torch.tensor(
        [vehicle.x_start + vehicle.speed_mps * time_s, vehicle.car.y, 0.0], dtype=template.means.dtype
    )
    q = torch.from_numpy(quaternion_multiply(yaw_quaternion(yaw)[None], template.quats.double().numpy())).to(
        template.quats.dtype
    )
    return GaussianModel(
        template.means @ rotation.T + position, q, template.log_scales, template.opacity_logits, template.sh
    )


def concat_models(a: GaussianModel, b: GaussianModel) -> GaussianModel:
    """Both sets of Gaussians in one model (``a`` first; SH degrees must match)."""
    return GaussianModel(**{k: torch.cat([va, b.tensors()[k]]) for k, va in a.tensors().items()})


def expected_depth(depth: torch.Tensor, alpha: torch.Tensor, min_alpha: float = 0.5) -> torch.Tensor:
    """``(V, 1, H, W)`` accumulated depth / alpha, 0 where alpha < ``min_alpha``."""
    return torch.where(alpha > min_alpha, depth / alpha.clamp_min(1e-6), torch.zeros_like(depth))


def capture_drive(
    static: GaussianModel,
    traversal: Traversal,
    rig: Sequence[CameraSpec],
    width: int,
    height: int,
    *,
    vehicle: tuple[GaussianModel, MovingVehicle] | None = None,
    tile_size: int = 8,
    mask_dilation_px: int = 2,
    device: str | torch.device = "cpu",
) -> Iterator[CapturedFrame]:
    """Render every timestep of ``traversal`` with all cameras of ``rig``, in timestep order.

    ``device``: where the (pure PyTorch) rasteriser runs; results come back as CPU numpy arrays.
    """
    static = static.to(device)
    for step in range(traversal.num_steps):
        cameras = [rig_camera(traversal, step, spec, width, height) for spec in rig]
        stamp = timestamp_us(step)
        model = static
        moving = None
        if vehicle is not None:
            moving = posed_vehicle(vehicle[0], vehicle[1], stamp / 1e6).to(device)
            model = concat_models(static, moving)
        with torch.no_grad():
            out = render(model, cameras, with_geometry=True, tile_size=tile_size)
            depth = expected_depth(out.depth, out.alpha)
            dynamic = torch.zeros_like(out.alpha, dtype=torch.bool)
            if moving is not None:
                car = render(moving, cameras, with_geometry=True, tile_size=tile_size)
                car_depth = expected_depth(car.depth, car.alpha, 1e-3)
                dynamic = (car.alpha > DYNAMIC_ALPHA) & (car_depth <= depth * 1.05 + 0.3)
        for v, spec in enumerate(rig):
            mask = dynamic[v, 0].cpu().numpy().astype(np.uint8)
            if mask.any() and mask_dilation_px > 0:
                kernel = np.ones((2 * mask_dilation_px + 1, 2 * mask_dilation_px + 1), np.uint8)
                mask = cv2.dilate(mask, kernel)
            yield CapturedFrame(
                name=frame_name(traversal.name, spec.name, step),
                traversal=traversal.name,
                sensor=spec.name,
                index=step,
                timestamp_us=stamp,
                camera=cameras[v],
                rgb=out.rgb[v].clamp(0, 1).permute(1, 2, 0).contiguous().cpu().numpy(),
                static_mask=mask == 0,
                depth=depth[v, 0].cpu().numpy(),
            )
