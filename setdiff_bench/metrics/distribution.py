"""Distribution metrics between two sets of image features: FID and KID.

Neither needs pairs: they compare the distribution of one image set (enhanced novel-view frames) with
another (the recorded frames of the same scenes), which is how frames without ground truth are scored
(ReconDreamer / DriveDreamer4D lane shifts, Fixer).  The features are Inception-v3 pool3 activations
(:mod:`setdiff_bench.metrics.inception`), but the formulas take any ``(N, D)`` features.

FID (Heusel et al. 2017): the Fréchet distance between the Gaussians fitted to the two sets,

    ``d² = ‖μ₁ − μ₂‖² + tr Σ₁ + tr Σ₂ − 2 tr (Σ₁^½ Σ₂ Σ₁^½)^½``

with the unbiased covariances (``N − 1``), as pytorch-fid and the TTUR reference compute them.  The
trace of the matrix square root is taken from the eigenvalues of the symmetric PSD matrix
``Σ₁^½ Σ₂ Σ₁^½`` (equal to ``tr (Σ₁ Σ₂)^½``), so no complex parts arise; negative round-off
eigenvalues are clipped to 0.

KID (Bińkowski et al. 2018): the unbiased estimate of the squared MMD with the cubic polynomial kernel
``k(x, y) = (xᵀy / D + 1)³``,

    ``MMD²ᵤ = Σ_{i≠j} k(xᵢ, xⱼ) / (m(m−1)) + Σ_{i≠j} k(yᵢ, yⱼ) / (n(n−1)) − 2 Σ_{i,j} k(xᵢ, yⱼ) / (mn)``.

KID is unbiased at any set size, which is why it suits the few dozen frames a scene gives where FID
(biased, and singular below D samples) does not.  When both sets are larger than ``subset_size``
the estimate is averaged over ``subsets`` random subsets of ``subset_size`` of each (without
replacement, seeded), as torch-fidelity and the KID paper do, and the standard deviation over subsets
is reported; otherwise the whole sets are used once (standard deviation 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: torch-fidelity's defaults: 100 subsets of 1000 features each.
KID_SUBSETS = 100
KID_SUBSET_SIZE = 1000


def _features(features: np.ndarray, name: str) -> np.ndarray:
    array = np.asarray(features, dtype=np.float64)
    if array.ndim != 2:
        raise ValueError(f"{name} must be (N, D) features, got shape {array.shape}")
    if array.shape[0] < 2:
        raise ValueError(f"{name} needs at least 2 feature vectors, got {array.shape[0]}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} contains NaN or infinite values")
    return array


def gaussian_statistics(features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(D,)`` and unbiased covariance ``(D, D)`` (divisor ``N − 1``) of ``(N, D)`` features, float64."""
    array = _features(features, "features")
    return array.mean(axis=0), np.cov(array, rowvar=False, ddof=1).reshape(array.shape[1], array.shape[1])


def _psd_sqrt(matrix: np.ndarray) -> np.ndarray:
    """Square root of a symmetric positive semi-definite matrix (eigenvalues clipped at 0)."""
    values, vectors = np.linalg.eigh((matrix + matrix.T) / 2.0)
    return (vectors * np.sqrt(np.clip(values, 0.0, None))) @ vectors.T


def frechet_distance(mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray) -> float:
    """Squared Fréchet (2-Wasserstein) distance between ``N(mu1, sigma1)`` and ``N(mu2, sigma2)``.

    Args:
        mu1, mu2: ``(D,)`` means.
        sigma1, sigma2: ``(D, D)`` symmetric PSD covariances.

    Returns:
        ``‖μ₁ − μ₂‖² + tr Σ₁ + tr Σ₂ − 2 tr (Σ₁^½ Σ₂ Σ₁^½)^½`` (≥ 0 up to round-off; clipped at 0).
    """
    mu1, mu2 = np.asarray(mu1, np.float64), np.asarray(mu2, np.float64)
    sigma1, sigma2 = np.asarray(sigma1, np.float64), np.asarray(sigma2, np.float64)
    if mu1.shape != mu2.shape or sigma1.shape != sigma2.shape or sigma1.shape != (mu1.size, mu1.size):
        raise ValueError(
            f"statistics differ in shape: mu {mu1.shape} / {mu2.shape}, sigma {sigma1.shape} / {sigma2.shape}"
        )
    root1 = _psd_sqrt(sigma1)
    middle = root1 @ sigma2 @ root1
    eigenvalues = np.linalg.eigvalsh((middle + middle.T) / 2.0)
    trace_sqrt = float(np.sqrt(np.clip(eigenvalues, 0.0, None)).sum())
    diff = mu1 - mu2
    value = float(diff @ diff + np.trace(sigma1) + np.trace(sigma2) - 2.0 * trace_sqrt)
    return max(value, 0.0)


def fid(features_a: np.ndarray, features_b: np.ndarray) -> float:
    """FID between two ``(N, D)`` feature sets (each N ≥ 2).

    With at least ``D`` features in each set this is :func:`frechet_distance` of their statistics.  When a
    set has fewer features than dimensions (the usual case here: a block gives tens of frames, pool3 has
    2048 values) the same value is computed exactly through the small centred matrices instead of two
    ``(D, D)`` eigendecompositions: :func:`fid_from_centred`.
    """
    a = _features(features_a, "features_a")
    b = _features(features_b, "features_b")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"feature sizes differ: {a.shape[1]} and {b.shape[1]}")
    if min(a.shape[0], b.shape[0]) < a.shape[1]:
        return fid_from_centred(a, b)
    return frechet_distance(*gaussian_statistics(a), *gaussian_statistics(b))


def fid_from_centred(features_a: np.ndarray, features_b: np.ndarray) -> float:
    """FID of ``(m, D)`` and ``(n, D)`` features from their centred ``(m, D)`` / ``(n, D)`` matrices.

    With ``A``, ``B`` the centred features, ``Σ₁ = AᵀA / (m−1)`` and ``Σ₂ = BᵀB / (n−1)``.  The non-zero
    eigenvalues of ``Σ₁Σ₂`` are those of ``(ABᵀ)(ABᵀ)ᵀ / ((m−1)(n−1))``, so ``tr (Σ₁Σ₂)^½`` is the sum of
    the singular values of the ``(m, n)`` matrix ``ABᵀ / √((m−1)(n−1))``, and ``tr Σ₁ = ‖A‖²_F / (m−1)``.
    Cost ``O(mnD + mn·min(m, n))`` instead of ``O(D³)``; the value equals :func:`frechet_distance` of
    :func:`gaussian_statistics` up to round-off (float64).
    """
    a = _features(features_a, "features_a")
    b = _features(features_b, "features_b")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"feature sizes differ: {a.shape[1]} and {b.shape[1]}")
    m, n = a.shape[0], b.shape[0]
    mu_a, mu_b = a.mean(axis=0), b.mean(axis=0)
    centred_a, centred_b = a - mu_a, b - mu_b
    cross = centred_a @ centred_b.T / np.sqrt((m - 1) * (n - 1))
    trace_sqrt = float(np.linalg.svd(cross, compute_uv=False).sum())
    diff = mu_a - mu_b
    trace_a = float(np.einsum("ij,ij->", centred_a, centred_a)) / (m - 1)
    trace_b = float(np.einsum("ij,ij->", centred_b, centred_b)) / (n - 1)
    return max(float(diff @ diff) + trace_a + trace_b - 2.0 * trace_sqrt, 0.0)


def polynomial_kernel(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """``(m, n)`` cubic polynomial kernel ``(xᵢᵀyⱼ / D + 1)³`` of ``(m, D)`` and ``(n, D)`` features."""
    return (x @ y.T / x.shape[1] + 1.0) ** 3


def mmd2_unbiased(x: np.ndarray, y: np.ndarray) -> float:
    """Unbiased squared MMD of ``(m, D)`` and ``(n, D)`` features (m, n ≥ 2) with :func:`polynomial_kernel`."""
    m, n = x.shape[0], y.shape[0]
    k_xx = polynomial_kernel(x, x)
    k_yy = polynomial_kernel(y, y)
    k_xy = polynomial_kernel(x, y)
    within_x = (k_xx.sum() - np.trace(k_xx)) / (m * (m - 1))
    within_y = (k_yy.sum() - np.trace(k_yy)) / (n * (n - 1))
    return float(within_x + within_y - 2.0 * k_xy.mean())


@dataclass(frozen=True)
class KID:
    """A KID estimate.

    Attributes:
        mean: the unbiased MMD² (averaged over subsets when subsets were drawn).
        std: its standard deviation over the subsets (0 when the whole sets were used once).
        subsets: how many estimates were averaged.
        subset_size: features per set in each estimate (``None``: the whole sets, possibly of
            different sizes).
    """

    mean: float
    std: float
    subsets: int
    subset_size: int | None


def kid(
    features_a: np.ndarray,
    features_b: np.ndarray,
    *,
    subsets: int = KID_SUBSETS,
    subset_size: int = KID_SUBSET_SIZE,
    seed: int = 0,
) -> KID:
    """KID between two ``(N, D)`` feature sets (module docstring).

    Args:
        features_a, features_b: ``(N_a, D)`` and ``(N_b, D)`` features, each N ≥ 2.
        subsets: how many random subset pairs when both sets exceed ``subset_size``.
        subset_size: features per subset (at most the smaller set's size).
        seed: seed of the subset draws (the same inputs and seed give the same value).
    """
    a = _features(features_a, "features_a")
    b = _features(features_b, "features_b")
    if a.shape[1] != b.shape[1]:
        raise ValueError(f"feature sizes differ: {a.shape[1]} and {b.shape[1]}")
    if subsets < 1 or subset_size < 2:
        raise ValueError(f"subsets must be >= 1 and subset_size >= 2, got {subsets} and {subset_size}")
    if a.shape[0] <= subset_size and b.shape[0] <= subset_size:
        return KID(mmd2_unbiased(a, b), 0.0, 1, None)
    size = min(subset_size, a.shape[0], b.shape[0])
    rng = np.random.default_rng(seed)
    values = np.array(
        [
            mmd2_unbiased(
                a[rng.choice(a.shape[0], size, replace=False)], b[rng.choice(b.shape[0], size, replace=False)]
            )
            for _ in range(subsets)
        ]
    )
    return KID(float(values.mean()), float(values.std()), subsets, size)
