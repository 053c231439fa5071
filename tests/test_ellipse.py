"""Uncertainty ellipses: axes, orientation, chi-square scale, headings, boundary points, NaN."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import InputError
from footprint_uq.uncertainty.ellipse import chi2_scale, ellipse_axes, ellipse_points, heading_deg


def _rot(deg):
    a = np.deg2rad(deg)
    return np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])


def test_diagonal_covariances():
    # sigma_x = 2, sigma_y = 1: major axis along x (east), orientation 0
    a, b, ang = ellipse_axes(np.diag([4.0, 1.0]))
    assert (a, b, ang) == (pytest.approx(2.0), pytest.approx(1.0), pytest.approx(0.0))
    # sigma_y larger: major axis along north, orientation 90 deg (in (-90, 90])
    a, b, ang = ellipse_axes(np.diag([1.0, 9.0]))
    assert (a, b, ang) == (pytest.approx(3.0), pytest.approx(1.0), pytest.approx(90.0))
    # a circle: orientation 0 by convention
    a, b, ang = ellipse_axes(np.eye(2) * 0.25)
    assert (a, b, ang) == (pytest.approx(0.5), pytest.approx(0.5), pytest.approx(0.0))


@pytest.mark.parametrize("deg", [30.0, -30.0, 60.0, 89.0, -89.0, 120.0])
def test_rotated_covariance(deg):
    # R diag(4, 1) R^T with R a rotation by 30 deg:
    #   = [[4 c^2 + s^2, 3 c s], [3 c s, 4 s^2 + c^2]] = [[3.25, 1.299], [1.299, 1.75]] for 30 deg
    C = _rot(deg) @ np.diag([4.0, 1.0]) @ _rot(deg).T
    if deg == 30.0:
        np.testing.assert_allclose(C, [[3.25, 1.5 * np.sqrt(3) / 2], [1.5 * np.sqrt(3) / 2, 1.75]], atol=1e-15)
    a, b, ang = ellipse_axes(C)
    assert a == pytest.approx(2.0) and b == pytest.approx(1.0)
    expect = (deg + 90.0) % 180.0 - 90.0  # the same axis, in (-90, 90]
    assert ang == pytest.approx(expect, abs=1e-9)


def test_chi2_scale():
    # 95 % of a 2-D Gaussian: k = sqrt(-2 ln 0.05) = sqrt(5.99146) = 2.44775 (not the 1-D 1.96)
    assert chi2_scale(0.95) == pytest.approx(2.4477, abs=5e-5)
    assert chi2_scale(0.95) == pytest.approx(np.sqrt(5.991464547), rel=1e-9)
    # 1 - exp(-1/2) = 39.35 % is the 1-sigma ellipse
    assert chi2_scale(1 - np.exp(-0.5)) == pytest.approx(1.0, rel=1e-12)
    assert chi2_scale(0.95, dof=1) == pytest.approx(1.959964, rel=1e-6)
    assert chi2_scale(0.99) == pytest.approx(3.034854, rel=1e-6)
    for bad in (0.0, 1.0, 1.5, -0.1, float("nan"), "x"):
        with pytest.raises(InputError, match="confidence"):
            chi2_scale(bad)


def test_confidence_scaling_of_axes():
    C = _rot(30.0) @ np.diag([4.0, 1.0]) @ _rot(30.0).T
    a, b, ang = ellipse_axes(C, confidence=0.95)
    assert a == pytest.approx(2.0 * 2.4477, rel=2e-5) and b == pytest.approx(2.4477, rel=2e-5)
    assert ang == pytest.approx(30.0)
    # the 95 % ellipse really holds 95 % of Gaussian samples
    rng = np.random.default_rng(1)
    n = 40_000
    x = rng.standard_normal((n, 2)) @ np.linalg.cholesky(C).T
    m2 = np.einsum("ni,ij,nj->n", x, np.linalg.inv(C), x)
    inside = np.mean(m2 <= chi2_scale(0.95) ** 2)
    assert abs(inside - 0.95) < 5 * np.sqrt(0.95 * 0.05 / n)


def test_heading_deg():
    # orientation counter-clockwise from east -> bearing clockwise from north, axis in [0, 180)
    np.testing.assert_allclose(heading_deg([0.0, 90.0, 45.0, -45.0, 30.0, -90.0 + 1e-9]),
                               [90.0, 0.0, 45.0, 135.0, 60.0, 180.0 - 1e-9], atol=1e-9)
    assert heading_deg(90.0) == 0.0


def test_ellipse_points_lie_on_the_ellipse():
    rng = np.random.default_rng(7)
    A = rng.standard_normal((5, 2, 2))
    C = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(2)
    centre = rng.uniform(-100, 100, (5, 2))
    for conf, k in ((None, 1.0), (0.95, chi2_scale(0.95))):
        pts = ellipse_points(centre, C, confidence=conf, n=33)
        assert pts.shape == (5, 33, 2)
        d = pts - centre[:, None, :]
        m = np.sqrt(np.einsum("bni,bij,bnj->bn", d, np.linalg.inv(C), d))
        np.testing.assert_allclose(m, k, rtol=1e-12)
        np.testing.assert_allclose(pts[:, 0], pts[:, -1], atol=1e-12)  # closed polygon
    # the farthest boundary point is the semi-major axis
    pts = ellipse_points(np.zeros(2), np.diag([4.0, 1.0]), n=361)
    assert np.linalg.norm(pts, axis=-1).max() == pytest.approx(2.0)


def test_nan_propagates():
    C = np.stack([np.diag([4.0, 1.0]), np.full((2, 2), np.nan), np.diag([1.0, 1.0])])
    a, b, ang = ellipse_axes(C, confidence=0.95)
    assert np.isnan([a[1], b[1], ang[1]]).all()
    assert np.isfinite([a[0], a[2], b[0], b[2], ang[0], ang[2]]).all()
    pts = ellipse_points(np.zeros((3, 2)), C, n=8)
    assert np.isnan(pts[1]).all() and np.isfinite(pts[[0, 2]]).all()
    assert np.isnan(ellipse_points([0.0, 0.0], np.full((2, 2), np.nan), n=4)).all()
    assert np.isnan(ellipse_points([np.nan, 0.0], np.eye(2), n=4)[:, 0]).all()


def test_shapes_and_degenerate_covariances():
    C = np.broadcast_to(np.diag([4.0, 1.0]), (3, 4, 2, 2))
    a, b, ang = ellipse_axes(C)
    assert a.shape == b.shape == ang.shape == (3, 4)
    # rank one (a line): minor axis 0, never NaN from round-off
    C1 = np.array([[1.0, 1.0 + 1e-15], [1.0 + 1e-15, 1.0]])
    a, b, ang = ellipse_axes(C1)
    assert a == pytest.approx(np.sqrt(2.0)) and b == pytest.approx(0.0, abs=1e-7) and ang == pytest.approx(45.0)
    a, b, ang = ellipse_axes(np.zeros((2, 2)))
    assert a == 0.0 and b == 0.0
