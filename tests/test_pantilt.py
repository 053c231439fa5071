"""The paper's pan-tilt closed form: equations, Table-1 partials, PanTiltCamera.backproject."""

import numpy as np
import pytest

from footprint_uq import InputError, PanTiltCamera, status
from footprint_uq import params as P
from footprint_uq.cameras import general
from footprint_uq.cameras.pantilt import closed_form_backproject, paper_partials, paper_xy

RNG_SEED = 20261121


def _random_paper_args(rng, n):
    """Points well below the horizon: f, c, r, h, alpha, theta."""
    f = rng.uniform(600, 3000, n)
    theta = rng.uniform(np.deg2rad(8), np.deg2rad(80), n)
    c = rng.uniform(-0.5, 0.5, n) * f
    # rows between 0.3 f above the boresight (but below the horizon) and 0.6 f below
    r_min = np.maximum(-0.3 * f, -np.tan(theta) * f * 0.7)
    r = rng.uniform(r_min, 0.6 * f)
    h = rng.uniform(2, 40, n)
    alpha = rng.uniform(-np.pi, np.pi, n)
    return f, c, r, h, alpha, theta


def _random_camera(rng, roll=True):
    return PanTiltCamera(
        focal_px=rng.uniform(600, 3000), image_size_px=(640, 480), height_m=rng.uniform(3, 30),
        pan_deg=rng.uniform(-180, 180), tilt_deg=rng.uniform(10, 70),
        roll_deg=rng.uniform(-20, 20) if roll else 0.0, position_m=rng.normal(0, 100, 2),
        principal_point_px=(rng.uniform(300, 340), rng.uniform(220, 260)))


def _rel_col_err(a, b):
    """Worst error of each Jacobian column, relative to the column's 2-vector norm at that point."""
    scale = np.linalg.norm(b, axis=-2, keepdims=True)
    scale = np.where(scale > 0, scale, 1.0)
    return (np.abs(a - b) / scale).max(axis=tuple(range(a.ndim - 1)))


# ---------------------------------------------------------------------------------------------
# the paper's equations and Table-1 partials
# ---------------------------------------------------------------------------------------------
def test_paper_partials_match_central_differences():
    rng = np.random.default_rng(RNG_SEED)
    args = _random_paper_args(rng, 400)
    part = paper_partials(*args)
    names = ["f", "c", "r", "h", "alpha", "theta"]
    steps = {"f": 1e-3, "c": 1e-3, "r": 1e-3, "h": 1e-5, "alpha": 1e-7, "theta": 1e-7}
    for i, name in enumerate(names):
        a_p = list(args)
        a_m = list(args)
        a_p[i] = args[i] + steps[name]
        a_m[i] = args[i] - steps[name]
        Xp, Yp, vp = paper_xy(*a_p)
        Xm, Ym, vm = paper_xy(*a_m)
        assert vp.all() and vm.all()
        fd = np.stack([(Xp - Xm), (Yp - Ym)], -1) / (2 * steps[name])
        an = np.stack(part[name], -1)
        scale = np.linalg.norm(an, axis=-1)
        worst = (np.linalg.norm(fd - an, axis=-1) / scale).max()
        assert worst < 1e-6, (name, worst)
    assert np.all(part["X0"][0] == 1) and np.all(part["Y0"][1] == 1)


def test_paper_partials_match_general_model():
    """Table 1 against the general model's Jacobian (f moves fx and fy together; c, r are u, v)."""
    rng = np.random.default_rng(RNG_SEED + 1)
    for _ in range(5):
        cam = _random_camera(rng, roll=False)
        uv = rng.uniform([0, 0], [640, 480], (300, 2))
        bp = general.backproject(cam.params, uv, get_gradients=True)
        ok = bp.valid
        cx, cy = cam.principal_point_px
        c, r = uv[ok, 0] - cx, uv[ok, 1] - cy
        f, h = cam.focal_px, cam.height_m
        a, t = np.deg2rad(cam.pan_deg), np.deg2rad(cam.tilt_deg)
        X, Y, valid = paper_xy(f, c, r, h, a, t)
        assert valid.all()
        np.testing.assert_allclose(np.stack([cam.position_m[0] + Y, cam.position_m[1] + X], -1),
                                   bp.xy_world_m[ok], rtol=1e-12, atol=1e-9)
        part = paper_partials(f, c, r, h, a, t)
        J, Juv = bp.dxy_dp[ok], bp.dxy_duv[ok]
        world = {  # paper (dX, dY) -> world (dx, dy) = (dY, dX)
            "f": J[..., P.FX] + J[..., P.FY], "c": Juv[..., 0], "r": Juv[..., 1], "h": J[..., P.HM],
            "alpha": J[..., P.PAN], "theta": J[..., P.TILT], "X0": J[..., P.YM], "Y0": J[..., P.XM],
        }
        for name, ref in world.items():
            got = np.stack([part[name][1], part[name][0]], -1) + np.zeros_like(ref)
            err = np.abs(got - ref).max(-1) / np.maximum(np.linalg.norm(ref, axis=-1), 1e-300)
            assert err.max() < 1e-9, (name, err.max())


# ---------------------------------------------------------------------------------------------
# PanTiltCamera.backproject (closed form) against the general path
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(6))
def test_backproject_matches_general_all_22_columns(seed):
    rng = np.random.default_rng(RNG_SEED + 10 + seed)
    cam = _random_camera(rng)
    uv = rng.uniform([-50, -50], [690, 530], (500, 2))
    a = cam.backproject(uv, get_gradients=True)
    b = general.backproject(cam.params, uv, get_gradients=True)
    np.testing.assert_array_equal(a.valid, b.valid)
    np.testing.assert_array_equal(a.reason, b.reason)
    assert a.valid.sum() > 100
    ok = a.valid
    scale = np.abs(b.xy_world_m[ok] - cam.position_m).max()
    assert np.abs(a.xy_world_m[ok] - b.xy_world_m[ok]).max() <= 1e-9 * scale
    assert a.dxy_dp.shape == (500, 2, P.N_PARAMS)
    col_err = _rel_col_err(a.dxy_dp[ok], b.dxy_dp[ok])
    assert col_err.shape == (P.N_PARAMS,)
    assert col_err.max() < 1e-9, dict(zip(P.PARAM_NAMES, col_err, strict=True))
    assert _rel_col_err(a.dxy_duv[ok], b.dxy_duv[ok]).max() < 1e-9
    assert np.isnan(a.xy_world_m[~ok]).all() and np.isnan(a.dxy_dp[~ok]).all() and np.isnan(a.dxy_duv[~ok]).all()


def test_closed_form_with_fx_fy_skew_matches_general():
    """The closed form accepts any fx, fy, skew (via the parameter vector)."""
    rng = np.random.default_rng(RNG_SEED + 30)
    cam = _random_camera(rng)
    p = cam.params.copy()
    p[P.FY] *= 1.07
    p[P.SKEW] = 2.5
    uv = rng.uniform([0, 0], [640, 480], (400, 2))
    a = closed_form_backproject(p, uv, get_gradients=True)
    b = general.backproject(p, uv, get_gradients=True)
    np.testing.assert_array_equal(a.valid, b.valid)
    ok = a.valid
    assert _rel_col_err(a.dxy_dp[ok], b.dxy_dp[ok]).max() < 1e-9
    assert _rel_col_err(a.dxy_duv[ok], b.dxy_duv[ok]).max() < 1e-9


def test_nonzero_nominal_distortion_falls_back_to_general():
    rng = np.random.default_rng(RNG_SEED + 31)
    cam = _random_camera(rng)
    cam.params[P.K1] = -0.1
    uv = rng.uniform([0, 0], [640, 480], (50, 2))
    a = cam.backproject(uv, get_gradients=True)
    b = general.backproject(cam.params, uv, get_gradients=True)
    np.testing.assert_array_equal(a.xy_world_m, b.xy_world_m)
    np.testing.assert_array_equal(a.dxy_dp, b.dxy_dp)


def test_backproject_with_stays_on_general_path():
    rng = np.random.default_rng(RNG_SEED + 32)
    cam = _random_camera(rng)
    p = cam.params + 0.0
    p[P.K1] = 0.05  # perturbed distortion, as Monte Carlo draws
    uv = rng.uniform([0, 0], [640, 480], (20, 2))
    np.testing.assert_array_equal(cam.backproject_with(p, uv).xy_world_m, general.backproject(p, uv).xy_world_m)


# ---------------------------------------------------------------------------------------------
# pinned hand-checked values
# ---------------------------------------------------------------------------------------------
def test_pinned_boresight_and_off_axis_points():
    # h = 10 m, tilt 45 deg, pan 0 (north), f = 1000 px, principal point (320, 240)
    cam = PanTiltCamera(1000, (641, 481), 10, 0, 45, position_m=(5, 7))
    bp = cam.backproject(np.array([[320.0, 240.0],  # boresight: 45 deg down -> 10 m ahead (north)
                                   [320.0, 1240.0],  # one focal length down: 45 + 45 = 90 deg -> foot point
                                   [1320.0, 240.0]]),  # one focal length right, see below
                         get_gradients=True)
    assert bp.valid.all()
    np.testing.assert_allclose(bp.xy_world_m[0], [5.0, 17.0], atol=1e-12)
    np.testing.assert_allclose(bp.xy_world_m[1], [5.0, 7.0], atol=1e-12)
    # ray (forward cos45, right 1, down sin45) per unit of normalised depth: it descends 10 m after
    # 10 / sin45 = 14.142 units -> forward 14.142 cos45 = 10 m (north), right 14.142 m (east)
    np.testing.assert_allclose(bp.xy_world_m[2], [5.0 + 10 * np.sqrt(2), 17.0], atol=1e-12)
    # boresight distance D = h / tan(tilt): dD/dh = 1 / tan45 = 1; dD/dtilt = -h / sin^2(45) = -20 m/rad
    np.testing.assert_allclose(bp.dxy_dp[0, :, P.HM], [0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(bp.dxy_dp[0, :, P.TILT], [0.0, -20.0], atol=1e-12)
    # pan turns the point about the camera: d(x, y)/d pan = (D, 0) at pan 0 (clockwise towards east)
    np.testing.assert_allclose(bp.dxy_dp[0, :, P.PAN], [10.0, 0.0], atol=1e-12)
    # pan 90 deg (east): boresight lands 10 m east
    cam_e = PanTiltCamera(1000, (641, 481), 10, 90, 45)
    np.testing.assert_allclose(cam_e.backproject([320.0, 240.0]).xy_world_m, [10.0, 0.0], atol=1e-12)


def test_project_ground_round_trip():
    rng = np.random.default_rng(RNG_SEED + 40)
    for _ in range(4):
        cam = _random_camera(rng)
        uv = rng.uniform([0, 0], [640, 480], (200, 2))
        bp = cam.backproject(uv)
        ok = bp.valid
        pr = cam.project_ground(bp.xy_world_m[ok])
        assert pr.valid.all()
        np.testing.assert_allclose(pr.uv_px, uv[ok], atol=1e-8)


# ---------------------------------------------------------------------------------------------
# horizon
# ---------------------------------------------------------------------------------------------
def test_horizon_pixels_are_invalid_never_negative():
    # tilt 0: the horizon is the principal row v = cy = 240 exactly
    cam = PanTiltCamera(800, (641, 481), 6, 30, 0)
    uv = np.array([[100.0, 240.0], [320.0, 240.0], [320.0, 100.0], [320.0, 0.0], [320.0, 240.001], [600.0, 480.0]])
    bp = cam.backproject(uv, get_gradients=True)
    np.testing.assert_array_equal(bp.valid, [False, False, False, False, True, True])
    np.testing.assert_array_equal(bp.reason[:4], status.ABOVE_HORIZON)
    assert np.isnan(bp.xy_world_m[:4]).all() and np.isnan(bp.dxy_dp[:4]).all() and np.isnan(bp.dxy_duv[:4]).all()
    # just below the horizon: very far, but ahead of the camera
    fwd = np.array([np.sin(np.deg2rad(30)), np.cos(np.deg2rad(30))])
    assert bp.xy_world_m[4] @ fwd > 1e5


def test_valid_points_are_ahead_of_the_camera_with_roll():
    rng = np.random.default_rng(RNG_SEED + 50)
    for _ in range(5):
        cam = PanTiltCamera(rng.uniform(300, 900), (640, 480), rng.uniform(3, 20), rng.uniform(-180, 180),
                            rng.uniform(-5, 15), roll_deg=rng.uniform(-30, 30))
        uv = rng.uniform([0, 0], [640, 480], (2000, 2))
        bp = cam.backproject(uv)
        ref = general.backproject(cam.params, uv)
        np.testing.assert_array_equal(bp.valid, ref.valid)
        assert 0 < bp.valid.sum() < uv.shape[0]
        # every valid ground point lies in front of the camera's vertical image plane
        R = cam.R_world_cam
        d = (bp.xy_world_m[bp.valid] - cam.position_m) @ R[:2, 2]
        assert np.all(d > 0)
        assert np.isnan(bp.xy_world_m[~bp.valid]).all()
        assert np.all(bp.reason[~bp.valid] == status.ABOVE_HORIZON)


# ---------------------------------------------------------------------------------------------
# shapes and bad input
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", [(2,), (1, 2), (7, 2), (3, 4, 2)])
def test_batch_shapes(shape):
    cam = PanTiltCamera(1000, (640, 480), 10, 20, 30)
    rng = np.random.default_rng(RNG_SEED + 60)
    uv = rng.uniform(200, 400, shape)
    lead = shape[:-1]
    bp = cam.backproject(uv, get_gradients=True)
    assert bp.xy_world_m.shape == lead + (2,)
    assert bp.valid.shape == lead and bp.reason.shape == lead
    assert bp.dxy_duv.shape == lead + (2, 2)
    assert bp.dxy_dp.shape == lead + (2, P.N_PARAMS)
    flat = cam.backproject(uv.reshape(-1, 2))
    np.testing.assert_array_equal(bp.xy_world_m.reshape(-1, 2), flat.xy_world_m)


def test_nan_pixel_is_reported_and_the_rest_goes_on():
    cam = PanTiltCamera(1000, (640, 480), 10, 20, 30)
    bp = cam.backproject([[320.0, 300.0], [np.nan, 300.0], [330.0, 310.0]], get_gradients=True)
    np.testing.assert_array_equal(bp.valid, [True, False, True])
    assert bp.reason[1] == status.NOT_FINITE
    assert np.isnan(bp.xy_world_m[1]).all() and np.isfinite(bp.xy_world_m[[0, 2]]).all()


@pytest.mark.parametrize("kwargs, field", [
    (dict(focal_px=-1000), "focal_px"),
    (dict(focal_px=np.nan), "focal_px"),
    (dict(height_m=0.0), "height_m"),
    (dict(height_m=-2.0), "height_m"),
    (dict(tilt_deg=np.nan), "tilt_deg"),
    (dict(image_size_px=(640,)), "image_size_px"),
    (dict(position_m=(1.0, np.inf)), "position_m[1]"),
])
def test_bad_camera_input_names_the_field(kwargs, field):
    args = dict(focal_px=1000, image_size_px=(640, 480), height_m=10, pan_deg=0, tilt_deg=30)
    args.update(kwargs)
    with pytest.raises(InputError) as e:
        PanTiltCamera(**args)
    assert e.value.field == field


@pytest.mark.parametrize("uv", [np.zeros(3), np.zeros((4, 3)), 5.0])
def test_bad_pixel_shape_names_the_field(uv):
    cam = PanTiltCamera(1000, (640, 480), 10, 20, 30)
    with pytest.raises(InputError) as e:
        cam.backproject(uv)
    assert e.value.field == "uv_px"
