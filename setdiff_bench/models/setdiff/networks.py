"""Build the UNet and VAE from config, or load them from a local diffusers SD-Turbo folder.

Nothing is ever downloaded, and only safetensors weights are read (``use_safetensors=True``: a folder
holding pickled ``.bin`` weights instead is refused, never unpickled).  ``from_pretrained`` runs with
``local_files_only=True`` on a folder laid
out like the Hugging Face repo (``unet/``, ``vae/``, ``scheduler/``, optionally ``text_encoder/`` +
``tokenizer/``).  With a text encoder the fixed prompt is encoded once (``last_hidden_state``,
``(1, 77, 1024)``) and the encoder is dropped; without one the caller uses a learned null embedding.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from setdiff_bench.errors import WeightsError
from setdiff_bench.models.setdiff.autoencoder import load_autoencoder_weights
from setdiff_bench.models.setdiff.config import ModelConfig

ARCHITECTURE_KEYS = (
    "in_channels",
    "out_channels",
    "block_out_channels",
    "down_block_types",
    "up_block_types",
    "layers_per_block",
    "cross_attention_dim",
    "latent_channels",
)


@dataclass
class Networks:
    """The diffusers modules a model is made of, and the prompt embedding if one was encoded."""

    unet: Any
    vae: Any
    prompt_embedding: torch.Tensor | None


def build_networks(config: ModelConfig, *, load_pretrained: bool = True) -> Networks:
    """Random-init networks from ``config``, or ``config.pretrained`` when set and ``load_pretrained``
    (then also the VAE weights of ``config.autoencoder``, when set)."""
    from diffusers import AutoencoderKL, UNet2DConditionModel

    if config.pretrained and load_pretrained:
        return load_pretrained_networks(Path(config.pretrained), config)
    unet = UNet2DConditionModel.from_config(dict(config.unet))
    vae = AutoencoderKL.from_config(dict(config.vae))
    if config.autoencoder and load_pretrained:
        load_autoencoder_weights(vae, config.autoencoder)
    return Networks(unet=unet, vae=vae, prompt_embedding=None)


def load_pretrained_networks(root: Path, config: ModelConfig) -> Networks:
    """Load ``unet/``, ``vae/`` (and the prompt embedding) from a local diffusers folder.

    Raises:
        WeightsError: a sub-folder is missing, unreadable, or its architecture or noise schedule
            differs from ``config`` (naming the folder and the differing key).
    """
    from diffusers import AutoencoderKL, UNet2DConditionModel

    for part in ("unet", "vae", "scheduler"):
        if not (root / part).is_dir():
            raise WeightsError(
                f"pretrained folder has no {part}/ sub-folder (expected a diffusers SD-Turbo layout)", root
            )
    check_schedule(root / "scheduler" / "scheduler_config.json", config)
    modules: dict[str, Any] = {}
    for part, cls in (("unet", UNet2DConditionModel), ("vae", AutoencoderKL)):
        try:
            modules[part] = cls.from_pretrained(
                root, subfolder=part, local_files_only=True, use_safetensors=True, torch_dtype=torch.float32
            )
        except (OSError, ValueError, RuntimeError) as error:
            raise WeightsError(f"cannot load {part}: {error}", root / part) from error
        expected = config.unet if part == "unet" else config.vae
        for key in ARCHITECTURE_KEYS:
            if key in expected and _norm(modules[part].config.get(key)) != _norm(expected[key]):
                raise WeightsError(
                    f"{part} {key} is {modules[part].config.get(key)!r} but the config says "
                    f"{expected[key]!r}; use the matching preset",
                    root / part,
                )
    prompt = None
    if (root / "text_encoder").is_dir() and (root / "tokenizer").is_dir():
        prompt = encode_prompt(root, config.text_prompt, config.text_length)
        if prompt.shape[-1] != config.cross_attention_dim:
            raise WeightsError(
                f"text encoder width {prompt.shape[-1]} != UNet cross_attention_dim "
                f"{config.cross_attention_dim}",
                root / "text_encoder",
            )
    return Networks(unet=modules["unet"], vae=modules["vae"], prompt_embedding=prompt)


def check_schedule(path: Path, config: ModelConfig) -> None:
    """The folder's noise schedule must give the same ᾱ as the config (ᾱ is computed analytically)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as error:
        raise WeightsError(f"cannot read scheduler config: {error}", path) from error
    for key, value in config.scheduler.items():
        found = data.get(key)
        same = (
            math.isclose(float(found), float(value), rel_tol=1e-9)
            if isinstance(value, float) and found is not None
            else found == value
        )
        if not same:
            raise WeightsError(f"scheduler {key} is {found!r} but the model assumes {value!r}", path)


@torch.no_grad()
def encode_prompt(root: Path, prompt: str, length: int) -> torch.Tensor:
    """``(1, length, D)`` float32 ``last_hidden_state`` of ``prompt`` from the local CLIP text encoder."""
    from transformers import AutoTokenizer, CLIPTextModel

    try:
        tokenizer = AutoTokenizer.from_pretrained(root / "tokenizer", local_files_only=True)
        encoder = CLIPTextModel.from_pretrained(
            root / "text_encoder", local_files_only=True, use_safetensors=True
        )
    except (OSError, ValueError) as error:
        raise WeightsError(f"cannot load the text encoder / tokenizer: {error}", root) from error
    tokens = tokenizer(prompt, padding="max_length", max_length=length, truncation=True, return_tensors="pt")
    hidden = encoder(tokens.input_ids).last_hidden_state
    return hidden.float().contiguous()


def _norm(value: Any) -> Any:
    return list(value) if isinstance(value, list | tuple) else value
