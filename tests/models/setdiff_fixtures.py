"""Fixtures of the SetDiff tests (imported by tests in other folders too): small packets with real cameras, tiny
configs (:func:`tiny_config` in memory, :func:`tiny_config_toml` the one writer of the ``train`` verb's TOML
configs), a real two-packet store (:func:`write_store`), an in-memory store for the ``train`` verb
(:class:`FakeStore`), an untrained residual model (:func:`residual_model`) and a tiny model with non-zero
LoRA, Ψ output and text embedding (:func:`perturbed_model`)."""

from __future__ import annotations

import json
import math
import random
from collections.abc import Mapping
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pandas as pd
import torch
import torch.nn.functional as F

from setdiff_bench.cameras import Camera
from setdiff_bench.models.setdiff.config import Config, TrainConfig, model_config_from_dict
from setdiff_bench.models.setdiff.inputs import TrainingSet, training_set
from setdiff_bench.models.setdiff.model import SetDiffModel
from setdiff_bench.models.setdiff.presets import TINY_UNET, TINY_VAE
from setdiff_bench.packets.index import merge_index
from setdiff_bench.packets.writer import PacketHeader, ViewContent, write_packet
from setdiff_bench.types import Packet, TrainingSample, ViewSet


def smooth_images(count: int, height: int, width: int, generator: torch.Generator) -> torch.Tensor:
    """``(count, 3, H, W)`` low-frequency random images in [0, 1]."""
    coarse = torch.rand(count, 3, max(2, height // 8), max(2, width // 8), generator=generator)
    return F.interpolate(coarse, size=(height, width), mode="bilinear", align_corners=False).clamp(0, 1)


def look_camera(yaw_deg: float, x: float, height: int, width: int) -> Camera:
    """A pinhole camera at ``(x, 0, 0)`` (world) turned by ``yaw`` about the y axis."""
    yaw = math.radians(yaw_deg)
    rotation = np.array(
        [[math.cos(yaw), 0.0, -math.sin(yaw)], [0.0, 1.0, 0.0], [math.sin(yaw), 0.0, math.cos(yaw)]]
    )
    center = np.array([x, 0.0, 0.0])
    w2c = np.eye(4)
    w2c[:3, :3] = rotation
    w2c[:3, 3] = -rotation @ center
    focal = 0.8 * width
    K = np.array([[focal, 0.0, width / 2], [0.0, focal, height / 2], [0.0, 0.0, 1.0]])
    return Camera(K=K, w2c=w2c, width=width, height=height)


def view_set(
    prefix: str, count: int, height: int, width: int, generator: torch.Generator, offset: float
) -> ViewSet:
    cameras = tuple(look_camera(7.0 * i + offset * 3, 0.1 * i + offset, height, width) for i in range(count))
    return ViewSet(
        names=tuple(f"{prefix}{i}" for i in range(count)),
        images=smooth_images(count, height, width, generator),
        cmaps=torch.randn(count, 3, height, width, generator=generator),
        alphas=torch.ones(count, 1, height, width),
        cameras=cameras,
    )


#: The dataset, protocol and group of every packet these helpers make or write.
UNIT_LABELS: dict[str, str] = {"dataset": "test", "protocol": "unit", "group": "g"}


def make_packet(num_refs: int, num_targets: int, size: tuple[int, int] = (32, 32), seed: int = 0) -> Packet:
    """A packet of random smooth images, random C-maps and distinct real cameras."""
    generator = torch.Generator().manual_seed(seed)
    height, width = size
    return Packet(
        packet_id=f"p{seed}",
        **UNIT_LABELS,
        split="train",
        scene="s",
        references=view_set("ref", num_refs, height, width, generator, 0.05),
        targets=view_set("tgt", num_targets, height, width, generator, 0.0),
    )


def make_sample(
    num_refs: int, num_targets: int, size: tuple[int, int] = (32, 32), seed: int = 0
) -> TrainingSample:
    """A training sample whose target renders are the ground truth, blurred and noised."""
    packet = make_packet(num_refs, num_targets, size, seed)
    generator = torch.Generator().manual_seed(seed + 1000)
    gt = smooth_images(num_targets, size[0], size[1], generator)
    blurred = F.avg_pool2d(gt, 3, stride=1, padding=1, count_include_pad=False)
    packet.targets.images = (blurred + 0.1 * torch.randn(gt.shape, generator=generator)).clamp(0, 1)
    masks = torch.ones(num_targets, 1, size[0], size[1], dtype=torch.bool)
    return TrainingSample(packet=packet, target_gt=gt, target_masks=masks)


def geometry_set(num_refs: int = 2, num_targets: int = 2, **options: Any) -> TrainingSet:
    """One training set with geometry drawn from :func:`make_sample` (32×32, seed 0) with ``random.Random(0)``;
    ``options`` go to :func:`~setdiff_bench.models.setdiff.inputs.training_set`."""
    return training_set(
        make_sample(num_refs, num_targets, size=(32, 32)),
        random.Random(0),
        min_views=2,
        max_views=8,
        use_geometry=True,
        cmap_clip=10.0,
        **options,
    )


#: Model overrides that make the tiny architecture a Difix-style baseline: RGB only, one reference per target.
DIFIX: dict[str, object] = {
    "method": "difix",
    "prediction": "epsilon",
    "use_geometry": False,
    "max_references": 1,
    "targets_per_set": 1,
    "skip_connections": True,
}


def tiny_config(**model_overrides: object) -> Config:
    """The tiny architecture with test-friendly training settings (no LPIPS weights needed)."""
    model = model_config_from_dict({"preset": "tiny", **model_overrides})
    train = TrainConfig(
        steps=4,
        learning_rate=1e-3,
        min_views=2,
        max_views=4,
        decode_targets=1,
        lpips_weight=0.0,
        checkpoint_every=1000,
        validate_every=1000,
        log_every=1,
        seed=0,
    )
    return Config(model=model, train=train)


# The scheduler_config.json of stabilityai/sd-turbo (docs/model.md, "SD-Turbo scheduler config").
SD_TURBO_SCHEDULER_JSON = {
    "_class_name": "EulerDiscreteScheduler",
    "beta_start": 0.00085,
    "beta_end": 0.012,
    "beta_schedule": "scaled_linear",
    "clip_sample": False,
    "interpolation_type": "linear",
    "num_train_timesteps": 1000,
    "prediction_type": "epsilon",
    "sample_max_value": 1.0,
    "set_alpha_to_one": False,
    "sigma_max": None,
    "sigma_min": None,
    "skip_prk_steps": True,
    "steps_offset": 1,
    "timestep_spacing": "trailing",
    "timestep_type": "discrete",
    "trained_betas": None,
    "use_karras_sigmas": False,
}


def write_diffusers_folder(root: Path, *, text: bool) -> tuple[Any, Any]:
    """A local folder laid out like the SD-Turbo repo, with tiny random networks; returns (unet, vae)."""
    from diffusers import AutoencoderKL, UNet2DConditionModel

    torch.manual_seed(3)
    unet = UNet2DConditionModel.from_config(dict(TINY_UNET))
    vae = AutoencoderKL.from_config(dict(TINY_VAE))
    unet.save_pretrained(root / "unet")
    vae.save_pretrained(root / "vae")
    (root / "scheduler").mkdir(parents=True)
    (root / "scheduler" / "scheduler_config.json").write_text(json.dumps(SD_TURBO_SCHEDULER_JSON))
    if text:
        from transformers import CLIPTextConfig, CLIPTextModel, CLIPTokenizer

        vocab = {"<|startoftext|>": 0, "<|endoftext|>": 1}
        for letter in "abcdefghijklmnopqrstuvwxyz":
            vocab[letter] = len(vocab)
            vocab[letter + "</w>"] = len(vocab)
        (root / "raw").mkdir()
        (root / "raw" / "vocab.json").write_text(json.dumps(vocab))
        (root / "raw" / "merges.txt").write_text("#version: 0.2\n")
        CLIPTokenizer(str(root / "raw" / "vocab.json"), str(root / "raw" / "merges.txt")).save_pretrained(
            root / "tokenizer"
        )
        encoder = CLIPTextModel(
            CLIPTextConfig(
                vocab_size=len(vocab),
                hidden_size=32,
                intermediate_size=64,
                num_hidden_layers=1,
                num_attention_heads=2,
                max_position_embeddings=77,
                bos_token_id=0,
                eos_token_id=1,
                pad_token_id=1,
            )
        )
        encoder.save_pretrained(root / "text_encoder")
    return unet, vae


def train_argv(config: Path | str, packets: Path | str, out: Path | str, *options: str) -> list[str]:
    """The words of ``setdiff-bench train --config C --packets P --out O`` followed by ``options``."""
    return ["train", "--config", str(config), "--packets", str(packets), "--out", str(out), *options]


#: The ``[model]`` table of the tiny SetDiff the tests train through the ``train`` verb.
TINY_MODEL: dict[str, object] = {
    "preset": "tiny",
    "method": "setdiff",
    "vae_decoder": "full",
    "skip_connections": True,
}


def _toml_value(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, int | float):
        return repr(value)
    raise TypeError(f"no TOML spelling for {value!r}")


def tiny_config_toml(model: Mapping[str, object] | None = None, **train: object) -> str:
    """The text of a TOML config for the ``train`` verb: the ``[model]`` table (default :data:`TINY_MODEL`)
    and a ``[train]`` table of ``train`` (none when empty); the one place the tests write such a config."""
    tables = [("model", TINY_MODEL if model is None else model)] + ([("train", train)] if train else [])
    return "\n".join(
        f"[{name}]\n" + "".join(f"{key} = {_toml_value(value)}\n" for key, value in table.items())
        for name, table in tables
    )


#: The config of the ``train`` verb tests on an in-memory store (:class:`FakeStore`).
CLI_TRAIN_CONFIG = tiny_config_toml(
    steps=2,
    learning_rate=1e-3,
    min_views=2,
    max_views=4,
    lpips_weight=0.0,
    validation_packets=1,
    validate_every=2,
    checkpoint_every=1,
    log_every=1,
)
#: The config of the tests that train on a real packet store (:func:`write_store`).
STORE_TRAIN_CONFIG = tiny_config_toml(
    steps=2,
    learning_rate=1e-3,
    min_views=3,
    max_views=4,
    lpips_weight=0.0,
    validation_packets=1,
    validate_every=2,
    checkpoint_every=2,
)


def contents(views: ViewSet, gt: torch.Tensor | None = None) -> list[ViewContent]:
    items = []
    for i, camera in enumerate(views.cameras):
        items.append(
            ViewContent(
                frame=views.names[i],
                sensor="front",
                traversal="lane0",
                timestamp_us=i,
                camera=camera,
                camera_world=camera,
                image=views.images[i].permute(1, 2, 0).numpy(),
                cmap=views.cmaps[i].permute(1, 2, 0).numpy(),
                alpha=views.alphas[i, 0].numpy(),
                gt=None if gt is None else gt[i].permute(1, 2, 0).numpy(),
                mask=None if gt is None else np.ones(gt.shape[-2:], dtype=bool),
                overlap_score=None if gt is not None else 1.0 - 0.1 * i,
            )
        )
    return items


def write_store(root: Path) -> None:
    """A real packet store of two packets (split train and test) of three references and three targets."""
    for split, seed in (("train", 0), ("test", 1)):
        sample = make_sample(3, 3, seed=seed)
        header = PacketHeader(
            packet_id=f"{split}-0",
            **UNIT_LABELS,
            split=split,
            scene=f"s{seed}",
            fit_key="fit",
            scale=1.0,
            recipe="r",
        )
        write_packet(
            root,
            header,
            contents(sample.packet.references),
            contents(sample.packet.targets, sample.target_gt),
        )
    merge_index(root)


class FakeStore:
    """The PacketStore interface the train verb uses, over two in-memory samples."""

    calls: ClassVar[list[tuple[str, object]]] = []

    def __init__(self, root: Path) -> None:
        self.root = Path(root)
        self.samples = {"train-0": make_sample(2, 2, seed=0), "test-0": make_sample(1, 2, seed=1)}
        # index rows as prepare writes them (only the columns the training manifest reads)
        self.index = pd.DataFrame(
            {
                "packet_id": ["train-0", "train-0", "test-0"],
                "split": ["train", "train", "test"],
                "scene": ["scene_0003_01", "scene_0003_01", "scene_0003_02"],
                "dataset": ["synthetic"] * 3,
                "height": [32, 32, 32],
                "width": [32, 32, 32],
                **{f"{c}_sha256": ["a" * 64, "b" * 64, "c" * 64] for c in ("image", "cmap", "gt")},
                "mask_sha256": ["", "d" * 64, ""],
            }
        )

    def training_dataset(
        self, split: str = "train", min_views: int = 8, max_views: int = 12, seed: int = 0
    ) -> list:
        FakeStore.calls.append(("training_dataset", (split, min_views, max_views, seed)))
        return [s for k, s in self.samples.items() if k.startswith(split)]

    def packet_ids(self, split: str) -> list[str]:
        return [k for k in self.samples if k.startswith(split)]

    def load_packet(self, packet_id: str) -> object:
        return self.samples[packet_id].packet

    def load_ground_truth(self, packet_id: str) -> tuple[object, object]:
        sample = self.samples[packet_id]
        return sample.target_gt, sample.target_masks


def residual_model(**overrides: object) -> SetDiffModel:
    torch.manual_seed(0)
    config = model_config_from_dict(
        {
            "preset": "tiny",
            "output_mode": "residual",
            "skip_connections": True,
            "vae_decoder": "full",
            **overrides,
        }
    )
    return SetDiffModel(config).eval()


def perturbed_model(config_overrides: dict[str, object] | None = None) -> tuple[SetDiffModel, object]:
    """A tiny model whose zero-initialised parts (LoRA B, Ψ output, text) are made non-zero."""
    config = tiny_config(**(config_overrides or {"skip_connections": True}))
    torch.manual_seed(1)
    model = SetDiffModel(config.model).eval()
    generator = torch.Generator().manual_seed(2)
    with torch.no_grad():
        for name, parameter in model.named_parameters():
            if "lora_B" in name or name.startswith("geometry_encoder.out") or name == "text_embedding":
                parameter.copy_(0.02 * torch.randn(parameter.shape, generator=generator))
    return model, config
