"""How good is the geometry a sparse-view fit gives the enhancer?  The sparse benchmark's geometry audit.

Every SetDiff mechanism that fetches content from a reference (the C-map attention bias, the C-map
conditioning, ``reproject``) finds *where* to fetch through the fit's C-maps.  On synthetic packets the
world is known, so this script measures, per test packet of the chosen groups (no training, no model):

* ``reproject``: mean per-target PSNR (dB, static pixels) of the ``reproject`` baseline with the packet's
  fit C-maps (``reproject_fit``) and with the true ones (``reproject_true``), beside the render
  (``identity``) — :mod:`benchmarks.reproject_geometry`;
* ``ceiling_true`` / ``ceiling_fit``: :mod:`benchmarks.reference_ceiling`'s measures (``copy_K``,
  ``visible_truth_K``, ``seen_K``, gains) with the true geometry, and with the *fit's* C-maps for the
  target pixels' surface points and the references' depth test.  ``ceiling_fit``'s ``copy_K`` is the
  training-free upper bound of C-map-grounded copying with what a user has; its ``visible_truth_K``
  replaces the pixels the fit geometry *claims* a reference sees by the truth (an optimistic bound: the
  claim may be wrong, and ``copy_K`` says how often it is);
* ``cmap_error``: per pixel with a point in both, ``‖X_fit − X_true‖ / z_true`` after ray-snapping (both
  points on the pixel's ray at their expected depths, so this is the relative depth error times the ray's
  length per unit depth), pooled over pixels: median and p90 on target pixels a reference sees (true
  geometry, tolerance ``--tolerance``, any of the packet's references), on target pixels none sees, and
  on the reference views themselves (the fit's training views); and the share of target pixels with a
  true surface where the fit has no point (alpha ≤ 0.5);
* ``tokens``: at each ``--tokens`` count per view (576 = the 32×18 latent, 144 = 16×9 for 256×144 views),
  the per-token points the model's C-map bias uses (``surface_points`` → 8×8 latent cells →
  ``pool_token_points``: area-mean C-map / alpha, valid where more than half the token has a point):
  ``invalid``: the share of target tokens without a valid fit point; ``error_share_invalid``: the share of
  the render's squared error (static pixels) on those tokens; and for target tokens valid in both, the
  agreement of the nearest reference token (over all the packet's references' valid tokens) by fit points
  and by true points: ``agree`` (the same token), ``agree_near`` (the same reference, within one token in
  each direction), and both again on ``matched`` tokens only (the true nearest reference token lies within
  one token footprint, ``z_true ×`` the token's angular size: a real correspondence), raw C-map points
  (``raw``, what the model uses) and ray-snapped ones (``snapped``).

Quantiles come from log-spaced histograms (200 bins per decade from 1e-5 to 1e3: about 1.2 % resolution).
Per-image PSNR over the packet's static pixels, then means per group, as the leaderboard does.

Usage (the sparse demo's test packets; ``setdiff-bench demo --benchmark sparse`` makes them under
``<out>/work``, or ``synth --preset sparse --indices 0,1`` then ``prepare dl3dv --protocol
dl3dv_sparse_synthetic --split test``)::

    python benchmarks/sparse_geometry_audit.py --packets runs/sparse/packets --scenes runs/sparse/scenes \\
        --group n3 --group n6 --out benchmarks/results/sparse_geometry_audit.json
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
from benchmarks.reference_ceiling import cmap_depths, copy_measures, summary, true_depths
from benchmarks.reproject_geometry import (
    add_store_arguments,
    masked_psnr,
    packet_and_world,
    with_true_geometry,
)
from setdiff_bench.cameras import Camera
from setdiff_bench.enhancers.reproject import ReprojectConfig, ReprojectEnhancer, blend_weights
from setdiff_bench.geometry import denormalize_cmaps, pixel_centers, snap_to_rays
from setdiff_bench.io.atomic import write_text_atomic
from setdiff_bench.models.setdiff.inputs import surface_points
from setdiff_bench.models.setdiff.set_mixer import pool_token_points, token_grid
from setdiff_bench.packets.store import PacketStore
from setdiff_bench.types import Packet

#: Latent cells per pixel side (the models' autoencoder).
LATENT_FACTOR = 8
#: Log-spaced histogram of relative errors: bin edges from 10^LOW to 10^HIGH, BINS_PER_DECADE per decade.
LOW, HIGH, BINS_PER_DECADE = -5, 3, 200
EDGES = np.logspace(LOW, HIGH, (HIGH - LOW) * BINS_PER_DECADE + 1)


class Histogram:
    """Pooled quantiles of non-negative values by counts in :data:`EDGES` (values below the first edge count
    in the first bin, above the last in the last)."""

    def __init__(self) -> None:
        self.counts = np.zeros(len(EDGES) - 1, np.int64)

    def add(self, values: np.ndarray) -> None:
        clipped = np.clip(np.asarray(values, np.float64), EDGES[0], EDGES[-1] * (1 - 1e-12))
        self.counts += np.histogram(clipped, EDGES)[0]

    def quantile(self, q: float) -> float:
        """The ``q`` quantile (geometric centre of its bin); NaN when empty."""
        total = int(self.counts.sum())
        if total == 0:
            return float("nan")
        index = int(np.searchsorted(np.cumsum(self.counts), q * total, side="left"))
        return float(np.sqrt(EDGES[index] * EDGES[index + 1]))

    def summary(self) -> dict[str, float]:
        return {"median": self.quantile(0.5), "p90": self.quantile(0.9), "pixels": int(self.counts.sum())}


def fit_world_cmaps(packet: Packet, cameras: list[Camera]) -> tuple[torch.Tensor, torch.Tensor]:
    """The packet's fit C-maps ``(V, 3, H, W)`` moved back to the world frame of ``cameras`` (references
    first; the packet was normalised into its first target's frame, scaled by ``packet.scale``) and the
    fit's alphas ``(V, 1, H, W)``."""
    n = len(packet.references)
    cmaps = torch.cat([packet.references.cmaps.float(), packet.targets.cmaps.float()])
    alphas = torch.cat([packet.references.alphas.float(), packet.targets.alphas.float()])
    anchor = cameras[n]
    world = denormalize_cmaps(cmaps, alphas, anchor.R, anchor.t, packet.scale, dtype=torch.float32)
    return world, alphas


def ray_points(camera: Camera, depth: torch.Tensor) -> np.ndarray:
    """``(H·W, 3)`` world points on the pixels' rays at camera-frame ``depth`` ``(1, H, W)``."""
    height, width = depth.shape[-2:]
    return camera.unproject(pixel_centers(height, width), depth.reshape(-1).double().numpy())


def relative_errors(
    camera: Camera, fit_depth: torch.Tensor, true_depth: torch.Tensor, both: torch.Tensor
) -> np.ndarray:
    """``‖X_fit − X_true‖ / z_true`` on the pixels where ``both`` ``(1, H, W)`` holds (ray-snapped points)."""
    keep = both.reshape(-1).numpy()
    fit_points = ray_points(camera, fit_depth)[keep]
    true_points = ray_points(camera, true_depth)[keep]
    z = true_depth.reshape(-1).double().numpy()[keep]
    return np.linalg.norm(fit_points - true_points, axis=1) / z


def token_points(points: torch.Tensor, tokens: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-pixel points × validity and validity ``(V, 4, H, W)`` → the model's per-token points
    ``(V, L, 3)`` and validity ``(V, L)`` (8×8 latent cells, then :func:`pool_token_points`)."""
    return pool_token_points(F.avg_pool2d(points.float(), LATENT_FACTOR), tokens)


def snapped_surface(points: torch.Tensor, cameras: tuple[Camera, ...]) -> torch.Tensor:
    """``surface_points``-layout ``(V, 4, H, W)`` with the points moved onto their pixels' rays."""
    valid = points[:, 3:] > 0.5
    return torch.cat([snap_to_rays(points[:, :3], valid, cameras) * valid, points[:, 3:]], dim=1)


def nearest_reference_tokens(
    points: torch.Tensor, valid: torch.Tensor, n: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """For every target token ``(M·L,)``: the flat index (reference × L + token) of the nearest valid
    reference token in 3D, and its distance (``inf`` when no reference token is valid)."""
    references = points[:n].reshape(-1, 3)
    reference_valid = valid[:n].reshape(-1)
    distances = torch.cdist(points[n:].reshape(-1, 3).double(), references.double())
    distances[:, ~reference_valid] = float("inf")
    best, index = distances.min(dim=1)
    return index, best


def token_measures(
    packet: Packet,
    true_packet: Packet,
    truth: torch.Tensor,
    masks: torch.Tensor,
    cameras: list[Camera],
    true_depth: torch.Tensor,
    tokens: int,
) -> dict[str, Any]:
    """Counts of one packet at ``tokens`` tokens per view (module docstring, ``tokens``); summed over packets
    and turned into shares by :func:`token_summary`."""
    n, m = len(packet.references), len(packet.targets)
    height, width = packet.height, packet.width
    fit_surface, true_surface = surface_points(packet), surface_points(true_packet)
    fit_cameras = (*packet.references.cameras, *packet.targets.cameras)
    counts: dict[str, Any] = {}
    grid = token_grid(height // LATENT_FACTOR, width // LATENT_FACTOR, tokens)
    rows, cols = grid
    for variant, (fit_pixels, true_pixels) in {
        "raw": (fit_surface, true_surface),
        "snapped": (snapped_surface(fit_surface, fit_cameras), snapped_surface(true_surface, tuple(cameras))),
    }.items():
        fit_points, fit_valid = token_points(fit_pixels, tokens)
        true_points, true_valid = token_points(true_pixels, tokens)
        fit_index, _ = nearest_reference_tokens(fit_points, fit_valid, n)
        true_index, true_distance = nearest_reference_tokens(true_points, true_valid, n)
        both = fit_valid[n:].reshape(-1) & true_valid[n:].reshape(-1)
        both &= torch.isfinite(true_distance)
        same = fit_index == true_index
        fit_ref, true_ref = fit_index // tokens, true_index // tokens
        fit_cell, true_cell = fit_index % tokens, true_index % tokens
        near = (fit_ref == true_ref) & ((fit_cell // cols - true_cell // cols).abs() <= 1)
        near &= (fit_cell % cols - true_cell % cols).abs() <= 1
        # a token's footprint: its true depth × its angular size (rows of pixels per token / fy)
        token_rows = height / rows
        target_depth = F.adaptive_avg_pool2d(
            torch.where(true_depth[n:] > 0, true_depth[n:], torch.zeros_like(true_depth[n:])), grid
        )
        coverage = F.adaptive_avg_pool2d((true_depth[n:] > 0).float(), grid)
        z = (target_depth / coverage.clamp_min(1e-6)).reshape(-1).double()
        fy = torch.tensor([cameras[n + k].K[1, 1] for k in range(m)], dtype=torch.float64)
        footprint = z * token_rows / fy.repeat_interleave(tokens)
        matched = both & (true_distance <= footprint)
        counts[variant] = {
            "valid_both": int(both.sum()),
            "agree": int((both & same).sum()),
            "agree_near": int((both & near).sum()),
            "matched": int(matched.sum()),
            "matched_agree": int((matched & same).sum()),
            "matched_agree_near": int((matched & near).sum()),
        }
        if variant == "raw":
            invalid = ~fit_valid[n:].reshape(m, 1, rows, cols)
            pixels = F.interpolate(invalid.float(), size=(height, width), mode="nearest") > 0.5
            squared = (packet.targets.images.float() - truth).square().sum(dim=1, keepdim=True) * masks
            counts["target_tokens"] = int(invalid.numel())
            counts["invalid_tokens"] = int(invalid.sum())
            counts["error_share_invalid"] = [
                float((squared[k] * pixels[k]).sum() / squared[k].sum().clamp_min(1e-12)) for k in range(m)
            ]
    return counts


def token_summary(records: list[dict[str, Any]]) -> dict[str, Any]:
    """Shares over a group's packets from :func:`token_measures`' counts (pooled over tokens; the error share
    is the mean over targets, as the ceiling's ``error_share``)."""
    result: dict[str, Any] = {
        "invalid": sum(r["invalid_tokens"] for r in records)
        / max(1, sum(r["target_tokens"] for r in records)),
        "error_share_invalid": statistics.fmean(s for r in records for s in r["error_share_invalid"]),
    }
    for variant in ("raw", "snapped"):
        total = {key: sum(r[variant][key] for r in records) for key in records[0][variant]}
        result[variant] = {
            "agree": total["agree"] / max(1, total["valid_both"]),
            "agree_near": total["agree_near"] / max(1, total["valid_both"]),
            "matched_share": total["matched"] / max(1, total["valid_both"]),
            "matched_agree": total["matched_agree"] / max(1, total["matched"]),
            "matched_agree_near": total["matched_agree_near"] / max(1, total["matched"]),
            "tokens": total["valid_both"],
        }
    return result


def packet_audit(
    store: PacketStore,
    packet_id: str,
    scenes: Path,
    cache: dict,
    sizes: list[int],
    tolerance: float,
    window: int,
    token_counts: list[int],
    histograms: dict[str, Histogram],
) -> dict[str, Any]:
    """Every measure of the module docstring for one packet (pixel errors go into ``histograms``)."""
    packet, truth, masks, cameras, world = packet_and_world(store, packet_id, scenes, cache)
    n, m = len(packet.references), len(packet.targets)
    true_packet = with_true_geometry(packet, cameras, world.cmap.float(), world.alpha.float())
    config = ReprojectConfig()
    weights = blend_weights(true_packet, config).float()
    depth_true, valid_true = true_depths(world.depth, world.alpha)
    fit_cmaps, fit_alphas = fit_world_cmaps(packet, cameras)
    depth_fit, valid_fit = cmap_depths(cameras, fit_cmaps, fit_alphas)
    args = (packet, truth, masks, cameras)
    true_records, true_mismatch = copy_measures(
        *args, depth_true, valid_true, weights, sizes, [tolerance], window
    )
    fit_records, _ = copy_measures(*args, depth_fit, valid_fit, weights, sizes, [tolerance], window)
    enhancer = ReprojectEnhancer(config)
    renders = packet.targets.images.float()
    outputs = {"reproject_fit": enhancer.enhance(packet), "reproject_true": enhancer.enhance(true_packet)}
    record: dict[str, Any] = {
        "packet_id": packet_id,
        "group": packet.group,
        "targets": m,
        "references": n,
        "identity": statistics.fmean(masked_psnr(renders[k], truth[k], masks[k]) for k in range(m)),
        **{
            name: statistics.fmean(masked_psnr(out[k], truth[k], masks[k]) for k in range(m))
            for name, out in outputs.items()
        },
    }
    no_point, surface = 0, 0
    for k in range(m):
        static = masks[k].bool()
        both = valid_fit[n + k] & valid_true[n + k] & static
        errors = relative_errors(cameras[n + k], depth_fit[n + k], depth_true[n + k], both)
        seen = (true_mismatch[k] <= tolerance).any(dim=0).reshape(1, *static.shape[-2:])[both]
        histograms["targets_seen"].add(errors[seen.numpy()])
        histograms["targets_unseen"].add(errors[~seen.numpy()])
        true_surface = valid_true[n + k] & static
        surface += int(true_surface.sum())
        no_point += int((true_surface & ~valid_fit[n + k]).sum())
    for r in range(n):
        both = valid_fit[r] & valid_true[r]
        histograms["references"].add(relative_errors(cameras[r], depth_fit[r], depth_true[r], both))
    record["no_fit_point"], record["true_surface"] = no_point, surface
    record["tokens"] = {
        str(t): token_measures(packet, true_packet, truth, masks, cameras, depth_true, t)
        for t in token_counts
    }
    record["ceiling_true"], record["ceiling_fit"] = true_records, fit_records
    return record


def group_summary(
    records: list[dict[str, Any]], histograms: dict[str, Histogram], sizes: list[int]
) -> dict[str, Any]:
    """Means over a group's packets and targets of every measure."""
    result: dict[str, Any] = {
        "packets": len(records),
        "targets": sum(r["targets"] for r in records),
        **{
            key: statistics.fmean(r[key] for r in records)
            for key in ("identity", "reproject_fit", "reproject_true")
        },
        "ceiling_true": summary([t for r in records for t in r["ceiling_true"]], sizes),
        "ceiling_fit": summary([t for r in records for t in r["ceiling_fit"]], sizes),
        "cmap_error": {name: h.summary() for name, h in histograms.items()},
        "no_fit_point_share": sum(r["no_fit_point"] for r in records)
        / max(1, sum(r["true_surface"] for r in records)),
    }
    result["tokens"] = {
        t: token_summary([r["tokens"][t] for r in records]) for t in records[0]["tokens"] if records
    }
    last = sizes[-1]
    result["headroom"] = {
        "render": result["ceiling_true"]["identity"],
        f"true_copy_{last}_minus_render": result["ceiling_true"][f"copy_{last}"]
        - result["ceiling_true"]["identity"],
        f"fit_copy_{last}_minus_render": result["ceiling_fit"][f"copy_{last}"]
        - result["ceiling_fit"]["identity"],
        f"visible_truth_{last}_minus_{sizes[0]}": result["ceiling_true"][f"visible_truth_{last}"]
        - result["ceiling_true"][f"visible_truth_{sizes[0]}"],
    }
    return result


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    add_store_arguments(parser)
    parser.add_argument("--group", action="append", required=True, help="packet group (repeatable), e.g. n3")
    parser.add_argument(
        "--per-group", type=int, default=0, help="packets per group, first in id order (0: all)"
    )
    parser.add_argument("--split", default="test")
    parser.add_argument(
        "--references", action="append", type=int, help="K: first K references (repeatable; default 1 and 3)"
    )
    parser.add_argument("--tolerance", type=float, default=0.03, help="relative inverse-depth tolerance")
    parser.add_argument("--window", type=int, default=3, help="the ceiling's visibility window (odd)")
    parser.add_argument(
        "--tokens", action="append", type=int, help="tokens per view (repeatable; default 576 and 144)"
    )
    parser.add_argument("--out", type=Path, help="JSON output (default: print only)")
    args = parser.parse_args()
    sizes = sorted(set(args.references or [1, 3]))
    token_counts = sorted(set(args.tokens or [576, 144]), reverse=True)
    if sizes[0] < 1:
        parser.error("--references must be >= 1")
    if args.window < 1 or args.window % 2 == 0:
        parser.error("--window must be an odd number >= 1")
    torch.set_num_threads(1)
    store, cache = PacketStore(args.packets), {}
    groups: dict[str, Any] = {}
    packets: dict[str, list[dict[str, Any]]] = {}
    for group in args.group:
        ids = [p for p in store.packet_ids(args.split) if store.rows(p)["group"].iloc[0] == group]
        if args.per_group > 0:
            ids = ids[: args.per_group]
        if not ids:
            parser.error(f"--group {group}: no {args.split} packets in {args.packets}")
        histograms = {name: Histogram() for name in ("targets_seen", "targets_unseen", "references")}
        records = [
            packet_audit(
                store, p, args.scenes, cache, sizes, args.tolerance, args.window, token_counts, histograms
            )
            for p in tqdm(ids, desc=group, unit="packet")
        ]
        groups[group] = group_summary(records, histograms, sizes)
        packets[group] = [
            {k: v for k, v in r.items() if k not in ("ceiling_true", "ceiling_fit", "tokens")}
            for r in records
        ]
        print(json.dumps({group: groups[group]["headroom"]}), flush=True)
    result = {
        "benchmark": "sparse_geometry_audit",
        "command": " ".join(["python", *sys.argv]),
        "machine": machine(),
        "tolerance": args.tolerance,
        "window": args.window,
        "groups": groups,
        "packets": packets,
    }
    print(json.dumps(groups, indent=2))
    if args.out:
        write_text_atomic(args.out, json.dumps(result, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
