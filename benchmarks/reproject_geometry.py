"""Why does the geometry-only ``reproject`` baseline not beat ``identity``?  Fit geometry against true geometry.

On synthetic packets the world that made the ground truth is known, so each packet view's true
C-map and alpha can be rendered from it (static world, the views' world cameras).  Per packet this
script runs ``reproject`` twice on the same references and renders — once with the fit's C-maps
(as stored in the packet) and once with the true ones — and reports, per group:

* ``identity`` / ``reproject_fit`` / ``reproject_true``: mean per-image PSNR (dB) against the ground
  truth, over static pixels (the packet's masks);
* ``coverage_fit`` / ``coverage_true``: share of target pixels that at least one reference accepts
  (the depth test of :mod:`setdiff_bench.enhancers.reproject`);
* per (target, reference) pair with true geometry: ``pair_accepted`` (share of target pixels the
  reference accepts), and on exactly those pixels ``pair_warp_psnr`` (the warped reference colour)
  against ``pair_render_psnr`` (the render) — what copying can gain where it is allowed to copy;
* ``world_vs_ground_truth_psnr``: the true-geometry render's colour against the stored ground truth
  (static pixels) — a check that the world cameras and the rebuilt world are the ground truth's.

Usage (the demo's packets and scenes)::

    python benchmarks/reproject_geometry.py --packets runs/demo/work/packets --scenes runs/demo/work/scenes \
        --group interp --group lane+1 --group lane+2 --per-group 2 --out benchmarks/results/reproject_geometry.json

The sparse-view scenes work the same way (groups ``n3`` / ``n6`` / ``n9``); ``benchmarks/sparse_geometry_audit.py``
runs this comparison with the rest of the sparse benchmark's geometry audit.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any

import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine
from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.reproject import ReprojectEnhancer, cmap_points
from setdiff_bench.gaussians.backends.common import RenderOutput
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.geometry import snap_to_rays
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.packets.store import PacketStore, row_camera
from setdiff_bench.synthetic.sparse import static_world
from setdiff_bench.types import Packet


def masked_psnr(image: torch.Tensor, truth: torch.Tensor, mask: torch.Tensor) -> float:
    """PSNR (dB) of ``(3, ...)`` images in [0, 1] over the pixels where ``mask`` ``(1, ...)`` is true
    (:func:`setdiff_bench.metrics.psnr.psnr` on one image; flat ``(3, P)`` pixel lists are accepted)."""
    shape = (1, image.shape[0], 1, -1)
    masks = mask.float().reshape(1, 1, 1, -1)
    return float(psnr(image.reshape(shape), truth.reshape(shape), masks)[0])


def world_model(scenes: Path, scene: str, cache: dict[str, GaussianModel]) -> GaussianModel:
    """The static world of a synthetic scene of either kind (a street or a sparse-view walk), rebuilt from its
    ``scene.json`` (preset, seed, index; :func:`setdiff_bench.synthetic.sparse.static_world`)."""
    if scene not in cache:
        cache[scene] = static_world(scenes / scene)
    return cache[scene]


def packet_and_world(
    store: PacketStore, packet_id: str, scenes: Path, cache: dict[str, GaussianModel]
) -> tuple[Packet, torch.Tensor, torch.Tensor, list[Camera], RenderOutput]:
    """A packet, its targets' ground truth ``(M, 3, H, W)`` and static masks ``(M, 1, H, W)``, its views'
    world cameras (references first) and the true world (a street or a sparse-view walk) rendered from them
    with C-maps and depth."""
    packet = store.load_packet(packet_id)
    truth, masks = store.load_ground_truth(packet_id)
    cameras = [row_camera(row, world=True) for _, row in store.rows(packet_id).iterrows()]
    with torch.no_grad():
        world = render(world_model(scenes, packet.scene, cache), cameras, with_geometry=True, tile_size=8)
    return packet, truth, masks, cameras, world


def with_true_geometry(packet: Packet, cameras: list, cmaps: torch.Tensor, alphas: torch.Tensor) -> Packet:
    """The packet with every view's camera, C-map and alpha replaced (world frame, references first)."""
    n = len(packet.references)

    def swap(views: Any, part: slice) -> Any:
        return replace(views, cameras=tuple(cameras[part]), cmaps=cmaps[part], alphas=alphas[part])

    return replace(
        packet, references=swap(packet.references, slice(0, n)), targets=swap(packet.targets, slice(n, None))
    )


def changed(output: torch.Tensor, render_images: torch.Tensor) -> torch.Tensor:
    """``(M, H, W)`` bool: pixels the enhancer replaced."""
    return (output - render_images).abs().sum(dim=1) > 1e-6


def packet_measures(
    store: PacketStore,
    packet_id: str,
    scenes: Path,
    cache: dict[str, GaussianModel],
    enhancer: ReprojectEnhancer,
) -> dict[str, Any]:
    """Every measure of the module docstring for one packet."""
    packet, truth, masks, cameras, world = packet_and_world(store, packet_id, scenes, cache)
    cmaps, alphas = world.cmap.float(), world.alpha.float()
    n, renders = len(packet.references), packet.targets.images
    fit_output = enhancer.enhance(packet)
    true_output = enhancer.enhance(with_true_geometry(packet, cameras, cmaps, alphas))
    points, valid = cmap_points(cmaps, alphas, enhancer.config.alpha_threshold)
    points = snap_to_rays(points, valid, tuple(cameras))
    geometry = torch.cat([points, valid.float()], dim=1)
    pairs = []
    for m in range(len(packet.targets)):
        target_points, target_valid = points[n + m].reshape(3, -1).T, valid[n + m].reshape(-1)
        for r in range(n):
            colour, found = enhancer.gather(
                target_points,
                (cameras[r],),
                geometry[r : r + 1],
                packet.references.images[r : r + 1],
                torch.ones(1),
            )
            keep = found & target_valid & masks[m].reshape(-1)
            record = {"target": m, "reference": r, "accepted": float(keep.float().mean())}
            if int(keep.sum()) >= 100:
                on = keep[None].expand(3, -1).reshape(3, -1)
                flat_truth = truth[m].reshape(3, -1)
                record["warp_psnr"] = masked_psnr(colour, flat_truth, on[:1])
                record["render_psnr"] = masked_psnr(renders[m].reshape(3, -1), flat_truth, on[:1])
            pairs.append(record)
    per_image = {
        name: [masked_psnr(images[m], truth[m], masks[m]) for m in range(len(truth))]
        for name, images in (
            ("identity", renders),
            ("reproject_fit", fit_output),
            ("reproject_true", true_output),
        )
    }
    return {
        "packet_id": packet_id,
        "group": packet.group,
        "targets": len(truth),
        "references": n,
        **{name: statistics.fmean(values) for name, values in per_image.items()},
        "coverage_fit": float(changed(fit_output, renders).float().mean()),
        "coverage_true": float(changed(true_output, renders).float().mean()),
        "world_vs_ground_truth_psnr": statistics.fmean(
            masked_psnr(world.rgb[n + m].clamp(0, 1), truth[m], masks[m]) for m in range(len(truth))
        ),
        "pairs": pairs,
    }


def group_summary(records: list[dict[str, Any]]) -> dict[str, float]:
    """Means over a group's packets (pair measures over all pairs with enough accepted pixels)."""
    keys = (
        "identity",
        "reproject_fit",
        "reproject_true",
        "coverage_fit",
        "coverage_true",
        "world_vs_ground_truth_psnr",
    )
    summary = {key: statistics.fmean(r[key] for r in records) for key in keys}
    pairs = [p for r in records for p in r["pairs"]]
    scored = [p for p in pairs if "warp_psnr" in p]
    summary["pair_accepted"] = statistics.fmean(p["accepted"] for p in pairs)
    summary["pair_warp_psnr"] = statistics.fmean(p["warp_psnr"] for p in scored) if scored else float("nan")
    summary["pair_render_psnr"] = (
        statistics.fmean(p["render_psnr"] for p in scored) if scored else float("nan")
    )
    summary["packets"] = len(records)
    return summary


def add_store_arguments(parser: argparse.ArgumentParser) -> None:
    """``--packets`` (a synthetic packet store) and ``--scenes`` (the scenes it was prepared from), as the
    scripts that rebuild a synthetic world to compare with need them."""
    parser.add_argument("--packets", required=True, type=Path, help="synthetic packet store")
    parser.add_argument(
        "--scenes", required=True, type=Path, help="the synthetic scenes the packets came from"
    )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_store_arguments(parser)
    parser.add_argument("--group", action="append", required=True, help="packet group (repeatable)")
    parser.add_argument("--per-group", type=int, default=2, help="packets per group (first in id order)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--out", type=Path, help="JSON output (default: print only)")
    args = parser.parse_args()
    torch.set_num_threads(1)
    store, cache, enhancer = PacketStore(args.packets), {}, ReprojectEnhancer()
    records: dict[str, list[dict[str, Any]]] = {}
    for group in args.group:
        ids = [p for p in store.packet_ids(args.split) if store.rows(p)["group"].iloc[0] == group][
            : args.per_group
        ]
        for packet_id in ids:
            record = packet_measures(store, packet_id, args.scenes, cache, enhancer)
            records.setdefault(group, []).append(record)
            print(json.dumps({k: v for k, v in record.items() if k != "pairs"}), flush=True)
    result = {
        "benchmark": "reproject_geometry",
        "command": " ".join(["python", *sys.argv]),
        "machine": machine(),
        "groups": {group: group_summary(items) for group, items in records.items()},
        "packets": records,
    }
    print(json.dumps(result["groups"], indent=2))
    if args.out:
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
