"""Fit quality of a generated benchmark: PSNR of each scene's ``fits/lane0.ply`` per view group, and an
image grid of ground truth vs fitted render.

Groups (front camera unless named): ``train`` (the fit frames), ``interp`` (``lane0`` timesteps held
out of the fit), ``side`` (``lane0`` front-left/front-right, never fitted), ``lane+1``, ``lane+2`` (the
parallel drives) and ``turn`` (the lane change).  PSNR is per image over static pixels (dynamic mask
255), averaged per group and scene, then over scenes.

Run: ``python -m setdiff_bench.synthetic.evaluate --root DIR --out results/synthetic``.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.errors import DatasetError
from setdiff_bench.gaussians.ply import read_ply
from setdiff_bench.gaussians.render import render
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.io.images import read_mask, read_rgb, to_tensor_chw
from setdiff_bench.loaders import load_scenes
from setdiff_bench.metrics.psnr import psnr
from setdiff_bench.types import Frame, Scene

GROUPS: dict[str, Callable[[Frame], bool]] = {
    "train": lambda f: f.split == "train",
    "interp": lambda f: f.split == "test" and f.traversal == "lane0" and f.sensor == "front",
    "side": lambda f: f.traversal == "lane0" and f.sensor in ("front_left", "front_right"),
    "lane+1": lambda f: f.traversal == "lane1" and f.sensor == "front",
    "lane+2": lambda f: f.traversal == "lane2" and f.sensor == "front",
    "turn": lambda f: f.traversal == "turn" and f.sensor == "front",
}
GRID_COLUMNS = ("interp", "lane+1", "lane+2", "side", "turn")


def fit_ply(scene: Scene) -> Path:
    return Path(scene.root) / "fits" / "lane0.ply"


def render_frames(scene: Scene, frames: Sequence[Frame]) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``(pred, target, mask)`` of ``frames``: ``(V, 3, H, W)``, ``(V, 3, H, W)``, ``(V, 1, H, W)`` bool."""
    model = read_ply(fit_ply(scene))
    preds, targets, masks = [], [], []
    for frame in frames:
        with torch.no_grad():
            preds.append(render(model, [frame.camera], with_geometry=False).rgb[0].clamp(0, 1))
        targets.append(to_tensor_chw(read_rgb(frame.image_path)))
        keep = (
            read_mask(frame.mask_path)
            if frame.mask_path is not None
            else np.ones(targets[-1].shape[1:], bool)
        )
        masks.append(torch.from_numpy(keep)[None])
    return torch.stack(preds), torch.stack(targets), torch.stack(masks)


def evaluate_scene(scene: Scene) -> dict[str, float]:
    """Mean masked PSNR (dB) per group of one scene."""
    out = {}
    for group, rule in GROUPS.items():
        frames = [f for f in scene.frames if rule(f)]
        if not frames:
            continue
        pred, target, mask = render_frames(scene, frames)
        out[group] = float(psnr(pred, target, mask).mean())
    return out


def grid_image(scene: Scene, out_path: Path) -> None:
    """Ground truth, fitted render and absolute error (rows), one column per group, middle timestep.

    The PSNR in each title is over static pixels (dynamic mask), as in the table.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    indices = sorted({int(f.metadata.get("index", 0)) for f in scene.frames})
    middle = indices[len(indices) // 2]
    picks = []
    for group in GRID_COLUMNS:
        frames = [f for f in scene.frames if GROUPS[group](f)]
        frames.sort(key=lambda f: (abs(int(f.metadata.get("index", 0)) - middle), f.name))
        if frames:
            picks.append((group, frames[0]))
    pred, target, mask = render_frames(scene, [f for _, f in picks])
    error = ((pred - target).abs().mean(dim=1) / 0.5).clamp(0, 1)  # (V, H, W), white at ≥ 0.5
    error_rgb = error[:, None].repeat(1, 3, 1, 1)
    error_rgb[:, 0] = torch.where(
        mask[:, 0], error_rgb[:, 0], torch.ones_like(error)
    )  # dynamic pixels in red
    error_rgb[:, 1:] = torch.where(mask, error_rgb[:, 1:], torch.zeros_like(error_rgb[:, 1:]))
    fig, axes = plt.subplots(3, len(picks), figsize=(3.3 * len(picks), 6.4), squeeze=False)
    for column, (group, frame) in enumerate(picks):
        value = float(psnr(pred[column : column + 1], target[column : column + 1], mask[column : column + 1]))
        panels = (
            (target[column].permute(1, 2, 0).numpy(), f"{group} — ground truth\n{frame.name}"),
            (pred[column].permute(1, 2, 0).numpy(), f"3DGS fit ({value:.1f} dB)"),
            (error_rgb[column].permute(1, 2, 0).numpy(), "|error|: black 0, white ≥ 0.5, red = masked"),
        )
        for row, (image, title) in enumerate(panels):
            ax = axes[row][column]
            ax.imshow(image, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            ax.set_title(title, fontsize=8)
    fig.suptitle(
        f"{scene.name}: 3DGS fitted on lane0 front (train_set.txt), rendered at held-out views", fontsize=10
    )
    fig.tight_layout()
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def report(rows: dict[str, dict[str, float]], command: str, notes: Sequence[str] = ()) -> str:
    """The Markdown table: one row per scene plus the mean, one column per group, and the step sizes."""
    groups = [g for g in GROUPS if any(g in r for r in rows.values())]
    lines = [
        "# Synthetic benchmark: fit quality (PSNR, dB, static pixels)",
        "",
        "Produced by:",
        "",
        "```",
        command,
        "```",
        "",
        "| scene | " + " | ".join(groups) + " |",
        "|---" * (len(groups) + 1) + "|",
    ]
    for name, values in rows.items():
        lines.append(
            f"| {name} | " + " | ".join(f"{values[g]:.2f}" if g in values else "–" for g in groups) + " |"
        )
    mean = {g: float(np.mean([r[g] for r in rows.values() if g in r])) for g in groups}
    lines.append("| **mean** | " + " | ".join(f"**{mean[g]:.2f}**" for g in groups) + " |")
    lines += [
        "",
        "Drops on average over the scenes (each must be ≥ 1.5 dB):",
        "",
        f"- interp → lane+1: {mean['interp'] - mean['lane+1']:.2f} dB",
        f"- lane+1 → lane+2: {mean['lane+1'] - mean['lane+2']:.2f} dB",
        f"- interp − side (held-out side cameras below the training camera): {mean['interp'] - mean['side']:.2f} dB",
        "",
    ]
    lines += list(notes)
    return "\n".join(lines) + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", required=True, type=Path, help="output folder of `setdiff-bench synth`")
    parser.add_argument("--out", required=True, type=Path, help="folder for fit_quality.md and fit_grid.png")
    parser.add_argument("--command", default=None, help="the command line to record in the report")
    parser.add_argument("--note", action="append", default=[], help="extra line for the report")
    args = parser.parse_args(argv)

    scenes = load_scenes("synthetic", args.root)
    missing = [s.name for s in scenes if not fit_ply(s).is_file()]
    if missing:
        raise DatasetError(f"scenes without fits/lane0.ply: {', '.join(missing)}", args.root)
    rows = {}
    for scene in scenes:
        rows[scene.name] = evaluate_scene(scene)
        print(scene.name, {k: round(v, 2) for k, v in rows[scene.name].items()}, flush=True)
    command = args.command or " ".join(
        [
            os.path.basename(sys.executable),
            "-m",
            "setdiff_bench.synthetic.evaluate",
            *(argv if argv is not None else sys.argv[1:]),
        ]
    )
    write_text_atomic(args.out / "fit_quality.md", report(rows, command, args.note))
    grid_image(scenes[0], args.out / "fit_grid.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())
