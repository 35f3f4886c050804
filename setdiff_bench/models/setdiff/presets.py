"""SetDiff / DiFix architectures as data: the SD-Turbo UNet, VAE and noise schedule, and a tiny CPU variant.

Architectures (``preset``):

* ``sd-turbo`` — stabilityai/sd-turbo's UNet and VAE configs (docs/model.md, "SD-Turbo UNet config"), i.e. the
  SD 2.1-base UNet (865.9 M parameters).  Note the diffusers quirk: ``attention_head_dim=(5, 10, 20, 20)``
  is really the *number of heads* per level (head dim 64).
* ``tiny`` — the same classes (``UNet2DConditionModel``, ``AutoencoderKL``) with two UNet levels of
  32/64 channels, one layer per block and a 16/32-channel VAE, so training and tests run on a CPU.

A model config names one with ``preset`` (:mod:`~setdiff_bench.models.setdiff.config`).

Scheduler constants are the SD-Turbo ``scaled_linear`` schedule; ᾱ_t is computed analytically in
float64 (:func:`alphas_cumprod`), never through ``DDPMScheduler`` (see docs/model.md, "Scheduler pitfalls").
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from setdiff_bench.errors import UsageError

#: stabilityai/sd-turbo ``unet/config.json`` (docs/model.md, "SD-Turbo UNet config").
SD_TURBO_UNET: dict[str, Any] = {
    "sample_size": 64,
    "in_channels": 4,
    "out_channels": 4,
    "center_input_sample": False,
    "flip_sin_to_cos": True,
    "freq_shift": 0,
    "down_block_types": [
        "CrossAttnDownBlock2D",
        "CrossAttnDownBlock2D",
        "CrossAttnDownBlock2D",
        "DownBlock2D",
    ],
    "mid_block_type": "UNetMidBlock2DCrossAttn",
    "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D", "CrossAttnUpBlock2D"],
    "only_cross_attention": False,
    "block_out_channels": [320, 640, 1280, 1280],
    "layers_per_block": 2,
    "downsample_padding": 1,
    "mid_block_scale_factor": 1,
    "dropout": 0.0,
    "act_fn": "silu",
    "norm_num_groups": 32,
    "norm_eps": 1e-5,
    "cross_attention_dim": 1024,
    "transformer_layers_per_block": 1,
    "attention_head_dim": [5, 10, 20, 20],  # diffusers quirk: these are head *counts* (head dim 64)
    "num_attention_heads": None,
    "dual_cross_attention": False,
    "use_linear_projection": True,
    "upcast_attention": None,
    "class_embed_type": None,
    "addition_embed_type": None,
    "num_class_embeds": None,
    "resnet_time_scale_shift": "default",
    "time_embedding_type": "positional",
    "time_cond_proj_dim": None,
    "conv_in_kernel": 3,
    "conv_out_kernel": 3,
    "attention_type": "default",
    "mid_block_only_cross_attention": None,
    "cross_attention_norm": None,
    "addition_embed_type_num_heads": 64,
}

#: stabilityai/sd-turbo ``vae/config.json`` (docs/model.md, "SD-Turbo VAE config").
SD_TURBO_VAE: dict[str, Any] = {
    "in_channels": 3,
    "out_channels": 3,
    "latent_channels": 4,
    "block_out_channels": [128, 256, 512, 512],
    "layers_per_block": 2,
    "norm_num_groups": 32,
    "act_fn": "silu",
    "down_block_types": ["DownEncoderBlock2D"] * 4,
    "up_block_types": ["UpDecoderBlock2D"] * 4,
    "sample_size": 768,
    "scaling_factor": 0.18215,
    "force_upcast": True,
}

#: stabilityai/sd-turbo ``scheduler/scheduler_config.json``, the keys that define ᾱ_t
#: (docs/model.md, "SD-Turbo scheduler config").
SD_TURBO_SCHEDULE: dict[str, Any] = {
    "beta_start": 0.00085,
    "beta_end": 0.012,
    "beta_schedule": "scaled_linear",
    "num_train_timesteps": 1000,
}

#: Same UNet class, CPU-sized: 2 levels (32, 64 ch), 1 layer per block, 2/4 heads of dim 16.
TINY_UNET: dict[str, Any] = {
    **SD_TURBO_UNET,
    "sample_size": 8,
    "down_block_types": ["CrossAttnDownBlock2D", "DownBlock2D"],
    "up_block_types": ["UpBlock2D", "CrossAttnUpBlock2D"],
    "block_out_channels": [32, 64],
    "layers_per_block": 1,
    "norm_num_groups": 8,
    "cross_attention_dim": 32,
    "attention_head_dim": [2, 4],
}

#: Same VAE class, CPU-sized: 4 levels (3 downsamplers → 8×), 16/32 channels, 1 layer per block.
TINY_VAE: dict[str, Any] = {
    **SD_TURBO_VAE,
    "block_out_channels": [16, 32, 32, 32],
    "layers_per_block": 1,
    "norm_num_groups": 8,
    "sample_size": 64,
}

PRESETS: dict[str, dict[str, Any]] = {
    "sd-turbo": {"unet": SD_TURBO_UNET, "vae": SD_TURBO_VAE, "geometry_channels": [32, 64, 128, 256, 256]},
    "tiny": {"unet": TINY_UNET, "vae": TINY_VAE, "geometry_channels": [8, 16, 16, 32, 32]},
}


def alphas_cumprod(
    beta_start: float, beta_end: float, beta_schedule: str, num_train_timesteps: int
) -> np.ndarray:
    """ᾱ_t for t = 0 … T−1 in float64.

    ``scaled_linear``: ``betas = linspace(√beta_start, √beta_end, T)²`` (SD-Turbo); ``linear``:
    ``linspace(beta_start, beta_end, T)``.  ᾱ_t = Π_{s ≤ t} (1 − β_s).
    """
    if beta_schedule == "scaled_linear":
        betas = (
            np.linspace(math.sqrt(beta_start), math.sqrt(beta_end), num_train_timesteps, dtype=np.float64)
            ** 2
        )
    elif beta_schedule == "linear":
        betas = np.linspace(beta_start, beta_end, num_train_timesteps, dtype=np.float64)
    else:
        raise UsageError(
            f"unsupported beta_schedule {beta_schedule!r} (expected scaled_linear or linear)",
            "model.scheduler",
        )
    return np.cumprod(1.0 - betas)
