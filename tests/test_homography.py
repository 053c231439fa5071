"""Homographies: the plane mapping and its Jacobians, the fit covariance, decomposition into a camera, the
``model: homography`` file and ``footprint-uq convert``."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera, save_camera
from footprint_uq.cameras.homography import (
    HomographyCamera,
    camera_from_homography,
    fit_homography,
    homography_from_camera,
)
from footprint_uq.cli.main import main
from footprint_uq.errors import ConfigError, InputError
from footprint_uq.io import load_camera
from footprint_uq.io.homography_files import load_homography

SIZE = (1920, 1080)


@pytest.fixture
def cam():
    return PanTiltCamera(focal_px=1400, image_size_px=SIZE, height_m=8.0, pan_deg=30, tilt_deg=20, roll_deg=1.0,
                         position_m=(3.0, 4.0), ground_z_m=0.5)


def _pixels(rng, n, vmin=560):
    return np.column_stack([rng.uniform(0, SIZE[0] - 1, n), rng.uniform(vmin, SIZE[1] - 1, n)])


def test_homography_of_a_camera_is_its_ground_mapping(cam):
    hc = HomographyCamera(homography_from_camera(cam), SIZE)
    uv = _pixels(np.random.default_rng(0), 50, vmin=200)
    ref = cam.backproject(uv)
    bp = hc.backproject(uv)
    np.testing.assert_array_equal(bp.valid, ref.valid)
    np.testing.assert_allclose(bp.xy_world_m[bp.valid], ref.xy_world_m[ref.valid], rtol=1e-10, atol=1e-9)
    np.testing.assert_allclose(hc.project_ground(ref.xy_world_m[ref.valid]), uv[ref.valid], atol=1e-7)
    # above the horizon: NaN with the reason, never a point behind the camera
    up = hc.backproject(np.array([[959.5, 5.0]]))
    assert not up.valid[0] and np.isnan(up.xy_world_m).all() and up.reason[0] == 1
    # decomposed with K: the same camera
    cam2, _ = camera_from_homography(hc, cam.K, SIZE, ground_z_m=0.5)
    np.testing.assert_allclose(cam2.params, cam.params, atol=1e-9)


def test_jacobians_match_central_differences(cam):
    hc = HomographyCamera(homography_from_camera(cam), SIZE)
    uv = _pixels(np.random.default_rng(1), 7)
    bp = hc.backproject(uv, get_gradients=True)
    e = 1e-3
    for j in range(2):
        d = np.zeros(2)
        d[j] = e
        num = (hc.backproject(uv + d).xy_world_m - hc.backproject(uv - d).xy_world_m) / (2 * e)
        np.testing.assert_allclose(bp.dxy_duv[..., j], num, rtol=1e-6, atol=1e-10)
    from footprint_uq.cameras.homography import apply_homography as _apply

    H = hc.H_ground_image
    for j in range(9):
        dh = np.zeros(9)
        dh[j] = 1e-9
        xp = _apply((H.ravel() + dh).reshape(3, 3), uv, False)[1]
        xm = _apply((H.ravel() - dh).reshape(3, 3), uv, False)[1]
        np.testing.assert_allclose(bp.dxy_dh[..., j], (xp - xm) / 2e-9, rtol=1e-5, atol=1e-6)
    # scale invariance: d xy / d h . h = 0
    assert np.abs(bp.dxy_dh @ H.ravel()).max() < 1e-9


def test_fit_covariance_matches_monte_carlo(cam):
    rng = np.random.default_rng(2)
    uv = _pixels(rng, 12)
    xy = cam.backproject(uv).xy_world_m
    test = np.array([[900.0, 800.0], [200.0, 620.0], [1700.0, 1000.0]])
    H, C, _ = fit_homography(uv, xy, sigma_px=1.0, sigma_m=0.05)
    _, cov = HomographyCamera(H, SIZE, cov_h=C).ground_covariance_m2(test)
    pts = []
    for _ in range(400):
        Hs, _, _ = fit_homography(uv + rng.normal(0, 1.0, uv.shape), xy + rng.normal(0, 0.05, xy.shape))
        pts.append(HomographyCamera(Hs, SIZE).backproject(test).xy_world_m)
    pts = np.array(pts)
    for k in range(len(test)):
        mc = np.cov(pts[:, k].T)
        # 400 samples: variances within ~15 % (2 sigma)
        np.testing.assert_allclose(np.diag(mc), np.diag(cov[k]), rtol=0.2)
    # the covariance has H itself in its null space (the scale of H is no parameter)
    assert np.abs(C @ H.ravel()).max() < 1e-12 * np.abs(C).max() * 9


def test_decomposed_pose_covariance_matches_monte_carlo(cam):
    rng = np.random.default_rng(3)
    uv = _pixels(rng, 12)
    xy = cam.backproject(uv).xy_world_m
    H, C, _ = fit_homography(uv, xy, sigma_px=1.0, sigma_m=0.05)
    _, cov = camera_from_homography(H, cam.K, SIZE, cov_h=C, ground_z_m=0.5)
    poses = []
    for _ in range(300):
        Hs, _, _ = fit_homography(uv + rng.normal(0, 1.0, uv.shape), xy + rng.normal(0, 0.05, xy.shape))
        poses.append(camera_from_homography(Hs, cam.K, SIZE, ground_z_m=0.5)[0].params[13:19])
    np.testing.assert_allclose(np.std(poses, axis=0, ddof=1), np.sqrt(np.diag(cov)), rtol=0.2)


def _write(path, d):
    path.write_text(yaml.safe_dump(d))
    return path


def test_homography_file(tmp_path, cam):
    rng = np.random.default_rng(4)
    uv = _pixels(rng, 8)
    xy = cam.backproject(uv).xy_world_m
    H = homography_from_camera(cam)
    base = {"model": "homography", "image_size_px": list(SIZE), "H_ground_image": H.tolist(), "ground_z_m": 0.5}
    # with K: a camera, loadable by load_camera
    p = _write(tmp_path / "hk.yaml", {**base, "K": cam.K.tolist()})
    np.testing.assert_allclose(load_camera(p).params, cam.params, atol=1e-9)
    # without K: the plane mapping, with the fit covariance of its points
    p = _write(tmp_path / "h.yaml", {**base, "points": {"uv_px": uv.tolist(), "xy_world_m": xy.tolist(),
                                                        "sigma_px": 1.0, "sigma_m": 0.05}})
    f = load_homography(p)
    assert f.camera is None and f.homography.cov_h is not None
    _, cov = f.homography.ground_covariance_m2([[900.0, 800.0]])
    assert 0 < cov[0, 0, 0] < 1.0
    with pytest.raises(ConfigError, match="K: got 'missing'"):
        load_camera(p)
    bad = [({**base, "H_ground_image": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}, "invertible"),
           ({k: v for k, v in base.items() if k != "H_ground_image"}, "H_ground_image: got 'missing'"),
           ({**base, "homography": 1}, "homography: got 1"),
           ({**base, "points": {"uv_px": uv.tolist(), "xy_world_m": xy[:5].tolist()}}, "pairs"),
           ({**base, "points": {"uv_px": uv.tolist(), "xy_world_m": xy.tolist(), "sigma_m": -1}}, "sigma_m"),
           ({**base, "dist": [0.1, 0, 0, 0, 0]}, "dist only with K")]
    for d, match in bad:
        with pytest.raises(InputError, match=match):
            load_homography(_write(tmp_path / "bad.yaml", d))


def test_convert_cli(tmp_path, cam):
    src = save_camera(cam, tmp_path / "cam.yaml")
    r = CliRunner().invoke(main, ["convert", "--camera", str(src), "--to", "homography", "--out",
                                  str(tmp_path / "h.yaml")])
    assert r.exit_code == 0, r.output
    f = load_homography(tmp_path / "h.yaml")
    uv = _pixels(np.random.default_rng(5), 20)
    np.testing.assert_allclose(f.homography.backproject(uv).xy_world_m, cam.backproject(uv).xy_world_m, rtol=1e-9)
    r = CliRunner().invoke(main, ["convert", "--camera", str(src), "--to", "homography", "--keep-intrinsics",
                                  "--out", str(tmp_path / "hk.json")])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(load_camera(tmp_path / "hk.json").params, cam.params, atol=1e-9)
    r = CliRunner().invoke(main, ["convert", "--camera", str(tmp_path / "hk.json"), "--to", "opencv", "--out",
                                  str(tmp_path / "o.yaml")])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(load_camera(tmp_path / "o.yaml").params, cam.params, atol=1e-9)
    # a camera with lens distortion has no homography: one line, exit 2
    from footprint_uq import OpenCVCamera

    T = cam.T_cam_world
    dc = OpenCVCamera(cam.K, [-0.2, 0.05, 0, 0, 0], T[:3, :3], T[:3, 3], SIZE)
    save_camera(dc, tmp_path / "d.yaml")
    r = CliRunner().invoke(main, ["convert", "--camera", str(tmp_path / "d.yaml"), "--to", "homography", "--out",
                                  str(tmp_path / "x.yaml")])
    assert r.exit_code == 2 and r.output.count("\n") == 1 and "no lens distortion" in r.output


@settings(max_examples=60, deadline=None)
@given(f=st.floats(600, 3000), h=st.floats(2.0, 40.0), pan=st.floats(-180, 180), tilt=st.floats(3.0, 85.0),
       roll=st.floats(-10, 10), x=st.floats(-100, 100), y=st.floats(-100, 100), gz=st.floats(-5, 5))
def test_homography_round_trip_property(f, h, pan, tilt, roll, x, y, gz):
    # any undistorted camera: its homography maps pixels to its ground points, and decomposes back into it
    cam = PanTiltCamera(focal_px=f, image_size_px=SIZE, height_m=h, pan_deg=pan, tilt_deg=tilt, roll_deg=roll,
                        position_m=(x, y), ground_z_m=gz)
    hc = HomographyCamera(homography_from_camera(cam), SIZE)
    uv = np.array([[959.5, 1079.0], [100.0, 1000.0], [1800.0, 900.0]])
    ref = cam.backproject(uv)
    bp = hc.backproject(uv)
    np.testing.assert_array_equal(bp.valid, ref.valid)
    ok = ref.valid
    scale = 1.0 + np.abs(ref.xy_world_m[ok]).max() if ok.any() else 1.0
    np.testing.assert_allclose(bp.xy_world_m[ok], ref.xy_world_m[ok], atol=1e-9 * scale * (1 + 1 / np.sin(
        np.deg2rad(tilt))))
    cam2, _ = camera_from_homography(hc, cam.K, SIZE, ground_z_m=gz)
    np.testing.assert_allclose(cam2.position_world_m, cam.position_world_m, atol=1e-6 * (1 + h))
    assert abs(cam2.tilt_deg - tilt) < 1e-6
