"""How much can more references give a target at all?  The information ceiling of the set-size ablation.

Issue 15 asks that SetDiff's set-size ablation gain ≥ 0.3 dB PSNR from 1 + 1 to 3 + 1 views.  A
reference can only help where it *sees* what the target shows: it carries that content cleanly (the
references are ground-truth captures), while everything else the model must infer from the render
itself, as a single-image enhancer does.  On synthetic packets the world is known, so this script
measures, per target and for the first ``K`` references (the packet's Eq. 2 order, the same subsets
``ablate setsize`` feeds the model), with the **true** geometry:

* ``seen_K``: the share of the target's static pixels that at least one of the first K references
  sees (the depth test of :mod:`setdiff_bench.enhancers.reproject`: the reference's own surface at the
  projected pixel lies within 3 % of the depth of the target's surface point);
* ``visible_truth_K``: PSNR (dB) of the render with every pixel that a first-K reference sees replaced
  by the ground truth — a method that recovered seen content perfectly and left the rest as rendered;
* ``copy_K``: PSNR of the render with seen pixels replaced by the Eq. 2-weighted blend of the first K
  references' warped colours (what ``--method reproject`` does with true geometry and K references);
* ``identity``: PSNR of the render.

``visible_truth_K − visible_truth_1`` is what the extra references can add: on the pixels that
references 2…K see and reference 1 does not, at most the render's whole error.  An enhancer that also
improves unseen pixels from the render alone (as every trained model here does) leaves less error on the
newly seen pixels, so its gain from the extra references is smaller still.  Per-image PSNR over the
packet's static pixels (masks), then means per group and over all targets, as the leaderboard does.

Usage (the store the shipped models were trained from; its test split holds the demo's scenes)::

    python benchmarks/reference_ceiling.py --packets runs/more/packets --scenes runs/more/scenes \\
        --references 1 --references 2 --references 3 --references 8 \\
        --out benchmarks/results/reference_ceiling.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine
from benchmarks.reproject_geometry import masked_psnr, with_true_geometry, world_model
from setdiff_bench.enhancers.reproject import (
    ReprojectEnhancer,
    blend_weights,
    cmap_points,
    snap_to_rays,
)
from setdiff_bench.gaussians.model import GaussianModel
from setdiff_bench.gaussians.render import render
from setdiff_bench.packets.store import PacketStore, row_camera


def target_measures(
    store: PacketStore,
    packet_id: str,
    scenes: Path,
    cache: dict[str, GaussianModel],
    enhancer: ReprojectEnhancer,
    sizes: list[int],
) -> list[dict[str, Any]]:
    """One record per target of the packet: ``identity`` and, per K in ``sizes``, ``seen_K``,
    ``visible_truth_K`` and ``copy_K`` (module docstring)."""
    rows = store.rows(packet_id)
    packet = store.load_packet(packet_id)
    truth, masks = store.load_ground_truth(packet_id)
    cameras = [row_camera(row, world=True) for _, row in rows.iterrows()]
    with torch.no_grad():
        world = render(world_model(scenes, packet.scene, cache), cameras, with_geometry=True, tile_size=8)
    true_packet = with_true_geometry(packet, cameras, world.cmap.float(), world.alpha.float())
    n, renders = len(packet.references), packet.targets.images.float()
    all_cmaps = torch.cat([true_packet.references.cmaps, true_packet.targets.cmaps]).float()
    all_alphas = torch.cat([true_packet.references.alphas, true_packet.targets.alphas]).float()
    points, valid = cmap_points(all_cmaps, all_alphas, enhancer.config.alpha_threshold)
    points = snap_to_rays(points, valid, tuple(cameras))
    geometry = torch.cat([points, valid.float()], dim=1)
    weights = blend_weights(true_packet, enhancer.config).float()  # (M, N)
    records = []
    for m in range(len(packet.targets)):
        target_points, target_valid = points[n + m].reshape(3, -1).T, valid[n + m].reshape(-1)
        static = masks[m].reshape(-1)
        flat_truth, flat_render = truth[m].reshape(3, -1), renders[m].reshape(3, -1)
        record: dict[str, Any] = {
            "packet_id": packet_id,
            "group": packet.group,
            "target": m,
            "identity": masked_psnr(flat_render, flat_truth, static[None]),
        }
        for size in sizes:
            k = min(size, n)
            colour, found = enhancer.gather(
                target_points,
                tuple(cameras[:k]),
                geometry[:k],
                packet.references.images[:k].float(),
                weights[m, :k],
            )
            seen = found & target_valid
            record[f"seen_{size}"] = float((seen & static).float().sum() / static.float().sum().clamp_min(1))
            record[f"visible_truth_{size}"] = masked_psnr(
                torch.where(seen[None], flat_truth, flat_render), flat_truth, static[None]
            )
            record[f"copy_{size}"] = masked_psnr(
                torch.where(seen[None], colour, flat_render).clamp(0, 1), flat_truth, static[None]
            )
        records.append(record)
    return records


def summary(records: list[dict[str, Any]], sizes: list[int]) -> dict[str, float]:
    """Means over targets of every measure, and the gains of each K over K = ``sizes[0]``."""
    keys = ["identity", *(f"{name}_{k}" for k in sizes for name in ("seen", "visible_truth", "copy"))]
    result = {key: statistics.fmean(r[key] for r in records) for key in keys}
    first = sizes[0]
    for k in sizes[1:]:
        for name in ("visible_truth", "copy"):
            result[f"{name}_gain_{first}_to_{k}"] = result[f"{name}_{k}"] - result[f"{name}_{first}"]
    result["targets"] = len(records)
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", required=True, type=Path, help="synthetic packet store")
    parser.add_argument(
        "--scenes", required=True, type=Path, help="the synthetic scenes the packets came from"
    )
    parser.add_argument(
        "--references", action="append", type=int, required=True, help="K: first K references (repeatable)"
    )
    parser.add_argument("--split", default="test")
    parser.add_argument("--out", type=Path, help="JSON output (default: print only)")
    args = parser.parse_args()
    sizes = sorted(set(args.references))
    if sizes[0] < 1:
        parser.error("--references must be >= 1")
    torch.set_num_threads(1)
    store, cache, enhancer = PacketStore(args.packets), {}, ReprojectEnhancer()
    records: list[dict[str, Any]] = []
    for packet_id in tqdm(store.packet_ids(args.split), desc="packets", unit="packet"):
        records.extend(target_measures(store, packet_id, args.scenes, cache, enhancer, sizes))
    groups = sorted({r["group"] for r in records})
    result = {
        "benchmark": "reference_ceiling",
        "command": " ".join(["python", *sys.argv]),
        "machine": machine(),
        "all": summary(records, sizes),
        "groups": {g: summary([r for r in records if r["group"] == g], sizes) for g in groups},
        "targets": records,
    }
    print(json.dumps({"all": result["all"], "groups": result["groups"]}, indent=2))
    if args.out:
        args.out.write_text(json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
