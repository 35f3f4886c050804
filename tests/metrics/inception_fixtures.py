"""A random-weight FID Inception-v3 for tests: no real weights can be downloaded here.

The convolutions are He-initialised: with the module's default initialisation the pool3 features of small
images are ~1e-7 and every FID ~1e-15, which would make any comparison of values vacuous.
"""

from __future__ import annotations

from pathlib import Path

import torch

from setdiff_bench.metrics.inception import FIDInceptionV3
from setdiff_bench.runtime.threads import torch_threads

#: pytorch-fid's file name, so the loader meets the name a user's file has.
PYTORCH_FID_FILE = "pt_inception-2015-12-05-6726825d.pth"


def random_inception(seed: int = 0) -> FIDInceptionV3:
    """A He-initialised network in eval mode, drawn from ``torch.manual_seed(seed)`` on one thread."""
    with torch_threads(1):
        torch.manual_seed(seed)
        model = FIDInceptionV3().eval()
        for parameter in model.parameters():
            if parameter.dim() == 4:
                torch.nn.init.kaiming_normal_(parameter, nonlinearity="relu")
    return model


def save_inception(model: FIDInceptionV3, folder: Path) -> Path:
    """``model``'s state dict saved in pytorch-fid's format under its file name in ``folder``."""
    path = folder / PYTORCH_FID_FILE
    torch.save(model.state_dict(), path)
    return path
