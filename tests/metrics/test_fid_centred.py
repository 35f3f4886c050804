"""FID through the small centred-feature matrices (issue 41) equals the ``(D, D)`` eigendecomposition path."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg

from setdiff_bench.metrics.distribution import fid, fid_from_centred, frechet_distance, gaussian_statistics

#: Relative tolerance in float64: both paths sum ~min(m, n) square roots of eigenvalues of size ~1, and
#: the eigendecomposition path clips round-off eigenvalues near 0 whose roots are ~1e-8 each.
RTOL = 1e-7


def _scipy_fid(a: np.ndarray, b: np.ndarray) -> float:
    """FID with numpy's statistics and scipy's general matrix square root (pytorch-fid's recipe)."""
    mu1, mu2 = a.mean(0), b.mean(0)
    s1, s2 = np.cov(a, rowvar=False), np.cov(b, rowvar=False)
    root = scipy.linalg.sqrtm(s1 @ s2)
    return float((mu1 - mu2) @ (mu1 - mu2) + np.trace(s1) + np.trace(s2) - 2.0 * np.trace(root).real)


@pytest.mark.parametrize(("m", "n"), [(12, 30), (30, 12), (5, 200), (40, 41)])
def test_centred_path_equals_the_covariance_path_on_random_features(m: int, n: int) -> None:
    rng = np.random.default_rng(m * 1000 + n)
    dim = 64
    a = rng.normal(size=(m, dim)) @ rng.normal(size=(dim, dim)) / 8.0
    b = rng.normal(0.3, 1.0, size=(n, dim)) @ rng.normal(size=(dim, dim)) / 8.0 + 0.5
    reference = frechet_distance(*gaussian_statistics(a), *gaussian_statistics(b))
    assert reference > 1.0  # well above zero: the check is not vacuous
    assert fid_from_centred(a, b) == pytest.approx(reference, rel=RTOL)
    assert fid(a, b) == pytest.approx(reference, rel=RTOL)  # fid() takes the centred path here
    assert fid(a, b) == pytest.approx(_scipy_fid(a, b), rel=1e-6)


def test_centred_path_on_a_set_against_itself_is_zero_and_symmetric() -> None:
    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(9, 32)), rng.normal(size=(15, 32))
    assert fid_from_centred(a, a) == pytest.approx(0.0, abs=1e-10)
    assert fid_from_centred(a, b) == pytest.approx(fid_from_centred(b, a), rel=1e-12)


def test_centred_path_of_two_point_sets_by_hand() -> None:
    # a = {(0,0), (2,0)}: mean (1,0), Σ₁ = diag(2, 0); b = {(0,1), (0,3)}: mean (0,2), Σ₂ = diag(0, 2).
    # Σ₁Σ₂ = 0, so FID = ‖(1,-2)‖² + 2 + 2 = 9.
    a = np.array([[0.0, 0.0], [2.0, 0.0]])
    b = np.array([[0.0, 1.0], [0.0, 3.0]])
    assert fid_from_centred(a, b) == pytest.approx(9.0, abs=1e-12)
    # the same pair shifted so that both axes coincide: b' = {(0,0),(2,0)} + (0,1): Σ₂ = Σ₁, FID = 1.
    assert fid_from_centred(a, a + np.array([0.0, 1.0])) == pytest.approx(1.0, abs=1e-12)


def test_large_sets_keep_the_covariance_path() -> None:
    rng = np.random.default_rng(5)
    a, b = rng.normal(size=(40, 8)), rng.normal(size=(50, 8)) + 0.2
    assert fid(a, b) == frechet_distance(*gaussian_statistics(a), *gaussian_statistics(b))
