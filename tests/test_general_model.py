"""The reference camera path (footprint_uq.cameras.general): Jacobians, round trips, validity, shapes."""

from __future__ import annotations

import numpy as np
import pytest

from footprint_uq import params as P
from footprint_uq import status
from footprint_uq.cameras import general
from footprint_uq.cameras.distortion import distort, undistort
from footprint_uq.cameras.pinhole import normalised_to_pixel, pixel_to_normalised
from footprint_uq.cameras.rotation import R_W_C

N_CAMERAS = 10
N_PIXELS = 16


def _steps(p):
    """Central-difference steps: 1e-6 of each parameter's natural scale."""
    typical = np.ones(P.N_PARAMS)
    typical[[P.FX, P.FY, P.CX, P.CY, P.SKEW]] = 1000.0
    return 1e-6 * np.maximum(np.abs(p), typical)


def _ground_xyz(p, xy):
    """World point (z from the nominal ground) on the perturbed ground plane of ``p`` at ``xy``."""
    z = p[P.GDZ] + p[P.GSX] * (xy[..., 0] - p[P.XM]) + p[P.GSY] * (xy[..., 1] - p[P.YM])
    return np.concatenate([xy, z[..., None]], -1)


def _simple_params(f=1000.0, h=10.0, pan_deg=0.0, tilt_deg=45.0, x0=0.0, y0=0.0):
    p = np.zeros(P.N_PARAMS)
    p[[P.FX, P.FY, P.CX, P.CY]] = f, f, 960.0, 540.0
    p[[P.XM, P.YM, P.HM]] = x0, y0, h
    p[[P.PAN, P.TILT]] = np.deg2rad([pan_deg, tilt_deg])
    return p


# --------------------------------------------------------------------------- Jacobians
def test_backproject_param_jacobian_all_22_columns(rng, random_params, ground_pixels, central_diff, rel_err):
    worst = np.zeros(P.N_PARAMS)
    for _ in range(N_CAMERAS):
        p = random_params(rng, distortion="strong")
        uv, _ = ground_pixels(rng, p, N_PIXELS)
        bp = general.backproject(p, uv, get_gradients=True)
        assert bp.valid.all(), bp.reason
        assert bp.dxy_dp.shape == (N_PIXELS, 2, P.N_PARAMS)
        fd = central_diff(lambda q, uv=uv: general.backproject(q, uv).xy_world_m, p, _steps(p))
        worst = np.maximum(worst, rel_err(fd, bp.dxy_dp, per_column=True))
    # every column is exercised (non-zero) with this camera family
    assert np.all(np.isfinite(worst)), dict(zip(P.PARAM_NAMES, worst, strict=True))
    # measured worst ~3e-8 (k3); central differences with 1e-6 relative steps are good to ~1e-8
    assert worst.max() < 1e-6, dict(zip(P.PARAM_NAMES, worst, strict=True))


def test_backproject_pixel_jacobian(rng, random_params, ground_pixels, central_diff, rel_err):
    worst = 0.0
    for _ in range(N_CAMERAS):
        p = random_params(rng, distortion="strong")
        uv, _ = ground_pixels(rng, p, N_PIXELS)
        bp = general.backproject(p, uv, get_gradients=True)
        assert bp.dxy_duv.shape == (N_PIXELS, 2, 2)
        fd = central_diff(lambda q, p=p: general.backproject(p, q).xy_world_m, uv, [1e-4, 1e-4])
        worst = max(worst, rel_err(fd, bp.dxy_duv, per_column=True).max())
    assert worst < 1e-6


def test_project_jacobians(rng, random_params, ground_pixels, central_diff, rel_err):
    worst_p = np.zeros(P.N_PARAMS)
    worst_x = 0.0
    for _ in range(N_CAMERAS):
        p = random_params(rng, distortion="strong")
        uv, _ = ground_pixels(rng, p, N_PIXELS)
        X = _ground_xyz(p, general.backproject(p, uv).xy_world_m)
        X[:, 2] += rng.uniform(0.0, 2.0, N_PIXELS)  # points above the ground too
        pr = general.project(p, X, get_gradients=True)
        assert pr.valid.all()
        assert pr.duv_dp.shape == (N_PIXELS, 2, P.N_PARAMS) and pr.duv_dxyz.shape == (N_PIXELS, 2, 3)
        # the ground parameters do not enter a projection
        assert np.all(pr.duv_dp[..., P.GDZ:P.GSY + 1] == 0.0)
        fd = central_diff(lambda q, X=X: general.project(q, X).uv_px, p, _steps(p))
        cols = np.r_[0:P.GDZ]
        worst_p[cols] = np.maximum(worst_p[cols], rel_err(fd[..., cols], pr.duv_dp[..., cols], per_column=True))
        fdx = central_diff(lambda q, p=p: general.project(p, q).uv_px, X, [1e-5] * 3)
        worst_x = max(worst_x, rel_err(fdx, pr.duv_dxyz, per_column=True).max())
    assert worst_p.max() < 1e-6, dict(zip(P.PARAM_NAMES, worst_p, strict=True))
    assert worst_x < 1e-6


def test_backproject_jacobian_is_inverse_of_projection(rng, random_params, ground_pixels):
    """On the (unperturbed, flat) ground, dxy/duv is the inverse of duv/dxy."""
    p = random_params(rng, ground=False)
    uv, _ = ground_pixels(rng, p, N_PIXELS)
    bp = general.backproject(p, uv, get_gradients=True)
    X = np.concatenate([bp.xy_world_m, np.zeros((N_PIXELS, 1))], -1)
    pr = general.project(p, X, get_gradients=True)
    prod = bp.dxy_duv @ pr.duv_dxyz[..., :2]
    np.testing.assert_allclose(prod, np.broadcast_to(np.eye(2), prod.shape), atol=1e-9)


# --------------------------------------------------------------------------- round trips and accuracy
def test_undistortion_redistorts_to_the_pixel(rng, random_params, ground_pixels):
    for _ in range(N_CAMERAS):
        p = random_params(rng, distortion="strong")
        uv, xn_true = ground_pixels(rng, p, 64)
        xd = pixel_to_normalised(uv, *p[:5])
        xn, conv = undistort(xd, p[P.DIST_SLICE])
        assert conv.all()
        uv2 = normalised_to_pixel(distort(xn, p[P.DIST_SLICE]), *p[:5])
        assert np.abs(uv2 - uv).max() < 1e-10
        assert np.abs(xn - xn_true).max() < 1e-12


def test_backproject_then_project_round_trip(rng, random_params, ground_pixels):
    for _ in range(N_CAMERAS):
        p = random_params(rng, distortion="strong")
        uv, _ = ground_pixels(rng, p, 64)
        xy = general.backproject(p, uv).xy_world_m
        uv2 = general.project(p, _ground_xyz(p, xy)).uv_px
        assert np.abs(uv2 - uv).max() < 1e-9  # px; the ray is recomputed from 100 m away


def test_pinned_hand_checked_values():
    # f = 1000 px, principal point (960, 540), camera at (0, 0), height 10 m, looking north, 45 deg down.
    # * principal point: boresight (0, cos45, -sin45) meets the ground 10 m north -> (0, 10).
    # * (960, 1540): 45 deg below the boresight = straight down -> the foot point (0, 0).
    # * (1960, 540): camera ray (1, 0, 1) -> world (1, cos45, -sin45) (right = east when facing north);
    #   lambda = 10 / sin45 = 14.142 -> (14.142, 10).
    # * dx/du at the principal point = range along the boresight / f = (10 / sin45) / 1000 = 0.014142 m/px;
    #   dy/dv = -h / (f sin^2 45) = -10 / (1000 * 0.5) = -0.02 m/px (a lower pixel is nearer).
    p = _simple_params()
    bp = general.backproject(p, [[960.0, 540.0], [960.0, 1540.0], [1960.0, 540.0]], get_gradients=True)
    np.testing.assert_allclose(bp.xy_world_m, [[0.0, 10.0], [0.0, 0.0], [10 * np.sqrt(2), 10.0]], atol=1e-12)
    np.testing.assert_allclose(bp.dxy_duv[0], [[0.01 * np.sqrt(2), 0.0], [0.0, -0.02]], atol=1e-15)
    # pan 90 deg = looking east: the principal point is 10 m east of the camera at (5, -3)
    bp = general.backproject(_simple_params(pan_deg=90.0, x0=5.0, y0=-3.0), [960.0, 540.0])
    np.testing.assert_allclose(bp.xy_world_m, [15.0, -3.0], atol=1e-12)
    # ground raised by 1 m: effective height 9 m -> 9 m ahead; slope dz/dy = 0.1 with the ray
    # (0, 1, -1): z = 10 - t = 0.1 t -> t = 10 / 1.1 -> y = 9.0909
    q = _simple_params()
    q[P.GDZ] = 1.0
    np.testing.assert_allclose(general.backproject(q, [960.0, 540.0]).xy_world_m, [0.0, 9.0], atol=1e-12)
    q = _simple_params()
    q[P.GSY] = 0.1
    np.testing.assert_allclose(general.backproject(q, [960.0, 540.0]).xy_world_m, [0.0, 10 / 1.1], atol=1e-12)


# --------------------------------------------------------------------------- validity
def test_above_horizon_flagged_and_never_negative_distance(rng, random_params):
    """Over whole images: valid points lie in front of the camera, invalid ones are NaN with a code."""
    grid = np.stack(np.meshgrid(np.arange(0, 1920, 40.0), np.arange(0, 1080, 40.0)), -1)
    seen_invalid = 0
    for _ in range(N_CAMERAS):
        p = random_params(rng, distortion="mild", tilt_deg=(2.0, 20.0))
        bp = general.backproject(p, grid, get_gradients=True)
        v = bp.valid
        assert v.any() and (~v).any()
        seen_invalid += (~v).sum()
        assert np.all(np.isnan(bp.xy_world_m[~v])) and np.all(np.isnan(bp.dxy_dp[~v]))
        assert np.all(np.isnan(bp.dxy_duv[~v]))
        assert np.all(bp.reason[~v] == status.ABOVE_HORIZON) and np.all(bp.reason[v] == status.OK)
        assert np.all(np.isfinite(bp.xy_world_m[v])) and np.all(np.isfinite(bp.dxy_dp[v]))
        # the ground point lies along the ray's horizontal direction (positive distance)
        xd = pixel_to_normalised(grid, *p[:5])
        xn, _ = undistort(xd, p[P.DIST_SLICE])
        ray = (R_W_C(p[P.PAN], p[P.TILT], p[P.ROLL]) @ np.concatenate([xn, np.ones(xn.shape[:-1] + (1,))],
                                                                        -1)[..., None])[..., 0]
        along = np.sum((bp.xy_world_m - p[P.XM:P.YM + 1]) * ray[..., :2], -1)
        assert np.all(along[v] > 0)
        # every invalid pixel's ray points at or above the (perturbed) horizon
        dn = ray[..., 2] - p[P.GSX] * ray[..., 0] - p[P.GSY] * ray[..., 1]
        assert np.all(dn[~v & np.isfinite(dn)] >= 0) and np.all(dn[v] < 0)
    assert seen_invalid > 100


def test_camera_looking_up_and_camera_under_ground():
    p = _simple_params(tilt_deg=-30.0)  # looking up: half of the image far above the horizon
    bp = general.backproject(p, [[960.0, 540.0], [960.0, 0.0]])
    assert not bp.valid.any() and np.isnan(bp.xy_world_m).all()
    assert np.all(bp.reason == status.ABOVE_HORIZON)
    q = _simple_params()
    q[P.GDZ] = 10.5  # the perturbed ground is above the camera: no intersection in front of it
    bp = general.backproject(q, [960.0, 540.0])
    assert not bp.valid and np.isnan(bp.xy_world_m).all()


def test_exact_horizon_is_invalid():
    p = _simple_params(tilt_deg=0.0)  # the principal point's ray is horizontal
    bp = general.backproject(p, [[960.0, 540.0], [960.0, 541.0]])
    assert bp.valid.tolist() == [False, True]
    assert bp.reason[0] == status.ABOVE_HORIZON
    # 1 px below the horizon: 1000 m * 10 m / 1 m ... = h f / dv = 10 * 1000 / 1 = 10 km ahead
    np.testing.assert_allclose(bp.xy_world_m[1], [0.0, 10_000.0], rtol=1e-9)


def test_projection_behind_camera():
    p = _simple_params()  # looking north from (0, 0, 10)
    pr = general.project(p, [[0.0, 20.0, 0.0], [0.0, -20.0, 0.0], [0.0, 0.0, 10.0]], get_gradients=True)
    assert pr.valid.tolist() == [True, False, False]
    assert pr.reason.tolist() == [status.OK, status.BEHIND_CAMERA, status.BEHIND_CAMERA]
    assert np.isnan(pr.uv_px[1:]).all() and np.isnan(pr.duv_dp[1:]).all() and np.isnan(pr.duv_dxyz[1:]).all()
    assert np.isfinite(pr.duv_dp[0]).all()


def test_nan_and_inf_input_flagged_not_finite(rng, random_params, ground_pixels):
    p = random_params(rng)
    uv, _ = ground_pixels(rng, p, 4)
    uv[1, 0] = np.nan
    uv[2, 1] = np.inf
    bp = general.backproject(p, uv, get_gradients=True)
    assert bp.valid.tolist() == [True, False, False, True]
    assert bp.reason.tolist() == [status.OK, status.NOT_FINITE, status.NOT_FINITE, status.OK]
    assert np.isnan(bp.xy_world_m[1:3]).all() and np.isnan(bp.dxy_dp[1:3]).all()
    # the good rows are untouched by the bad ones
    np.testing.assert_array_equal(bp.xy_world_m[[0, 3]], general.backproject(p, uv[[0, 3]]).xy_world_m)
    q = p.copy()
    q[P.TILT] = np.nan
    bq = general.backproject(q, uv[0])
    assert not bq.valid and bq.reason == status.NOT_FINITE
    pr = general.project(p, [[np.nan, 1.0, 0.0], [1.0, 1e3, 0.0]])
    assert pr.reason[0] == status.NOT_FINITE and np.isnan(pr.uv_px[0]).all()


def test_undistortion_failure_flagged():
    p = _simple_params()
    p[P.K1] = -0.5  # barrel: r_d = r (1 - 0.5 r^2) folds at r = 0.816, r_d max = 0.544
    # 0.3 normalised (300 px) below the centre is invertible; 0.7 (700 px) is beyond the fold;
    # at r_d = 2 the cubic has a root at r = -2 (the opposite side): it must not be taken
    uv = [[960.0, 840.0], [960.0, 1240.0], [1660.0, 540.0], [960.0, 2540.0]]
    bp = general.backproject(p, uv, get_gradients=True)
    assert bp.valid.tolist() == [True, False, False, False]
    assert bp.reason.tolist() == [status.OK] + [status.UNDISTORT_FAILED] * 3
    assert np.isnan(bp.xy_world_m[1:]).all() and np.isnan(bp.dxy_duv[1:]).all()


def test_projection_past_the_lens_fold_is_flagged():
    """A ground point 70 deg off-axis would map through k1 = -0.35 to the opposite side of the image.

    x_n = tan 70 = 2.75 -> r_d = 2.75 (1 - 0.35 * 2.75^2) = -4.5: the 'pixel' is meaningless.
    """
    p = _simple_params(tilt_deg=0.0)
    p[P.K1] = -0.35
    X = np.array([[10 * np.tan(np.deg2rad(70.0)), 10.0, 10.0], [1.0, 10.0, 9.0]])  # 70 deg right; near axis
    pr = general.project(p, X, get_gradients=True)
    assert pr.valid.tolist() == [False, True]
    assert pr.reason.tolist() == [status.UNDISTORT_FAILED, status.OK]
    assert np.isnan(pr.uv_px[0]).all() and np.isnan(pr.duv_dp[0]).all()
    # without the lens model the same point is an ordinary (if far off-image) projection
    q = p.copy()
    q[P.K1] = 0.0
    np.testing.assert_allclose(general.project(q, X[0]).uv_px, [960.0 + 1000 * np.tan(np.deg2rad(70.0)), 540.0])


# --------------------------------------------------------------------------- shapes and broadcasting
@pytest.mark.parametrize("shape", [(), (1,), (7,), (3, 5)])
def test_batch_shapes(rng, random_params, ground_pixels, shape):
    p = random_params(rng)
    n = int(np.prod(shape))
    uv_flat, _ = ground_pixels(rng, p, max(n, 1))
    uv = uv_flat[:max(n, 1)].reshape(shape + (2,))
    bp = general.backproject(p, uv, get_gradients=True)
    assert bp.xy_world_m.shape == shape + (2,)
    assert bp.valid.shape == shape and bp.reason.shape == shape
    assert bp.dxy_duv.shape == shape + (2, 2) and bp.dxy_dp.shape == shape + (2, P.N_PARAMS)
    ref = general.backproject(p, uv_flat[:max(n, 1)], get_gradients=True)
    np.testing.assert_array_equal(bp.xy_world_m.reshape(-1, 2), ref.xy_world_m)
    np.testing.assert_array_equal(bp.dxy_dp.reshape(-1, 2, P.N_PARAMS), ref.dxy_dp)
    X = _ground_xyz(p, bp.xy_world_m)
    pr = general.project(p, X, get_gradients=True)
    assert pr.uv_px.shape == shape + (2,) and pr.duv_dp.shape == shape + (2, P.N_PARAMS)
    assert pr.duv_dxyz.shape == shape + (2, 3)


def test_params_broadcast_against_pixels(rng, random_params, ground_pixels):
    """params (M, 1, 22) with uv (1, N, 2) -> (M, N); each camera row equals its own call."""
    M, N = 4, 6
    ps = np.stack([random_params(rng, distortion="strong") for _ in range(M)])
    ps[:, P.TILT] = np.deg2rad(35.0)  # all cameras see the same pixels below the horizon
    ps[:, P.ROLL] = 0.0
    uv, _ = ground_pixels(rng, ps[0], N, min_depression_deg=10.0, box=(0.4, 0.3))
    bp = general.backproject(ps[:, None, :], uv[None, :, :], get_gradients=True)
    assert bp.xy_world_m.shape == (M, N, 2) and bp.dxy_dp.shape == (M, N, 2, P.N_PARAMS)
    assert bp.dxy_duv.shape == (M, N, 2, 2)
    for m in range(M):
        one = general.backproject(ps[m], uv, get_gradients=True)
        np.testing.assert_allclose(bp.xy_world_m[m], one.xy_world_m, rtol=0, atol=1e-12)
        np.testing.assert_allclose(bp.dxy_dp[m], one.dxy_dp, rtol=1e-12, atol=1e-15)
        np.testing.assert_array_equal(bp.valid[m], one.valid)
    pr = general.project(ps[:, None, :], np.concatenate([bp.xy_world_m, np.zeros((M, N, 1))], -1),
                         get_gradients=True)
    assert pr.uv_px.shape == (M, N, 2) and pr.duv_dp.shape == (M, N, 2, P.N_PARAMS)


def test_camera_methods_accept_single_points_and_reject_bad_shapes(random_opencv_camera, rng):
    from footprint_uq.errors import InputError

    cam = random_opencv_camera(rng, distortion="mild")
    assert cam.backproject([960.0, 900.0]).xy_world_m.shape == (2,)
    assert cam.backproject([[960.0, 900.0]]).xy_world_m.shape == (1, 2)
    with pytest.raises(InputError, match="uv_px"):
        cam.backproject([1.0, 2.0, 3.0])
    with pytest.raises(InputError, match="xyz_world_m"):
        cam.project([1.0, 2.0])
    with pytest.raises(InputError, match="uv_px"):
        cam.backproject("960, 900")
    with pytest.raises(InputError, match="uv_px"):
        cam.backproject([[960.0, "a"]])
