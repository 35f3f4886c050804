"""EUVS's DINOv2 cosine similarity ("Cos_Similarity") and ``Final_Score``, with local weights only.

As in ai4ce/EUVS-Benchmark@f3b2d907 ``baselines/3DGS/metrics_with_dyn_masks.py`` (docs/evaluation_profiles.md):

1. Each image (render and ground truth, 8-bit RGB) is resized so its shorter side is 518 px (PIL
   bilinear, torchvision ``Resize(518)``: the long side becomes ``int(518 · long / short)``),
   centre-cropped to 518×518 (torchvision ``CenterCrop``: offsets ``round((size − 518) / 2)``), scaled
   to [0, 1] and normalised with mean 0.5, std 0.5.
2. ViT-B/14 tokens: ``get_intermediate_layers(x, n=1)[0]`` — the last block's normed **patch** tokens,
   ``(1, 1369, 768)`` — and the script then drops one more token (``[:, 1:, :]``, written as if the
   class token were still there), keeping 1368 patches.
3. The per-patch cosine similarities are averaged to one scalar *before* the mask weighting, so the
   weighting cancels: the score is the mean patch cosine, or 0 when the mask (resized to 518 with
   nearest, centre-cropped, > 0.5) keeps no pixel.
4. ``Final_Score = 0.25·SSIM + 0.15·PSNR + 0.35·(1 − LPIPS) + 0.25·Cos`` of the reported means.

Weights are never downloaded: ``--dinov2 DIR`` names a local transformers folder (``config.json`` +
``model.safetensors`` of a ``Dinov2Model``, e.g. ``facebook/dinov2-base``), read with safetensors.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F

from setdiff_bench.errors import WeightsError

INPUT_SIZE = 518
PATCH = 14
FINAL_SCORE_WEIGHTS = {"ssim": 0.25, "psnr": 0.15, "lpips": 0.35, "cos": 0.25}


def preprocess_image(image: np.ndarray) -> torch.Tensor:
    """``(H, W, 3)`` uint8 → ``(1, 3, 518, 518)`` float32 as the EUVS DINOv2 transform makes it."""
    from PIL import Image

    height, width = image.shape[:2]
    if width <= height:
        size = (INPUT_SIZE, int(INPUT_SIZE * height / width))
    else:
        size = (int(INPUT_SIZE * width / height), INPUT_SIZE)
    resized = np.asarray(Image.fromarray(np.ascontiguousarray(image)).resize(size, Image.Resampling.BILINEAR))
    top, left = _crop_offsets(resized.shape[0], resized.shape[1])
    window = resized[top : top + INPUT_SIZE, left : left + INPUT_SIZE].astype(np.float32) / 255.0
    tensor = torch.from_numpy(np.ascontiguousarray(window.transpose(2, 0, 1)))[None]
    return (tensor - 0.5) / 0.5


def preprocess_mask(mask: np.ndarray) -> torch.Tensor:
    """``(H, W)`` bool/0-1 mask → ``(518, 518)`` bool (shorter side 518 by nearest, centre crop, > 0.5)."""
    height, width = mask.shape
    if width <= height:
        out_w, out_h = INPUT_SIZE, int(INPUT_SIZE * height / width)
    else:
        out_w, out_h = int(INPUT_SIZE * width / height), INPUT_SIZE
    tensor = torch.from_numpy(np.ascontiguousarray(mask).astype(np.float32))[None, None]
    resized = F.interpolate(tensor, size=(out_h, out_w), mode="nearest")[0, 0]
    top, left = _crop_offsets(out_h, out_w)
    return resized[top : top + INPUT_SIZE, left : left + INPUT_SIZE] > 0.5


def _crop_offsets(height: int, width: int) -> tuple[int, int]:
    return round((height - INPUT_SIZE) / 2.0), round((width - INPUT_SIZE) / 2.0)


def masked_cosine(model: Any, render: np.ndarray, ground_truth: np.ndarray, mask: np.ndarray) -> float:
    """EUVS ``Cos_Similarity`` of one image pair.

    Args:
        model: anything with ``get_intermediate_layers(x, n=1)`` returning a sequence whose first item is
            ``(1, P, C)`` patch tokens (DINOv2 hub semantics; :class:`TransformersDinov2` adapts a
            transformers model).
        render, ground_truth: ``(H, W, 3)`` uint8 images.
        mask: ``(H, W)`` bool, True = evaluated (static).

    Returns:
        The mean cosine over the patch tokens after the first (as the script slices), or 0.0 when the
        preprocessed mask keeps no pixel.
    """
    if not bool(preprocess_mask(mask).any()):
        return 0.0
    parameter = next(iter(model.parameters()), None) if hasattr(model, "parameters") else None
    device = parameter.device if parameter is not None else torch.device("cpu")
    dtype = parameter.dtype if parameter is not None else torch.float32
    with torch.no_grad():
        feats = [
            model.get_intermediate_layers(preprocess_image(x).to(device, dtype), n=1)[0][:, 1:, :]
            for x in (render, ground_truth)
        ]
    return float(F.cosine_similarity(feats[0].float(), feats[1].float(), dim=2).mean())


def final_score(ssim: float, psnr: float, lpips: float, cos: float) -> float:
    """EUVS ``Final_Score = 0.25·SSIM + 0.15·PSNR + 0.35·(1 − LPIPS) + 0.25·Cos`` (PSNR in dB, unscaled)."""
    w = FINAL_SCORE_WEIGHTS
    return w["ssim"] * ssim + w["psnr"] * psnr + w["lpips"] * (1.0 - lpips) + w["cos"] * cos


class TransformersDinov2(torch.nn.Module):
    """A transformers ``Dinov2Model`` behind the hub's ``get_intermediate_layers(x, n=1)`` for the last layer.

    The hub method returns the last block's output after the final LayerNorm without the class token;
    transformers' ``last_hidden_state`` is the same LayerNorm output with the class token first.
    """

    def __init__(self, model: Any) -> None:
        super().__init__()
        self.model = model

    def get_intermediate_layers(self, x: torch.Tensor, n: int = 1) -> tuple[torch.Tensor]:
        if n != 1:
            raise ValueError("only the last layer (n=1) is supported")
        tokens = self.model(pixel_values=x).last_hidden_state
        registers = int(getattr(self.model.config, "num_register_tokens", 0) or 0)
        return (tokens[:, 1 + registers :, :],)


def load_dinov2(folder: str | Path, device: str = "cpu") -> TransformersDinov2:
    """DINOv2 from a local transformers folder (``config.json`` + ``model.safetensors``).

    Raises:
        WeightsError: the folder or one of its files is missing, or it is not a DINOv2 model.
    """
    path = Path(folder)
    if not path.is_dir():
        raise WeightsError(
            "DINOv2 weights folder not found (pass --dinov2 DIR: a transformers folder with "
            "config.json and model.safetensors, e.g. facebook/dinov2-base)",
            path,
        )
    for name in ("config.json", "model.safetensors"):
        if not (path / name).is_file():
            raise WeightsError(
                f"DINOv2 folder has no {name} (expected a transformers Dinov2Model folder; "
                "weights are read from safetensors only)",
                path,
            )
    import json

    from transformers import Dinov2Model

    try:
        model_type = json.loads((path / "config.json").read_text(encoding="utf-8")).get("model_type")
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, AttributeError) as error:
        raise WeightsError(f"unreadable config.json ({type(error).__name__})", path / "config.json") from None
    if model_type != "dinov2":
        raise WeightsError(
            f"config.json has model_type {model_type!r}, expected 'dinov2'", path / "config.json"
        )
    model = Dinov2Model.from_pretrained(path, local_files_only=True, use_safetensors=True)
    return TransformersDinov2(model.eval().to(device))
