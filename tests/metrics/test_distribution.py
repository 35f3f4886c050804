"""FID and KID formulas against closed forms, hand-derived values and scipy (issue 41)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from setdiff_bench.metrics.distribution import (
    fid,
    frechet_distance,
    gaussian_statistics,
    kid,
    mmd2_unbiased,
    polynomial_kernel,
)


def test_frechet_distance_of_two_diagonal_gaussians_by_hand() -> None:
    # |mu1 - mu2|^2 = 1 + 4 = 5; tr S1 + tr S2 = 5 + 13; tr (S1 S2)^1/2 = sqrt(4) + sqrt(36) = 8
    value = frechet_distance(np.zeros(2), np.diag([1.0, 4.0]), np.array([1.0, 2.0]), np.diag([4.0, 9.0]))
    assert value == pytest.approx(5 + 18 - 2 * 8, abs=1e-12)


def test_frechet_distance_with_non_commuting_covariances() -> None:
    # S1 = I, S2 with eigenvalues 1 and 3: tr S2^1/2 = 1 + sqrt 3; d^2 = 2 + 4 - 2 (1 + sqrt 3)
    s2 = np.array([[2.0, 1.0], [1.0, 2.0]])
    assert frechet_distance(np.ones(2), np.eye(2), np.ones(2), s2) == pytest.approx(4 - 2 * math.sqrt(3))
    # random SPD pairs: against scipy's sqrtm of the (non-symmetric) product, as pytorch-fid computes it
    rng = np.random.default_rng(0)
    for _ in range(5):
        a, b = rng.normal(size=(6, 6)), rng.normal(size=(6, 6))
        s1, s2 = a @ a.T + 0.1 * np.eye(6), b @ b.T + 0.1 * np.eye(6)
        mu1, mu2 = rng.normal(size=6), rng.normal(size=6)
        reference = (
            float((mu1 - mu2) @ (mu1 - mu2))
            + np.trace(s1)
            + np.trace(s2)
            - 2 * np.trace(scipy.linalg.sqrtm(s1 @ s2)).real
        )
        assert frechet_distance(mu1, s1, mu2, s2) == pytest.approx(reference, rel=1e-9)


def test_statistics_are_the_unbiased_mean_and_covariance() -> None:
    x = np.array([[0.0, 1.0], [2.0, 1.0], [4.0, 4.0]])
    mu, sigma = gaussian_statistics(x)
    assert mu.tolist() == [2.0, 2.0]
    # deviations (-2,-1), (0,-1), (2,2): sums of products / (3 - 1)
    assert sigma.tolist() == [[4.0, 3.0], [3.0, 3.0]]


def test_a_set_against_itself_has_zero_fid_and_sampled_gaussians_match_the_closed_form() -> None:
    rng = np.random.default_rng(1)
    x = rng.normal(size=(50, 8))
    assert fid(x, x) == pytest.approx(0.0, abs=1e-9)
    # 200 000 samples of N(0, I) and N(m, diag(4)) in 2-D: d^2 = |m|^2 + 2 + 8 - 2 * (2 + 2) = |m|^2 + 2
    m = np.array([1.0, -1.0])
    a = rng.normal(size=(200_000, 2))
    b = m + 2.0 * rng.normal(size=(200_000, 2))
    assert fid(a, b) == pytest.approx(4.0, abs=0.05)


def test_kid_unbiased_estimate_on_tiny_features_by_hand() -> None:
    # D = 1, k(a, b) = (a b + 1)^3
    x, y = np.array([[0.0], [1.0]]), np.array([[1.0], [2.0]])
    assert polynomial_kernel(x, y).tolist() == [[1.0, 1.0], [8.0, 27.0]]
    # k_xx off-diagonal: k(0,1) = 1; k_yy: k(1,2) = 27; k_xy mean = (1 + 1 + 8 + 27) / 4
    assert mmd2_unbiased(x, y) == pytest.approx(1 + 27 - 2 * 37 / 4)
    estimate = kid(x, y)
    assert (estimate.mean, estimate.std, estimate.subsets, estimate.subset_size) == (9.5, 0.0, 1, None)
    # unequal sizes: x = 0, 1, 2 -> off-diagonal pairs (0,1) 1, (0,2) 1, (1,2) 27: 2 * 29 / (3 * 2)
    # k_xy: 1, 1 | 8, 27 | 27, 125 = 189 over 6
    x3 = np.array([[0.0], [1.0], [2.0]])
    assert kid(x3, y).mean == pytest.approx(58 / 6 + 27 - 2 * 189 / 6)
    # D = 2 divides the inner product: k((1, 1), (1, 1)) = (2 / 2 + 1)^3 = 8
    assert polynomial_kernel(np.ones((1, 2)), np.ones((1, 2))).tolist() == [[8.0]]


def test_kid_of_a_set_against_itself_is_the_hand_formula_and_same_distributions_near_zero() -> None:
    # X vs X: 2 * (off-diagonal mean) - 2 * (mean over all pairs, diagonal included)
    x = np.array([[0.0], [1.0]])  # k = [[1, 1], [1, 8]]
    assert kid(x, x).mean == pytest.approx(2 * 1 - 2 * 11 / 4)
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=(400, 16)), rng.normal(size=(400, 16))
    shifted = rng.normal(size=(400, 16)) + 0.5
    same = kid(a, b, subsets=20, subset_size=100, seed=0)
    different = kid(a, shifted, subsets=20, subset_size=100, seed=0)
    assert abs(same.mean) < 3 * same.std + 1e-3
    assert different.mean > 10 * abs(same.mean) and different.subset_size == 100 and different.subsets == 20
    assert kid(a, b, subsets=20, subset_size=100, seed=0) == same  # seeded: the same value again


def test_bad_features_are_refused() -> None:
    with pytest.raises(ValueError, match="at least 2"):
        fid(np.zeros((1, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="NaN"):
        kid(np.full((3, 2), np.nan), np.zeros((3, 2)))
    with pytest.raises(ValueError, match="feature sizes differ"):
        kid(np.zeros((3, 2)), np.zeros((3, 4)))
