"""OpenCVCamera: agreement with real OpenCV, conversions to and from the pan-tilt model, bad input."""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from footprint_uq import ConsistencyWarning, InputError, OpenCVCamera, PanTiltCamera
from footprint_uq import params as P
from footprint_uq.cameras import general

IMAGE = (1920, 1080)


def _pantilt(**kw):
    args = dict(focal_px=1200.0, image_size_px=IMAGE, height_m=8.0, pan_deg=135.0, tilt_deg=25.0, roll_deg=3.0,
                position_m=(10.0, -5.0), principal_point_px=(955.0, 545.0), ground_z_m=2.0)
    args.update(kw)
    return PanTiltCamera(**args)


def _ground_world_points(rng, cam, n):
    """World points (x, y, z) on and above the camera's ground plane, in view."""
    uv = np.stack([rng.uniform(100, 1820, 4 * n), rng.uniform(600, 1000, 4 * n)], -1)
    xy = cam.backproject(uv).xy_world_m
    xy = xy[np.isfinite(xy).all(-1)][:n]
    z = cam.ground_z_m + rng.uniform(0.0, 2.0, len(xy))
    return np.concatenate([xy, z[:, None]], -1)


@pytest.mark.parametrize("distortion", ["mild", "strong"])
def test_project_matches_cv2_project_points(rng, random_opencv_camera, distortion):
    for ground_z_m in (0.0, 37.5):
        cam = random_opencv_camera(rng, distortion=distortion, ground_z_m=ground_z_m)
        X = _ground_world_points(rng, cam, 50)
        assert len(X) == 50
        rvec = cv2.Rodrigues(cam.R)[0]
        n = 8 if distortion == "strong" else 5
        ref = cv2.projectPoints(X, rvec, cam.t, cam.K, cam.dist[:n])[0][:, 0, :]
        pr = cam.project(X)
        assert pr.valid.all()
        np.testing.assert_allclose(pr.uv_px, ref, rtol=0, atol=1e-8)


def test_skew_follows_the_K_matrix(rng):
    # OpenCV's projectPoints ignores K[0, 1]; we honour it: u = fx x + skew y + cx.
    K = np.array([[1000.0, 4.0, 960.0], [0.0, 1010.0, 540.0], [0.0, 0.0, 1.0]])
    cam = OpenCVCamera(K, None, np.eye(3) @ np.diag([1.0, -1.0, -1.0]), [0.0, 0.0, 10.0], IMAGE)
    # camera looking straight down from 10 m (R = diag(1, -1, -1)): world (2, -3, 0) is camera (2, 3, 10)
    # -> normalised (0.2, 0.3) -> u = 1000 * 0.2 + 4 * 0.3 + 960 = 1161.2, v = 1010 * 0.3 + 540 = 843
    np.testing.assert_allclose(cam.project([2.0, -3.0, 0.0]).uv_px, [1161.2, 843.0], atol=1e-9)
    np.testing.assert_allclose(cam.backproject([1161.2, 843.0]).xy_world_m, [2.0, -3.0], atol=1e-12)


def test_backproject_project_round_trip_with_ground_height(rng, random_opencv_camera):
    cam = random_opencv_camera(rng, distortion="strong", ground_z_m=-12.0)
    X = _ground_world_points(rng, cam, 30)
    X[:, 2] = cam.ground_z_m
    uv = cam.project(X).uv_px
    np.testing.assert_allclose(cam.backproject(uv).xy_world_m, X[:, :2], rtol=0, atol=1e-9)
    pg = cam.project_ground(X[:, :2], get_gradients=True)
    np.testing.assert_allclose(pg.uv_px, uv, atol=1e-12)
    assert pg.duv_dxyz.shape == (30, 2, 2)
    bp = cam.backproject(uv, get_gradients=True)
    np.testing.assert_allclose(bp.dxy_duv @ pg.duv_dxyz, np.broadcast_to(np.eye(2), (30, 2, 2)), atol=1e-9)


def test_pose_properties_are_consistent(rng, random_opencv_camera):
    cam = random_opencv_camera(rng, ground_z_m=3.0)
    T = cam.T_cam_world
    np.testing.assert_allclose(T[:3, :3], cam.R, atol=1e-15)
    np.testing.assert_allclose(T[:3, 3], cam.t, atol=1e-12)
    np.testing.assert_allclose(cam.T_world_cam @ T, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(cam.position_world_m, -cam.R.T @ cam.t, atol=1e-12)
    assert cam.height_m == pytest.approx(cam.position_world_m[2] - 3.0)
    np.testing.assert_allclose(cam.P, cam.K @ np.hstack([cam.R, cam.t[:, None]]))


def test_pantilt_to_opencv_and_back_is_exact():
    cam = _pantilt()
    oc = cam.to_opencv()
    np.testing.assert_allclose(oc.params, cam.params, rtol=0, atol=1e-12)
    assert oc.ground_z_m == cam.ground_z_m and oc.image_size_px == cam.image_size_px
    back = PanTiltCamera.from_opencv(oc)
    assert isinstance(back, PanTiltCamera)
    np.testing.assert_allclose(back.params, cam.params, rtol=0, atol=1e-12)
    uv = np.array([[100.0, 900.0], [960.0, 600.0], [1800.0, 1000.0]])
    np.testing.assert_allclose(oc.backproject(uv).xy_world_m, cam.backproject(uv).xy_world_m, atol=1e-9)


@pytest.mark.parametrize("tilt_deg", [90.0, -30.0, 0.0, 60.0])
def test_pantilt_opencv_round_trip_any_tilt(tilt_deg):
    cam = _pantilt(tilt_deg=tilt_deg, roll_deg=20.0)
    oc = cam.to_opencv()
    np.testing.assert_allclose(oc.R_world_cam, cam.R_world_cam, atol=1e-14)
    back = PanTiltCamera.from_opencv(oc)
    np.testing.assert_allclose(back.R_world_cam, cam.R_world_cam, atol=1e-14)
    if tilt_deg == 90.0:  # gimbal: pan + roll is what is defined
        assert back.roll_deg == 0.0
        assert back.pan_deg == pytest.approx(cam.pan_deg + cam.roll_deg)


@pytest.mark.parametrize("scale", [1.0, 3.7, -2.0])
def test_from_projection_matrix(rng, random_opencv_camera, scale):
    cam = random_opencv_camera(rng, distortion="mild", ground_z_m=1.5)
    back = OpenCVCamera.from_projection_matrix(scale * cam.P, cam.image_size_px, dist=cam.dist[:5], ground_z_m=1.5)
    np.testing.assert_allclose(back.params, cam.params, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(back.R, cam.R, atol=1e-12)
    np.testing.assert_allclose(back.t, cam.t, atol=1e-9)


def test_strict_conversion_to_pantilt():
    cam = _pantilt().to_opencv()
    for K, dist in (([[1200.0, 0, 955], [0, 1210.0, 545], [0, 0, 1]], None),
                    ([[1200.0, 2.0, 955], [0, 1200.0, 545], [0, 0, 1]], None),
                    ([[1200.0, 0, 955], [0, 1200.0, 545], [0, 0, 1]], [-0.1, 0, 0, 0])):
        oc = OpenCVCamera(K, dist, cam.R, cam.t, IMAGE, cam.ground_z_m)
        with pytest.raises(InputError, match="camera intrinsics"):
            PanTiltCamera.from_opencv(oc)
        with pytest.warns(ConsistencyWarning, match="approximating"):
            approx = PanTiltCamera.from_opencv(oc, strict=False)
        assert approx.focal_px == pytest.approx((K[0][0] + K[1][1]) / 2)
        np.testing.assert_allclose(approx.R_world_cam, cam.R_world_cam, atol=1e-14)


def test_non_orthonormal_rotation():
    cam = _pantilt().to_opencv()
    R_noisy = cam.R + 1e-6 * np.array([[0.3, -0.2, 0.1], [0.5, 0.0, -0.4], [0.2, 0.1, 0.3]])
    with pytest.warns(ConsistencyWarning, match="orthonormal"):
        oc = OpenCVCamera(cam.K, None, R_noisy, cam.t, IMAGE, cam.ground_z_m)
    np.testing.assert_allclose(oc.R @ oc.R.T, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(oc.R, cam.R, atol=1e-5)
    with pytest.raises(InputError, match="rotation matrix"):
        OpenCVCamera(cam.K, None, cam.R * 1.05, cam.t, IMAGE, cam.ground_z_m)
    with pytest.raises(InputError, match="det"):
        OpenCVCamera(cam.K, None, -cam.R, cam.t, IMAGE, cam.ground_z_m)  # a reflection
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # an exact rotation gives no warning
        OpenCVCamera(cam.K, None, cam.R, cam.t, IMAGE, cam.ground_z_m)


def test_camera_below_ground_is_an_error():
    cam = _pantilt().to_opencv()  # centre 8 m above a ground at z = 2
    with pytest.raises(InputError, match="camera height"):
        OpenCVCamera(cam.K, None, cam.R, cam.t, IMAGE, ground_z_m=20.0)
    with pytest.raises(InputError, match="camera height"):
        OpenCVCamera(cam.K, None, cam.R, cam.t, IMAGE, ground_z_m=10.0)  # exactly on the ground
    with pytest.raises(InputError, match="height_m"):
        PanTiltCamera(1000.0, IMAGE, -1.0, 0.0, 20.0)


@pytest.mark.parametrize("kwargs, field", [
    (dict(K=[[1000, 0, 960], [1e-3, 1000, 540], [0, 0, 1]]), "K"),
    (dict(K=[[-1000, 0, 960], [0, 1000, 540], [0, 0, 1]]), "K"),
    (dict(K=[[1000, 0, 960], [0, 1000, 540]]), "K"),
    (dict(K=[[1000, 0, 960], [0, np.nan, 540], [0, 0, 1]]), "K"),
    (dict(dist=[0.1, 0.2, 0.3]), "dist"),
    (dict(dist=[0.1, 0.0, 0.0, 0.0, 0.0, np.nan]), "dist"),
    (dict(t=[0.0, 1.0]), "t"),
    (dict(t=[0.0, np.inf, 1.0]), "t"),
    (dict(image_size_px=(1920, 0)), "image_size_px"),
    (dict(image_size_px="big"), "image_size_px"),
    (dict(image_size_px=(1920.5, 1080)), "image_size_px"),
    (dict(ground_z_m=True), "ground_z_m"),
    (dict(R=np.eye(2)), "R"),
])
def test_bad_input_names_the_field(kwargs, field):
    base = _pantilt().to_opencv()
    args = dict(K=base.K, dist=None, R=base.R, t=base.t, image_size_px=IMAGE, ground_z_m=base.ground_z_m)
    args.update(kwargs)
    with pytest.raises(InputError) as ei:
        OpenCVCamera(**args)
    assert ei.value.field.startswith(field)
    assert "\n" not in str(ei.value)


def test_dist_lengths_and_params_layout(rng):
    base = _pantilt().to_opencv()
    for d in ([], [0.1, -0.01, 1e-3, 2e-3], [0.1, -0.01, 1e-3, 2e-3, 0.001],
              [0.1, -0.01, 1e-3, 2e-3, 0.001, 0.01, 0.002, 0.0003]):
        oc = OpenCVCamera(base.K, d, base.R, base.t, IMAGE, base.ground_z_m)
        expect = np.zeros(8)
        expect[:len(d)] = d
        np.testing.assert_array_equal(oc.params[P.DIST_SLICE], expect)
        np.testing.assert_array_equal(oc.dist, expect)
    # the camera is exactly the general model on its parameter vector
    uv = np.array([[300.0, 900.0], [1500.0, 700.0]])
    np.testing.assert_array_equal(oc.backproject(uv).xy_world_m, general.backproject(oc.params, uv).xy_world_m)


def test_base_class_helpers():
    cam = _pantilt(roll_deg=4.0).to_opencv()
    # the horizon row: just below it a ray meets the ground (far away), just above it does not
    u = np.array([0.0, 700.0, 1919.0])
    v_h = cam.horizon_v_px(u)
    below = cam.backproject(np.stack([u, v_h + 0.5], -1))
    above = cam.backproject(np.stack([u, v_h - 0.5], -1))
    assert below.valid.all() and not above.valid.any()
    # tilt 25 deg at 8 m: the horizon is f tan(25 deg) = 1200 * 0.4663 = 559.6 px above the principal point
    # at the principal column (roll 0)
    flat = _pantilt(roll_deg=0.0)
    assert flat.horizon_v_px(955.0) == pytest.approx(545.0 - 1200.0 * np.tan(np.deg2rad(25.0)))
    assert cam.in_image([[-0.5, -0.5], [1919.5, 1079.5], [-0.6, 0.0], [0.0, 1079.6]]).tolist() == [
        True, True, False, False]
    g = cam.pixel_grid(8)
    assert g.shape == (135, 240, 2) and g[0, 0].tolist() == [0.0, 0.0] and g[-1, -1].tolist() == [1912.0, 1072.0]
    np.testing.assert_array_equal(cam.K, [[1200.0, 0.0, 955.0], [0.0, 1200.0, 545.0], [0.0, 0.0, 1.0]])
    assert (cam.pan_deg, cam.tilt_deg, cam.roll_deg) == pytest.approx((135.0, 25.0, 4.0))
