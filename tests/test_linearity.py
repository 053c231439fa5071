"""The linearity flag: ``nonlinearity`` / ``linear_ok`` against its algebra, finite differences and Monte Carlo.

The indicator predicts the relative error of the linear 1-sigma semi-major axis from a
second-order expansion of ``1 / Dn`` (``propagation.nonlinearity_from_forms``).  Checked
here: the closed form on cases with a known answer, the denominator's gradient against
central differences, and the prediction against seeded Monte Carlo from near the camera
to the horizon, for several budgets, both readings of Table 3's angles and two cameras.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import (
    ErrorBudget,
    InputError,
    OpenCVCamera,
    PanTiltCamera,
    ellipse_axes,
    monte_carlo,
    propagate,
    propagate_joint,
)
from footprint_uq import params as P
from footprint_uq.products.footprints import centre_covariance_sampled, footprints_from_corners
from footprint_uq.uncertainty.propagation import nonlinearity, nonlinearity_from_forms, ray_denominator

DEMO = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BENCH = PanTiltCamera(1400, (1920, 1080), 10.0, 30.0, 12.0, roll_deg=1.0, position_m=(5.0, -3.0))
_T = DEMO.T_cam_world
LENS = OpenCVCamera(DEMO.K, [-0.08, 0.02, 1e-3, -5e-4, 0.0], _T[:3, :3], _T[:3, 3], (1920, 1080))  # with distortion
SLOPE = ErrorBudget.preset("basler1").replace(roll_deg=0.05, ground_height_m=0.05, ground_slope_deg=0.5,
                                              name="basler1+slope0.5")


def _series(q2):
    return np.sqrt(1 + 8 * q2 + 69 * q2**2 + 696 * q2**3) - 1


@pytest.mark.parametrize("sigma", [0.01, 0.05, 0.1])
def test_pure_depth_error_gives_the_series_of_one_over_one_plus_eps(sigma):
    """Only the denominator is uncertain: Var(1/(1+eps)) = q2 + 8 q2^2 + 69 q2^3 + 696 q2^4 + ..."""
    # one parameter of unit variance, dDn/dp = sigma, Dn = -1, lam = 1, d_xy = e = (1, 0): b = 1, w = 1
    lam_max, mu, gamma = sigma**2, sigma**2, sigma**2
    nl = nonlinearity_from_forms(lam_max, np.array([1.0, 0.0]), -1.0, 1.0, np.array([1.0, 0.0]), mu, gamma)
    assert nl == pytest.approx(_series(sigma**2), rel=1e-12)
    assert nl == pytest.approx(4 * sigma**2, rel=0.25)  # leading order: 4 q2


def test_independent_numerator_error_gains_three_q2():
    """xy = A / (1 + eps) with A independent of eps and no depth term along e: variance x (1 + 3 q2)."""
    q2 = 0.003
    # d_xy perpendicular to e: b = w = 0; mu = r Sigma g = 0 (independent)
    nl = nonlinearity_from_forms(2.0, np.array([1.0, 0.0]), -0.5, 3.0, np.array([0.0, 1.0]), 0.0, q2 * 0.25)
    assert nl == pytest.approx(np.sqrt(1 + 3 * q2) - 1, rel=1e-12)


def test_nan_in_nan_out():
    nl = nonlinearity_from_forms(np.nan, np.array([1.0, 0.0]), -1.0, 1.0, np.array([1.0, 0.0]), 1.0, 1.0)
    assert np.isnan(nl)


@pytest.mark.parametrize("camera", ["pantilt", "opencv"])
def test_denominator_gradient_matches_central_differences(camera):
    cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    if camera == "opencv":
        T = DEMO.T_cam_world
        cam = OpenCVCamera(DEMO.K, [-0.05, 0.01, 1e-3, -5e-4, 0.0], T[:3, :3], T[:3, 3], (1920, 1080))
    cam.params[P.GSX] = 0.01  # a tilted ground, so that the slope columns are exercised
    cam.params[P.GSY] = -0.02
    uv = np.array([[959.5, 800.0], [300.0, 200.0], [1800.0, 500.0]])
    dn, lam, d_xy, g, g_uv = ray_denominator(cam, uv)
    assert np.all(dn < 0) and np.all(lam > 0)
    bp = cam.backproject(uv)
    np.testing.assert_allclose(cam.position_world_m[:2] + lam[:, None] * d_xy, bp.xy_world_m, rtol=1e-10)
    p0 = cam.params.copy()
    for k in range(P.N_PARAMS):
        h = 1e-6 * max(1.0, abs(p0[k]))
        vals = []
        for s in (1, -1):
            cam.params[:] = p0
            cam.params[k] += s * h
            vals.append(ray_denominator(cam, uv)[0])
        cam.params[:] = p0
        np.testing.assert_allclose(g[:, k], (vals[0] - vals[1]) / (2 * h), atol=1e-7, err_msg=P.PARAM_NAMES[k])
    for j in range(2):
        du = np.zeros(2)
        du[j] = 1e-3
        fd = (ray_denominator(cam, uv + du)[0] - ray_denominator(cam, uv - du)[0]) / 2e-3
        np.testing.assert_allclose(g_uv[:, j], fd, atol=1e-9)


def test_propagate_fields_threshold_and_invalid_points():
    uv = np.array([[959.5, 800.0], [959.5, 60.0], [959.5, 20.0]])  # near, near the horizon, above it
    est = propagate(DEMO, "bw-cube1@deg", uv)
    assert est.nonlinearity.shape == (3,) and est.linear_ok.dtype == bool and est.linear_threshold == 0.05
    assert est.nonlinearity[0] < 0.01 and est.linear_ok[0]
    assert est.nonlinearity[1] > 0.5 and not est.linear_ok[1]
    assert np.isnan(est.nonlinearity[2]) and not est.linear_ok[2]
    loose = propagate(DEMO, "bw-cube1@deg", uv, linear_threshold=10.0)
    assert loose.linear_ok.tolist() == [True, True, False]
    np.testing.assert_array_equal(nonlinearity(DEMO, "bw-cube1@deg", uv), est.nonlinearity)
    assert propagate(DEMO, "basler1", uv, linearity=False).nonlinearity is None
    for bad in (0.0, -0.1, float("nan"), "x"):
        with pytest.raises(InputError, match="linear_threshold"):
            propagate(DEMO, "basler1", uv, linear_threshold=bad)
    # broadcasting over leading dimensions
    grid = np.stack(np.meshgrid([300.0, 959.5, 1600.0], [100.0, 500.0, 900.0]), -1)  # (3, 3, 2)
    e2 = propagate(DEMO, SLOPE, grid)
    assert e2.nonlinearity.shape == (3, 3)
    np.testing.assert_allclose(e2.nonlinearity[1], propagate(DEMO, SLOPE, grid[1]).nonlinearity, rtol=1e-12)


# Points from near the camera to 5 px below the horizon, spaced geometrically in rows
# (fixed before looking at the results: 10 rows per camera, column 700).
def _sweep(cam):
    hz = float(cam.horizon_v_px(700.0))
    v = hz + np.geomspace(5.0, 1000.0 - hz, 10)
    return np.stack([np.full_like(v, 700.0), v], -1)


CASES = [(DEMO, "basler1"), (DEMO, "bw-cube1"), (DEMO, "basler1@deg"), (DEMO, "bw-cube1@deg"),
         (DEMO, "bw-bullet1@deg"), (DEMO, SLOPE), (BENCH, SLOPE), (BENCH, "bw-cube1@deg"), (LENS, "bw-cube1@deg")]


@pytest.fixture(scope="module")
def sweep():
    out = []
    for cam, budget in CASES:
        uv = _sweep(cam)
        est = propagate(cam, budget, uv)
        mc = monte_carlo(cam, budget, uv, n_samples=60_000, seed=7)
        with np.errstate(invalid="ignore"):
            measured = ellipse_axes(mc.cov_m2)[0] / ellipse_axes(est.cov_m2)[0] - 1
        out.append((budget, est.nonlinearity, est.linear_ok, measured))
    return out


def test_where_linear_ok_monte_carlo_agrees_within_5_percent(sweep):
    n_ok = 0
    for budget, _, ok, measured in sweep:
        assert np.all(np.abs(measured[ok]) <= 0.05), (budget, measured[ok])
        n_ok += ok.sum()
    assert n_ok >= 40  # the check is not empty
    # and the flag is not trivially True: each @deg budget fails near the horizon
    assert all((~ok).any() for b, _, ok, _ in sweep if isinstance(b, str) and b.endswith("@deg"))


def test_indicator_tracks_the_monte_carlo_deviation(sweep):
    rows = 0
    for budget, nl, _, measured in sweep:
        sel = nl <= 0.15
        # within 20 % of the prediction plus the Monte Carlo noise (60,000 samples: ~0.4 % on a sigma)
        assert np.all(np.abs(np.abs(measured[sel]) - nl[sel]) <= 0.2 * nl[sel] + 0.006), (budget, nl, measured)
        rows += int(np.sum(sel & (nl > 0.01)))
    assert rows >= 8  # enough points in the interesting range
    # beyond the flag the linear axis under-estimates, and the indicator says so
    big = np.concatenate([m[n > 0.3] for _, n, _, m in sweep])
    assert big.size and np.all(big > 0.2)


@settings(max_examples=40, deadline=None)
@given(pan=st.floats(-180, 180), tilt=st.floats(5, 60), height=st.floats(3, 30), u=st.floats(0, 1919),
       v=st.floats(0, 1079), x=st.floats(-1e4, 1e4), slope=st.floats(0.0, 1.0))
def test_properties_over_cameras_and_pixels(pan, tilt, height, u, v, x, slope):
    """Finite and >= 0 where valid; invariant to where the camera stands; ~ k^2 when the budget is scaled by k."""
    budget = ErrorBudget.preset("bw-cube1@deg").replace(ground_slope_deg=slope, roll_deg=0.1)
    cam = PanTiltCamera(1400.0, (1920, 1080), height, pan, tilt)
    far = PanTiltCamera(1400.0, (1920, 1080), height, pan, tilt, position_m=(x, -x / 3))
    uv = np.array([u, v])
    est = propagate(cam, budget, uv)
    if not est.valid:
        assert np.isnan(est.nonlinearity) and not est.linear_ok
        return
    nl = float(est.nonlinearity)
    assert np.isfinite(nl) and nl >= 0.0
    assert float(propagate(far, budget, uv).nonlinearity) == pytest.approx(nl, rel=1e-6, abs=1e-12)
    if 1e-8 < nl < 1e-3:  # leading order: every term of delta / lam_max scales with the variances
        nl2 = float(propagate(cam, budget.scaled(2.0), uv).nonlinearity)
        assert nl2 / nl == pytest.approx(4.0, rel=0.03)


def test_joint_propagation_carries_the_same_flag():
    uv = np.array([[[959.5, 800.0], [959.5, 60.0], [300.0, 200.0]], [[959.5, 20.0], [1500.0, 300.0], [10.0, 1000.0]]])
    j = propagate_joint(DEMO, "bw-cube1@deg", uv, linear_threshold=0.02)
    e = propagate(DEMO, "bw-cube1@deg", uv, linear_threshold=0.02)
    np.testing.assert_allclose(j.nonlinearity, e.nonlinearity, rtol=1e-10)
    np.testing.assert_array_equal(j.linear_ok, e.linear_ok)
    assert j.linear_ok.shape == (2, 3) and propagate_joint(DEMO, "basler1", uv, linearity=False).nonlinearity is None


def test_camera_position_error_is_additive_not_through_the_denominator():
    """Isotropic position noise adds sigma^2 I to the covariance and nothing to the second-order change delta."""
    uv = np.array([[959.5, 100.0], [400.0, 150.0]])
    tilt = ErrorBudget.from_dict({"tilt_deg": 0.5, "height_m": 0.2})
    both = tilt.replace(position_m=[0.3, 0.3])
    a, b = propagate(DEMO, tilt, uv), propagate(DEMO, both, uv)
    la = ellipse_axes(a.cov_m2)[0] ** 2
    lb = ellipse_axes(b.cov_m2)[0] ** 2
    np.testing.assert_allclose(lb, la + 0.09, rtol=1e-9)
    delta_a = ((1 + a.nonlinearity) ** 2 - 1) * la
    delta_b = ((1 + b.nonlinearity) ** 2 - 1) * lb
    np.testing.assert_allclose(delta_b, delta_a, rtol=1e-9)
    assert np.all(b.nonlinearity < a.nonlinearity)


def test_covariance_for_v2x_follows_the_policy():
    from footprint_uq.uncertainty.propagation import (
        V2X_COV_LINEAR,
        V2X_COV_SAMPLED,
        V2X_COV_UNAVAILABLE,
        covariance_for_v2x,
    )

    uv = np.array([[959.5, 800.0], [959.5, 60.0], [959.5, 20.0]])  # near, flagged (8 %), above the horizon
    cov, src, est = covariance_for_v2x(DEMO, "basler1@deg", uv, n_samples=20_000, seed=3)
    assert src.tolist() == [V2X_COV_LINEAR, V2X_COV_SAMPLED, V2X_COV_UNAVAILABLE]
    assert est.linear_ok[0] and 0.05 < est.nonlinearity[1] <= 0.5
    np.testing.assert_array_equal(cov[0], est.cov_m2[0])
    assert np.isnan(cov[2]).all()
    # the sampled covariance where its semi-major axis is the larger: never less than the linear one
    mc = monte_carlo(DEMO, "basler1@deg", uv[1:2], n_samples=20_000, seed=3)
    a_mc, a_lin = ellipse_axes(mc.cov_m2)[0][0], ellipse_axes(est.cov_m2[1])[0]
    assert a_mc > a_lin
    np.testing.assert_allclose(cov[1], mc.cov_m2[0], rtol=1e-12)
    # far beyond the expansion (BW-Cube1 in degrees near the horizon): unavailable, NaN
    cov2, src2, est2 = covariance_for_v2x(DEMO, "bw-cube1@deg", np.array([[959.5, 45.0]]), n_samples=2000)
    assert est2.nonlinearity[0] > 0.5 and src2.tolist() == [V2X_COV_UNAVAILABLE] and np.isnan(cov2).all()


@pytest.mark.parametrize("camera", [DEMO, LENS], ids=["pantilt", "opencv"])
def test_centre_flag_tracks_the_sampled_centre(camera):
    """An object's centre carries the largest of its corners' flags; against a seeded Monte Carlo of the centre
    (the full model, shared camera errors, every corner's pixel noise), from near the camera to the horizon:
    where linear_ok the linear centre's semi-major axis is within 5 % (+ Monte-Carlo noise), and up to 0.15
    the flag is within 20 % of the measured deviation, as for single points."""
    v = np.array([900.0, 500.0, 300.0, 200.0, 150.0, 120.0, 100.0, 85.0, 75.0, 65.0])  # chosen before the results
    corners = np.array([[0.0, 0.0], [60.0, 0.0], [60.0, -12.0], [0.0, -12.0]])
    uv = np.stack([np.full(v.size, 900.0), v], -1)[:, None, :] + corners
    n_ok = 0
    for budget in ("bw-cube1@deg", "basler1@deg", "bw-bullet1@deg"):
        est = footprints_from_corners(camera, budget, uv, v2x_policy="linear")
        mc, frac = centre_covariance_sampled(camera, budget, uv, n_samples=20_000, seed=3)
        dev = ellipse_axes(mc)[0] / ellipse_axes(est.centre_cov_m2)[0] - 1.0
        use = est.centre_valid & (frac >= 0.999)
        ok = use & est.centre_linear_ok
        n_ok += ok.sum()
        assert np.all(np.abs(dev[ok]) <= 0.05 + 0.015), (budget, dev[ok])
        mid = use & (est.centre_nonlinearity <= 0.15)
        assert np.all(np.abs(np.abs(dev[mid]) - est.centre_nonlinearity[mid])
                      <= 0.2 * est.centre_nonlinearity[mid] + 0.015), (budget, dev[mid], est.centre_nonlinearity[mid])
        assert (use & ~est.centre_linear_ok).any(), budget  # the sweep reaches where the flag trips
    assert n_ok >= 15
