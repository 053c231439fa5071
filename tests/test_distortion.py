"""OpenCV lens distortion and its inverse against real OpenCV, Jacobians against finite differences."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from footprint_uq.cameras.distortion import distort, in_principal_region, undistort


def _random_dist(rng, n):
    d = np.zeros(8)
    d[:5] = [rng.uniform(-0.35, 0.15), rng.uniform(-0.1, 0.1), rng.uniform(-5e-3, 5e-3), rng.uniform(-5e-3, 5e-3),
             rng.uniform(-0.02, 0.02)]
    if n == 8:
        d[5:] = [rng.uniform(-0.1, 0.1), rng.uniform(-0.05, 0.05), rng.uniform(-0.02, 0.02)]
    return d


def _points(rng, n=200, box=(0.6, 0.4)):
    return rng.uniform([-box[0], -box[1]], [box[0], box[1]], (n, 2))


@pytest.mark.parametrize("n_coef", [5, 8])
def test_distort_matches_cv2_project_points(rng, n_coef):
    for _ in range(10):
        d = _random_dist(rng, n_coef)
        xn = _points(rng)
        obj = np.concatenate([xn, np.ones((len(xn), 1))], -1)
        ref = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), np.eye(3), d[:n_coef])[0][:, 0, :]
        np.testing.assert_allclose(distort(xn, d), ref, rtol=0, atol=1e-14)


@pytest.mark.parametrize("n_coef", [5, 8])
def test_undistort_matches_cv2_undistort_points(rng, n_coef):
    K = np.array([[1000.0, 0.0, 960.0], [0.0, 1000.0, 540.0], [0.0, 0.0, 1.0]])
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 1000, 1e-14)
    for _ in range(10):
        d = _random_dist(rng, n_coef)
        xn_true = _points(rng, 100)
        uv = distort(xn_true, d) * 1000.0 + [960.0, 540.0]
        ref = cv2.undistortPoints(uv.reshape(-1, 1, 2), K, d[:n_coef], criteria=criteria)[:, 0, :]
        xn, conv = undistort((uv - [960.0, 540.0]) / 1000.0, d)
        assert conv.all()
        # OpenCV's fixed-point iteration stops at 1e-14 px of reprojection error ...
        np.testing.assert_allclose(xn, ref, rtol=0, atol=1e-10)
        # ... ours is a Newton solve to round-off
        np.testing.assert_allclose(xn, xn_true, rtol=0, atol=1e-13)


def test_distort_jacobians_vs_central_differences(rng, central_diff, rel_err):
    for _ in range(10):
        d = _random_dist(rng, 8)
        xn = _points(rng, 50)
        _, J, Jk = distort(xn, d, get_gradients=True)
        fd = central_diff(lambda q, d=d: distort(q, d), xn, [1e-6, 1e-6])
        assert rel_err(fd, J, per_column=True).max() < 1e-8
        fdk = central_diff(lambda q, xn=xn: distort(xn, q), d, [1e-6] * 8)
        assert rel_err(fdk, Jk, per_column=True).max() < 1e-7


def test_undistort_implicit_jacobians_vs_central_differences(rng, central_diff, rel_err):
    for _ in range(10):
        d = _random_dist(rng, 8)
        xd = distort(_points(rng, 50), d)
        xn, conv, J, Jk = undistort(xd, d, get_gradients=True)
        assert conv.all() and J.shape == (50, 2, 2) and Jk.shape == (50, 2, 8)
        fd = central_diff(lambda q, d=d: undistort(q, d)[0], xd, [1e-6, 1e-6])
        assert rel_err(fd, J, per_column=True).max() < 1e-7
        fdk = central_diff(lambda q, xd=xd: undistort(xd, q)[0], d, [1e-6] * 8)
        assert rel_err(fdk, Jk, per_column=True).max() < 1e-6
        # implicit function theorem: dx/dxd is the inverse of the distortion Jacobian at the solution
        Jd = distort(xn, d, get_gradients=True)[1]
        np.testing.assert_allclose(J @ Jd, np.broadcast_to(np.eye(2), J.shape), atol=1e-12)


def test_zero_distortion_is_identity(rng):
    xd = _points(rng, 20)
    xn, conv, J, Jk = undistort(xd, np.zeros(8), get_gradients=True)
    np.testing.assert_array_equal(xn, xd)
    assert conv.all()
    np.testing.assert_array_equal(J, np.broadcast_to(np.eye(2), (20, 2, 2)))
    # d x / d k1 = -x r^2 at zero distortion (the first-order inverse of x r^2)
    r2 = (xd**2).sum(-1)
    np.testing.assert_allclose(Jk[:, :, 0], -xd * r2[:, None], rtol=1e-14)


def test_pinned_radial_value():
    # k1 = -0.5 only: r_d = r (1 - r^2 / 2).  For r = 0.5: r_d = 0.5 * 0.875 = 0.4375.
    # Inverse of r_d = 0.5: r - r^3/2 = 0.5 -> r = (sqrt(5) - 1) / 2 = 0.6180339887 (golden ratio conjugate:
    # r^3 = 2r - 1 holds for r^2 + r - 1 = 0).
    k = np.array([-0.5, 0, 0, 0, 0, 0, 0, 0.0])
    np.testing.assert_allclose(distort([0.5, 0.0], k), [0.4375, 0.0], atol=1e-16)
    xn, conv = undistort([0.5, 0.0], k)
    assert conv
    np.testing.assert_allclose(xn, [(np.sqrt(5) - 1) / 2, 0.0], atol=1e-15)


def test_non_invertible_region_not_converged():
    k = np.array([-0.5, 0, 0, 0, 0, 0, 0, 0.0])
    # r_d = r - r^3/2 peaks at r = sqrt(2/3) with r_d = 0.5443: beyond that there is no principal solution.
    # At r_d = 2 the cubic has the root r = -2 (the opposite side of the image, rad = -1): it is not a
    # valid undistortion and must not be reported as converged.
    xd = np.array([[0.5, 0.0], [0.6, 0.0], [0.7, 0.1], [2.0, 0.0], [0.0, -3.0], [0.3, 0.3]])
    xn, conv = undistort(xd, k)
    assert conv.tolist() == [True, False, False, False, False, True]
    assert np.isnan(xn[~conv]).all() and np.isfinite(xn[conv]).all()
    xn, conv, J, Jk = undistort(xd, k, get_gradients=True)
    assert np.isnan(J[~conv]).all() and np.isnan(Jk[~conv]).all()


def test_principal_region_pinned():
    # k1 = -0.5: d(r - r^3/2)/dr = 1 - 1.5 r^2 > 0 for r < sqrt(2/3) = 0.8165
    k = np.array([-0.5, 0, 0, 0, 0, 0, 0, 0.0])
    pts = np.array([[0.0, 0.0], [0.81, 0.0], [0.0, -0.82], [0.6, 0.6], [0.5, 0.5], [-2.0, 0.0]])
    assert in_principal_region(pts, k).tolist() == [True, True, False, False, True, False]
    # no distortion: everything is
    assert in_principal_region(pts, np.zeros(8)).all()


def test_root_past_the_fold_is_avoided():
    """Newton started at x_d converges to a root past the fold here; the principal root exists and is found."""
    k = np.array([0.135, -0.175, -0.005, -0.007, 0.022, -0.076, -0.071, 0.041])
    x_true = np.array([-0.89071778, -0.85201404])
    xn, conv = undistort(distort(x_true, k), k)
    assert conv
    np.testing.assert_allclose(xn, x_true, atol=1e-12)


def test_random_strong_lenses_invert_or_flag(rng):
    """Across strong lenses and large fields, a converged result always re-distorts to x_d."""
    n_conv = 0
    for _ in range(12):
        d = _random_dist(rng, 8)
        xd = rng.uniform(-1.5, 1.5, (500, 2))
        xn, conv = undistort(xd, d)
        n_conv += conv.sum()
        np.testing.assert_allclose(distort(xn[conv], d), xd[conv], rtol=0, atol=1e-13)
        # a converged solution is on the principal branch: never on the opposite side of the axis
        rad = np.einsum("ij,ij->i", xn[conv], xd[conv])
        assert np.all(rad > 0)
        assert in_principal_region(xn[conv], d).all()
    assert n_conv > 3000


def test_non_finite_input_and_broadcasting(rng):
    d = _random_dist(rng, 8)
    xd = np.array([[0.1, 0.2], [np.nan, 0.0], [np.inf, 0.1]])
    xn, conv = undistort(xd, d)
    assert conv.tolist() == [True, False, False] and np.isnan(xn[1:]).all()
    xn, conv = undistort(xd[0], np.stack([d, np.full(8, np.nan)]))
    assert xn.shape == (2, 2) and conv.tolist() == [True, False]
    # (M, 1, 8) distortions with (N, 2) points -> (M, N)
    ds = np.stack([_random_dist(rng, 8) for _ in range(3)])[:, None, :]
    pts = _points(rng, 5)
    xn, conv, J, Jk = undistort(pts, ds, get_gradients=True)
    assert xn.shape == (3, 5, 2) and conv.shape == (3, 5) and J.shape == (3, 5, 2, 2) and Jk.shape == (3, 5, 2, 8)
    for m in range(3):
        np.testing.assert_allclose(xn[m], undistort(pts, ds[m, 0])[0], rtol=0, atol=1e-15)
    assert distort(pts[0], ds).shape == (3, 1, 2)
