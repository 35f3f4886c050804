"""How far the tiny autoencoder's reconstruction goes with width, latent channels and training length.

Issue 15 asks for a tiny autoencoder that reconstructs test frames at >= 30 dB PSNR at 256x144; the one
shipped until 2026-11-27 (base width 16, 8 latent channels, 1,200 steps of 64-pixel crops on the CPU)
reached 23.9 dB, and the one shipped since (16 latent channels, 6,000 steps of 128-pixel crops, made by
this script's ``one`` verb on a lent H200) 31.25 dB.  This
script trains several variants with the toolkit's own loop (:func:`fit_autoencoder`, the loop behind
``setdiff-bench train autoencoder``) for the same number of steps, side by side on one device, and
reports each variant's reconstruction of the training and test frames, so the choice of architecture and
step count is measured rather than guessed.

Separate verbs, so the sweep can run where the packet store (and OpenImageIO) is not (it needs torch, numpy,
opencv and diffusers there: carry diffusers as a wheel to a machine that lacks it)::

    # 1. the frames: every distinct ground-truth frame of the store's train and test splits
    python3 benchmarks/autoencoder_sweep.py export --packets runs/more/packets --to frames.npz \\
        --every-train 2 --every-test 3
    # 2. the sweep: one process per variant (width c, latent channels l), side by side on one device
    python3 benchmarks/autoencoder_sweep.py sweep --frames frames.npz --variants c16_l8,c32_l8 \
        --steps 6000 --device cuda --out sweep/
    # 3. every test frame of the store, for the folders brought back
    python3 benchmarks/autoencoder_sweep.py score --packets runs/more/packets sweep/c16_l8

Each variant's manifest names the equivalent ``setdiff-bench train autoencoder --steps N --base-channels c
--latent-channels l ...`` command (on the whole store rather than the exported subset).
``sweep/sweep.json`` gathers every variant's manifest; ``sweep/<variant>/`` is a complete autoencoder
folder that a model config can name.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import torch

from setdiff_bench.models.setdiff.autoencoder_settings import AutoencoderTraining
from setdiff_bench.models.setdiff.autoencoder_train import FrameSet, fit_autoencoder, save_autoencoder


def export_frames(packets: Path, to: Path, every: dict[str, int]) -> None:
    """Write every ``every[split]``-th distinct ground-truth frame of the store's train and test splits to
    ``to`` (npz): lossless PNG bytes (one buffer and offsets, so no pickled objects), their file hashes and
    the splits' scenes.  Subsampling keeps the file small enough to travel to a lent GPU machine."""
    import cv2

    from setdiff_bench.models.setdiff.autoencoder_train import ground_truth_frames
    from setdiff_bench.packets.store import PacketStore

    store = PacketStore(packets)
    arrays: dict[str, np.ndarray] = {}
    for split in ("train", "test"):
        frames = ground_truth_frames(store, split)
        chosen = range(0, len(frames.images), every[split])
        encoded = [
            cv2.imencode(
                ".png",
                frames.images[i].permute(1, 2, 0).numpy()[..., ::-1].copy(),
                [cv2.IMWRITE_PNG_COMPRESSION, 9],
            )[1]
            for i in chosen
        ]
        arrays[f"{split}_png"] = np.concatenate(encoded)
        arrays[f"{split}_offsets"] = np.cumsum([0] + [len(e) for e in encoded])
        arrays[f"{split}_hashes"] = np.array([frames.hashes[i] for i in chosen])
        arrays[f"{split}_scenes"] = np.array(sorted(set(store.index[store.index["split"] == split]["scene"])))
    to.parent.mkdir(parents=True, exist_ok=True)
    np.savez(to, **arrays)
    print(f"{to}: {len(arrays['train_hashes'])} train, {len(arrays['test_hashes'])} test frames")


def load_frames(path: Path) -> tuple[FrameSet, FrameSet, dict[str, list[str]]]:
    """The frames written by :func:`export_frames` → ``(train, test, scenes per split)``."""
    import cv2

    sets = {}
    with np.load(path) as data:
        for split in ("train", "test"):
            buffer, offsets = data[f"{split}_png"], data[f"{split}_offsets"]
            images = [
                cv2.imdecode(buffer[offsets[i] : offsets[i + 1]], cv2.IMREAD_COLOR)[..., ::-1].copy()
                for i in range(len(offsets) - 1)
            ]
            pixels = torch.from_numpy(np.stack(images)).permute(0, 3, 1, 2).contiguous()
            sets[split] = FrameSet(pixels, [str(h) for h in data[f"{split}_hashes"]])
        scenes = {split: [str(s) for s in data[f"{split}_scenes"]] for split in ("train", "test")}
    return sets["train"], sets["test"], scenes


def parse_variant(name: str) -> tuple[int, int]:
    """``c32_l8`` → ``(base channels 32, latent channels 8)``."""
    width, latent = name.split("_")
    if not (width.startswith("c") and latent.startswith("l")):
        raise ValueError(f"variant {name!r} is not c<width>_l<latent channels>")
    return int(width[1:]), int(latent[1:])


def run_variant(args: argparse.Namespace) -> None:
    """Train one variant for its budget and write its autoencoder folder."""
    base, latent = parse_variant(args.variant)
    train, test, scenes = load_frames(args.frames)
    settings = AutoencoderTraining(
        batch_size=args.batch_size,
        crop=args.crop,
        learning_rate=args.learning_rate,
        latent_channels=latent,
        base_channels=base,
        seed=args.seed,
        steps=args.steps,
        checkpoint_every=10**9,  # a sweep run is short and not resumed
    )
    out = args.out / args.variant
    vae, wall = fit_autoencoder(train, out, settings, device=args.device, progress=False)
    command = (
        f"setdiff-bench train autoencoder --packets PACKETS --out {args.variant} --steps {args.steps} "
        f"--base-channels {base} --latent-channels {latent} --crop {args.crop} "
        f"--batch-size {args.batch_size} --learning-rate {args.learning_rate} --seed {args.seed}"
    )
    manifest = save_autoencoder(
        vae, out, settings, train, test, scenes=scenes, wall_seconds=wall, device=args.device, command=command
    )
    print(json.dumps({"variant": args.variant, **manifest}), flush=True)


def run_sweep(args: argparse.Namespace) -> None:
    """One subprocess per variant, side by side; gather their manifests into ``out/sweep.json``."""
    args.out.mkdir(parents=True, exist_ok=True)
    processes = {}
    for variant in args.variants.split(","):
        command = [
            sys.executable,
            __file__,
            "one",
            "--variant",
            variant,
            "--frames",
            str(args.frames),
            "--out",
            str(args.out),
            "--device",
            args.device,
            "--crop",
            str(args.crop),
            "--batch-size",
            str(args.batch_size),
            "--learning-rate",
            str(args.learning_rate),
            "--seed",
            str(args.seed),
            "--steps",
            str(args.steps),
        ]
        log = open(args.out / f"{variant}.log", "w")  # noqa: SIM115 - closed below
        processes[variant] = (subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT), log)
    results = {}
    for variant, (process, log) in processes.items():
        process.wait()
        log.close()
        lines = (args.out / f"{variant}.log").read_text().splitlines()
        found = [json.loads(line) for line in lines if line.startswith("{")]
        results[variant] = found[-1] if found else {"error": "\n".join(lines[-5:])}
        test = results[variant].get("reconstruction_test") or {}
        print(variant, results[variant].get("settings", {}).get("steps"), test, flush=True)
    summary = {
        "benchmark": "autoencoder_sweep",
        "device": args.device,
        "gpu": torch.cuda.get_device_name() if args.device.startswith("cuda") else None,
        "steps": args.steps,
        "variants": results,
    }
    (args.out / "sweep.json").write_text(json.dumps(summary, indent=2, sort_keys=True) + "\n")


def score_autoencoders(packets: Path, folders: list[Path]) -> None:
    """Print each autoencoder's reconstruction of *every* distinct test frame of a store (the sweep scores
    the subset that travelled), as JSON lines."""
    from setdiff_bench.models.setdiff.autoencoder import load_autoencoder
    from setdiff_bench.models.setdiff.autoencoder_train import ground_truth_frames, reconstruction_metrics
    from setdiff_bench.packets.store import PacketStore

    frames = ground_truth_frames(PacketStore(packets), "test")
    for folder in folders:
        metrics = reconstruction_metrics(load_autoencoder(folder), frames.images)
        print(
            json.dumps({"autoencoder": str(folder), "test_frames": len(frames.images), **metrics}), flush=True
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    verbs = parser.add_subparsers(dest="verb", required=True)
    export = verbs.add_parser("export", help="write a store's train/test frames to an npz")
    export.add_argument("--packets", type=Path, required=True)
    export.add_argument("--to", type=Path, required=True)
    export.add_argument("--every-train", type=int, default=1, help="keep every N-th training frame")
    export.add_argument("--every-test", type=int, default=1, help="keep every N-th test frame")
    score = verbs.add_parser("score", help="reconstruction of every test frame of a store")
    score.add_argument("--packets", type=Path, required=True)
    score.add_argument("folders", type=Path, nargs="+", help="autoencoder folders")
    for name in ("sweep", "one"):
        verb = verbs.add_parser(
            name, help="train variants side by side" if name == "sweep" else "one variant"
        )
        verb.add_argument("--frames", type=Path, required=True)
        verb.add_argument("--out", type=Path, required=True)
        verb.add_argument("--device", default="cuda" if torch.cuda.is_available() else "cpu")
        verb.add_argument("--steps", type=int, default=6000, help="training steps per variant")
        verb.add_argument("--crop", type=int, default=128)
        verb.add_argument("--batch-size", type=int, default=16)
        verb.add_argument("--learning-rate", type=float, default=2e-3)
        verb.add_argument("--seed", type=int, default=0)
        if name == "sweep":
            verb.add_argument("--variants", default="c16_l8,c16_l16,c32_l8,c32_l16")
        else:
            verb.add_argument("--variant", required=True)
    args = parser.parse_args()
    if args.verb == "export":
        export_frames(args.packets, args.to, {"train": args.every_train, "test": args.every_test})
    elif args.verb == "score":
        score_autoencoders(args.packets, args.folders)
    elif args.verb == "sweep":
        run_sweep(args)
    else:
        run_variant(args)


if __name__ == "__main__":
    main()
