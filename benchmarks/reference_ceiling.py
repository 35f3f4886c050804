"""How much can more references give a target at all?  The information ceiling of the set-size ablation.

Issue 15 asks that SetDiff's set-size ablation gain ≥ 0.3 dB PSNR from 1 + 1 to 3 + 1 views.  A
reference can only help where it *sees* what the target shows: it carries that content cleanly (the
references are ground-truth captures), while everything else the model must infer from the render
itself, as a single-image enhancer does.  On synthetic packets the world is known, so this script
measures, per target and for the first ``K`` references (the packet's Eq. 2 order, the same subsets
``ablate setsize`` feeds the model), with the **true** geometry:

* ``seen_K``: the share of the target's static pixels that at least one of the first K references
  sees.  The world is itself made of Gaussians, so a pixel's surface is its expected depth (composited
  depth / alpha, where alpha > 0.5): the target pixel's point ``X`` on its ray at that depth projects
  inside the reference at depth ``z``, and the reference's own inverse expected depth, interpolated
  bilinearly from four neighbours that all have a surface, is within ``tolerance`` (relative) of
  ``1/z``.  Inverse depth is exact under bilinear interpolation on planes, so a road seen at a grazing
  angle is not rejected for falling between reference pixels; an occluder in front of ``X`` makes the
  reference's inverse depth larger and rejects it.  Expected depth of overlapping Gaussians differs
  from view to view by a few per cent, so no tolerance is exactly right: the script reports several
  (``--tolerance``, repeatable).  Sky (no surface) is never seen;
* ``visible_truth_K``: PSNR (dB) of the render with every pixel that a first-K reference sees replaced
  by the ground truth — a method that recovered seen content perfectly and left the rest as rendered;
* ``copy_K``: PSNR of the render with seen pixels replaced by the Eq. 2-weighted blend of the seeing
  references' colours there (bilinear) — a geometry-only copy with true geometry;
* ``identity``: PSNR of the render;
* ``error_share_K``: the share of the render's squared error (static pixels) that lies on the pixels
  the first K references see, ``1 − 10^(−(visible_truth_K − identity)/10)`` per target.

Every measure is also given for ``all`` the packet's references (``seen_all``, ``visible_truth_all``,
``error_share_all``): the share of the render's error that the references see at all.

``visible_truth_K − visible_truth_1`` is what the extra references can add: on the pixels that
references 2…K see and reference 1 does not, at most the render's whole error.  An enhancer that also
improves unseen pixels from the render alone (as every trained model here does) leaves less error on the
newly seen pixels, so its gain from the extra references is smaller still.  Per-image PSNR over the
packet's static pixels (masks), then means per group and over all targets, as the leaderboard does.

Usage (the store the shipped models were trained from; its test split holds the demo's scenes)::

    python benchmarks/reference_ceiling.py --packets runs/more/packets --scenes runs/more/scenes \\
        --references 1 --references 2 --references 3 --references 8 \\
        --tolerance 0.01 --tolerance 0.03 --tolerance 0.1 --out benchmarks/results/reference_ceiling.json

The sparse-view scenes (``synth --preset sparse``, DL3DV layout, protocol
``dl3dv_sparse_synthetic``; groups ``n3`` / ``n6`` / ``n9``) work the same way: the world is
rebuilt from each scene's ``scene.json`` whichever kind it is (:func:`setdiff_bench.synthetic.sparse.static_world`)::

    python benchmarks/reference_ceiling.py --packets runs/sparse/packets --scenes runs/sparse/scenes \
        --references 1 --references 2 --references 3 --references 6 \
        --tolerance 0.01 --tolerance 0.03 --tolerance 0.1 --out benchmarks/results/sparse_reference_ceiling.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine
from benchmarks.reproject_geometry import (
    add_store_arguments,
    masked_psnr,
    packet_and_world,
    with_true_geometry,
)
from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.reproject import (
    ReprojectConfig,
    blend_weights,
    cmap_points,
    project,
)
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.geometry import pixel_centers
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.types import Packet

#: Relative inverse-depth tolerance of the visibility test (module docstring).
TOLERANCE = 0.03


def reference_samples(
    points: torch.Tensor,
    cameras: list[Camera],
    inverse_depths: torch.Tensor,
    images: torch.Tensor,
    window: int = 1,
) -> tuple[torch.Tensor, torch.Tensor]:
    """For ``P`` surface points ``(P, 3)`` and ``N`` references: ``(N, P)`` the relative inverse-depth
    mismatch ``|1/z_ref − 1/z| · z`` where the point projects inside the reference onto four pixels with a
    surface (``inf`` elsewhere) — a reference sees a point when it is within the tolerance (module
    docstring) — and ``(N, 3, P)`` the references' colours there (bilinear).

    With ``window`` = ``w`` > 1 (odd), the mismatch is the smallest of the bilinear one and those of the
    ``w × w`` reference pixels nearest the projection (each pixel's own inverse depth, where it has a
    surface): a point counts as seen when the reference shows a surface at its depth within ``(w − 1) / 2``
    pixels of where it projects (module docstring, "window").

    Args:
        inverse_depths: ``(N, 2, H, W)``: each reference's inverse depth × validity, and its validity.
        images: ``(N, 3, H, W)`` the references' ground-truth images in [0, 1].
        window: odd neighbourhood size (1 = the bilinear test alone).
    """
    height, width = images.shape[-2:]
    uv, z = project(tuple(cameras), points)  # (N, P, 2), (N, P)
    inside = (z > 0) & (uv[..., 0] >= 0.5) & (uv[..., 0] <= width - 0.5)
    inside &= (uv[..., 1] >= 0.5) & (uv[..., 1] <= height - 0.5)
    grid = torch.stack([uv[..., 0] * (2.0 / width) - 1.0, uv[..., 1] * (2.0 / height) - 1.0], dim=-1)
    grid = torch.where(inside[..., None], grid, torch.zeros_like(grid))[:, None]  # (N, 1, P, 2)
    sampled = F.grid_sample(inverse_depths, grid, mode="bilinear", align_corners=False)[:, :, 0]
    colours = F.grid_sample(images, grid, mode="bilinear", align_corners=False)[:, :, 0]
    inverse = 1.0 / z.clamp_min(1e-6)
    mismatch = (sampled[:, 0] - inverse).abs() / inverse
    usable = inside & (sampled[:, 1] > 1.0 - 1e-4)
    mismatch = torch.where(usable, mismatch, torch.full_like(mismatch, float("inf")))
    half = (window - 1) // 2
    if half > 0:
        col = torch.floor(uv[..., 0]).long()  # the pixel the projection falls in (pixel centres at +0.5)
        row = torch.floor(uv[..., 1]).long()
        flat = inverse_depths.flatten(2)  # (N, 2, H·W)
        for dy in range(-half, half + 1):
            for dx in range(-half, half + 1):
                c, r = col + dx, row + dy
                ok = inside & (c >= 0) & (c < width) & (r >= 0) & (r < height)
                index = torch.where(ok, r * width + c, torch.zeros_like(c))  # (N, P)
                values = torch.gather(flat, 2, index[:, None].expand(-1, 2, -1))  # (N, 2, P)
                ok &= values[:, 1] > 0.5
                near = torch.where(
                    ok, (values[:, 0] - inverse).abs() / inverse, torch.full_like(mismatch, float("inf"))
                )
                mismatch = torch.minimum(mismatch, near)
    return mismatch, colours


def share(mask: torch.Tensor, static: torch.Tensor) -> float:
    """The share of the static pixels ``(P,)`` bool where ``mask`` ``(P,)`` bool holds."""
    return float((mask & static).float().sum() / static.float().sum().clamp_min(1))


def true_depths(world_depth: torch.Tensor, world_alpha: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Expected depth ``(V, 1, H, W)`` (composited depth / alpha, 0 where invalid) and validity (alpha above
    the reproject threshold and depth > 0) of the true world rendered from the packet's views."""
    alphas = world_alpha.float()
    valid = alphas > ReprojectConfig().alpha_threshold
    depths = torch.where(valid, world_depth.float() / alphas.clamp_min(1e-6), torch.zeros_like(alphas))
    return depths, valid & (depths > 0)


def cmap_depths(
    cameras: list[Camera], cmaps: torch.Tensor, alphas: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The same as :func:`true_depths` from C-maps ``(V, 3, H, W)`` and alphas in the frame of ``cameras``
    (the fit's, moved to the world frame): the camera-frame depth of each pixel's point C-map / alpha."""
    points, valid = cmap_points(cmaps.float(), alphas.float(), ReprojectConfig().alpha_threshold)
    depths = torch.zeros_like(alphas, dtype=torch.float32)
    for v, camera in enumerate(cameras):
        row = torch.from_numpy(np.array(camera.R[2], dtype=np.float64))  # copies: camera arrays are read-only
        flat = points[v].reshape(3, -1).double()
        depths[v, 0] = ((row @ flat) + float(camera.t[2])).reshape(depths.shape[-2:]).float()
    depths = torch.where(valid, depths, torch.zeros_like(depths))
    return depths, valid & (depths > 0)


def copy_measures(
    packet: Packet,
    truth: torch.Tensor,
    masks: torch.Tensor,
    cameras: list[Camera],
    depths: torch.Tensor,
    valid: torch.Tensor,
    weights: torch.Tensor,
    sizes: list[int],
    tolerances: list[float],
    window: int = 1,
) -> tuple[list[dict[str, Any]], list[torch.Tensor]]:
    """The ceiling's records of one packet with the given per-view geometry (module docstring): the target
    pixels' points on their rays at ``depths`` and the references' surfaces at theirs.

    Args:
        cameras: the packet's world cameras, references first.
        depths, valid: ``(V, 1, H, W)`` per view (:func:`true_depths`, or :func:`cmap_depths` of the fit).
        weights: ``(M, N)`` Eq. 2 weights (:func:`setdiff_bench.enhancers.reproject.blend_weights`).

    Returns:
        one record per target and tolerance, and per target the ``(N, H·W)`` relative inverse-depth mismatch
        (:func:`reference_samples`; ``inf`` where the target pixel has no point).
    """
    n, renders = len(packet.references), packet.targets.images.float()
    inverse_depths = torch.cat(
        [
            torch.where(valid[:n], 1.0 / depths[:n].clamp_min(1e-6), torch.zeros_like(depths[:n])),
            valid[:n].float(),
        ],
        dim=1,
    )
    images = packet.references.images.float()
    records, mismatches = [], []
    pixels = pixel_centers(packet.height, packet.width)
    for m in range(len(packet.targets)):
        target_depth = depths[n + m].reshape(-1).double().numpy()
        target_points = torch.from_numpy(cameras[n + m].unproject(pixels, target_depth)).float()
        target_valid = valid[n + m].reshape(-1)
        static = masks[m].reshape(-1)
        flat_truth, flat_render = truth[m].reshape(3, -1), renders[m].reshape(3, -1)
        mismatch, colours = reference_samples(target_points, cameras[:n], inverse_depths, images, window)
        mismatch = torch.where(target_valid[None], mismatch, torch.full_like(mismatch, float("inf")))
        mismatches.append(mismatch)
        common = {
            "packet_id": packet.packet_id,
            "group": packet.group,
            "target": m,
            "identity": masked_psnr(flat_render, flat_truth, static[None]),
            "surface": share(target_valid, static),
            "references": n,
        }
        for tolerance in tolerances:
            seen_by = mismatch <= tolerance
            record: dict[str, Any] = {**common, "tolerance": tolerance}
            for size in [*sizes, "all"]:
                k = n if size == "all" else min(int(size), n)
                w = weights[m, :k, None] * seen_by[:k]  # (k, P)
                seen = w.sum(dim=0) > 0
                copied = (colours[:k] * w[:, None]).sum(dim=0) / w.sum(dim=0).clamp_min(1e-12)
                record[f"seen_{size}"] = share(seen, static)
                record[f"visible_truth_{size}"] = masked_psnr(
                    torch.where(seen[None], flat_truth, flat_render), flat_truth, static[None]
                )
                record[f"copy_{size}"] = masked_psnr(
                    torch.where(seen[None], copied, flat_render).clamp(0, 1), flat_truth, static[None]
                )
            records.append(record)
    return records, mismatches


def target_measures(
    store: PacketStore,
    packet_id: str,
    scenes: Path,
    cache: dict[str, GaussianModel],
    sizes: list[int],
    tolerances: list[float],
    window: int = 1,
) -> list[dict[str, Any]]:
    """One record per target of the packet and visibility tolerance: ``identity``, ``surface`` (share
    of static pixels with a surface) and, per K in ``sizes`` and for ``all`` the packet's references,
    ``seen_K``, ``visible_truth_K`` and ``copy_K`` (module docstring), with the true geometry."""
    packet, truth, masks, cameras, world = packet_and_world(store, packet_id, scenes, cache)
    depths, valid = true_depths(world.depth, world.alpha)
    true_packet = with_true_geometry(packet, cameras, world.cmap.float(), world.alpha.float())
    weights = blend_weights(true_packet, ReprojectConfig()).float()  # (M, N)
    records, _ = copy_measures(
        packet, truth, masks, cameras, depths, valid, weights, sizes, tolerances, window
    )
    return records


def summary(records: list[dict[str, Any]], sizes: list[int]) -> dict[str, float]:
    """Means over targets of every measure (per K in ``sizes`` and for ``all`` references), and the gains of
    each K over K = ``sizes[0]``."""
    keys = [
        "identity",
        "surface",
        *(f"{name}_{k}" for k in [*sizes, "all"] for name in ("seen", "visible_truth", "copy")),
    ]
    result = {key: statistics.fmean(r[key] for r in records) for key in keys}
    result["references"] = statistics.fmean(r["references"] for r in records)
    for k in [
        *sizes,
        "all",
    ]:  # the share of the render's squared error on the pixels the first K references see
        result[f"error_share_{k}"] = statistics.fmean(
            1.0 - 10.0 ** (-(r[f"visible_truth_{k}"] - r["identity"]) / 10.0) for r in records
        )
    first = sizes[0]
    for k in sizes[1:]:
        for name in ("visible_truth", "copy"):
            result[f"{name}_gain_{first}_to_{k}"] = result[f"{name}_{k}"] - result[f"{name}_{first}"]
    result["targets"] = len(records)
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_store_arguments(parser)
    parser.add_argument(
        "--references", action="append", type=int, required=True, help="K: first K references (repeatable)"
    )
    parser.add_argument("--split", default="test")
    parser.add_argument(
        "--tolerance",
        action="append",
        type=float,
        help=f"relative inverse-depth tolerance of the visibility test (repeatable; default {TOLERANCE})",
    )
    parser.add_argument(
        "--window",
        type=int,
        default=1,
        help="odd w: a point is also seen where one of the w x w reference pixels nearest its projection "
        "has a surface at its depth (default 1: the bilinear test alone)",
    )
    parser.add_argument("--out", type=Path, help="JSON output (default: print only)")
    args = parser.parse_args()
    sizes = sorted(set(args.references))
    tolerances = sorted(set(args.tolerance or [TOLERANCE]))
    if sizes[0] < 1:
        parser.error("--references must be >= 1")
    if args.window < 1 or args.window % 2 == 0:
        parser.error("--window must be an odd number >= 1")
    torch.set_num_threads(1)
    store, cache = PacketStore(args.packets), {}
    records: list[dict[str, Any]] = []
    for packet_id in tqdm(store.packet_ids(args.split), desc="packets", unit="packet"):
        records.extend(target_measures(store, packet_id, args.scenes, cache, sizes, tolerances, args.window))
    groups = sorted({r["group"] for r in records})
    by_tolerance = {}
    for tolerance in tolerances:
        chosen = [r for r in records if r["tolerance"] == tolerance]
        by_tolerance[str(tolerance)] = {
            "all": summary(chosen, sizes),
            "groups": {g: summary([r for r in chosen if r["group"] == g], sizes) for g in groups},
        }
    result = {
        "benchmark": "reference_ceiling",
        "command": " ".join(["python", *sys.argv]),
        "machine": machine(),
        "window": args.window,
        "tolerances": by_tolerance,
        "targets": records,
    }
    print(json.dumps(by_tolerance, indent=2))
    if args.out:
        write_text_atomic(args.out, json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
