"""The toolkit's own pretrained tiny autoencoder: the stand-in for SD's VAE in the tiny models — its files.

A trained autoencoder is a folder (:data:`~setdiff_bench.models.setdiff.files.AUTOENCODER_FILES`):
``config.json`` (the diffusers VAE config, ``scaling_factor`` included), ``weights.safetensors`` (every VAE
parameter, float32) and ``manifest.json`` (command, seed, steps, wall time, data hash, reconstruction metrics on
the training and test frames).  A model config names it with ``autoencoder = "DIR"`` (or a packaged name); its
VAE architecture then comes from ``config.json`` and its weights are loaded when the model is built.

This module only finds and reads such a folder, so that a model config or a model can be built without
importing training; ``setdiff-bench train autoencoder`` (how the weights are made: data, loss, scale) is
:mod:`~setdiff_bench.models.setdiff.autoencoder_train`.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

from setdiff_bench.errors import WeightsError
from setdiff_bench.models.setdiff.files import AUTOENCODER_WEIGHTS_FILE, CONFIG_FILE
from setdiff_bench.models.setdiff.packaged import packaged_folder, packaged_names

if TYPE_CHECKING:
    import torch


def resolve_autoencoder(source: str | Path) -> Path:
    """A folder path, or a packaged autoencoder's name → its folder (checked to hold every file)."""
    path = Path(source)
    if not path.is_dir():
        shipped = packaged_folder(str(source), "autoencoder")
        if shipped is None:
            known = ", ".join(packaged_names("autoencoder")) or "none"
            raise WeightsError(
                f"autoencoder folder not found (packaged autoencoders: {known}); "
                "train one with `setdiff-bench train autoencoder`",
                source,
            )
        path = shipped
    for name in (CONFIG_FILE, AUTOENCODER_WEIGHTS_FILE):
        if not (path / name).is_file():
            raise WeightsError(f"autoencoder folder has no {name}", path)
    return path


def read_autoencoder_config(source: str | Path) -> dict[str, Any]:
    """The diffusers VAE config saved with an autoencoder (``scaling_factor`` included)."""
    path = resolve_autoencoder(source) / CONFIG_FILE
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise WeightsError(f"cannot read the autoencoder config: {error}", path) from error
    if not isinstance(data, dict) or "latent_channels" not in data or "scaling_factor" not in data:
        raise WeightsError("not an autoencoder config (needs latent_channels and scaling_factor)", path)
    return data


def load_autoencoder_weights(vae: torch.nn.Module, source: str | Path) -> None:
    """Load an autoencoder's weights into ``vae`` (an ``AutoencoderKL`` of the same config), strictly."""
    from safetensors.torch import load_file

    path = resolve_autoencoder(source) / AUTOENCODER_WEIGHTS_FILE
    try:
        state = load_file(str(path))
    except (OSError, ValueError) as error:
        raise WeightsError(f"cannot read autoencoder weights: {error}", path) from error
    missing, unexpected = vae.load_state_dict(state, strict=False)
    if missing or unexpected:
        raise WeightsError(
            f"autoencoder weights do not match the VAE (missing {len(missing)}, unexpected "
            f"{len(unexpected)}, e.g. {(missing or unexpected)[0]})",
            path,
        )


def load_autoencoder(source: str | Path) -> Any:
    """A trained autoencoder folder (or packaged name) → its diffusers ``AutoencoderKL``, in eval mode."""
    from diffusers import AutoencoderKL

    vae = AutoencoderKL.from_config(read_autoencoder_config(source))
    load_autoencoder_weights(vae, source)
    return vae.eval()
