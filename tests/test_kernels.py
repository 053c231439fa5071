"""Fused kernels (covariance_map, covariance_points) against propagate (and finite differences)."""

import numpy as np
import pytest

from footprint_uq import ErrorBudget, InputError, OpenCVCamera, PanTiltCamera, propagate
from footprint_uq import params as P
from footprint_uq.products.covariance import covariance_map, covariance_points

SEED = 77


def _assert_same(got, ref, rtol=1e-9):
    """Kernel ``(xy, cov, valid)`` against a GroundEstimate: same validity, NaN where invalid, values to rtol.

    Covariance entries are compared relative to ``sqrt(c_ii c_jj)`` of the reference, ground
    points relative to the largest offset from the camera.
    """
    xy, cov, valid = got
    np.testing.assert_array_equal(valid, ref.valid)
    assert np.isnan(xy[~valid]).all() and np.isnan(cov[~valid]).all()
    v = valid
    assert np.isfinite(xy[v]).all() and np.isfinite(cov[v]).all()
    scale_xy = np.abs(ref.xy_world_m[v]).max()
    assert np.abs(xy[v] - ref.xy_world_m[v]).max() <= rtol * scale_xy
    c = ref.cov_m2[v]
    sd = np.sqrt(c[:, [0, 1], [0, 1]])
    scale = sd[:, :, None] * sd[:, None, :]
    err = (np.abs(cov[v] - c) / scale).max()
    assert err <= rtol, err
    np.testing.assert_array_equal(cov[v][:, 0, 1], cov[v][:, 1, 0])


def _random_pantilt(rng, size=(64, 41), tilt=(3, 40)):
    w, h = size
    return PanTiltCamera(rng.uniform(0.6, 1.5) * w, size, rng.uniform(3, 25), rng.uniform(-180, 180),
                         rng.uniform(*tilt), roll_deg=rng.uniform(-15, 15), position_m=rng.normal(0, 50, 2),
                         principal_point_px=((w - 1) / 2 + rng.uniform(-3, 3), (h - 1) / 2 + rng.uniform(-3, 3)))


def _random_opencv(rng, size=(64, 41)):
    cam = _random_pantilt(rng, size, tilt=(10, 40))
    K = cam.K.copy()
    K[1, 1] *= rng.uniform(0.97, 1.03)
    K[0, 1] = rng.uniform(-1, 1)
    dist = [rng.uniform(-0.25, -0.05), rng.uniform(0, 0.05), rng.uniform(-2e-3, 2e-3), rng.uniform(-2e-3, 2e-3),
            rng.uniform(-0.01, 0.01), rng.uniform(0, 0.02), 0.0, rng.uniform(0, 0.01)]
    T = cam.T_cam_world
    return OpenCVCamera(K, dist, T[:3, :3], T[:3, 3], size)


def _full_budget(rng, base):
    """The base budget plus a random full covariance coupling ray, position, height and ground parameters."""
    names = ["fx_px", "fy_px", "cx_px", "cy_px", "skew_px", "k1", "k2", "p1", "k3", "k5", "x_m", "y_m", "height_m",
             "pan_rad", "tilt_rad", "roll_rad", "ground_dz_m", "ground_slope_x", "ground_slope_y"]
    sig = np.array([0.5, 0.5, 0.3, 0.3, 0.1, 1e-3, 2e-3, 5e-5, 3e-4, 1e-4, 0.1, 0.1, 0.2, 2e-3, 2e-3, 1e-3, 0.05,
                    0.01, 0.01])
    A = rng.normal(size=(len(names), len(names)))
    C = A @ A.T / len(names) + 0.2 * np.eye(len(names))
    C = C / np.sqrt(np.outer(np.diag(C), np.diag(C)))  # correlation matrix
    cov = C * np.outer(sig, sig)
    d = base.to_dict()
    d["covariance"] = {"names": names, "matrix": cov.tolist()}
    return ErrorBudget.from_dict(d)


def _budgets(rng):
    basler = ErrorBudget.preset("basler1")
    everything = basler.replace(roll_deg=0.05, ground_height_m=0.05, ground_slope_deg=0.5, pan_deg=0.05,
                                tilt_deg=0.05)
    return {"basler1": basler, "all sources": everything, "full covariance": _full_budget(rng, everything),
            "one source": ErrorBudget(height_m=0.2), "pixel noise only": ErrorBudget(imaging_px=(0.3, 0.2))}


# ---------------------------------------------------------------------------------------------
# closed-form (pan-tilt) kernel
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(4))
def test_pantilt_map_matches_propagate(seed):
    rng = np.random.default_rng(SEED + seed)
    cam = _random_pantilt(rng)
    for name, budget in _budgets(rng).items():
        got = covariance_map(cam, budget)
        ref = propagate(cam, budget, cam.pixel_grid(1))
        assert got[0].shape == (41, 64, 2) and got[1].shape == (41, 64, 2, 2) and got[2].shape == (41, 64)
        _assert_same(got, ref)
        assert got[2].any(), name


def test_pantilt_map_wide_angle():
    """|x_n| up to ~2: the per-row polynomials (degree 14 with distortion) keep their precision."""
    rng = np.random.default_rng(SEED + 10)
    for _ in range(3):
        cam = PanTiltCamera(rng.uniform(0.25, 0.4) * 96, (96, 60), rng.uniform(3, 20), rng.uniform(-180, 180),
                            rng.uniform(30, 80), roll_deg=rng.uniform(-30, 30))
        budget = _budgets(rng)["full covariance"]
        _assert_same(covariance_map(cam, budget), propagate(cam, budget, cam.pixel_grid(1)))


def test_empty_budget_gives_zero_covariance():
    cam = PanTiltCamera(50, (32, 20), 5, 0, 30)
    xy, cov, valid = covariance_map(cam, ErrorBudget())
    assert valid.all() and np.all(cov == 0)
    np.testing.assert_allclose(xy, cam.backproject(cam.pixel_grid(1)).xy_world_m, rtol=1e-12)


def test_pantilt_map_horizon_in_view_and_steps():
    # tilt 2 deg, f = 60 px: the horizon crosses the image; cy = 20 exactly on a grid row
    cam = PanTiltCamera(60, (64, 41), 8, 45, 2, roll_deg=7)
    budget = ErrorBudget.preset("basler1").replace(ground_slope_deg=1.0)
    for step in (1, 2, 5):
        got = covariance_map(cam, budget, step_px=step)
        ref = propagate(cam, budget, cam.pixel_grid(step))
        _assert_same(got, ref)
        assert 0 < got[2].sum() < got[2].size
    # tilt 0, no roll: the principal row (v = cy = 20) is exactly on the horizon
    cam0 = PanTiltCamera(60, (64, 41), 8, 45, 0)
    xy, cov, valid = covariance_map(cam0, budget)
    assert not valid[:21].any() and valid[21:].all()
    assert np.isnan(xy[20]).all() and np.isnan(cov[20]).all()
    _assert_same((xy, cov, valid), propagate(cam0, budget, cam0.pixel_grid(1)))


def test_kernel_handles_nominal_ground_perturbations():
    """Nominal ground offset/slope in the parameter vector (not reachable by the constructors)."""
    rng = np.random.default_rng(SEED + 20)
    cam = _random_pantilt(rng)
    cam.params[[P.GDZ, P.GSX, P.GSY]] = 0.4, 0.02, -0.03
    for budget in _budgets(rng).values():
        _assert_same(covariance_map(cam, budget), propagate(cam, budget, cam.pixel_grid(1)))


def test_undistorted_opencv_camera_uses_closed_form_kernel():
    rng = np.random.default_rng(SEED + 21)
    cam = _random_pantilt(rng)
    T = cam.T_cam_world
    K = cam.K.copy()
    K[0, 1] = 0.7
    K[1, 1] *= 1.02
    oc = OpenCVCamera(K, None, T[:3, :3], T[:3, 3], cam.image_size_px)
    for budget in _budgets(rng).values():
        _assert_same(covariance_map(oc, budget), propagate(oc, budget, oc.pixel_grid(1)))


def test_map_matches_finite_difference_covariance():
    """Independent check: J from central differences of backproject_with, Cov = J S J^T + J_uv S_uv J_uv^T."""
    rng = np.random.default_rng(SEED + 30)
    cam = _random_pantilt(rng)
    budget = _budgets(rng)["full covariance"]
    xy, cov, valid = covariance_map(cam, budget, step_px=9)
    uv = cam.pixel_grid(9)[valid]
    S = budget.param_covariance()
    Juv = np.empty(uv.shape[:-1] + (2, 2))
    Jp = np.empty(uv.shape[:-1] + (2, P.N_PARAMS))
    for k in range(P.N_PARAMS):
        h = 1e-6 * max(abs(cam.params[k]), 1.0)
        dp = np.zeros(P.N_PARAMS)
        dp[k] = h
        Jp[..., k] = (cam.backproject_with(cam.params + dp, uv).xy_world_m
                      - cam.backproject_with(cam.params - dp, uv).xy_world_m) / (2 * h)
    for k in range(2):
        du = np.zeros(2)
        du[k] = 1e-4
        Juv[..., k] = (cam.backproject_with(cam.params, uv + du).xy_world_m
                       - cam.backproject_with(cam.params, uv - du).xy_world_m) / 2e-4
    ref = Jp @ S @ np.swapaxes(Jp, -1, -2) + Juv @ budget.pixel_covariance() @ np.swapaxes(Juv, -1, -2)
    sd = np.sqrt(ref[:, [0, 1], [0, 1]])
    err = np.abs(cov[valid] - ref) / (sd[:, :, None] * sd[:, None, :])
    assert err.max() < 1e-5


# ---------------------------------------------------------------------------------------------
# OpenCV kernel with distortion
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(3))
def test_opencv_map_matches_propagate(seed):
    rng = np.random.default_rng(SEED + 40 + seed)
    cam = _random_opencv(rng)
    assert np.any(cam.dist)
    for budget in _budgets(rng).values():
        for step in (1, 3):
            _assert_same(covariance_map(cam, budget, step_px=step), propagate(cam, budget, cam.pixel_grid(step)))


def test_opencv_map_with_horizon_and_larger_grid():
    rng = np.random.default_rng(SEED + 50)
    cam = PanTiltCamera(300, (320, 200), 6, 20, 4, roll_deg=3)
    T = cam.T_cam_world
    oc = OpenCVCamera(cam.K, [-0.15, 0.03, 1e-3, -5e-4, 0.002], T[:3, :3], T[:3, 3], cam.image_size_px)
    budget = _budgets(rng)["full covariance"]
    got = covariance_map(oc, budget)
    _assert_same(got, propagate(oc, budget, oc.pixel_grid(1)))
    assert 0 < got[2].sum() < got[2].size


# ---------------------------------------------------------------------------------------------
# scattered points
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("make", [_random_pantilt, _random_opencv])
def test_covariance_points_matches_propagate(make):
    rng = np.random.default_rng(SEED + 60)
    cam = make(rng)
    budget = _budgets(rng)["full covariance"]
    uv = rng.uniform([-5, -5], [70, 46], (3, 50, 2))
    A = rng.normal(size=(3, 50, 2, 2))
    pc = A @ np.swapaxes(A, -1, -2) * 0.5
    got = covariance_points(cam, budget, uv, pixel_cov_px2=pc)
    assert got[0].shape == (3, 50, 2) and got[1].shape == (3, 50, 2, 2) and got[2].shape == (3, 50)
    _assert_same(got, propagate(cam, budget, uv, pixel_cov_px2=pc))
    # one shared detector covariance, single point, NaN row
    one = covariance_points(cam, budget, [30.0, 35.0], pixel_cov_px2=np.eye(2))
    assert one[0].shape == (2,) and one[1].shape == (2, 2) and one[2].shape == ()
    _assert_same(one, propagate(cam, budget, [30.0, 35.0], pixel_cov_px2=np.eye(2)))
    bad = covariance_points(cam, budget, [[30.0, 35.0], [np.nan, 3.0]])
    np.testing.assert_array_equal(bad[2], [True, False])
    assert np.isnan(bad[0][1]).all() and np.isfinite(bad[0][0]).all()


# ---------------------------------------------------------------------------------------------
# API details and bad input
# ---------------------------------------------------------------------------------------------
def test_out_arrays_are_filled_in_place():
    cam = PanTiltCamera(50, (32, 20), 5, 0, 30)
    out = (np.full((20, 32, 2), 7.0), np.full((20, 32, 2, 2), 7.0), np.zeros((20, 32), bool))
    res = covariance_map(cam, "basler1", out=out)
    assert all(a is b for a, b in zip(res, out, strict=True))
    _assert_same(out, propagate(cam, "basler1", cam.pixel_grid(1)))
    out3 = (np.empty((7, 11, 2)), np.empty((7, 11, 2, 2)), np.empty((7, 11), bool))
    covariance_map(cam, "basler1", step_px=3, out=out3)  # ceil(20/3) x ceil(32/3)


@pytest.mark.parametrize("out, field", [
    ((np.empty((20, 32, 2)), np.empty((20, 32, 2, 2))), "out"),
    ((np.empty((20, 31, 2)), np.empty((20, 32, 2, 2)), np.empty((20, 32), bool)), "out[0] (xy_world_m)"),
    ((np.empty((20, 32, 2)), np.empty((20, 32, 2, 2), np.float32), np.empty((20, 32), bool)), "out[1] (cov_m2)"),
    ((np.empty((20, 32, 2)), np.empty((20, 32, 2, 2)), np.empty((20, 32))), "out[2] (valid)"),
])
def test_bad_out_names_the_field(out, field):
    cam = PanTiltCamera(50, (32, 20), 5, 0, 30)
    with pytest.raises(InputError) as e:
        covariance_map(cam, "basler1", out=out)
    assert e.value.field == field


@pytest.mark.parametrize("step", [0, -1, 1.5, "a"])
def test_bad_step(step):
    cam = PanTiltCamera(50, (32, 20), 5, 0, 30)
    with pytest.raises(InputError) as e:
        covariance_map(cam, "basler1", step_px=step)
    assert e.value.field == "step_px"


def test_bad_points_input():
    cam = PanTiltCamera(50, (32, 20), 5, 0, 30)
    with pytest.raises(InputError) as e:
        covariance_points(cam, "basler1", np.zeros((4, 3)))
    assert e.value.field == "uv_px"
    with pytest.raises(InputError) as e:
        covariance_points(cam, "basler1", np.zeros((4, 2)), pixel_cov_px2=-np.eye(2))
    assert e.value.field == "pixel_cov_px2"
