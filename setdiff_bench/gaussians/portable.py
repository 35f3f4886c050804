"""Arithmetic that rounds the same on every x86-64 CPU, for the scene fit.

A 3DGS fit runs thousands of optimiser steps, so the last bit of any operation it repeats grows into
visible differences (up to 0.3 dB on a group mean; docs/reproducibility.md).  Several ATen CPU kernels
round differently depending on the instruction set they dispatch to (``ATEN_CPU_CAPABILITY``: default,
AVX2, AVX-512): ``torch.sigmoid``, ``linalg_vector_norm`` (and so ``F.normalize``), ``torch.randn``'s
Box–Muller, ``lerp_`` / ``addcmul_`` (Adam); oneDNN's ``conv2d`` picks its kernels by ISA too.  These
functions compute the same quantities from element-wise IEEE operations (one rounding per multiply,
add, division, square root or ``exp``, no fused multiply-add, no reduction whose order follows the
vector width), which every vector width rounds identically; their autograd backward is made of the
same operations.  Measured: a tiny scene's fit is byte-identical under every ``ATEN_CPU_CAPABILITY``,
``ONEDNN_MAX_CPU_ISA`` and ``MKL_ENABLE_INSTRUCTIONS`` setting (tests/gaussians/fit/test_portable_fit.py).

Written by hand because no library offers ISA-independent CPU kernels; the cost is a few element-wise
passes over ``(N, 3)`` / ``(N, 4)`` tensors per step, small beside rasterisation.
"""

from __future__ import annotations

import numpy as np
import torch

__all__ = ["logistic", "normalize", "standard_normal", "vector_norm"]


def logistic(logits: torch.Tensor) -> torch.Tensor:
    """``1 / (1 + exp(−x))`` element-wise (``torch.sigmoid``'s value), differentiable."""
    return torch.reciprocal(1.0 + torch.exp(-logits))


def vector_norm(vectors: torch.Tensor) -> torch.Tensor:
    """Euclidean norm over the last dimension, summed left to right: ``(..., D)`` → ``(...)``."""
    squares = vectors[..., 0] * vectors[..., 0]
    for i in range(1, vectors.shape[-1]):
        squares = squares + vectors[..., i] * vectors[..., i]
    return torch.sqrt(squares)


def normalize(vectors: torch.Tensor, eps: float = 1e-12) -> torch.Tensor:
    """``vectors / max(‖vectors‖, eps)`` over the last dimension (``F.normalize``'s value): ``(..., D)``."""
    return vectors / torch.clamp_min(vector_norm(vectors), eps)[..., None]


def standard_normal(count: int, dims: int, generator: torch.Generator) -> torch.Tensor:
    """``(count, dims)`` float32 standard-normal samples drawn from ``generator``'s stream.

    The generator gives one 63-bit seed; numpy's ziggurat sampler (scalar integer arithmetic) draws the
    samples, so they are deterministic and resumable with the generator's state, and CPU-independent.
    """
    seed = int(torch.randint(0, 2**63 - 1, (1,), generator=generator))
    return torch.from_numpy(np.random.default_rng(seed).standard_normal((count, dims)).astype(np.float32))
