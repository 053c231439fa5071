"""Multi-camera fusion: information-form weighting and the Mahalanobis consistency check."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import InputError
from footprint_uq.products.fusion import chi2_threshold, fuse_by_id, pairwise_mahalanobis


def test_hand_computed_two_cameras():
    # camera A: (0, 0), C = diag(1, 4); camera B: (2, 2), C = diag(1, 1)
    # P = diag(1 / (1 + 1), 1 / (1/4 + 1)) = diag(0.5, 0.8)
    # x = P (C_A^-1 x_A + C_B^-1 x_B) = (0.5 * 2, 0.8 * 2) = (1.0, 1.6)
    # pairwise d^2 = 2^2 / (1 + 1) + 2^2 / (4 + 1) = 2.8 for both sources
    r = fuse_by_id(["car7", "car7"], [[0.0, 0.0], [2.0, 2.0]], [np.diag([1.0, 4.0]), np.eye(2)],
                   camera_id=["A", "B"])
    assert r.object_id.tolist() == ["car7"]
    assert np.allclose(r.xy_world_m, [[1.0, 1.6]], rtol=1e-15)
    assert np.allclose(r.cov_m2, [np.diag([0.5, 0.8])], rtol=1e-15)
    assert np.allclose(r.source_d2, [2.8, 2.8], rtol=1e-14)
    # chi2 = sum r_i^T C_i^-1 r_i = (1 + 1.6^2 / 4) + (1 + 0.4^2) = 1.64 + 1.16 = 2.8
    assert r.chi2[0] == pytest.approx(2.8, rel=1e-14)
    assert r.chi2_threshold[0] == pytest.approx(9.2103404, rel=1e-7)  # chi2_2(0.99)
    assert r.consistent[0] and not r.source_inconsistent.any()
    assert r.n_sources.tolist() == [2]
    assert np.allclose(pairwise_mahalanobis([[0.0, 0.0], [2.0, 2.0]], [np.diag([1.0, 4.0]), np.eye(2)]),
                       [[0.0, 2.8], [2.8, 0.0]])


def test_hand_computed_correlated_and_disagreeing():
    # C_A = [[2, 1], [1, 2]] (inverse [[2, -1], [-1, 2]] / 3), C_B = I
    CA = np.array([[2.0, 1.0], [1.0, 2.0]])
    xA, xB = np.array([3.0, 0.0]), np.array([-3.0, 0.0])
    info = np.array([[2.0, -1.0], [-1.0, 2.0]]) / 3 + np.eye(2)  # [[5/3, -1/3], [-1/3, 5/3]]
    P = np.linalg.inv(info)  # [[5, 1], [1, 5]] / 8
    assert np.allclose(P, np.array([[5.0, 1.0], [1.0, 5.0]]) / 8)
    x = P @ (np.array([[2.0, -1.0], [-1.0, 2.0]]) / 3 @ xA + xB)  # P @ (2 - 3, -1) = P @ (-1, -1) = (-0.75, -0.75)
    assert np.allclose(x, [-0.75, -0.75])
    # pairwise d^2 = (6, 0) [[3, 1], [1, 3]]^-1 (6, 0)^T = 36 * 3 / 8 = 13.5 > 9.21
    r = fuse_by_id([1, 1], [xA, xB], [CA, np.eye(2)])
    assert np.allclose(r.xy_world_m[0], [-0.75, -0.75])
    assert np.allclose(r.cov_m2[0], P)
    assert np.allclose(r.source_d2, [13.5, 13.5])
    assert r.source_inconsistent.all() and not r.consistent[0]
    # at a looser level the same pair passes: 13.5 < chi2_2(0.999) = 13.8155
    assert fuse_by_id([1, 1], [xA, xB], [CA, np.eye(2)], confidence=0.999).consistent[0]


def test_three_sources_degrees_of_freedom_and_outlier():
    xy = [[0.0, 0.0], [0.1, -0.1], [5.0, 0.0]]
    C = [np.eye(2) * 0.04] * 3
    r = fuse_by_id([9, 9, 9], xy, C)
    assert r.chi2_threshold[0] == pytest.approx(13.2767, rel=1e-4)  # chi2_4(0.99)
    # the outlier drags the fused mean, so against the mean every source fails (d^2 = 108.4, 96.2, 408.4)...
    assert r.source_d2 == pytest.approx([108.4167, 96.1667, 408.4167], rel=1e-4)
    assert r.source_inconsistent.all() and not r.consistent[0]
    # ...and the pairwise table isolates it
    d2 = pairwise_mahalanobis(xy, C)
    assert d2[0, 1] == pytest.approx(0.25) and d2[0, 2] > 300 and d2[1, 2] > 300
    # equal covariances: the fused mean is the plain mean, covariance divided by 3
    assert np.allclose(r.xy_world_m[0], np.mean(xy, 0))
    assert np.allclose(r.cov_m2[0], np.eye(2) * 0.04 / 3)


def test_single_source_and_unusable_rows():
    r = fuse_by_id([1, 2, 2], [[1.0, 2.0], [np.nan, np.nan], [3.0, 4.0]],
                   [np.eye(2), np.full((2, 2), np.nan), 2 * np.eye(2)])
    assert np.allclose(r.xy_world_m, [[1.0, 2.0], [3.0, 4.0]])
    assert np.allclose(r.cov_m2[1], 2 * np.eye(2))
    assert r.n_sources.tolist() == [1, 1]
    assert r.source_used.tolist() == [True, False, True]
    assert r.source_reason[1].startswith("estimate not finite")
    assert np.isnan(r.source_d2).all() and r.consistent.all() and np.isnan(r.chi2).all()
    r2 = fuse_by_id([5], [[np.nan, 0.0]], [np.eye(2)])
    assert r2.n_sources[0] == 0 and np.isnan(r2.xy_world_m).all()


def test_flag_rate_matches_the_confidence_level():
    rng = np.random.default_rng(42)
    n = 4000
    truth = rng.uniform(-50, 50, (n, 2))
    A = rng.normal(size=(n, 2, 2, 2)) * 0.3
    C = A @ np.swapaxes(A, -1, -2) + 0.01 * np.eye(2)  # (n, 2 cams, 2, 2)
    L = np.linalg.cholesky(C)
    est = truth[:, None, :] + (L @ rng.standard_normal((n, 2, 2, 1)))[..., 0]
    ids = np.repeat(np.arange(n), 2)
    r = fuse_by_id(ids, est.reshape(-1, 2), C.reshape(-1, 2, 2), camera_id=np.tile([0, 1], n))
    rate = 1.0 - r.consistent.mean()
    assert 0.006 < rate < 0.015  # 1 % expected; binomial sd 0.16 %
    # the fused error is consistent with the fused covariance
    e = r.xy_world_m - truth
    m2 = np.einsum("ni,nij,nj->n", e, np.linalg.inv(r.cov_m2), e)
    assert np.mean(m2) == pytest.approx(2.0, rel=0.06)


def test_bad_input():
    with pytest.raises(InputError, match="^camera_id"):
        fuse_by_id([1, 1], [[0, 0], [1, 1]], [np.eye(2)] * 2, camera_id=["A", "A"])
    with pytest.raises(InputError, match=r"^cov_m2\[1\]"):
        fuse_by_id([1, 1], [[0, 0], [1, 1]], [np.eye(2), np.array([[1.0, 2.0], [2.0, 1.0]])])
    with pytest.raises(InputError, match="^object_id"):
        fuse_by_id([1, 1, 1], [[0, 0], [1, 1]], [np.eye(2)] * 2)
    with pytest.raises(InputError, match="^confidence"):
        fuse_by_id([1], [[0, 0]], [np.eye(2)], confidence=1.5)
    assert chi2_threshold(0.95, 2) == pytest.approx(5.991464547, rel=1e-9)
