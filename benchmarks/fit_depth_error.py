"""Is the sparse fits' C-map error the C-map's definition, or where the Gaussians are?  (No training.)

The geometry audit (``benchmarks/sparse_geometry_audit.py``) finds the 3-view fits' C-maps off by 16 % of the
depth (median) on the fit's own training views.  The C-map (Eq. 1) composites Gaussian *centres*; a large
Gaussian's centre can lie far from where the pixel's ray meets it, so the error could come from the
definition rather than from the fit.  This script renders each packet's fit (``<scenes>/<walk>/fits/<fit_key>.ply``)
from the packet's views with two per-pixel depths and compares both with the true world's (tolerance-free):

* ``centre``: the C-map's own depth, Σ wᵢ zᵢ / Σ wᵢ over the camera-space depths zᵢ of the centres;
* ``ray_peak``: each Gaussian's depth of maximum density along the pixel's ray, linearised in the image plane
  around the centre's projection (the per-Gaussian depth plane of RaDe-GS, Zhang et al. 2024), composited with
  the same weights.  Along the ray ``s·(x, y, 1)`` of normalised image point ``(x, y)`` the density of a Gaussian
  ``N(μ, Σ)`` (camera frame) peaks at ``s*(x, y) = dᵀΣ⁻¹μ / dᵀΣ⁻¹d`` with ``d = (x, y, 1)``; at the centre's own
  point ``s* = μ_z`` and its gradient there is ``−(Σ⁻¹μ)_xy · μ_z² / (μᵀΣ⁻¹μ)``.  The linear plane
  ``z(x, y) = μ_z + g·((x, y) − (μ_x, μ_y)/μ_z)`` splits into three per-Gaussian constants
  ``(μ_z − g·c, g_x, g_y)`` that the rasteriser composites like colours; the pixel's depth is
  ``F₀ + x F₁ + y F₂`` over alpha.

Written here because no maintained CPU rasteriser renders per-Gaussian depth planes.  Per view group and per
role (the fit's training views = the packet's references; the targets), over pixels where both the fit
(alpha > 0.5) and the truth have a surface: the median and p90 of ``|z_fit − z_true| / z_true`` and the shares
of pixels more than 30 % too far and too near, with the true and fit depths of the too-far pixels (medians).

Usage (the packets and scenes of the audit)::

    python benchmarks/fit_depth_error.py --packets runs/sparse/packets --scenes runs/sparse/scenes --group n3 \\
        --packets-max 4 --out sparse_fit_depth_error
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine, write_result
from benchmarks.reference_ceiling import true_depths
from benchmarks.reproject_geometry import packet_and_world
from benchmarks.sparse_geometry_audit import Histogram
from setdiff_bench.cameras import Camera
from setdiff_bench.errors import SetDiffBenchError
from setdiff_bench.gaussians.backends import cpu_rasterizer, torch_ref
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import camera_tensors, render
from setdiff_bench.packets.store import PacketStore

#: Fit alpha above which a pixel has a fit surface (as the audit's C-map validity).
ALPHA_SURFACE = 0.5
#: A pixel is "too far" / "too near" when its relative depth error is beyond ± this.
GROSS = 0.3
DEPTHS = ("centre", "ray_peak")


def ray_peak_depth(model: GaussianModel, camera: Camera, tile_size: int = 8) -> torch.Tensor:
    """``(1, H, W)`` depth of each Gaussian's density peak along the pixel's ray, linearised in the image
    plane and composited with the render's weights, over alpha (module docstring; 0 where alpha is 0)."""
    w2c, K = camera_tensors(camera, model.means.device, torch.float64)
    rotation, translation = w2c[:3, :3], w2c[:3, 3]
    mean = model.means.detach().double() @ rotation.T + translation  # (N, 3) camera frame
    axes = (
        torch_ref.quaternion_to_rotation(model.quats.detach().double())
        * model.scales.detach().double()[:, None]
    )
    covariance = rotation @ (axes @ axes.transpose(1, 2)) @ rotation.T
    precision = torch.linalg.inv(covariance + 1e-10 * torch.eye(3, dtype=torch.float64))
    pulled = (precision @ mean[:, :, None])[:, :, 0]  # Σ⁻¹μ
    z = mean[:, 2]
    gradient = -pulled[:, :2] * (z.square() / (mean * pulled).sum(-1).clamp_min(1e-30))[:, None]
    offset = z - gradient[:, 0] * mean[:, 0] / z - gradient[:, 1] * mean[:, 1] / z
    features = torch.stack([offset, gradient[:, 0], gradient[:, 1]], dim=1).float()
    parameters = (model.means, model.quats, model.scales, model.opacities)
    projection = torch_ref.project(
        *(p.detach() for p in parameters), w2c.float(), K.float(), camera.width, camera.height
    )
    rasterize = cpu_rasterizer.rasterize if cpu_rasterizer.handles(features) else torch_ref.rasterize
    image, alpha = rasterize(projection, features, camera.width, camera.height, tile_size=tile_size)
    fx, fy, cx, cy = (float(K[0, 0]), float(K[1, 1]), float(K[0, 2]), float(K[1, 2]))
    x = (torch.arange(camera.width) + 0.5 - cx) / fx
    y = (torch.arange(camera.height) + 0.5 - cy) / fy
    composited = image[0] + x[None, :] * image[1] + y[:, None] * image[2]
    return (composited / alpha[0].clamp_min(1e-6))[None]


class RoleErrors:
    """Pooled relative depth errors of one depth definition on one role's pixels."""

    def __init__(self) -> None:
        self.histogram = Histogram()
        self.too_far = self.too_near = self.pixels = 0
        self.far_true: list[np.ndarray] = []
        self.far_fit: list[np.ndarray] = []

    def add(self, fit: torch.Tensor, truth: torch.Tensor) -> None:
        signed = ((fit - truth) / truth).numpy()
        self.histogram.add(np.abs(signed))
        far = signed > GROSS
        self.too_far += int(far.sum())
        self.too_near += int((signed < -GROSS).sum())
        self.pixels += signed.size
        self.far_true.append(truth.numpy()[far])
        self.far_fit.append(fit.numpy()[far])

    def summary(self) -> dict[str, Any]:
        far_true, far_fit = np.concatenate(self.far_true), np.concatenate(self.far_fit)
        return {
            **self.histogram.summary(),
            "share_too_far": round(self.too_far / max(1, self.pixels), 4),
            "share_too_near": round(self.too_near / max(1, self.pixels), 4),
            "too_far_true_depth_median": float(np.median(far_true)) if far_true.size else None,
            "too_far_fit_depth_median": float(np.median(far_fit)) if far_fit.size else None,
        }


def choose_packets(store: PacketStore, groups: list[str], per_walk: int) -> dict[tuple[str, str], list[str]]:
    """The first ``per_walk`` test packets of each walk in each of ``groups``, by ``(group, walk)``."""
    chosen: dict[tuple[str, str], list[str]] = {}
    for packet_id in store.packet_ids("test"):
        _, walk, group, _ = packet_id.split("__")
        if group in groups and len(chosen.setdefault((group, walk), [])) < per_walk:
            chosen[(group, walk)].append(packet_id)
    return chosen


def measure(
    store: PacketStore, scenes: Path, chosen: dict[tuple[str, str], list[str]]
) -> dict[str, dict[str, dict[str, RoleErrors]]]:
    """The pooled errors by group, depth definition and role of the ``chosen`` packets."""
    errors: dict[str, dict[str, dict[str, RoleErrors]]] = {}
    worlds: dict[str, GaussianModel] = {}
    fits: dict[Path, GaussianModel] = {}
    ids = [(group, pid) for (group, _), pids in sorted(chosen.items()) for pid in pids]
    for group, packet_id in tqdm(ids, desc="packets"):
        by_depth = errors.setdefault(
            group, {d: {r: RoleErrors() for r in ("references", "targets")} for d in DEPTHS}
        )
        packet, _, _, cameras, world = packet_and_world(store, packet_id, scenes, worlds)
        fit_key = str(store.rows(packet_id)["fit_key"].iloc[0])
        ply = scenes / packet.scene / "fits" / f"{fit_key}.ply"
        if ply not in fits:
            fits[ply] = read_ply(ply)
        model = fits[ply]
        depth_true, valid_true = true_depths(world.depth, world.alpha)
        with torch.no_grad():
            out = render(model, cameras, with_geometry=True, tile_size=8)
            depth = {
                "centre": out.depth / out.alpha.clamp_min(1e-6),
                "ray_peak": torch.stack([ray_peak_depth(model, camera) for camera in cameras]),
            }
        surface = valid_true & (out.alpha > ALPHA_SURFACE)
        for view in range(len(cameras)):
            role = "references" if view < len(packet.references) else "targets"
            keep = surface[view]
            for name in DEPTHS:
                by_depth[name][role].add(depth[name][view][keep], depth_true[view][keep])
    return errors


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", required=True, type=Path, help="packet store (test split)")
    parser.add_argument("--scenes", required=True, type=Path, help="the walks' folders (with fits/)")
    parser.add_argument("--group", action="append", help="view groups (default n3)")
    parser.add_argument("--packets-max", type=int, default=4, help="packets per walk and group")
    parser.add_argument("--out", default="sparse_fit_depth_error", help="result name in benchmarks/results/")
    args = parser.parse_args()
    torch.set_num_threads(1)
    groups = args.group or ["n3"]
    try:
        store = PacketStore(args.packets)
        chosen = choose_packets(store, groups, args.packets_max)
        if not chosen:
            parser.error(f"--packets {args.packets}: no test packets of groups {groups}")
        errors = measure(store, args.scenes, chosen)
    except (SetDiffBenchError, OSError) as error:  # a missing store, scene, fit or image: one line, exit 2
        print(f"fit_depth_error: error: {error}", file=sys.stderr)
        return 2
    payload = {
        "benchmark": "sparse_fit_depth_error",
        "command": "python benchmarks/fit_depth_error.py " + " ".join(sys.argv[1:]),
        "packets": {g: sum(len(v) for (gg, _), v in chosen.items() if gg == g) for g in groups},
        "gross_error": GROSS,
        "groups": {
            g: {d: {r: e.summary() for r, e in by_role.items()} for d, by_role in by_depth.items()}
            for g, by_depth in errors.items()
        },
        "machine": machine(),
    }
    print(f"wrote {write_result(args.out, payload)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
