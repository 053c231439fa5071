"""Covariance propagation: linear vs Monte Carlo and unscented, breakdowns, joint covariances, validity.

Monte Carlo tolerances: for N independent Gaussian samples, a sample variance has
a relative standard error sqrt(2/N) and a sample correlation-like quantity 1/sqrt(N).
We compare in the frame that whitens the linear covariance (L^-1 C_mc L^-T, which is
I if the two agree), so the diagonal may differ from 1 by about sqrt(2/N) and the
off-diagonal from 0 by about 1/sqrt(N); we allow 5 standard errors plus 1 % for the
(second-order) non-linearity of the camera model well below the horizon.
"""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import ErrorBudget, InputError, OpenCVCamera, PanTiltCamera, propagate, propagate_joint, status
from footprint_uq import params as P
from footprint_uq.uncertainty.propagation import linearity_ratio, monte_carlo, unscented

N_MC = 20_000


def _camera():
    """An OpenCV camera with distortion, skew-free K, 9 m high, looking 20 deg down towards the north-east."""
    cam = PanTiltCamera(1300.0, (1920, 1080), 9.0, 45.0, 20.0, 1.5, (5.0, -3.0), (965.0, 530.0))
    base = cam.to_opencv()
    K = base.K.copy()
    K[1, 1] = 1310.0
    return OpenCVCamera(K, [-0.12, 0.03, 4e-4, -3e-4, -0.004], base.R, base.t, (1920, 1080), ground_z_m=1.0)


def _budget():
    """Paper's BW-Cube1 errors with angular errors in the range of real roadside calibrations and a ground model."""
    return ErrorBudget.preset("bw-cube1").replace(pan_deg=0.15, tilt_deg=0.15, roll_deg=0.1, ground_height_m=0.05,
                                                  ground_slope_deg=0.3)


PIXELS = np.array([[960.0, 950.0], [300.0, 1000.0], [1650.0, 800.0], [960.0, 700.0]])  # well below the horizon


def _whitened(C_lin, C_mc):
    L = np.linalg.cholesky(C_lin)
    Li = np.linalg.inv(L)
    return Li @ C_mc @ np.swapaxes(Li, -1, -2)


def _assert_cov_matches(C_lin, C_mc, n, nonlinear=0.01):
    W = _whitened(C_lin, C_mc)
    d = W.shape[-1]
    diag = np.diagonal(W, axis1=-2, axis2=-1)
    off = W[..., ~np.eye(d, dtype=bool)]
    assert np.abs(diag - 1).max() < 5 * np.sqrt(2 / n) + nonlinear, diag
    assert np.abs(off).max() < 5 * np.sqrt(1 / n) + nonlinear, off


# --------------------------------------------------------------------------- linear vs sampling
def _budget_angles_intrinsics():
    """Errors on the non-linear parameters only (no position/height, which act almost linearly)."""
    return ErrorBudget.from_dict({"focal_px": 8.0, "principal_point_px": [4.0, 4.0],
                                  "distortion": [0.01, 0.003, 2e-4, 2e-4, 0.001], "pan_deg": 0.3, "tilt_deg": 0.3,
                                  "roll_deg": 0.3, "ground_slope_deg": 0.4, "imaging_px": [1.5, 1.5]})


@pytest.mark.parametrize("make_budget", [_budget, _budget_angles_intrinsics])
def test_linear_matches_monte_carlo_on_the_full_model(make_budget):
    cam, b = _camera(), make_budget()
    lin = propagate(cam, b, PIXELS)
    assert lin.valid.all()
    mc = monte_carlo(cam, b, PIXELS, n_samples=N_MC, seed=11)
    assert np.all(mc.fraction_valid == 1.0) and mc.n_samples == N_MC
    _assert_cov_matches(lin.cov_m2, mc.cov_m2, N_MC)
    # the mean agrees with the nominal point to a small fraction of a sigma (first-order bias is tiny here)
    sig = np.sqrt(np.diagonal(lin.cov_m2, axis1=-2, axis2=-1))
    assert np.all(np.abs(mc.xy_world_m - lin.xy_world_m) < 0.05 * sig + 5 * sig / np.sqrt(N_MC))


def test_georeferenced_coordinates_do_not_lose_precision():
    """A camera at UTM-like coordinates (x 5e5 m, y 5.4e6 m) gives the same covariances as at the origin.

    Regression: Monte Carlo once accumulated raw sums of squares of the coordinates, whose
    cancellation against the squared mean (~3e13 m^2) left nothing of a 0.01 m^2 variance.
    """
    b = ErrorBudget.from_dict({"pan_deg": 0.01, "tilt_deg": 0.01, "imaging_px": [0.2, 0.2]})
    local = PanTiltCamera(1200.0, (1920, 1080), 8.0, 30.0, 15.0)
    utm = PanTiltCamera(1200.0, (1920, 1080), 8.0, 30.0, 15.0, 0.0, (500_000.0, 5_400_000.0))
    uv = PIXELS[:2]
    np.testing.assert_allclose(propagate(utm, b, uv).cov_m2, propagate(local, b, uv).cov_m2, rtol=1e-6)
    m_local = monte_carlo(local, b, uv, n_samples=2000, seed=1)
    m_utm = monte_carlo(utm, b, uv, n_samples=2000, seed=1)
    np.testing.assert_allclose(m_utm.cov_m2, m_local.cov_m2, rtol=1e-4)
    np.testing.assert_allclose(m_utm.xy_world_m - [500_000.0, 5_400_000.0], m_local.xy_world_m, atol=1e-6)
    np.testing.assert_allclose(unscented(utm, b, uv).cov_m2, unscented(local, b, uv).cov_m2, rtol=1e-4)


def test_monte_carlo_is_seeded():
    cam, b = _camera(), _budget()
    a = monte_carlo(cam, b, PIXELS[:2], n_samples=500, seed=3)
    c = monte_carlo(cam, b, PIXELS[:2], n_samples=500, seed=3, chunk=128)
    np.testing.assert_allclose(a.cov_m2, monte_carlo(cam, b, PIXELS[:2], n_samples=500, seed=3).cov_m2, rtol=0)
    assert a.cov_m2.shape == (2, 2, 2)
    assert not np.allclose(a.cov_m2, monte_carlo(cam, b, PIXELS[:2], n_samples=500, seed=4).cov_m2, rtol=1e-6)
    assert np.all(np.isfinite(c.cov_m2))


def test_unscented_agrees_with_linear():
    cam, b = _camera(), _budget()
    lin = propagate(cam, b, PIXELS)
    ut = unscented(cam, b, PIXELS)
    assert ut.valid.all()
    # second-order differences only, well below the horizon: < 1 % in the whitened frame
    W = _whitened(lin.cov_m2, ut.cov_m2)
    np.testing.assert_allclose(W, np.broadcast_to(np.eye(2), W.shape), atol=0.01)
    np.testing.assert_allclose(ut.xy_world_m, lin.xy_world_m, atol=0.01 * np.sqrt(lin.cov_m2.max()))


def test_linear_sources_are_exact_for_ut_and_pinned():
    """Camera position errors move every ground point rigidly: cov = diag(sx^2, sy^2) for every method."""
    cam, b = _camera(), ErrorBudget.from_dict({"position_m": [0.3, 0.2]})
    for est in (propagate(cam, b, PIXELS), unscented(cam, b, PIXELS)):
        np.testing.assert_allclose(est.cov_m2, np.broadcast_to(np.diag([0.09, 0.04]), (4, 2, 2)), atol=1e-12)


def test_pinned_hand_checked_covariances():
    # f = 1000 px, height 10 m, looking north 45 deg down, principal point (959.5, 539.5): the centre pixel
    # sees (0, 10).  y = h / tan(theta) => dy/dh = 1 / tan 45 = 1 and dy/dtheta = -h / sin^2(45) = -20 m/rad.
    cam = PanTiltCamera(1000.0, (1920, 1080), 10.0, 0.0, 45.0)
    uv = [959.5, 539.5]
    est = propagate(cam, {"height_m": 0.1}, uv)
    np.testing.assert_allclose(est.xy_world_m, [0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(est.cov_m2, [[0.0, 0.0], [0.0, 0.01]], atol=1e-15)
    # sigma tilt 0.1 deg = 1.7453e-3 rad -> sigma_y = 20 * 1.7453e-3 = 0.034907 m
    est = propagate(cam, {"tilt_deg": 0.1}, uv)
    assert np.sqrt(est.cov_m2[1, 1]) == pytest.approx(20 * np.deg2rad(0.1), rel=1e-12)
    assert est.cov_m2[0, 0] == pytest.approx(0.0, abs=1e-20)
    # sigma pan 0.1 deg: the point swings sideways on a 10 m radius: sigma_x = 10 * 1.7453e-3 m
    est = propagate(cam, {"pan_deg": 0.1}, uv)
    assert np.sqrt(est.cov_m2[0, 0]) == pytest.approx(10 * np.deg2rad(0.1), rel=1e-12)
    # pixel noise 1 px: dx/du = range / f = 14.142 / 1000, dy/dv = -h / (f sin^2 45) = -0.02 m/px
    est = propagate(cam, {"imaging_px": [1.0, 1.0]}, uv)
    np.testing.assert_allclose(est.cov_m2, np.diag([2e-4, 4e-4]), rtol=1e-12, atol=1e-18)


# --------------------------------------------------------------------------- breakdown
def test_contributions_sum_to_the_total():
    cam, b = _camera(), _budget()
    det = np.array([[4.0, 1.0], [1.0, 2.0]])
    est = propagate(cam, b, PIXELS, pixel_cov_px2=det, breakdown=True)
    c = est.contributions
    assert {"focal", "principal_point", "distortion", "position", "height", "pan", "tilt", "roll", "ground_height",
            "ground_slope", "imaging", "resolution", "detector"} == set(c)
    assert "cross_terms" not in c  # independent sources
    total = sum(c.values())
    np.testing.assert_allclose(total, est.cov_m2, rtol=1e-12, atol=1e-15)
    for v in c.values():  # each one is a covariance
        assert np.all(np.linalg.eigvalsh(v) > -1e-12)
    # correlated sources (full covariance across pan and height) add a cross term
    bc = b.replace(covariance={"names": ["pan_deg", "height_m"], "matrix": [[0.04, 0.01], [0.01, 0.04]]})
    est = propagate(cam, bc, PIXELS, breakdown=True)
    assert "cross_terms" in est.contributions
    np.testing.assert_allclose(sum(est.contributions.values()), est.cov_m2, rtol=1e-12, atol=1e-15)


# --------------------------------------------------------------------------- detector covariance
def test_pixel_covariance_adds_through_the_pixel_jacobian():
    cam, b = _camera(), _budget()
    C = np.array([[[9.0, 2.0], [2.0, 4.0]], [[1.0, 0.0], [0.0, 1.0]], [[0.25, -0.1], [-0.1, 0.3]],
                  [[0.0, 0.0], [0.0, 0.0]]])
    base = propagate(cam, b, PIXELS)
    est = propagate(cam, b, PIXELS, pixel_cov_px2=C, breakdown=True)
    J = cam.backproject(PIXELS, get_gradients=True).dxy_duv
    added = J @ C @ np.swapaxes(J, -1, -2)
    np.testing.assert_allclose(est.cov_m2 - base.cov_m2, added, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(est.contributions["detector"], added, rtol=1e-12)
    # Monte Carlo with the same detector noise agrees
    mc = monte_carlo(cam, b, PIXELS, n_samples=N_MC, seed=5, pixel_cov_px2=C)
    _assert_cov_matches(est.cov_m2, mc.cov_m2, N_MC)


def test_bad_pixel_covariance_is_an_input_error():
    cam, b = _camera(), _budget()
    with pytest.raises(InputError, match="pixel_cov_px2"):
        propagate(cam, b, PIXELS, pixel_cov_px2=[[1.0, 0.0], [0.0, -1.0]])
    with pytest.raises(InputError, match="pixel_cov_px2"):
        propagate(cam, b, PIXELS, pixel_cov_px2=[[1.0, 0.5], [0.0, 1.0]])
    with pytest.raises(InputError, match="pixel_cov_px2"):
        propagate(cam, b, PIXELS, pixel_cov_px2=np.eye(3))
    with pytest.raises(InputError, match="pixel_cov_px2"):  # 3 covariances for 4 points
        propagate(cam, b, PIXELS, pixel_cov_px2=np.broadcast_to(np.eye(2), (3, 2, 2)))
    with pytest.raises(InputError, match=r"pixel_cov_px2\[1\]: .*positive semi-definite"):  # names the matrix
        propagate(cam, b, PIXELS, pixel_cov_px2=np.stack([np.eye(2), np.diag([1.0, -1.0]), np.eye(2), np.eye(2)]))
    with pytest.raises(InputError, match=r"pixel_cov_px2\[2, 0, 0\]"):  # names the offending element
        propagate(cam, b, PIXELS, pixel_cov_px2=np.stack([np.eye(2)] * 2 + [np.full((2, 2), np.nan)] + [np.eye(2)]))
    with pytest.raises(InputError, match="uv_px"):
        propagate(cam, b, [1.0, 2.0, 3.0])


# --------------------------------------------------------------------------- joint covariance
def test_joint_blocks():
    cam, b = _camera(), _budget()
    C = np.broadcast_to(np.array([[2.0, 0.3], [0.3, 1.0]]), (4, 2, 2))
    joint = propagate_joint(cam, b, PIXELS, pixel_cov_px2=C)
    assert joint.cov_m2.shape == (8, 8) and joint.xy_world_m.shape == (4, 2) and joint.valid.shape == (4,)
    single = propagate(cam, b, PIXELS, pixel_cov_px2=C)
    bp = cam.backproject(PIXELS, get_gradients=True)
    Sp = b.param_covariance()
    for i in range(4):
        np.testing.assert_allclose(joint.cov_m2[2 * i:2 * i + 2, 2 * i:2 * i + 2], single.cov_m2[i], rtol=1e-12)
        for j in range(4):
            if i != j:  # only the shared camera-level errors couple points
                expect = bp.dxy_dp[i] @ Sp @ bp.dxy_dp[j].T
                np.testing.assert_allclose(joint.cov_m2[2 * i:2 * i + 2, 2 * j:2 * j + 2], expect, rtol=1e-12,
                                           atol=1e-15)
    np.testing.assert_allclose(joint.cov_m2, joint.cov_m2.T, atol=1e-15)
    assert np.linalg.eigvalsh(joint.cov_m2).min() > 0


def test_joint_matches_monte_carlo():
    """Shared camera errors drawn once per sample, pixel noise per point: the 8x8 sample covariance."""
    cam, b = _camera(), _budget()
    n = N_MC
    rng = np.random.default_rng(21)
    Sp = b.param_covariance()
    w, V = np.linalg.eigh(Sp)
    dp = rng.standard_normal((n, P.N_PARAMS)) @ (V * np.sqrt(np.clip(w, 0, None))).T
    Suv = b.pixel_covariance()
    noise = rng.standard_normal((n, 4, 2)) @ np.linalg.cholesky(Suv).T
    # validity judged in the nominal camera's lens domain, as monte_carlo does (building a domain per sampled
    # lens costs ~25 ms each: 20,000 of them were 150-700 s of this test)
    xy = cam.backproject_with(cam.params + dp[:, None, :], PIXELS + noise).xy_world_m  # (n, 4, 2)
    samples = xy.reshape(n, 8)
    C_mc = np.cov(samples, rowvar=False)
    joint = propagate_joint(cam, b, PIXELS)
    _assert_cov_matches(joint.cov_m2, C_mc, n)
    # the points are strongly correlated: the joint covariance is not block-diagonal
    corr = joint.cov_m2[1, 3] / np.sqrt(joint.cov_m2[1, 1] * joint.cov_m2[3, 3])
    assert abs(corr) > 0.3


def test_joint_with_leading_dimensions_and_invalid_points():
    cam, b = _camera(), _budget()
    uv = np.stack([PIXELS, np.concatenate([PIXELS[:3], [[960.0, 0.0]]])])  # (2 frames, 4 points); last above horizon
    joint = propagate_joint(cam, b, uv)
    assert joint.cov_m2.shape == (2, 8, 8) and joint.valid.tolist() == [[True] * 4, [True, True, True, False]]
    assert joint.reason[1, 3] == status.ABOVE_HORIZON
    np.testing.assert_allclose(joint.cov_m2[1, :6, :6], joint.cov_m2[0, :6, :6], rtol=1e-12)
    assert np.isnan(joint.cov_m2[1, 6:, :]).all() and np.isnan(joint.cov_m2[1, :, 6:]).all()
    with pytest.raises(InputError, match="uv_px"):
        propagate_joint(cam, b, [960.0, 900.0])


# --------------------------------------------------------------------------- linearity and validity
def test_linearity_ratio_near_one_far_below_the_horizon_and_degrading_near_it():
    cam = PanTiltCamera(1200.0, (1920, 1080), 8.0, 30.0, 15.0)
    v_horizon = float(cam.horizon_v_px(959.5))
    # rows: far below the horizon ... 12 and 6 px below it
    uv = np.stack([np.full(4, 959.5), np.array([1000.0, 700.0, v_horizon + 12.0, v_horizon + 6.0])], -1)
    b = ErrorBudget.preset("bw-cube1").replace(pan_deg=0.2, tilt_deg=0.2)
    ratio, frac = linearity_ratio(cam, b, uv, n_samples=4000, seed=2)
    assert ratio.shape == (4,) and frac.shape == (4,)
    assert np.all(np.abs(ratio[:2] - 1.0) < 5 * np.sqrt(1 / 4000) + 0.01)
    assert ratio[3] < ratio[2] < 0.95  # the linear sigma under-estimates the heavy far tail
    assert frac[0] == 1.0 and frac[3] < 1.0  # some samples even miss the ground


def test_invalid_pixels_give_nan_and_codes():
    cam, b = _camera(), _budget()
    uv = np.array([[960.0, 950.0], [960.0, 5.0], [np.nan, 900.0]])
    for est in (propagate(cam, b, uv, breakdown=True), unscented(cam, b, uv)):
        assert est.valid.tolist() == [True, False, False]
        assert est.reason.tolist() == [status.OK, status.ABOVE_HORIZON, status.NOT_FINITE]
        assert np.isnan(est.cov_m2[1:]).all() and np.isnan(est.xy_world_m[1:]).all()
        assert np.isfinite(est.cov_m2[0]).all()
    est = propagate(cam, b, uv, breakdown=True)
    assert all(np.isnan(v[1:]).all() for v in est.contributions.values())
    # the valid point does not depend on the invalid ones
    np.testing.assert_array_equal(est.cov_m2[0], propagate(cam, b, uv[0]).cov_m2)
    # sigma_xy_m and ellipse() travel with the estimate
    assert est.sigma_xy_m.shape == (3, 2) and np.isnan(est.sigma_xy_m[1:]).all()
    a, bb, ang = est.ellipse(0.95)
    assert np.isfinite(a[0]) and np.isnan(a[1:]).all()


@pytest.mark.parametrize("shape", [(), (1,), (5,), (2, 3)])
def test_shapes(shape):
    cam, b = _camera(), _budget()
    n = int(np.prod(shape))
    uv = np.stack([np.linspace(300, 1600, max(n, 1)), np.linspace(700, 1000, max(n, 1))], -1).reshape(shape + (2,))
    est = propagate(cam, b, uv, breakdown=True)
    assert est.xy_world_m.shape == shape + (2,) and est.cov_m2.shape == shape + (2, 2)
    assert est.valid.shape == shape and est.reason.shape == shape
    assert all(v.shape == shape + (2, 2) for v in est.contributions.values())
    assert unscented(cam, b, uv).cov_m2.shape == shape + (2, 2)
    assert monte_carlo(cam, b, uv, n_samples=200).cov_m2.shape == shape + (2, 2)
    flat = propagate(cam, b, uv.reshape(-1, 2))
    np.testing.assert_allclose(est.cov_m2.reshape(-1, 2, 2), flat.cov_m2, rtol=1e-13)
