"""Where a result came from: package versions, git revision, device — recorded in run manifests."""

from __future__ import annotations

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


def device_description(device: str | torch.device) -> dict[str, Any]:
    """The compute device in words: type, name (GPU model or CPU architecture), torch threads."""
    device = torch.device(device)
    info: dict[str, Any] = {"type": device.type, "torch_threads": torch.get_num_threads()}
    if device.type == "cuda" and torch.cuda.is_available():
        index = device.index if device.index is not None else torch.cuda.current_device()
        info["name"] = torch.cuda.get_device_name(index)
        info["cuda"] = torch.version.cuda
    else:
        info["name"] = platform.processor() or platform.machine()
    return info
