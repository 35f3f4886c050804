"""Training the toolkit's own tiny autoencoder (``setdiff-bench train autoencoder``): the stand-in for SD's VAE in
the tiny models.

The paper freezes SD-Turbo's *pretrained* VAE encoder, whose latents carry the image's content, so the
set mixer has something worth fetching from a reference.  Nothing pretrained can be downloaded here,
so ``setdiff-bench train autoencoder`` trains the tiny ``AutoencoderKL`` (the ``tiny`` preset's VAE
architecture, diffusers) on ground-truth frames of the *training* split of a packet store — clean
reference images and the targets' ground truth, each distinct frame once.  Test-split frames only
measure it.

Training: random crops (multiples of 8), horizontal flips, loss ``L1 + L2 + kl_weight · KL`` on the
posterior *mean* reconstruction (the mean is what SetDiff encodes with).  After training the latent
scale is measured as SD's was: ``scaling_factor = 1 / std(posterior means)`` over the training frames,
so scaled latents have unit variance.

The folder it writes, and how a model config reads it back, are :mod:`~setdiff_bench.models.setdiff.autoencoder`.
"""

from __future__ import annotations

import hashlib
import json
import math
import random
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.errors import UsageError
from setdiff_bench.io.atomic import atomic_path, write_text_atomic
from setdiff_bench.models.setdiff.autoencoder_settings import AutoencoderTraining
from setdiff_bench.models.setdiff.files import (
    AUTOENCODER_STATE_FILE,
    AUTOENCODER_WEIGHTS_FILE,
    CONFIG_FILE,
    MANIFEST_FILE,
)
from setdiff_bench.models.setdiff.packaged import file_table
from setdiff_bench.models.setdiff.presets import TINY_VAE


def tiny_vae_config(latent_channels: int, base_channels: int = 16) -> dict[str, Any]:
    """The ``tiny`` preset's VAE config with ``latent_channels`` latent channels and blocks of
    ``(base_channels, 2·base_channels, 2·base_channels, 2·base_channels)`` channels."""
    c = int(base_channels)
    return {
        **TINY_VAE,
        "latent_channels": int(latent_channels),
        "block_out_channels": [c, 2 * c, 2 * c, 2 * c],
    }


# ---------------------------------------------------------------------- data
@dataclass
class FrameSet:
    """Distinct ground-truth frames of one split: ``images`` ``(F, 3, H, W)`` uint8, and their file hashes."""

    images: torch.Tensor
    hashes: list[str]

    def data_hash(self) -> str:
        """SHA-256 over the sorted per-file SHA-256s (what the autoencoder saw, independent of order)."""
        return hashlib.sha256("\n".join(sorted(self.hashes)).encode()).hexdigest()


def ground_truth_frames(store: Any, split: str) -> FrameSet:
    """Every distinct ground-truth frame of ``split`` in a packet store: clean references and target GT.

    Frames are deduplicated by their file's SHA-256 (references recur across packets).  Targets without
    ground truth (novel-trajectory views, :meth:`PacketStore.has_ground_truth`) are left out; their
    packets' references are recorded frames and count.
    """
    # lazy: OpenImageIO is needed only to read a store; training from frames in memory runs without it
    from setdiff_bench.io.images import read_rgb

    seen: dict[str, torch.Tensor] = {}
    for packet_id in store.packet_ids(split):
        rows = store.rows(packet_id)
        for _, row in rows.iterrows():
            column = "image" if row["role"] == "ref" else "gt"
            if column == "gt" and not isinstance(row["gt"], str):
                continue  # a novel-trajectory target: no ground-truth frame
            digest = str(row[f"{column}_sha256"])
            if digest in seen:
                continue
            size = (int(row["height"]), int(row["width"]))
            pixels = torch.from_numpy(read_rgb(store.file_path(row, column), size)).permute(2, 0, 1)
            seen[digest] = (pixels * 255.0).round().to(torch.uint8).contiguous()
    if not seen:
        raise UsageError(f"the packet store has no {split!r} frames to train the autoencoder on", store.root)
    shapes = {tuple(image.shape) for image in seen.values()}
    if len(shapes) != 1:
        raise UsageError(f"frames of several sizes in the {split!r} split: {sorted(shapes)}", store.root)
    ordered = sorted(seen)
    return FrameSet(torch.stack([seen[d] for d in ordered]), ordered)


def random_crops(frames: torch.Tensor, count: int, crop: int, rng: random.Random) -> torch.Tensor:
    """``count`` random ``crop × crop`` crops (clipped to the frame, multiples of 8), randomly flipped,
    as float ``(count, 3, h, w)`` in [0, 1]."""
    _, _, height, width = frames.shape
    ch, cw = min(crop, height) // 8 * 8, min(crop, width) // 8 * 8
    crops = []
    for _ in range(count):
        image = frames[rng.randrange(len(frames))]
        y, x = rng.randint(0, height - ch), rng.randint(0, width - cw)
        piece = image[:, y : y + ch, x : x + cw]
        if rng.random() < 0.5:
            piece = piece.flip(-1)
        crops.append(piece)
    return torch.stack(crops).float() / 255.0


# ---------------------------------------------------------------------- model maths
def reconstruct(vae: Any, images: torch.Tensor) -> tuple[torch.Tensor, Any]:
    """Posterior-mean reconstruction of ``(B, 3, H, W)`` images in [0, 1] → ``(images in [0, 1], posterior)``."""
    posterior = vae.encode(images * 2.0 - 1.0).latent_dist
    decoded = vae.decode(posterior.mean).sample
    return (decoded.clamp(-1.0, 1.0) + 1.0) / 2.0, posterior


@torch.no_grad()
def reconstruction_metrics(vae: Any, frames: torch.Tensor, batch: int = 8) -> dict[str, float]:
    """Mean PSNR (dB) and SSIM of whole-frame reconstructions (H, W must be multiples of 8)."""
    # lazy: SSIM's filter imports OpenCV, which fitting frames held in memory does not need
    from setdiff_bench.metrics.psnr import psnr
    from setdiff_bench.metrics.ssim import ssim

    values: dict[str, list[float]] = {"psnr": [], "ssim": []}
    device = next(vae.parameters()).device
    for start in range(0, len(frames), batch):
        images = frames[start : start + batch].float() / 255.0
        output, _ = reconstruct(vae, images.to(device))
        output = output.float().cpu()
        values["psnr"] += psnr(output, images).tolist()
        values["ssim"] += ssim(output, images).tolist()
    return {k: round(sum(v) / len(v), 4) for k, v in values.items()}


@torch.no_grad()
def latent_std(vae: Any, frames: torch.Tensor, batch: int = 8) -> float:
    """Standard deviation of the unscaled posterior means over ``frames`` (SD's scale rule)."""
    device = next(vae.parameters()).device
    means = [
        vae.encode((frames[s : s + batch].float() / 255.0 * 2.0 - 1.0).to(device)).latent_dist.mean.cpu()
        for s in range(0, len(frames), batch)
    ]
    return float(torch.cat(means).std())


# ---------------------------------------------------------------------- training
def train_autoencoder(
    packets: str | Path,
    out_dir: str | Path,
    settings: AutoencoderTraining,
    *,
    device: str = "cpu",
    progress: bool = True,
    command: str | None = None,
) -> dict[str, Any]:
    """Train the tiny autoencoder on a packet store's training frames; returns the manifest.

    Resumes from ``out_dir/training_state.pt`` when present (same settings).  The final folder holds
    :data:`~setdiff_bench.models.setdiff.files.AUTOENCODER_FILES`; the training state is removed once they are
    written.

    Raises:
        UsageError: no training frames, frames of mixed sizes, or a resume with other settings.
    """
    from setdiff_bench.packets.store import PacketStore  # lazy: reads the store with OpenImageIO, as above

    check_settings(settings)
    store = PacketStore(packets)
    train_frames = ground_truth_frames(store, "train")
    test_frames = ground_truth_frames(store, "test") if store.packet_ids("test") else None
    scenes = {
        split: sorted(set(store.index[store.index["split"] == split]["scene"])) for split in ("train", "test")
    }
    vae, wall_seconds = fit_autoencoder(train_frames, out_dir, settings, device=device, progress=progress)
    return save_autoencoder(
        vae,
        out_dir,
        settings,
        train_frames,
        test_frames,
        scenes=scenes,
        wall_seconds=wall_seconds,
        device=device,
        command=command or " ".join(["setdiff-bench", *sys.argv[1:]]),
    )


def check_settings(settings: AutoencoderTraining) -> None:
    """Refuse settings no VAE can be trained with (one line, naming the command)."""
    if (
        settings.crop % 8
        or settings.crop < 16
        or settings.steps < 1
        or settings.batch_size < 1
        or settings.base_channels < 8
        or settings.base_channels % 8
    ):
        raise UsageError(
            "crop must be a multiple of 8 (>= 16); base channels a multiple of 8 (>= 8); "
            "steps and batch size >= 1",
            "train autoencoder",
        )


def fit_autoencoder(
    train_frames: FrameSet,
    out_dir: str | Path,
    settings: AutoencoderTraining,
    *,
    device: str = "cpu",
    progress: bool = True,
) -> tuple[Any, float]:
    """The optimisation itself: a fresh (or resumed) VAE trained on ``train_frames`` → ``(vae in eval mode,
    wall seconds of training over all sessions)``.

    Crops and flips are drawn on the CPU from a generator seeded by ``(seed, step)``, so a resumed run sees
    the same batches; ``device`` only moves the arithmetic (CUDA results differ from the CPU's in the last
    bits).  The resume point ``out_dir/training_state.pt`` is written every ``checkpoint_every`` steps.
    """
    from diffusers import AutoencoderKL
    from tqdm.auto import tqdm

    check_settings(settings)
    out = Path(out_dir)
    torch.manual_seed(settings.seed)
    vae = AutoencoderKL.from_config(tiny_vae_config(settings.latent_channels, settings.base_channels))
    vae.to(device)  # before the optimiser, so a resumed optimiser state lands on the parameters' device
    optimizer = torch.optim.AdamW(vae.parameters(), lr=settings.learning_rate, weight_decay=0.0)
    schedule = torch.optim.lr_scheduler.LambdaLR(optimizer, lambda step: cosine_factor(step, settings.steps))
    start, elapsed = load_state(out / AUTOENCODER_STATE_FILE, settings, vae, optimizer, schedule)
    began = time.perf_counter()
    bar = tqdm(
        total=settings.steps,
        initial=start,
        disable=not progress,
        desc="train autoencoder",
        dynamic_ncols=True,
    )
    vae.train()
    for step in range(start, settings.steps):
        rng = random.Random(f"{settings.seed}/{step}")
        images = random_crops(train_frames.images, settings.batch_size, settings.crop, rng).to(device)
        output, posterior = reconstruct(vae, images)
        l1 = (output - images).abs().mean()
        l2 = (output - images).square().mean()
        kl = posterior.kl().mean() / images[0].numel()
        loss = l1 + l2 + settings.kl_weight * kl
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(vae.parameters(), 1.0)
        optimizer.step()
        schedule.step()
        bar.update(1)
        if (step + 1) % 25 == 0:
            bar.set_postfix(psnr=f"{-10 * torch.log10(l2.detach().clamp_min(1e-10)).item():.2f}")
        if (step + 1) % settings.checkpoint_every == 0 and step + 1 < settings.steps:
            save_state(
                out / AUTOENCODER_STATE_FILE,
                settings,
                vae,
                optimizer,
                schedule,
                step + 1,
                elapsed + time.perf_counter() - began,
            )
    bar.close()
    vae.eval()
    return vae, elapsed + time.perf_counter() - began


def save_autoencoder(
    vae: Any,
    out_dir: str | Path,
    settings: AutoencoderTraining,
    train_frames: FrameSet,
    test_frames: FrameSet | None,
    *,
    scenes: dict[str, list[str]],
    wall_seconds: float,
    device: str,
    command: str,
) -> dict[str, Any]:
    """Measure a trained VAE (latent scale, reconstruction on both splits) and write
    :data:`~setdiff_bench.models.setdiff.files.AUTOENCODER_FILES` to ``out_dir`` (the resume point is removed once
    they are written) → the manifest."""
    from safetensors.torch import save_file

    out = Path(out_dir)
    config = dict(vae.config)
    config = {k: v for k, v in config.items() if not k.startswith("_")}
    config["scaling_factor"] = round(1.0 / latent_std(vae, train_frames.images), 6)
    manifest = {
        "command": command,
        "settings": asdict(settings),
        "device": torch.device(device).type,
        "train_frames": len(train_frames.images),
        "test_frames": 0 if test_frames is None else len(test_frames.images),
        "frame_size": list(train_frames.images.shape[-2:]),
        "data_sha256": train_frames.data_hash(),
        "train_scenes": scenes.get("train", []),
        "test_scenes": scenes.get("test", []),
        "wall_seconds": round(wall_seconds, 1),
        "reconstruction_train": reconstruction_metrics(vae, train_frames.images),
        "reconstruction_test": None
        if test_frames is None
        else reconstruction_metrics(vae, test_frames.images),
        "parameters": sum(p.numel() for p in vae.parameters()),
        "scaling_factor": config["scaling_factor"],
    }
    out.mkdir(parents=True, exist_ok=True)
    state = {k: v.detach().cpu().contiguous() for k, v in vae.state_dict().items()}
    with atomic_path(out / AUTOENCODER_WEIGHTS_FILE) as temporary:
        save_file(state, str(temporary))
    write_text_atomic(out / CONFIG_FILE, json.dumps(config, indent=2, sort_keys=True) + "\n")
    manifest["files"] = file_table(
        out, [CONFIG_FILE, AUTOENCODER_WEIGHTS_FILE]
    )  # what `weights verify` re-hashes
    write_text_atomic(out / MANIFEST_FILE, json.dumps(manifest, indent=2, sort_keys=True) + "\n")
    (out / AUTOENCODER_STATE_FILE).unlink(missing_ok=True)
    return manifest


def cosine_factor(step: int, total: int, floor: float = 0.05) -> float:
    """Learning-rate multiplier: cosine from 1 to ``floor`` over ``total`` steps."""
    progress = min(step / max(total, 1), 1.0)
    return floor + (1.0 - floor) * 0.5 * (1.0 + math.cos(math.pi * progress))


def save_state(
    path: Path,
    settings: AutoencoderTraining,
    vae: Any,
    optimizer: Any,
    schedule: Any,
    step: int,
    elapsed: float,
) -> None:
    """The resume point: weights, optimiser and schedule state, step and settings (tensors + plain data)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(path) as temporary:
        torch.save(
            {
                "settings": asdict(settings),
                "step": step,
                "elapsed": elapsed,
                "vae": vae.state_dict(),
                "optimizer": optimizer.state_dict(),
                "schedule": schedule.state_dict(),
            },
            temporary,
        )


def load_state(
    path: Path, settings: AutoencoderTraining, vae: Any, optimizer: Any, schedule: Any
) -> tuple[int, float]:
    """Restore a resume point written by :func:`save_state` → ``(step, elapsed seconds)``; ``(0, 0)`` if none."""
    if not path.is_file():
        return 0, 0.0
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except (OSError, RuntimeError, ValueError) as error:
        raise UsageError(f"cannot read the autoencoder training state: {error}", path) from error
    if state.get("settings") != asdict(settings):
        raise UsageError(
            "the training state was written with other settings; use another --out or the same options", path
        )
    vae.load_state_dict(state["vae"])
    optimizer.load_state_dict(state["optimizer"])
    schedule.load_state_dict(state["schedule"])
    return int(state["step"]), float(state["elapsed"])
