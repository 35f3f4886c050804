"""The 3DGS parameter set and its activations (Inria conventions).

Stored values are pre-activation, exactly as in the standard PLY: opacity logits (sigmoid),
log-scales (exp), unnormalised quaternions ``w, x, y, z`` (normalised at use), and SH coefficients
with the DC term first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np
import torch

from setdiff_bench.errors import PlyError
from setdiff_bench.gaussians.portable import logistic, normalize
from setdiff_bench.gaussians.sh import eval_sh, num_sh_bases, rgb_to_sh_dc


@dataclass
class GaussianModel:
    """A set of N 3D Gaussians.

    Attributes:
        means: ``(N, 3)`` centres in world coordinates.
        quats: ``(N, 4)`` rotations, scalar-first ``w, x, y, z`` (any norm > 0).
        log_scales: ``(N, 3)`` natural-log standard deviations along the local axes.
        opacity_logits: ``(N,)`` pre-sigmoid opacities.
        sh: ``(N, K, 3)`` SH coefficients, ``K = (degree + 1)²``, index 0 = DC (``f_dc``).
    """

    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh: torch.Tensor

    def __post_init__(self) -> None:
        n = self.means.shape[0]
        expected = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, 3), "opacity_logits": (n,)}
        for name, shape in expected.items():
            if tuple(getattr(self, name).shape) != shape:
                raise ValueError(
                    f"GaussianModel.{name} must have shape {shape}, got {tuple(getattr(self, name).shape)}"
                )
        if self.sh.ndim != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3:
            raise ValueError(f"GaussianModel.sh must be (N, K, 3), got {tuple(self.sh.shape)}")
        if self.sh.shape[1] not in (1, 4, 9, 16):
            raise ValueError(f"GaussianModel.sh has {self.sh.shape[1]} bases; expected 1, 4, 9 or 16")

    # ------------------------------------------------------------------ basic facts
    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        return math.isqrt(self.sh.shape[1]) - 1

    @property
    def device(self) -> torch.device:
        return self.means.device

    @property
    def scales(self) -> torch.Tensor:
        """``(N, 3)`` activated scales."""
        return torch.exp(self.log_scales)

    @property
    def opacities(self) -> torch.Tensor:
        """``(N,)`` activated opacities in (0, 1) (:func:`logistic` of the logits)."""
        return logistic(self.opacity_logits)

    @property
    def unit_quats(self) -> torch.Tensor:
        """``(N, 4)`` normalised quaternions ``w, x, y, z``."""
        return normalize(self.quats)

    def colors(self, camera_center: torch.Tensor, degree: int | None = None) -> torch.Tensor:
        """View-dependent colours ``(N, 3)``: ``max(SH(dir) + 0.5, 0)`` with ``dir = mean − camera centre``."""
        degree = self.sh_degree if degree is None else min(degree, self.sh_degree)
        if degree == 0:
            return torch.clamp_min(self.sh[:, 0, :] * 0.28209479177387814 + 0.5, 0.0)
        dirs = normalize(self.means - camera_center.to(self.means))
        return torch.clamp_min(eval_sh(degree, self.sh, dirs) + 0.5, 0.0)

    # ------------------------------------------------------------------ conversions
    def tensors(self) -> dict[str, torch.Tensor]:
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def to(self, device: torch.device | str, dtype: torch.dtype | None = None) -> GaussianModel:
        return GaussianModel(
            **{k: v.to(device=device, dtype=dtype or v.dtype) for k, v in self.tensors().items()}
        )

    def detach(self) -> GaussianModel:
        return GaussianModel(**{k: v.detach() for k, v in self.tensors().items()})

    def clone(self) -> GaussianModel:
        return GaussianModel(**{k: v.detach().clone() for k, v in self.tensors().items()})

    def subset(self, index: torch.Tensor) -> GaussianModel:
        """The Gaussians selected by a boolean mask or an index tensor."""
        return GaussianModel(**{k: v[index] for k, v in self.tensors().items()})

    def check_finite(self, source: str) -> None:
        """Raise :class:`PlyError` naming ``source`` if any parameter is NaN or infinite."""
        for name, value in self.tensors().items():
            if not torch.isfinite(value).all():
                bad = int((~torch.isfinite(value)).reshape(value.shape[0], -1).any(dim=1).sum())
                raise PlyError(f"{bad} Gaussians have NaN or infinite {name}", source)

    @classmethod
    def from_points(
        cls,
        points: np.ndarray | torch.Tensor,
        colors: np.ndarray | torch.Tensor | None = None,
        *,
        sh_degree: int = 3,
        initial_opacity: float = 0.1,
        scale_neighbours: int = 3,
        min_scale: float = 1e-4,
    ) -> GaussianModel:
        """Isotropic Gaussians at ``points`` ``(P, 3)``, the standard 3DGS initialisation.

        Scale = RMS distance to the ``scale_neighbours`` nearest points (the Inria ``distCUDA2``
        rule), colour from ``colors`` (uint8 ``(P, 3)`` or float in [0, 1]; grey if ``None``),
        opacity ``initial_opacity``, identity rotation.
        """
        pts = torch.as_tensor(np.asarray(points, dtype=np.float32))
        n = pts.shape[0]
        if colors is None:
            rgb = torch.full((n, 3), 0.5)
        else:
            rgb = torch.as_tensor(np.asarray(colors))
            rgb = rgb.float() / 255.0 if rgb.dtype == torch.uint8 else rgb.float()
        dist = knn_mean_distance(pts, scale_neighbours).clamp_min(min_scale)
        sh = torch.zeros(n, num_sh_bases(sh_degree), 3)
        sh[:, 0, :] = rgb_to_sh_dc(rgb)
        quats = torch.zeros(n, 4)
        quats[:, 0] = 1.0
        logit = math.log(initial_opacity / (1.0 - initial_opacity))
        return cls(pts.clone(), quats, torch.log(dist)[:, None].repeat(1, 3), torch.full((n,), logit), sh)


def knn_mean_distance(points: torch.Tensor, k: int, chunk: int = 4096) -> torch.Tensor:
    """``(P,)`` root-mean-square distance from each point to its ``k`` nearest others (Inria ``distCUDA2``, exact)."""
    n = points.shape[0]
    if n <= 1:
        return torch.ones(n)
    k = min(k, n - 1)
    out = torch.empty(n)
    for start in range(0, n, chunk):
        block = points[start : start + chunk]
        d2 = torch.cdist(block, points).pow(2)
        d2[torch.arange(block.shape[0]), torch.arange(start, start + block.shape[0])] = float("inf")
        nearest = torch.topk(d2, k, dim=1, largest=False).values
        out[start : start + block.shape[0]] = nearest.clamp_min(0).mean(dim=1).sqrt()
    return out
