"""Where a result came from: package versions, git revision, device — recorded in run manifests."""

from __future__ import annotations

import os
import platform
import subprocess
from importlib import metadata
from pathlib import Path
from typing import Any

import torch

#: Distributions whose versions are recorded (absent ones are recorded as ``null``).
DISTRIBUTIONS = (
    "setdiff-bench",
    "torch",
    "numpy",
    "pandas",
    "pyarrow",
    "OpenImageIO",
    "opencv-contrib-python-headless",
    "diffusers",
    "peft",
    "safetensors",
    "accelerate",
    "gsplat",
)


def package_versions(names: tuple[str, ...] = DISTRIBUTIONS) -> dict[str, str | None]:
    """Installed version of each distribution, ``None`` when it is not installed."""
    versions: dict[str, str | None] = {"python": platform.python_version()}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def git_revision(folder: Path | None = None) -> dict[str, Any]:
    """``{"revision": sha or None, "dirty": bool or None}`` of the checkout holding ``folder``.

    ``folder`` defaults to this package's source folder; an installed (non-git) copy gives ``None``s.
    """
    folder = folder or Path(__file__).resolve().parent
    try:
        revision = subprocess.run(
            ["git", "-C", str(folder), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        status = subprocess.run(
            ["git", "-C", str(folder), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout
    except (OSError, subprocess.SubprocessError):
        return {"revision": None, "dirty": None}
    return {"revision": revision or None, "dirty": bool(status.strip())}


#: Environment variables that choose the CPU kernels torch runs (ATen, oneDNN, MKL) or the rasteriser.
NUMERIC_ENVIRONMENT = (
    "ATEN_CPU_CAPABILITY",
    "ONEDNN_MAX_CPU_ISA",
    "MKL_ENABLE_INSTRUCTIONS",
    "SETDIFF_RASTERIZER",
)


def numeric_settings() -> dict[str, Any]:
    """The settings a run's last bits depend on: the ATen kernel set in use (``default``, ``AVX2``,
    ``AVX512``), the environment variables that choose kernels, and the torch thread count.

    Scene fits, renders and packets do not depend on them (docs/reproducibility.md); enhancer inference
    and scoring change in the last bits, within the published tolerance.
    """
    return {
        "cpu_capability": torch.backends.cpu.get_cpu_capability(),
        "environment": {name: os.environ.get(name) for name in NUMERIC_ENVIRONMENT},
        "torch_threads": torch.get_num_threads(),
    }


def device_description(device: str | torch.device) -> dict[str, Any]:
    """The compute device in words: type, name (GPU model or CPU architecture), torch threads, and the
    numeric settings (:func:`numeric_settings`)."""
    device = torch.device(device)
    info: dict[str, Any] = {
        "type": device.type,
        "torch_threads": torch.get_num_threads(),
        "numeric": numeric_settings(),
    }
    if device.type == "cuda" and torch.cuda.is_available():
        index = device.index if device.index is not None else torch.cuda.current_device()
        info["name"] = torch.cuda.get_device_name(index)
        info["cuda"] = torch.version.cuda
    else:
        info["name"] = platform.processor() or platform.machine()
    return info
