"""How much memory enhancing one packet takes, estimated before it runs (so a run can refuse in one line
instead of being killed by the kernel; :func:`setdiff_bench.runtime.memory.check_memory`).

The estimate follows what :func:`~setdiff_bench.models.setdiff.inference.enhance_packet` holds at its peak,
in bytes, for P = H·W pixels, S sets per UNet call of V views (N references + M targets), ``b`` bytes per
element of the model's dtype (inputs are float32):

* held throughout: the loaded packet (RGB, C-map, alpha: 7 float32 channels per view) with its targets'
  ground truth and mask for scoring, the stacked set batch (RGB 3 + Ψ input 9 + bias points 4 channels),
  the encoder skips the decoder needs for the targets, and the output;
* plus the largest of the stages' working sets: building the batch (one more copy of it), the VAE encoder
  on one chunk of views (:data:`~setdiff_bench.models.setdiff.model.INFERENCE_CHUNK_PIXELS`), the UNet on
  the whole set (both CFG branches) with one block of the attention bias, and the decoder on one chunk.

The stage working sets are activations × a small count of live tensors per layer (``_LIVE``), measured
on the shipped tiny models at 576×1024: a 4 + 4 packet peaked 1.28 GB above the loaded model against
1.28 GB estimated (``benchmarks/memory.py``; the test checks the estimate within a stated factor).
Attention itself adds nothing quadratic: the fused SDPA kernels and the blockwise distance bias
(:func:`~setdiff_bench.models.setdiff.set_mixer.biased_attention`) hold no token × token tensor.
"""

from __future__ import annotations

import math

from setdiff_bench.models.setdiff.config import ModelConfig
from setdiff_bench.models.setdiff.model import views_per_chunk
from setdiff_bench.models.setdiff.set_mixer import BIAS_BLOCK_ELEMENTS
from setdiff_bench.runtime.memory import FLOAT32_BYTES, VIEW_CHANNELS

#: Live tensors per activation in a stage's working set (input, normalised, activated, convolved).
_LIVE = 4
#: Per target, beside its view's channels: ground truth 3 and the mask (1 byte, a quarter channel).
_TARGET_CHANNELS = 3.25
#: Allocations that do not grow with the packet (kernel workspaces, allocator slack): 0.14–0.16 GB above
#: the loaded model for a 2 + 2 packet at 256×144 (``benchmarks/memory.py``).
_OVERHEAD = 128 << 20


def set_input_channels(config: ModelConfig) -> int:
    """Channels of a view in the stacked set batch: RGB, Ψ's input, the attention-bias points."""
    geometry = 9 if config.use_geometry else 0
    points = 4 if config.attention_bias != "none" else 0
    return 3 + geometry + points


def skip_channels(config: ModelConfig) -> float:
    """Full-resolution-equivalent channels of the encoder activations kept per target for the decoder's
    skip connections: the input of down block i has ``block_out_channels[i − 1]`` channels at 1/4^i of
    the pixels (block 0 takes ``conv_in``'s ``block_out_channels[0]``)."""
    if not config.skip_connections:
        return 0.0
    widths = [int(c) for c in config.vae["block_out_channels"]]
    inputs = [widths[0], *widths[:-1]]
    return sum(channels / 4**level for level, channels in enumerate(inputs))


def inference_bytes(
    config: ModelConfig,
    *,
    references: int,
    targets: int,
    height: int,
    width: int,
    max_references: int | None = None,
    targets_per_set: int | None = None,
    sets_per_call: int | None = None,
    guidance_scale: float | None = None,
    dtype_bytes: int = FLOAT32_BYTES,
) -> int:
    """Peak bytes above the loaded model to enhance one packet (see the module docstring).

    Args:
        references, targets: the packet's N and M.
        height, width: the packet's image size in pixels.
        max_references, targets_per_set, sets_per_call, guidance_scale: the enhancer's inference options
            (``None`` = the config's), which set how the packet is split into sets and UNet calls.
    """
    cap = config.max_references if max_references is None else max_references
    per_set = config.targets_per_set if targets_per_set is None else targets_per_set
    set_references = references if cap is None else min(references, cap)
    set_targets = targets if per_set is None else max(1, min(per_set, targets))
    sets = math.ceil(targets / set_targets)
    if sets_per_call is not None:
        sets = min(sets, max(1, sets_per_call))
    scale = config.guidance_scale if guidance_scale is None else guidance_scale
    pixels = height * width
    views = set_references + set_targets
    widths = [int(c) for c in config.vae["block_out_channels"]]
    chunk = min(views_per_chunk(height, width), sets * views)
    decode_chunk = min(2 * max(1, chunk // 2), 2 * sets * set_targets)
    if config.output_mode != "residual":
        decode_chunk = min(chunk, sets * set_targets)
    unet_width = int(config.unet["block_out_channels"][0])
    branches = 2 if config.use_geometry and scale != 1.0 else 1
    latent_pixels = pixels / config.latent_factor**2

    held = (
        FLOAT32_BYTES
        * pixels
        * ((references + targets) * VIEW_CHANNELS + targets * _TARGET_CHANNELS + sets * set_targets * 3)
    )
    batch = FLOAT32_BYTES * pixels * sets * views * set_input_channels(config)
    skips = dtype_bytes * pixels * sets * set_targets * skip_channels(config)
    lowest_tokens = (
        views * pixels / (config.latent_factor * 2 ** (len(config.unet["block_out_channels"]) - 1)) ** 2
    )
    bias_elements = min(BIAS_BLOCK_ELEMENTS, branches * sets * lowest_tokens**2)
    bias_block = 3 * FLOAT32_BYTES * bias_elements if config.attention_bias != "none" else 0
    working = max(
        batch,  # the stacked copy while the batch is built
        _LIVE * dtype_bytes * pixels * chunk * widths[0],
        _LIVE * dtype_bytes * latent_pixels * branches * sets * views * unet_width + bias_block,
        _LIVE * dtype_bytes * pixels * decode_chunk * max(widths[:2]),
    )
    return int(_OVERHEAD + held + batch + skips + working)
