"""The FID Inception-v3 (pool3, 2048 features) from a local weights file; never downloaded.

The network is the one every common FID implementation uses: TensorFlow's 2015-12-05 Inception graph
as ported to PyTorch by pytorch-fid (``pt_inception-2015-12-05-6726825d.pth``).  torch-fidelity
distributes the same port as ``weights-inception-2015-12-05-6726825d.pth`` (same SHA-256 prefix in
the name, the torch-hub convention).  The file is a PyTorch state dict keyed like torchvision's
``Inception3`` built with ``num_classes=1008, aux_logits=False`` (``Conv2d_1a_3x3.conv.weight``,
``Mixed_7c.branch_pool.bn.running_var``, ``fc.weight`` ...); a ``.safetensors`` file with the same
keys is read too.

The architecture is written here (torchvision is not a dependency) with the FID port's departures
from the Inception-v3 paper, which the weights were trained with:

- every average pool in the Inception blocks excludes the zero padding (TensorFlow's
  ``count_include_pad=False``);
- the last block (``Mixed_7c``) pools its fourth branch with a 3×3 **max** pool;
- batch norm ε = 0.001.

Input: ``(N, 3, H, W)`` float RGB in [0, 1], resized to 299×299 (bilinear, ``align_corners=False``)
and mapped to [-1, 1]; output: the global average of ``Mixed_7c`` — ``(N, 2048)`` float32 features.
The classifier (``fc``) is never evaluated, but a file must carry it (1008 classes) to be recognised.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from setdiff_bench.errors import WeightsError
from setdiff_bench.io.state_dicts import shapes_of, state_dict_problem

INPUT_SIZE = 299
FEATURES = 2048
CLASSES = 1008
#: File names of the FID weights in pytorch-fid and torch-fidelity (the same tensors).
KNOWN_FILES = ("pt_inception-2015-12-05-6726825d.pth", "weights-inception-2015-12-05-6726825d.pth")


class BasicConv2d(nn.Module):
    """Convolution (no bias) → batch norm (ε 0.001) → ReLU."""

    def __init__(self, cin: int, cout: int, kernel: int | tuple[int, int], **kwargs: object) -> None:
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, kernel, bias=False, **kwargs)  # type: ignore[arg-type]
        self.bn = nn.BatchNorm2d(cout, eps=0.001)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.bn(self.conv(x)))


def _avg3(x: torch.Tensor) -> torch.Tensor:
    """3×3 stride-1 average pool over the unpadded pixels only (TensorFlow's rule)."""
    return F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)


class InceptionA(nn.Module):
    """35×35 block: 1×1, 5×5, double 3×3 and pooled branches → ``224 + pool_features`` channels."""

    def __init__(self, cin: int, pool_features: int) -> None:
        super().__init__()
        self.branch1x1 = BasicConv2d(cin, 64, 1)
        self.branch5x5_1 = BasicConv2d(cin, 48, 1)
        self.branch5x5_2 = BasicConv2d(48, 64, 5, padding=2)
        self.branch3x3dbl_1 = BasicConv2d(cin, 64, 1)
        self.branch3x3dbl_2 = BasicConv2d(64, 96, 3, padding=1)
        self.branch3x3dbl_3 = BasicConv2d(96, 96, 3, padding=1)
        self.branch_pool = BasicConv2d(cin, pool_features, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        double = self.branch3x3dbl_3(self.branch3x3dbl_2(self.branch3x3dbl_1(x)))
        return torch.cat(
            [
                self.branch1x1(x),
                self.branch5x5_2(self.branch5x5_1(x)),
                double,
                self.branch_pool(_avg3(x)),
            ],
            1,
        )


class InceptionB(nn.Module):
    """35×35 → 17×17 reduction: strided 3×3, strided double 3×3 and a max pool → ``480 + cin`` channels."""

    def __init__(self, cin: int) -> None:
        super().__init__()
        self.branch3x3 = BasicConv2d(cin, 384, 3, stride=2)
        self.branch3x3dbl_1 = BasicConv2d(cin, 64, 1)
        self.branch3x3dbl_2 = BasicConv2d(64, 96, 3, padding=1)
        self.branch3x3dbl_3 = BasicConv2d(96, 96, 3, stride=2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        double = self.branch3x3dbl_3(self.branch3x3dbl_2(self.branch3x3dbl_1(x)))
        return torch.cat([self.branch3x3(x), double, F.max_pool2d(x, 3, stride=2)], 1)


class InceptionC(nn.Module):
    """17×17 block with factorised 7×7 convolutions (``c7`` inner channels) → 768 channels."""

    def __init__(self, cin: int, c7: int) -> None:
        super().__init__()
        self.branch1x1 = BasicConv2d(cin, 192, 1)
        self.branch7x7_1 = BasicConv2d(cin, c7, 1)
        self.branch7x7_2 = BasicConv2d(c7, c7, (1, 7), padding=(0, 3))
        self.branch7x7_3 = BasicConv2d(c7, 192, (7, 1), padding=(3, 0))
        self.branch7x7dbl_1 = BasicConv2d(cin, c7, 1)
        self.branch7x7dbl_2 = BasicConv2d(c7, c7, (7, 1), padding=(3, 0))
        self.branch7x7dbl_3 = BasicConv2d(c7, c7, (1, 7), padding=(0, 3))
        self.branch7x7dbl_4 = BasicConv2d(c7, c7, (7, 1), padding=(3, 0))
        self.branch7x7dbl_5 = BasicConv2d(c7, 192, (1, 7), padding=(0, 3))
        self.branch_pool = BasicConv2d(cin, 192, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        single = self.branch7x7_3(self.branch7x7_2(self.branch7x7_1(x)))
        double = x
        for layer in (
            self.branch7x7dbl_1,
            self.branch7x7dbl_2,
            self.branch7x7dbl_3,
            self.branch7x7dbl_4,
            self.branch7x7dbl_5,
        ):
            double = layer(double)
        return torch.cat([self.branch1x1(x), single, double, self.branch_pool(_avg3(x))], 1)


class InceptionD(nn.Module):
    """17×17 → 8×8 reduction → ``512 + cin`` channels."""

    def __init__(self, cin: int) -> None:
        super().__init__()
        self.branch3x3_1 = BasicConv2d(cin, 192, 1)
        self.branch3x3_2 = BasicConv2d(192, 320, 3, stride=2)
        self.branch7x7x3_1 = BasicConv2d(cin, 192, 1)
        self.branch7x7x3_2 = BasicConv2d(192, 192, (1, 7), padding=(0, 3))
        self.branch7x7x3_3 = BasicConv2d(192, 192, (7, 1), padding=(3, 0))
        self.branch7x7x3_4 = BasicConv2d(192, 192, 3, stride=2)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        seven = self.branch7x7x3_4(self.branch7x7x3_3(self.branch7x7x3_2(self.branch7x7x3_1(x))))
        return torch.cat([self.branch3x3_2(self.branch3x3_1(x)), seven, F.max_pool2d(x, 3, stride=2)], 1)


class InceptionE(nn.Module):
    """8×8 block with split 1×3 / 3×1 branches → 2048 channels; ``max_pool`` selects Mixed_7c's pooling."""

    def __init__(self, cin: int, *, max_pool: bool) -> None:
        super().__init__()
        self.max_pool = max_pool
        self.branch1x1 = BasicConv2d(cin, 320, 1)
        self.branch3x3_1 = BasicConv2d(cin, 384, 1)
        self.branch3x3_2a = BasicConv2d(384, 384, (1, 3), padding=(0, 1))
        self.branch3x3_2b = BasicConv2d(384, 384, (3, 1), padding=(1, 0))
        self.branch3x3dbl_1 = BasicConv2d(cin, 448, 1)
        self.branch3x3dbl_2 = BasicConv2d(448, 384, 3, padding=1)
        self.branch3x3dbl_3a = BasicConv2d(384, 384, (1, 3), padding=(0, 1))
        self.branch3x3dbl_3b = BasicConv2d(384, 384, (3, 1), padding=(1, 0))
        self.branch_pool = BasicConv2d(cin, 192, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        single = self.branch3x3_1(x)
        double = self.branch3x3dbl_2(self.branch3x3dbl_1(x))
        pooled = F.max_pool2d(x, 3, stride=1, padding=1) if self.max_pool else _avg3(x)
        return torch.cat(
            [
                self.branch1x1(x),
                self.branch3x3_2a(single),
                self.branch3x3_2b(single),
                self.branch3x3dbl_3a(double),
                self.branch3x3dbl_3b(double),
                self.branch_pool(pooled),
            ],
            1,
        )


class FIDInceptionV3(nn.Module):
    """The FID Inception-v3 up to pool3 (module docstring); ``forward`` gives ``(N, 2048)`` features."""

    def __init__(self) -> None:
        super().__init__()
        self.Conv2d_1a_3x3 = BasicConv2d(3, 32, 3, stride=2)
        self.Conv2d_2a_3x3 = BasicConv2d(32, 32, 3)
        self.Conv2d_2b_3x3 = BasicConv2d(32, 64, 3, padding=1)
        self.Conv2d_3b_1x1 = BasicConv2d(64, 80, 1)
        self.Conv2d_4a_3x3 = BasicConv2d(80, 192, 3)
        self.Mixed_5b = InceptionA(192, 32)
        self.Mixed_5c = InceptionA(256, 64)
        self.Mixed_5d = InceptionA(288, 64)
        self.Mixed_6a = InceptionB(288)
        self.Mixed_6b = InceptionC(768, 128)
        self.Mixed_6c = InceptionC(768, 160)
        self.Mixed_6d = InceptionC(768, 160)
        self.Mixed_6e = InceptionC(768, 192)
        self.Mixed_7a = InceptionD(768)
        self.Mixed_7b = InceptionE(1280, max_pool=False)
        self.Mixed_7c = InceptionE(2048, max_pool=True)
        self.fc = nn.Linear(FEATURES, CLASSES)  # in the file, never evaluated

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """``(N, 3, H, W)`` RGB in [0, 1] → ``(N, 2048)`` pool3 features."""
        x = F.interpolate(images, size=(INPUT_SIZE, INPUT_SIZE), mode="bilinear", align_corners=False)
        x = 2.0 * x - 1.0
        x = self.Conv2d_2b_3x3(self.Conv2d_2a_3x3(self.Conv2d_1a_3x3(x)))
        x = F.max_pool2d(x, 3, stride=2)
        x = F.max_pool2d(self.Conv2d_4a_3x3(self.Conv2d_3b_1x1(x)), 3, stride=2)
        for block in (
            self.Mixed_5b,
            self.Mixed_5c,
            self.Mixed_5d,
            self.Mixed_6a,
            self.Mixed_6b,
            self.Mixed_6c,
            self.Mixed_6d,
            self.Mixed_6e,
            self.Mixed_7a,
            self.Mixed_7b,
            self.Mixed_7c,
        ):
            x = block(x)
        return x.mean(dim=(2, 3))


def _read_state_dict(path: Path) -> dict[str, torch.Tensor]:
    if path.suffix == ".safetensors":
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        try:
            return load_file(str(path))
        except (SafetensorError, OSError, ValueError) as error:
            raise WeightsError(f"unreadable safetensors file ({error})", path) from None
    try:
        state = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as error:  # any damage to the pickle or zip: one line naming the file
        raise WeightsError(
            f"not a PyTorch state dict readable without code execution ({type(error).__name__})", path
        ) from None
    if not isinstance(state, dict) or not all(isinstance(v, torch.Tensor) for v in state.values()):
        raise WeightsError("expected a state dict (names → tensors), e.g. pytorch-fid's FID weights", path)
    return state


def load_inception(file: str | Path, device: str | torch.device = "cpu") -> FIDInceptionV3:
    """The FID Inception-v3 with the weights of ``file`` (pytorch-fid / torch-fidelity state dict).

    Every tensor of the network must be in the file with its shape; batch norms' ``num_batches_tracked``
    may be absent.  Nothing is ever downloaded.

    Raises:
        WeightsError: the file is missing or unreadable, or its keys or shapes are not the FID
            Inception-v3's (the first missing, unexpected or misshapen key is named).
    """
    path = Path(file).expanduser()
    if not path.is_file():
        raise WeightsError(
            "Inception weights file not found (pass --inception FILE: pytorch-fid's "
            f"{KNOWN_FILES[0]} or torch-fidelity's {KNOWN_FILES[1]}; nothing is downloaded)",
            path,
        )
    state = _read_state_dict(path)
    model = FIDInceptionV3()
    problem = state_dict_problem(
        shapes_of(model.state_dict()),
        state,
        optional=lambda key: key.endswith("num_batches_tracked"),
        finite=True,
    )
    if problem is not None:
        first = problem.names[0]
        messages = {
            "missing": f"not the FID Inception-v3 weights: {len(problem.names)} tensors missing (first {first!r})",
            "unexpected": f"not the FID Inception-v3 weights: unexpected tensor {first!r} "
            f"({len(problem.names)} in all; an auxiliary classifier is not part of the FID network)",
            "shape": f"tensor {first!r} has shape {problem.found}, the FID Inception-v3 has {problem.expected}",
            "non_finite": f"tensor {first!r} contains NaN or infinite values",
        }
        raise WeightsError(messages[problem.kind], path)
    model.load_state_dict(state, strict=False)
    return model.eval().to(device)


@torch.no_grad()
def inception_features(
    model: nn.Module, images: Iterable[torch.Tensor], *, batch_size: int = 16
) -> np.ndarray:
    """Pool3 features of ``(3, H, W)`` float images in [0, 1] (any sizes), ``(N, D)`` float64.

    ``model`` is anything mapping ``(B, 3, H, W)`` in [0, 1] to ``(B, D)`` (the FID network, or a small
    stand-in in tests).  Images of one size are batched ``batch_size`` at a time.
    """
    parameter = next(iter(model.parameters()), None)
    device = parameter.device if parameter is not None else torch.device("cpu")
    dtype = parameter.dtype if parameter is not None else torch.float32
    rows: list[np.ndarray] = []
    pending: list[torch.Tensor] = []

    def flush() -> None:
        if pending:
            batch = torch.stack(pending).to(device, dtype)
            rows.append(model(batch).detach().double().cpu().numpy())
            pending.clear()

    for image in images:
        if pending and (tuple(image.shape) != tuple(pending[0].shape) or len(pending) >= max(1, batch_size)):
            flush()
        pending.append(image.float())
    flush()
    if not rows:
        return np.zeros((0, FEATURES))
    return np.concatenate(rows)
