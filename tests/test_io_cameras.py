"""Camera and budget files: round trips, every reader, every inconsistency, every bad-input message."""

from __future__ import annotations

import json
import warnings
from contextlib import contextmanager
from pathlib import Path

import cv2
import numpy as np
import pytest

from footprint_uq import ConfigError, ConsistencyWarning, ErrorBudget, InputError, OpenCVCamera, PanTiltCamera
from footprint_uq.cameras.rotation import R_W_C
from footprint_uq.io import (
    camera_from_dict,
    camera_from_intrinsics_and_pose,
    detect_format,
    load_camera,
    load_intrinsics,
    save_budget,
    save_camera,
)
from footprint_uq.io.camera_files import _exact_deg
from footprint_uq.uncertainty.budget import load_budget
from footprint_uq.uncertainty.presets import PRESET_NAMES

DATA = Path(__file__).parent / "data" / "cameras"

# the camera of every fixture (see tests/data/cameras/make_fixtures.py)
SIZE = (1920, 1200)
K = np.array([[1402.3, 0.0, 967.8], [0.0, 1400.1, 581.7], [0.0, 0.0, 1.0]])
DIST = np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03])
POSE = {"height_m": 6.5, "pan_deg": 30.0, "tilt_deg": 12.0, "roll_deg": 0.5, "position_m": [12.0, -3.5]}
R = R_W_C(*np.deg2rad([30.0, 12.0, 0.5])).T
CW = np.array([12.0, -3.5, 6.5])
T = -R @ CW
K_CAL = np.array([[1029.3, 0.0, 982.0], [0.0, 1122.3, 1129.1], [0.0, 0.0, 1.0]])


@pytest.fixture()
def ref():
    return OpenCVCamera(K, DIST, R, T, SIZE)


def same_camera(a, b, atol=1e-7):
    """Same parameters (angles to 1e-7 rad, pixels/metres to 1e-7 relative) and same ground points."""
    assert type(a) is type(b) or isinstance(a, OpenCVCamera) and isinstance(b, OpenCVCamera)
    assert a.image_size_px == b.image_size_px
    np.testing.assert_allclose(a.params, b.params, rtol=atol, atol=atol)
    uv = np.array([[100.0, 1100.0], [960.0, 900.0], [1800.0, 700.0]])
    np.testing.assert_allclose(a.backproject(uv).xy_world_m, b.backproject(uv).xy_world_m, rtol=0, atol=1e-6)


@contextmanager
def strict():
    """Context in which any warning fails the test."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        yield


# -- round trips ---------------------------------------------------------------------------------
@pytest.mark.parametrize("ext", ["yaml", "yml", "json"])
def test_roundtrip_pantilt_is_bit_exact(tmp_path, ext):
    rng = np.random.default_rng(1)
    for i in range(60):
        cam = PanTiltCamera(rng.uniform(300, 5000), (int(rng.integers(320, 4000)), int(rng.integers(240, 3000))),
                            rng.uniform(0.5, 40), rng.uniform(-180, 180), rng.uniform(-89, 89), rng.uniform(-20, 20),
                            tuple(rng.normal(0, 500, 2)), tuple(rng.uniform(100, 300, 2)), rng.normal(0, 30))
        back = load_camera(save_camera(cam, tmp_path / f"c{i}.{ext}"))
        assert isinstance(back, PanTiltCamera)
        assert np.array_equal(back.params, cam.params), i
        assert back.image_size_px == cam.image_size_px and back.ground_z_m == cam.ground_z_m


@pytest.mark.parametrize("ext", ["yaml", "json"])
def test_roundtrip_opencv_is_bit_exact(tmp_path, ext):
    rng = np.random.default_rng(2)
    for i, n in enumerate([0, 4, 5, 8, 8]):
        Km = np.array([[rng.uniform(800, 3000), rng.normal(0, 2), 950.0 + rng.normal(0, 20)],
                       [0.0, rng.uniform(800, 3000), 600 + rng.normal(0, 20)], [0.0, 0.0, 1.0]])
        Rm = R_W_C(*np.deg2rad([rng.uniform(-180, 180), rng.uniform(5, 60), rng.normal(0, 3)])).T
        C = np.array([rng.normal(0, 100), rng.normal(0, 100), rng.uniform(3, 30)])
        cam = OpenCVCamera(Km, rng.normal(0, 0.05, n), Rm, -Rm @ C, (1920, 1200), ground_z_m=rng.normal(0, 2))
        back = load_camera(save_camera(cam, tmp_path / f"o{i}.{ext}"))
        assert isinstance(back, OpenCVCamera)
        assert np.array_equal(back.params, cam.params)
        assert np.array_equal(back.R, cam.R) and np.array_equal(back.t, cam.t)
        assert back.ground_z_m == cam.ground_z_m


def test_exact_degrees_recover_the_written_value():
    # values whose rad2deg(deg2rad(d)) != d: the file must still say d and convert back bit-exactly
    odd = [d for d in np.round(np.linspace(-179.9, 179.9, 3599), 1) if float(np.rad2deg(np.deg2rad(d))) != d]
    assert odd, "expected some degree values that do not survive rad2deg(deg2rad())"
    for d in odd[:200]:
        assert _exact_deg(np.deg2rad(d)) == d


def test_saved_file_is_readable_text(tmp_path):
    cam = PanTiltCamera(1400, (1920, 1080), 6.5, 30.000000000000004 - 4e-15, 12, position_m=(1.5, -2))
    text = save_camera(cam, tmp_path / "c.yaml").read_text()
    assert "pan_deg: 30.0\n" in text and "height_m: 6.5\n" in text and "position_m: [1.5, -2.0]" in text
    d = json.loads(save_camera(cam, tmp_path / "c.json").read_text())
    assert d["model"] == "pan-tilt" and d["image_size_px"] == [1920, 1080]


def test_save_camera_rejects_unknown_extension(tmp_path):
    with pytest.raises(InputError, match="path.*yaml"):
        save_camera(PanTiltCamera(1400, (640, 480), 5, 0, 10), tmp_path / "c.txt")


@pytest.mark.parametrize("ext", ["yaml", "json"])
def test_budget_roundtrip(tmp_path, ext):
    for name in PRESET_NAMES:
        b = ErrorBudget.preset(name)
        back = load_budget(save_budget(b, tmp_path / f"{name}.{ext}"))
        assert back == b
        np.testing.assert_array_equal(back.param_covariance(), b.param_covariance())
    cov = {"names": ["pan_deg", "tilt_deg"], "matrix": [[0.04, 0.01], [0.01, 0.09]]}
    b = ErrorBudget.from_dict({"height_m": 0.2, "imaging_px": [0.3, 0.4], "covariance": cov, "name": "surveyed"})
    back = load_budget(save_budget(b, tmp_path / f"cov.{ext}"))
    np.testing.assert_array_equal(back.param_covariance(), b.param_covariance())
    np.testing.assert_array_equal(back.pixel_covariance(), b.pixel_covariance())
    assert back.name == "surveyed"


# -- our own files -------------------------------------------------------------------------------
def test_pantilt_fixture_pinned_ground_point():
    cam = load_camera(DATA / "pantilt.yaml")
    assert isinstance(cam, PanTiltCamera) and cam.image_size_px == SIZE
    # the principal ray lands h / tan(tilt) along the heading (roll does not move it)
    d = 6.5 / np.tan(np.deg2rad(12.0))
    xy = cam.backproject([959.5, 599.5]).xy_world_m
    np.testing.assert_allclose(xy, [12 + d * np.sin(np.deg2rad(30)), -3.5 + d * np.cos(np.deg2rad(30))], atol=1e-9)
    np.testing.assert_allclose(xy, [27.2900479, 22.9831397], atol=1e-6)
    js = load_camera(DATA / "pantilt.json")  # principal point defaults to the image centre
    assert np.array_equal(js.params, cam.params)


@pytest.mark.parametrize("name", ["opencv.yaml", "opencv.json", "opencv_P.yaml"])
def test_opencv_own_files(name, ref):
    with strict():
        cam = load_camera(DATA / name)
    same_camera(cam, ref)


def test_camera_from_dict_arguments_fill_and_conflict():
    d = {"model": "pan-tilt", "focal_px": 1000, "height_m": 5, "pan_deg": 0, "tilt_deg": 10}
    cam = camera_from_dict(d, image_size_px=(640, 480), ground_z_m=2.0)
    assert cam.image_size_px == (640, 480) and cam.ground_z_m == 2.0
    with pytest.raises(ConfigError, match="image_size_px"):
        camera_from_dict({**d, "image_size_px": [640, 480]}, where="c.yaml", image_size_px=(1280, 960))
    with pytest.raises(ConfigError, match="c.yaml: ground_z_m"):
        camera_from_dict({**d, "image_size_px": [640, 480], "ground_z_m": 1.0}, where="c.yaml", ground_z_m=2.0)
    with pytest.raises(ConfigError, match="c.yaml: model"):
        camera_from_dict({**d, "image_size_px": [640, 480], "model": "fisheye"}, where="c.yaml")
    with pytest.raises(ConfigError, match="c.yaml: model.*did you mean 'model'"):
        camera_from_dict({"type": "pan-tilt"}, where="c.yaml")


# -- OpenCV FileStorage ---------------------------------------------------------------------------
def test_opencv_filestorage_written_by_cv2(tmp_path):
    rng = np.random.default_rng(3)
    for i, (ext, n) in enumerate([("yaml", 5), ("yml", 4), ("xml", 8), ("json", 5), ("yaml", 14)]):
        Km = np.array([[rng.uniform(500, 3000), 0, rng.uniform(600, 1300)], [0, rng.uniform(500, 3000),
                       rng.uniform(400, 800)], [0, 0, 1]])
        dist = rng.normal(0, 0.1, n)
        if n == 14:
            dist[8:] = 0.0
        path = str(tmp_path / f"calib{i}.{ext}")
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", 1920)
        fs.write("image_height", 1200)
        fs.write("camera_matrix", Km)
        fs.write("distortion_coefficients", dist.reshape(1, -1))
        fs.release()
        assert detect_format(path) == "opencv"
        K2, d2, size = load_intrinsics(path)
        np.testing.assert_array_equal(K2, Km)
        np.testing.assert_array_equal(d2, dist[:8])
        assert size == (1920, 1200)


def test_opencv_classic_header_and_no_size(tmp_path):
    # as written by OpenCV 3/4 (%YAML:1.0), without image size
    text = ("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
            "   data: [ 1402.3, 0., 967.8, 0., 1400.1, 581.7, 0., 0., 1. ]\n"
            "distortion_coefficients: !!opencv-matrix\n   rows: 1\n   cols: 5\n   dt: d\n"
            "   data: [ -0.17, 0.12, -1.2e-04, -2.35e-03, -0.03 ]\n")
    p = tmp_path / "old.yml"
    p.write_text(text)
    K2, d2, size = load_intrinsics(p)
    np.testing.assert_array_equal(K2, K)
    np.testing.assert_array_equal(d2, DIST)
    assert size is None
    with pytest.raises(ConfigError, match="old.yml: image size.*image_size_px"):
        load_camera(p, pose=POSE)
    cam = load_camera(p, pose=POSE, image_size_px=SIZE)
    same_camera(cam, OpenCVCamera(K, DIST, R, T, SIZE))


def test_opencv_fixture_intrinsics_only_needs_pose(ref):
    K2, d2, size = load_intrinsics(DATA / "opencv_calibration.yaml")
    np.testing.assert_array_equal(K2, K)
    np.testing.assert_array_equal(d2, DIST)
    assert size == SIZE
    with pytest.raises(ConfigError, match=r"opencv_calibration.yaml: pose: .*intrinsics only.*pose=.*12 "
                                          r"calibration-board poses"):
        load_camera(DATA / "opencv_calibration.yaml")
    for pose in (DATA / "pose.yaml", str(DATA / "pose.yaml"), POSE, {"R": R.tolist(), "t": T.tolist()},
                 {"rvec": cv2.Rodrigues(R)[0].ravel().tolist(), "tvec": T.tolist()}):
        with strict():
            same_camera(load_camera(DATA / "opencv_calibration.yaml", pose=pose), ref)
    same_camera(load_camera(DATA / "opencv_calibration.xml", pose=POSE), ref)


def test_opencv_fixture_with_pose(ref):
    with strict():
        same_camera(load_camera(DATA / "opencv_with_pose.yaml"), ref)
    with pytest.raises(ConfigError, match="pose.*the file has one \\(rvec, tvec\\)"):
        load_camera(DATA / "opencv_with_pose.yaml", pose=POSE)


def test_opencv_malformed(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                   "   data: [ 1., 2. ]\n")
    with pytest.raises(ConfigError, match="bad.yaml: camera_matrix: .*rows x cols"):
        load_intrinsics(bad)
    nan = tmp_path / "nan.yaml"
    nan.write_text("%YAML:1.0\n---\ncamera_matrix: !!opencv-matrix\n   rows: 3\n   cols: 3\n   dt: d\n"
                   "   data: [ 1400., 0., .Nan, 0., 1400., 600., 0., 0., 1. ]\nimage_width: 1920\n"
                   "image_height: 1200\n")
    with pytest.raises(ConfigError, match=r"nan.yaml: camera_matrix\[0, 2\]: got nan, expected a finite number"):
        load_intrinsics(nan)
    syntax = tmp_path / "syntax.yaml"
    syntax.write_text("%YAML:1.0\n---\ncamera_matrix: [1, 2\n")
    with pytest.raises(ConfigError, match="syntax.yaml"):
        load_intrinsics(syntax)
    nok = tmp_path / "nok.yaml"
    nok.write_text("%YAML:1.0\n---\nimage_width: 1920\nimage_height: 1200\nfoo: !!opencv-matrix\n   rows: 1\n"
                   "   cols: 1\n   dt: d\n   data: [ 1. ]\n")
    with pytest.raises(ConfigError, match="nok.yaml: camera_matrix: got 'missing'"):
        load_intrinsics(nok)
    with pytest.raises(ConfigError, match="fisheye_model"):
        load_camera(DATA / "broken_opencv_fisheye.yaml", pose=POSE)
    path = str(tmp_path / "prism.yaml")
    fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.r_[DIST, 0, 0, 0, 0.01, 0, 0, 0, 0, 0])
    fs.release()
    with pytest.raises(ConfigError, match="prism.yaml: distortion_coefficients: .*thin-prism"):
        load_intrinsics(path)


# -- ROS CameraInfo -------------------------------------------------------------------------------
def test_ros_camera_info(ref, tmp_path):
    assert detect_format(DATA / "ros_camera_info.yaml") == "ros"
    K2, d2, size = load_intrinsics(DATA / "ros_camera_info.yaml")
    np.testing.assert_array_equal(K2, K)
    np.testing.assert_array_equal(d2, DIST)
    assert size == SIZE
    with pytest.raises(ConfigError, match="ros_camera_info.yaml: pose: .*intrinsics only"):
        load_camera(DATA / "ros_camera_info.yaml")
    with strict():
        same_camera(load_camera(DATA / "ros_camera_info.yaml", pose=DATA / "pose.yaml"), ref)
    # rational_polynomial: 8 coefficients; a stereo rectification is reported
    text = (DATA / "ros_camera_info.yaml").read_text()
    rat = text.replace("plumb_bob", "rational_polynomial").replace(
        "cols: 5\n  data: [-0.17, 0.12, -0.00012, -0.00235, -0.03]",
        "cols: 8\n  data: [-0.17, 0.12, -0.00012, -0.00235, -0.03, 0.01, 0.002, 0.0003]")
    rat = rat.replace("data: [1, 0, 0, 0, 1, 0, 0, 0, 1]", "data: [0.9999, -0.0141, 0, 0.0141, 0.9999, 0, 0, 0, 1]")
    p = tmp_path / "rat.yaml"
    p.write_text(rat)
    with pytest.warns(ConsistencyWarning, match="rat.yaml: rectification_matrix is not the identity"):
        K3, d3, _ = load_intrinsics(p)
    np.testing.assert_array_equal(d3, [-0.17, 0.12, -0.00012, -0.00235, -0.03, 0.01, 0.002, 0.0003])
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text(text.replace("plumb_bob", "rational_polynomial"))
    with pytest.raises(ConfigError, match="wrong.yaml: distortion_coefficients: .*8 coefficients"):
        load_intrinsics(wrong)


def test_ros_message_dump(tmp_path, ref):
    # a sensor_msgs/CameraInfo message dumped as YAML (flat K, D, R, P; width/height)
    msg = {"header": {"frame_id": "cam"}, "height": 1200, "width": 1920, "distortion_model": "plumb_bob",
           "D": DIST.tolist(), "K": K.ravel().tolist(), "R": np.eye(3).ravel().tolist(),
           "P": np.c_[K, np.zeros(3)].ravel().tolist(), "binning_x": 0, "binning_y": 0}
    p = tmp_path / "msg.yaml"
    p.write_text(json.dumps(msg))
    assert detect_format(p) == "ros"
    with strict():
        same_camera(load_camera(p, pose=POSE), ref)
    p.write_text(json.dumps({**msg, "height": 0, "width": 0}))
    assert load_intrinsics(p)[2] is None
    same_camera(load_camera(p, pose=POSE, image_size_px=SIZE), ref)


@pytest.mark.parametrize("name, match", [
    ("broken_ros_fisheye.yaml", "distortion_model: got 'equidistant'.*not supported"),
    ("broken_ros_rows.yaml", r"camera_matrix.data: got '5 numbers', expected rows x cols = 3 x 3 = 9"),
])
def test_ros_broken(name, match):
    with pytest.raises(ConfigError, match=f"{name}: {match}"):
        load_camera(DATA / name, pose=POSE)


# -- TUMTraf / A9 -------------------------------------------------------------------------------
def test_tumtraf_consistent(ref):
    assert detect_format(DATA / "tumtraf_consistent.json") == "tumtraf"
    with strict():
        same_camera(load_camera(DATA / "tumtraf_consistent.json"), ref)


def test_tumtraf_s110_projection_matrix_from_other_intrinsics(ref):
    # like the released s110 files: projection_matrix = calibrated_intrinsic_camera_matrix [R | t]
    with pytest.warns(ConsistencyWarning, match=r"projection_matrix differs from K \[R \| t\].*px.*"
                                                 r"calibrated_intrinsic_camera_matrix \[R \| t\] instead"):
        cam = load_camera(DATA / "tumtraf_s110_camera.json")
    same_camera(cam, ref)
    with pytest.warns(ConsistencyWarning, match="distortion .* is not applied"):
        camP = load_camera(DATA / "tumtraf_s110_camera.json", use="projection_matrix")
    np.testing.assert_allclose(camP.K, K_CAL, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(camP.position_world_m, CW, atol=1e-9)
    assert not np.any(camP.dist)


def test_tumtraf_translation_conventions(ref):
    with strict():  # 'translation' {x, y, z} is the sensor pose (camera -> world)
        same_camera(load_camera(DATA / "tumtraf_sensor_pose.json"), ref)
    with pytest.raises(ConfigError, match=r"rotation_matrix/translation_vector: got 'read as world_to_camera: camera "
                                          r"height -?[\d.]+ m.*pose_convention='camera_to_world'"):
        load_camera(DATA / "broken_tumtraf_position_as_t.json")
    with strict():
        same_camera(load_camera(DATA / "broken_tumtraf_position_as_t.json", pose_convention="camera_to_world"), ref)
    with pytest.raises(ConfigError, match="pose_convention"):
        load_camera(DATA / "tumtraf_consistent.json", pose_convention="camera_from_world")


def test_a9_intrinsics_only_and_placeholders(ref):
    K2, d2, size = load_intrinsics(DATA / "a9_s040_camera.json")  # 3x4 intrinsic matrix with a zero column
    np.testing.assert_array_equal(K2, K)
    assert size == SIZE
    with pytest.raises(ConfigError, match="a9_s040_camera.json: pose: got 'no usable extrinsics"):
        load_camera(DATA / "a9_s040_camera.json")
    same_camera(load_camera(DATA / "a9_s040_camera.json", pose=POSE), ref)
    with pytest.raises(ConfigError, match="placeholders of -1 in projection_matrix, rotation_matrix, "
                                          "translation_matrix"):
        load_camera(DATA / "tumtraf_vehicle_placeholders.json")
    same_camera(load_camera(DATA / "tumtraf_vehicle_placeholders.json", pose=POSE), ref)


def test_tumtraf_extrinsic_matrix_and_ground(tmp_path, ref):
    d = json.loads((DATA / "tumtraf_consistent.json").read_text())
    for k in ("rotation_matrix", "translation_matrix", "projection_matrix"):
        del d[k]
    d["extrinsic_matrix"] = np.vstack([np.c_[R, T], [0, 0, 0, 1]]).tolist()
    p = tmp_path / "ext.json"
    p.write_text(json.dumps(d))
    with strict():
        same_camera(load_camera(p), ref)
    cam = load_camera(p, ground_z_m=1.5)
    assert cam.ground_z_m == 1.5 and cam.height_m == pytest.approx(5.0)


# -- inconsistencies -------------------------------------------------------------------------------
def _opencv_dict(**over):
    d = {"model": "opencv", "image_size_px": list(SIZE), "K": K.tolist(), "dist": DIST.tolist(), "R": R.tolist(),
         "t": T.tolist()}
    d.update(over)
    return d


def test_P_consistency_levels(ref):
    P = K @ np.c_[R, T]
    with strict():  # any homogeneous scale, including negative, is the same P
        same_camera(camera_from_dict(_opencv_dict(P=(-2.5 * P).tolist()), where="c.yaml"), ref)
    six = np.vectorize(lambda x: float(f"{x:.6g}"))(P)  # P printed with 6 significant digits: < 0.05 px
    assert np.linalg.norm(six - P) / np.linalg.norm(P) > 1e-6
    with strict():
        camera_from_dict(_opencv_dict(P=six.tolist()), where="c.yaml")
    five = np.vectorize(lambda x: float(f"{x:.5g}"))(P)  # 5 digits: about 0.09 px, reported
    with pytest.warns(ConsistencyWarning, match=r"c.yaml: P differs from K \[R \| t\]"):
        camera_from_dict(_opencv_dict(P=five.tolist()), where="c.yaml")
    small = P.copy()
    small[0] += 0.5 * P[2]  # u + 0.5 px everywhere
    with pytest.warns(ConsistencyWarning, match=r"c.yaml: P differs from K \[R \| t\].*0.5 px"):
        camera_from_dict(_opencv_dict(P=small.tolist()), where="c.yaml")
    with pytest.raises(ConfigError, match=r"broken_P_inconsistent.yaml: P: got '[\d.]+ px away from K \[R \| t\]'"):
        load_camera(DATA / "broken_P_inconsistent.yaml")
    with pytest.raises(ConfigError, match=r"broken_opencv_P_far.yaml: P: .*px away"):
        load_camera(DATA / "broken_opencv_P_far.yaml")


def test_rotation_checks(ref):
    Rn = R + 2e-5 * np.random.default_rng(4).normal(size=(3, 3))
    with pytest.warns(ConsistencyWarning, match="not orthonormal"):
        cam = camera_from_dict(_opencv_dict(R=Rn.tolist()), where="c.yaml")
    np.testing.assert_allclose(cam.R @ cam.R.T, np.eye(3), atol=1e-12)
    with pytest.raises(ConfigError, match=r"broken_not_orthonormal.yaml: R: got '\|R R\^T - I\| = 0.02"):
        load_camera(DATA / "broken_not_orthonormal.yaml")
    with pytest.raises(ConfigError, match="broken_det_minus1.yaml: R: got 'det = -1'.*reflection"):
        load_camera(DATA / "broken_det_minus1.yaml")


def test_K_checks():
    with pytest.raises(ConfigError, match=r"broken_K10.yaml: K\[1\]\[0\]: got 3.5, expected 0"):
        load_camera(DATA / "broken_K10.yaml")
    Kr = K.copy()
    Kr[1, 0] = 1e-13
    with pytest.warns(ConsistencyWarning, match=r"K\[1\]\[0\] = 1e-13 \(round-off\) set to 0"):
        cam = camera_from_dict(_opencv_dict(K=Kr.tolist()), where="c.yaml")
    assert cam.K[1, 0] == 0
    with pytest.raises(ConfigError, match=r"c.yaml: K \(fx, fy\)"):
        camera_from_dict(_opencv_dict(K=(K * [[-1], [1], [1]]).tolist()), where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: K\[2\]\[2\]"):
        camera_from_dict(_opencv_dict(K=(K * 2).tolist()), where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: K: got 'shape \(2, 3\)'"):
        camera_from_dict(_opencv_dict(K=K[:2].tolist()), where="c.yaml")


def test_principal_point_outside_image_warns():
    with pytest.warns(ConsistencyWarning, match=r"broken_pp_outside.yaml: principal point \(1959.5, 599.5\) px "
                                                r"lies outside the 1920x1200 image"):
        load_camera(DATA / "broken_pp_outside.yaml")
    with pytest.warns(ConsistencyWarning, match="principal point"):
        camera_from_dict(_opencv_dict(image_size_px=[960, 600]), where="c.yaml")


# -- bad input: each message names the file and the field ------------------------------------------
@pytest.mark.parametrize("name, match", [
    ("broken_height_no_unit.yaml", r"height: got 6.5, expected .*use 'height_m' \(metres\)"),
    ("broken_pan_rad.yaml", r"pan_rad: got 0.52, expected .*use 'pan_deg' \(degrees\).*radians, convert"),
    ("broken_negative_focal.yaml", r"focal_px: got -1400.0, expected a number > 0"),
    ("broken_zero_height.yaml", r"height_m: got 0.0, expected a number > 0"),
    ("broken_missing_tilt.yaml", r"tilt_deg: got 'missing', expected a value for 'tilt_deg'"),
    ("broken_nan.json", r"tilt_deg: got nan, expected a finite number"),
])
def test_broken_own_files(name, match):
    with pytest.raises(ConfigError, match=f"{name}: {match}"):
        load_camera(DATA / name)


@pytest.mark.parametrize("key, value, match", [
    ("focal_mm", 8.0, r"use 'focal_px' \(pixels = focal length / pixel pitch\)"),
    ("height_cm", 650, r"use 'height_m' \(metres\).*centimetres"),
    ("tilt_rad", 0.2, r"use 'tilt_deg' \(degrees\).*radians"),
    ("hieght_m", 6.5, r"did you mean 'height_m'"),
    ("fx", 1400, r"use 'focal_px'.*model: opencv"),
    ("colour", "red", r"one of the keys"),
])
def test_unknown_key_suggestions(key, value, match):
    d = {"model": "pan-tilt", "image_size_px": [1920, 1080], "focal_px": 1400, "height_m": 6.5, "pan_deg": 0,
         "tilt_deg": 10, key: value}
    with pytest.raises(ConfigError, match=f"cam.yaml: {key}: got .*{match}"):
        camera_from_dict(d, where="cam.yaml")


def test_opencv_model_bad_fields():
    with pytest.raises(ConfigError, match=r"c.yaml: R, t: got 'missing', expected the pose"):
        camera_from_dict({k: v for k, v in _opencv_dict().items() if k not in ("R", "t")}, where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: t: got 'missing'"):
        camera_from_dict({k: v for k, v in _opencv_dict().items() if k != "t"}, where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: dist: .*4 or 5 or 8 distortion coefficients"):
        camera_from_dict(_opencv_dict(dist=[0.1, 0.2, 0.3]), where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: t\[2\]: got nan"):
        camera_from_dict(_opencv_dict(t=[0.0, 1.0, float("nan")]), where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: rotation_matrix: .*use 'R'"):
        camera_from_dict({**_opencv_dict(), "rotation_matrix": R.tolist()}, where="c.yaml")
    with pytest.raises(ConfigError, match=r"c.yaml: camera height \(from R, t\)"):
        camera_from_dict(_opencv_dict(t=(-R @ np.array([0, 0, -2.0])).tolist()), where="c.yaml")


def test_file_level_errors(tmp_path):
    with pytest.raises(ConfigError, match="camera file: got .*nope.yaml.*an existing file"):
        load_camera(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("model: pan-tilt\nfocal_px: [1, 2\n")
    with pytest.raises(ConfigError, match=r"bad.yaml: line 3, column 1: got .*valid YAML syntax"):
        load_camera(bad)
    badj = tmp_path / "bad.json"
    badj.write_text("{'model': 'pan-tilt'}")
    with pytest.raises(ConfigError, match="bad.json: got .*valid JSON"):
        load_camera(badj)
    lst = tmp_path / "list.yaml"
    lst.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match="list.yaml: got 'list', expected a mapping"):
        load_camera(lst)
    with pytest.raises(ConfigError, match="pose.yaml: got .*keys.*formats footprint-uq, opencv, ros, tumtraf"):
        load_camera(DATA / "pose.yaml")
    with pytest.raises(ConfigError, match="format: got 'kitti'"):
        load_camera(DATA / "pantilt.yaml", format="kitti")
    with pytest.raises(ConfigError, match="pantilt.yaml: pose: .*pan-tilt camera files contain the pose"):
        load_camera(DATA / "pantilt.yaml", pose=POSE)


def test_intrinsics_and_pose_api(ref):
    same_camera(camera_from_intrinsics_and_pose(K, DIST, SIZE, **POSE), ref)
    same_camera(camera_from_intrinsics_and_pose(K, DIST, SIZE, R=R, t=T), ref)
    lifted = camera_from_intrinsics_and_pose(K, DIST, SIZE, **POSE, ground_z_m=3.0)
    assert lifted.height_m == pytest.approx(6.5) and lifted.position_world_m[2] == pytest.approx(9.5)
    with pytest.raises(ConfigError, match="pose: got 'missing'"):
        camera_from_intrinsics_and_pose(K, DIST, SIZE)
    with pytest.raises(ConfigError, match="pose: got 'both R, t and height_m, pan_deg, tilt_deg'"):
        camera_from_intrinsics_and_pose(K, DIST, SIZE, R=R, t=T, **POSE)
    with pytest.raises(ConfigError, match="tilt_deg: got 'missing'"):
        camera_from_intrinsics_and_pose(K, DIST, SIZE, height_m=6.5, pan_deg=30)
    with pytest.raises(ConfigError, match="height_m: got -6.5"):
        camera_from_intrinsics_and_pose(K, DIST, SIZE, height_m=-6.5, pan_deg=30, tilt_deg=12)
    with pytest.raises(ConfigError, match=r"pose: height: .*use 'height_m'"):
        load_camera(DATA / "ros_camera_info.yaml", pose={"height": 6.5, "pan_deg": 30, "tilt_deg": 12})
    with pytest.raises(ConfigError, match="ros_camera_info.yaml: image size: got \\[1920, 1200\\]"):
        load_camera(DATA / "ros_camera_info.yaml", pose=POSE, image_size_px=(1280, 800))
    cam = load_camera(DATA / "ros_camera_info.yaml", pose={**POSE, "ground_z_m": 2.0})
    assert cam.ground_z_m == 2.0
    with pytest.raises(ConfigError, match="ground_z_m"):
        load_camera(DATA / "ros_camera_info.yaml", pose={**POSE, "ground_z_m": 2.0}, ground_z_m=1.0)


@pytest.mark.parametrize("name, fmt", [
    ("pantilt.yaml", "footprint-uq"), ("opencv.json", "footprint-uq"), ("opencv_calibration.yaml", "opencv"),
    ("opencv_calibration.xml", "opencv"), ("ros_camera_info.yaml", "ros"), ("tumtraf_s110_camera.json", "tumtraf"),
    ("a9_s040_camera.json", "tumtraf"),
])
def test_detect_format(name, fmt):
    assert detect_format(DATA / name) == fmt


def test_fixtures_are_up_to_date(tmp_path, monkeypatch):
    """The committed fixtures are what make_fixtures.py writes (cv2.FileStorage output included)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_fixtures", DATA / "make_fixtures.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    monkeypatch.setattr(mod, "HERE", tmp_path)
    mod.own_files()  # (the cv2.FileStorage files depend on the OpenCV version's formatting: checked by content above)
    mod.tumtraf_files()
    from numeric_text import assert_same_numbers

    files = sorted(tmp_path.iterdir())
    assert [f.name for f in files if not (DATA / f.name).exists()] == []
    for f in files:  # numbers to 1e-12 relative: their last printed digit depends on the CPU (issue 11)
        assert_same_numbers(f, DATA / f.name, rtol=1e-12)


def test_own_intrinsics_only_file_with_pose(tmp_path):
    """`calibrate intrinsics` writes a `model: opencv` file without R, t: usable with a pose."""
    import yaml

    K = [[1400.0, 0.0, 959.5], [0.0, 1401.0, 539.5], [0.0, 0.0, 1.0]]
    f = tmp_path / "intrinsics.yaml"
    f.write_text(yaml.safe_dump({"model": "opencv", "image_size_px": [1920, 1080], "K": K,
                                 "dist": [-0.1, 0.01, 0.0, 0.0, 0.0]}))
    K2, dist, size = load_intrinsics(f)
    assert np.array_equal(K2, np.array(K)) and size == (1920, 1080)
    assert np.allclose(dist, [-0.1, 0.01, 0, 0, 0])
    with pytest.raises(ConfigError, match="intrinsics.yaml: R, t: got 'missing'.*pose"):
        load_camera(f)
    cam = load_camera(f, pose={"height_m": 8.0, "pan_deg": 30.0, "tilt_deg": 20.0})
    assert cam.model == "opencv"
    assert np.isclose(cam.height_m, 8.0) and np.isclose(cam.tilt_deg, 20.0) and np.isclose(cam.pan_deg, 30.0)
    assert np.allclose(cam.K, K) and np.allclose(cam.dist[:5], [-0.1, 0.01, 0, 0, 0])
    # a file that has its pose refuses a second one
    with pytest.raises(ConfigError, match="pose: got 'given as argument'"):
        load_camera(DATA / "opencv.yaml", pose={"height_m": 8.0, "pan_deg": 30.0, "tilt_deg": 20.0})
