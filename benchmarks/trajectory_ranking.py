"""Do FID / KID rank methods as PSNR / LPIPS do on novel trajectories?  (issue 41, the synthetic comparison)

On a real capture a lane shift has no ground truth, so it is scored by FID / KID against the recorded
frames.  The synthetic world can render the truth at any pose, so here the same shifted frames get both:

1. ``synth --preset PRESET --scenes N`` (scenes and their lane-0 fits);
2. ``prepare synthetic --trajectory shift:-3 --trajectory shift:-6`` (packets without ground truth:
   targets are the fit frames' cameras moved 3 / 6 m toward the other lanes);
3. ``run`` each method on that store (``identity`` = the raw 3DGS render, the shipped ``tiny_difix`` and
   ``tiny_setdiff``);
4. the ground truth of every target, rendered from the generator's world (static scene plus the drive's
   moving vehicle at the target's timestamp, with the capture's dynamic mask), checked first against the
   recorded captures (an unmoved fit frame must come out as its captured PNG);
5. PSNR and LPIPS (masked, as ``run`` scores) of each method's written frames against that truth; FID and
   KID of the same frames against the recorded frames (``evaluation.distribution_scoring``, what a user
   without ground truth gets) and, for reference, against the true shifted frames;
6. per shift, the ranking of the methods by each metric and whether it equals PSNR's and LPIPS's.

Features: ``--inception FILE`` (pytorch-fid's ``pt_inception-2015-12-05-6726825d.pth``) when given.  This
machine has no Inception weights and nothing is downloaded, so by default the features are those of an
ImageNet-trained network that is on the machine: the LPIPS AlexNet trunk's conv5 (ReLU), averaged over
the image, 256 values, from images resized to a height of 224.  The JSON names which was used.

    python3 -m benchmarks.trajectory_ranking --out WORK --scenes 10   (from the repository root)
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from itertools import combinations
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F

from benchmarks.common import machine, write_result
from setdiff_bench.cli.main import main as cli
from setdiff_bench.evaluation.distribution_scoring import score_distribution
from setdiff_bench.evaluation.run import RunSettings, run_method
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.atomic import sha256_file
from setdiff_bench.io.images import read_rgb, to_tensor_chw
from setdiff_bench.metrics.distribution import fid, kid
from setdiff_bench.metrics.inception import inception_features, load_inception
from setdiff_bench.metrics.lpips import SCALE, SHIFT, load_lpips
from setdiff_bench.metrics.registry import METRICS
from setdiff_bench.packets.prepare import prepare
from setdiff_bench.packets.store import PacketStore, row_camera
from setdiff_bench.runtime.provenance import git_revision
from setdiff_bench.synthetic.capture import DYNAMIC_ALPHA, concat_models, expected_depth, posed_vehicle
from setdiff_bench.synthetic.generate import build_scene
from setdiff_bench.synthetic.presets import get_preset

SHIFTS = ("shift:-3", "shift:-6")
METHODS = (("identity", None), ("difix", "tiny_difix"), ("setdiff", "tiny_setdiff"))
#: Lower is better for these; higher for PSNR.
LOWER_IS_BETTER = {
    "psnr": False,
    "lpips": True,
    "fid": True,
    "kid": True,
    "fid_vs_truth": True,
    "kid_vs_truth": True,
}
MASK_DILATION_PX = 2  # as synthetic.capture.capture_drive


class AlexNetPool(torch.nn.Module):
    """``(B, 3, H, W)`` in [0, 1] → ``(B, 256)``: the LPIPS AlexNet trunk's conv5 ReLU map, image-averaged,
    from the image resized (bilinear) to a height of 224 and normalised as LPIPS does."""

    def __init__(self) -> None:
        super().__init__()
        self.lpips = load_lpips("alex")
        self.register_buffer("shift", torch.tensor(SHIFT).view(1, 3, 1, 1), persistent=False)
        self.register_buffer("scale", torch.tensor(SCALE).view(1, 3, 1, 1), persistent=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        height = 224
        width = max(1, round(x.shape[-1] * height / x.shape[-2]))
        x = F.interpolate(x.float(), size=(height, width), mode="bilinear", align_corners=False)
        x = ((x * 2 - 1) - self.shift) / self.scale
        return self.lpips.features(x)[-1].mean(dim=(2, 3))


def truth(
    world: Any, moving: Any, camera: Any, timestamp_us: int, tile_size: int
) -> tuple[np.ndarray, np.ndarray]:
    """The world at ``camera``: ``(H, W, 3)`` float32 RGB and the ``(H, W)`` bool static mask (True = evaluate),
    exactly as the generator captures a frame (synthetic/capture.py's rule, re-applied to one camera)."""
    model = world.static
    vehicle = None
    if moving is not None:
        vehicle = posed_vehicle(moving[0], moving[1], timestamp_us / 1e6)
        model = concat_models(world.static, vehicle)
    with torch.no_grad():
        out = render(model, [camera], with_geometry=True, tile_size=tile_size)
        depth = expected_depth(out.depth, out.alpha)
        dynamic = torch.zeros_like(out.alpha, dtype=torch.bool)
        if vehicle is not None:
            car = render(vehicle, [camera], with_geometry=True, tile_size=tile_size)
            car_depth = expected_depth(car.depth, car.alpha, 1e-3)
            dynamic = (car.alpha > DYNAMIC_ALPHA) & (car_depth <= depth * 1.05 + 0.3)
    mask = dynamic[0, 0].numpy().astype(np.uint8)
    if mask.any():
        kernel = np.ones((2 * MASK_DILATION_PX + 1,) * 2, np.uint8)
        mask = cv2.dilate(mask, kernel)
    rgb = out.rgb[0].clamp(0, 1).permute(1, 2, 0).contiguous().numpy()
    return np.round(rgb * 255) / 255, mask == 0


def ranking(values: dict[str, float], metric: str) -> list[str]:
    """Methods best first by ``metric``."""
    sign = 1.0 if LOWER_IS_BETTER[metric] else -1.0
    return sorted(values, key=lambda m: (sign * values[m], m))


def kendall_tau(a: list[str], b: list[str]) -> float:
    """Kendall's tau between two rankings of the same methods (1 = same order, -1 = reversed)."""
    pos_a, pos_b = {m: i for i, m in enumerate(a)}, {m: i for i, m in enumerate(b)}
    pairs = list(combinations(a, 2))
    score = sum(1 if (pos_a[x] - pos_a[y]) * (pos_b[x] - pos_b[y]) > 0 else -1 for x, y in pairs)
    return score / len(pairs) if pairs else 1.0


def _image(path: Path) -> torch.Tensor:
    return to_tensor_chw(read_rgb(path))


def bootstrap(
    group: str,
    samples: dict[tuple[str, str], dict[str, Any]],
    recorded: dict[tuple[str, str], np.ndarray],
    reps: int,
    seed: int,
) -> dict[str, dict[str, float]]:
    """For each pair of methods ``A>B`` and metric: the fraction of scene-bootstrap resamples (scenes drawn
    with replacement; a drawn scene brings its targets and its recorded frames) in which the metric rates
    ``A`` better than ``B``.  Near 0 or 1: the order is stable at this sample size; near 0.5: it is not."""
    methods = sorted(m for g, m in samples if g == group)
    scenes = sorted(set(samples[(group, methods[0])]["scene"]))
    rng = np.random.default_rng(seed)
    wins: dict[str, dict[str, int]] = {
        f"{a}>{b}": dict.fromkeys(("psnr", "lpips", "fid", "kid"), 0) for a, b in combinations(methods, 2)
    }
    for _ in range(reps):
        drawn = rng.choice(scenes, size=len(scenes), replace=True)
        real = np.concatenate([recorded[(group, sc)] for sc in drawn])
        value: dict[str, dict[str, float]] = {}
        for method in methods:
            sample = samples[(group, method)]
            pick = np.concatenate([np.flatnonzero(sample["scene"] == sc) for sc in drawn])
            feats = sample["features"][pick]
            value[method] = {
                "psnr": float(sample["psnr"][pick].mean()),
                "lpips": float(sample["lpips"][pick].mean()),
                "fid": fid(feats, real),
                "kid": kid(feats, real).mean,
            }
        for a, b in combinations(methods, 2):
            for metric in ("psnr", "lpips", "fid", "kid"):
                better = (
                    value[a][metric] < value[b][metric]
                    if LOWER_IS_BETTER[metric]
                    else value[a][metric] > value[b][metric]
                )
                wins[f"{a}>{b}"][metric] += int(better)
    return {pair: {m: round(n / reps, 3) for m, n in counts.items()} for pair, counts in wins.items()}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, required=True, help="work folder (scenes, packets, runs)")
    parser.add_argument("--preset", default="tiny")
    parser.add_argument("--scenes", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--inception", type=Path, default=None, help="FID Inception-v3 weights (else AlexNet)"
    )
    parser.add_argument("--name", default="trajectory_ranking", help="results file stem")
    parser.add_argument("--bootstrap", type=int, default=200, help="scene-bootstrap resamples")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    started = time.perf_counter()
    scenes_dir, store_dir = args.out / "scenes", args.out / "packets"
    synth = ["synth", "--out", str(scenes_dir), "--preset", args.preset, "--scenes", str(args.scenes)]
    if cli([*synth, "--seed", str(args.seed), "--no-progress"]) != 0:
        return 1
    prepare("synthetic", scenes_dir, store_dir, fits=scenes_dir, progress=False, trajectories=SHIFTS)
    store = PacketStore(store_dir)
    preset = get_preset(args.preset)

    # ground truth at every target, after checking the world reproduces the recorded captures
    targets = store.index[store.index["role"] == "target"].sort_values(["packet_id", "view"])
    worlds: dict[str, Any] = {}
    truths: dict[tuple[str, str], tuple[np.ndarray, np.ndarray]] = {}
    worst_recorded = 0.0
    for scene, rows in targets.groupby("scene", sort=True):
        seed, index = (int(v) for v in str(scene).split("_")[1:3])
        build = build_scene(preset, seed, index)
        worlds[scene] = build
        moving = (build.world.vehicles["lane0"], build.moving["lane0"]) if "lane0" in build.moving else None
        refs = store.index[(store.index["role"] == "ref") & (store.index["scene"] == scene)]
        for row in refs.drop_duplicates("frame").to_dict("records"):  # an unmoved camera: the capture itself
            rgb, _ = truth(
                build.world, moving, row_camera(row, world=True), int(row["timestamp_us"]), preset.tile_size
            )
            captured = read_rgb(scenes_dir / str(scene) / "images" / row["frame"])
            worst_recorded = max(worst_recorded, float(np.abs(rgb - captured).max()))
        for row in rows.to_dict("records"):
            camera = row_camera(row, world=True)
            truths[(row["packet_id"], row["frame"])] = truth(
                build.world, moving, camera, int(row["timestamp_us"]), preset.tile_size
            )
    if worst_recorded > 1.5 / 255:
        print(f"the rendered world differs from the captures by {worst_recorded:.4f}", file=sys.stderr)
        return 1

    if args.inception is not None:
        network: torch.nn.Module = load_inception(args.inception)
        features_name = f"FID Inception-v3 ({args.inception.name}, sha256 {sha256_file(args.inception)[:12]})"
    else:
        network = AlexNetPool().eval()
        features_name = "LPIPS AlexNet trunk conv5 ReLU, image mean (256-d), input resized to height 224"
    psnr, lpips = METRICS["psnr"], METRICS["lpips"]
    per_method: dict[str, dict[str, dict[str, float]]] = {}
    runs: dict[str, Any] = {}
    # per (group, method): per-target scene, PSNR, LPIPS and features; per (group, scene): recorded features
    samples: dict[tuple[str, str], dict[str, Any]] = {}
    recorded_features: dict[tuple[str, str], np.ndarray] = {}
    references = store.index[store.index["role"] == "ref"]
    for (group, scene), rows in references.groupby(["group", "scene"], sort=True):
        paths = [store.root / p for p in rows.drop_duplicates("frame")["image"]]
        recorded_features[(str(group), str(scene))] = inception_features(network, [_image(p) for p in paths])
    for method, checkpoint in METHODS:
        out = args.out / "runs" / method
        options = {"checkpoint": checkpoint} if checkpoint else {}
        t0 = time.perf_counter()
        run_method(store, out, RunSettings(method, options=options, metrics=("psnr",)), progress=False)
        runs[method] = {"checkpoint": checkpoint, "run_s": round(time.perf_counter() - t0, 1)}
        table = score_distribution(out, store, network)
        metrics = pd.read_parquet(out / "metrics.parquet")
        for group, rows in metrics.groupby("group", sort=True):
            preds, gts, masks = [], [], []
            for row in rows.to_dict("records"):
                preds.append(to_tensor_chw(read_rgb(out / row["image"])))
                rgb, mask = truths[(row["packet_id"], row["frame"])]
                gts.append(to_tensor_chw(rgb.astype(np.float32)))
                masks.append(torch.from_numpy(mask)[None])
            pred, gt, mask = torch.stack(preds), torch.stack(gts), torch.stack(masks)
            with torch.no_grad():
                p = psnr.compute(pred, gt, mask).double().numpy()
                lp = lpips.compute(pred, gt, mask).double().numpy()
            a = inception_features(network, list(pred))
            b = inception_features(network, list(gt))
            block = table[table["group"] == group].iloc[0]
            scenes = [str(v) for v in rows["scene"]]
            samples[(str(group), method)] = {"scene": np.array(scenes), "psnr": p, "lpips": lp, "features": a}
            recorded = np.concatenate([recorded_features[(str(group), sc)] for sc in sorted(set(scenes))])
            own_fid = fid(a, recorded)  # the same sets as distribution_scoring's: a check of this script
            if not math.isclose(own_fid, float(block["fid"]), rel_tol=1e-6, abs_tol=1e-9):
                print(f"{method} {group}: FID {own_fid} here, {block['fid']} in the run", file=sys.stderr)
                return 1
            per_method.setdefault(str(group), {})[method] = {
                "psnr": float(p.mean()),
                "lpips": float(lp.mean()),
                "fid": float(block["fid"]),
                "kid": float(block["kid"]),
                "fid_vs_truth": fid(a, b),
                "kid_vs_truth": kid(a, b).mean,
                "targets": len(rows),
                "recorded": int(block["recorded"]),
            }
    verdict: dict[str, Any] = {}
    for group, values in per_method.items():
        ranks = {m: ranking({k: v[m] for k, v in values.items()}, m) for m in LOWER_IS_BETTER}
        verdict[group] = {
            "rankings": ranks,
            "bootstrap": bootstrap(group, samples, recorded_features, args.bootstrap, args.seed),
            "agree_with_psnr": {
                m: ranks[m] == ranks["psnr"] for m in ("fid", "kid", "fid_vs_truth", "kid_vs_truth")
            },
            "agree_with_lpips": {
                m: ranks[m] == ranks["lpips"] for m in ("fid", "kid", "fid_vs_truth", "kid_vs_truth")
            },
            "kendall_tau_vs_psnr": {m: kendall_tau(ranks[m], ranks["psnr"]) for m in ("lpips", "fid", "kid")},
            "kendall_tau_vs_lpips": {
                m: kendall_tau(ranks[m], ranks["lpips"]) for m in ("psnr", "fid", "kid")
            },
        }
    payload = {
        "question": "on the same novel-trajectory frames, do FID / KID (vs the recorded frames) rank methods "
        "as PSNR / LPIPS (vs the true shifted frames) do?",
        "command": "python3 -m benchmarks.trajectory_ranking "
        + " ".join("WORK" if a == str(args.out) else a for a in (argv if argv is not None else sys.argv[1:])),
        "revision": git_revision(),
        "preset": args.preset,
        "scenes": args.scenes,
        "seed": args.seed,
        "trajectories": list(SHIFTS),
        "methods": runs,
        "features": features_name,
        "truth_check_max_abs_diff": worst_recorded,
        "paired_metrics": "PSNR and LPIPS (alex) with the capture rule's dynamic masks, on the 8-bit written frames",
        "distribution_metrics": "fid / kid: the enhanced frames vs the recorded frames the packets carry as "
        "references (what a user without ground truth gets); *_vs_truth: vs the true frames at the same poses",
        "scores": per_method,
        "verdict": verdict,
        "bootstrap": "verdict.<shift>.bootstrap['A>B'][metric]: fraction of scene resamples in which the metric "
        "rates A better than B (FID / KID recomputed on the resampled sets)",
        "machine": machine(),
        "wall_s": round(time.perf_counter() - started, 1),
    }
    path = write_result(
        args.name,
        json.loads(
            json.dumps(payload, default=lambda v: None if isinstance(v, float) and math.isnan(v) else v)
        ),
    )
    print(json.dumps(verdict, indent=1))
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
