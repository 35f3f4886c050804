"""What does a trained SetDiff do to a render that is already good?  (The held-out gap of issue 15.)

For each checkpoint and each packet of the chosen groups, with ``r`` the render, ``y`` the enhanced
image and ``g`` the ground truth (``(M, 3, H, W)`` in [0, 1], at the packet's stored size):

* ``identity_psnr`` / ``enhanced_psnr``: PSNR (dB) of ``r`` and ``y`` against ``g``;
* ``change_psnr``: PSNR of ``y`` against ``r`` — how much the enhancer changes the render;
* ``change_error_correlation``: cosine between the change ``y − r`` and the error ``g − r`` over all
  pixels (1 = it moves exactly towards the truth, 0 = its change is unrelated to the error);
* ``best_step``: the least-squares scale ``s`` of the change that would minimise ``‖r + s(y − r) − g‖``
  (1 = the change has the right size, 0 = any change hurts);
* ``lowpass_identity_psnr`` / ``lowpass_enhanced_psnr``: the same PSNRs after 8×8 average pooling (one
  value per latent cell of the tiny model) — where in frequency the damage sits;
* ``no_reference_psnr``: ``y`` recomputed with 0 references (does the set matter?).

Usage (the shipped model and its earlier training checkpoints on the demo's packets)::

    python benchmarks/heldout_damage.py --packets runs/demo/work/packets --checkpoint tiny_setdiff \
        --group interp --group lane+2 --out benchmarks/results/heldout_damage.json
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from pathlib import Path
from typing import Any

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.models.setdiff.checkpoint import load_model
from setdiff_bench.models.setdiff.inference import enhance_packet
from setdiff_bench.packets.store import PacketStore


def pooled_psnr(image: torch.Tensor, truth: torch.Tensor) -> float:
    """PSNR (dB) over all values of two equally shaped tensors in [0, 1] (one MSE over everything, via
    :func:`setdiff_bench.metrics.psnr.psnr`)."""
    return float(psnr(image.reshape(1, 1, 1, -1), truth.reshape(1, 1, 1, -1))[0])


def packet_measures(model: Any, store: PacketStore, packet_id: str) -> dict[str, float]:
    """The measures of the module docstring for one packet (means over its targets where per image)."""
    packet = store.load_packet(packet_id)
    truth, _ = store.load_ground_truth(packet_id)
    render = packet.targets.images
    enhanced = enhance_packet(model, packet)
    alone = enhance_packet(model, packet, max_references=0)
    change, error = enhanced - render, truth - render
    return {
        "identity_psnr": statistics.fmean(pooled_psnr(render[m], truth[m]) for m in range(len(truth))),
        "enhanced_psnr": statistics.fmean(pooled_psnr(enhanced[m], truth[m]) for m in range(len(truth))),
        "no_reference_psnr": statistics.fmean(pooled_psnr(alone[m], truth[m]) for m in range(len(truth))),
        "change_psnr": statistics.fmean(pooled_psnr(enhanced[m], render[m]) for m in range(len(truth))),
        "change_error_correlation": float(
            (change * error).sum() / (change.norm() * error.norm()).clamp_min(1e-12)
        ),
        "best_step": float((change * error).sum() / (change * change).sum().clamp_min(1e-12)),
        "lowpass_identity_psnr": pooled_psnr(F.avg_pool2d(render, 8), F.avg_pool2d(truth, 8)),
        "lowpass_enhanced_psnr": pooled_psnr(F.avg_pool2d(enhanced, 8), F.avg_pool2d(truth, 8)),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--packets", required=True, type=Path, help="packet store")
    parser.add_argument(
        "--checkpoint",
        action="append",
        required=True,
        help="checkpoint folder or shipped model name (repeatable)",
    )
    parser.add_argument("--group", action="append", required=True, help="packet group (repeatable)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--out", type=Path, help="JSON output (default: print only)")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    store = PacketStore(args.packets)
    ids = {
        group: [p for p in store.packet_ids(args.split) if store.rows(p)["group"].iloc[0] == group]
        for group in args.group
    }
    results: dict[str, Any] = {}
    for checkpoint in args.checkpoint:
        model, _ = load_model(checkpoint)
        per_group = {}
        for group, packet_ids in ids.items():
            records = {packet_id: packet_measures(model, store, packet_id) for packet_id in packet_ids}
            means = {
                key: statistics.fmean(r[key] for r in records.values())
                for key in next(iter(records.values()))
            }
            per_group[group] = {"means": means, "packets": records}
            print(checkpoint, group, json.dumps({k: round(v, 3) for k, v in means.items()}), flush=True)
        results[checkpoint] = per_group
    output = {
        "benchmark": "heldout_damage",
        "command": " ".join(["python", *sys.argv]),
        "machine": machine(),
        "checkpoints": results,
    }
    if args.out:
        args.out.write_text(json.dumps(output, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
