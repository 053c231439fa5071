"""Dataset calibration files as users have them: TUMTraf / A9 (station base, LiDAR projections, -1 sentinels,
empty matrices, translations not in metres, vehicle cameras).  Fixtures: tests/data/cameras/datasets/
(make_dataset_fixtures.py writes them from the public format descriptions)."""

from __future__ import annotations

import json
import shutil
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from click.testing import CliRunner

from footprint_uq.cli.main import main
from footprint_uq.errors import ConfigError, ConsistencyWarning
from footprint_uq.io import load_camera

DATA = Path(__file__).parent / "data" / "cameras" / "datasets"
SENSOR_TO_CV = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _read(name):
    return json.loads((DATA / name).read_text())


def _pixels(n=40, seed=0):
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(0, 1919, n), rng.uniform(500, 1199, n)])


def _distort(uv_undistorted, K, dist):
    """Undistorted pixels (K) -> raw pixels, by OpenCV's forward lens model."""
    xn = np.linalg.solve(K, np.c_[uv_undistorted, np.ones(len(uv_undistorted))].T).T
    return cv2.projectPoints(xn, np.zeros(3), np.zeros(3), K, np.asarray(dist, dtype=float))[0].reshape(-1, 2)


def _round_trip_P(cam, P_world, K, dist):
    """pixel -> ground (our reader) -> the file's projection -> pixel; and ground -> pixel -> ground."""
    uv = _pixels()
    bp = cam.backproject(uv)
    assert bp.valid.sum() > 30
    X = np.c_[bp.xy_world_m[bp.valid], np.zeros(bp.valid.sum()), np.ones(bp.valid.sum())]
    q = X @ P_world.T
    uv_file = q[:, :2] / q[:, 2:]  # P maps to undistorted pixels (the file's K)
    raw = _distort(uv_file, K, dist)
    np.testing.assert_allclose(raw, uv[bp.valid], atol=1e-6)
    # ground -> the file's projection -> raw pixel -> ground: under 1 mm
    back = cam.backproject(raw).xy_world_m
    assert np.abs(back - X[:, :2]).max() < 1e-3


def test_station_base_pose():
    d = _read("s040_camera_basler_north_16mm.json")
    with warnings.catch_warnings():
        warnings.simplefilter("error", ConsistencyWarning)
        cam = load_camera(DATA / "s040_camera_basler_north_16mm.json")
    T = np.asarray(d["transformation_sensor_station_base_to_sensor"])
    np.testing.assert_allclose(cam.position_world_m, T[:3, 3], atol=1e-12)
    assert cam.height_m == pytest.approx(7.5) and cam.tilt_deg == pytest.approx(14.0, abs=1e-9)
    assert cam.pan_deg == pytest.approx(30.0, abs=1e-9)  # yaw 60 deg from the base x axis = heading 30 deg
    R_cam_base = (T[:3, :3] @ SENSOR_TO_CV).T
    K = np.asarray(d["intrinsic_camera_matrix"])[:, :3]
    P = K @ np.c_[R_cam_base, -R_cam_base @ T[:3, 3]]
    _round_trip_P(cam, P, K, d["dist_coefficients"])


def test_station_base_rpy_disagreeing_with_the_matrix_is_reported(tmp_path):
    d = _read("s040_camera_basler_north_16mm.json")
    d["rotation_sensor_station_base_to_sensor"]["pitch"] = 12.7
    p = tmp_path / "s040.json"
    p.write_text(json.dumps(d))
    with pytest.warns(ConsistencyWarning, match="disagrees with rotation_matrix_sensor_station_base_to_sensor"):
        cam = load_camera(p)
    assert cam.tilt_deg == pytest.approx(14.0, abs=1e-9)  # the matrix is used


def test_lidar_projection_with_the_lidar_to_base_transform(tmp_path):
    d = _read("s110_camera_basler_south1_8mm_R4.json")
    T = np.asarray(_read("s110_lidar_ouster_south.json")["transformation_matrix_s110_lidar_ouster_south_to_s110_base"])
    K = np.asarray(d["intrinsic_matrix"])
    for kw in ({"lidar_to_base": DATA / "s110_lidar_ouster_south.json"}, {"lidar_to_base": T}, {}):
        with pytest.warns(ConsistencyWarning, match=r"rotation_matrix/translation_matrix not used .*not metres"):
            cam = load_camera(DATA / "s110_camera_basler_south1_8mm_R4.json", **kw)  # {}: the sibling file
        assert cam.height_m == pytest.approx(7.5, abs=1e-6)  # in s110_base, road at z = 0
        _round_trip_P(cam, np.asarray(d["projection_from_s110_lidar_ouster_south"]) @ np.linalg.inv(T), K,
                      d["dist_coefficients"])
    # without the LiDAR's file next to it and no transform: refused, naming what to pass
    shutil.copy(DATA / "s110_camera_basler_south1_8mm_R4.json", tmp_path)
    with pytest.raises(ConfigError, match=r"projection_from_s110_lidar_ouster_south: .*lidar_to_base="):
        load_camera(tmp_path / "s110_camera_basler_south1_8mm_R4.json")


def test_projection_matrix_when_the_extrinsics_are_not_in_metres():
    d = _read("s110_camera_basler_north_8mm.json")
    with pytest.warns(ConsistencyWarning, match="not metres"):
        cam = load_camera(DATA / "s110_camera_basler_north_8mm.json")
    assert cam.height_m == pytest.approx(7.5, abs=1e-6) and np.any(cam.dist)  # P = K [R | t]: distortion kept
    _round_trip_P(cam, np.asarray(d["projection_matrix"]), np.asarray(d["intrinsic_camera_matrix"]),
                  d["dist_coefficients"])


@pytest.mark.parametrize("name,match", [
    ("s110_camera_basler_east_8mm.json", r"rotation_matrix/translation_matrix: got 'camera 526.4 m above the ground, "
                                         r"tilt -13 deg', expected .*not metres\?.*projection_matrix empty.*pose="),
    ("vehicle_camera_basler_16mm.json", "pose: got 'a vehicle camera', expected a camera with a fixed ground pose"),
])
def test_files_without_a_usable_pose_are_refused(name, match):
    with pytest.raises(ConfigError, match=match):
        load_camera(DATA / name)
    r = CliRunner().invoke(main, ["locate", "--camera", str(DATA / name), "--budget", "basler1", "--pixel", "900",
                                  "800"])
    assert r.exit_code == 2 and r.output.count("\n") == 1


def test_half_filled_and_bad_files(tmp_path):
    d = _read("s040_camera_basler_north_16mm.json")
    half = dict(d)
    half["rotation_matrix_sensor_station_base_to_sensor"] = [[-1] * 3] * 3
    (tmp_path / "half.json").write_text(json.dumps(half))
    with pytest.raises(ConfigError, match="no usable extrinsics.*placeholders of -1 in "
                                          "rotation_matrix_sensor_station_base_to_sensor"):
        load_camera(tmp_path / "half.json")
    bad = dict(d)
    bad["translation_sensor_station_base_to_sensor"] = {"x": 1.0, "y": 2.0}
    (tmp_path / "bad.json").write_text(json.dumps(bad))
    with pytest.raises(ConfigError, match=r"translation_sensor_station_base_to_sensor.z: got 'missing'"):
        load_camera(tmp_path / "bad.json")
    up = dict(d)
    c, s_ = np.cos(np.deg2rad(-10.0)), np.sin(np.deg2rad(-10.0))  # pitch -10 deg: looking up
    up["rotation_matrix_sensor_station_base_to_sensor"] = [[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]]
    up.pop("rotation_sensor_station_base_to_sensor")
    (tmp_path / "up.json").write_text(json.dumps(up))
    with pytest.raises(ConfigError, match="above the horizon"):
        load_camera(tmp_path / "up.json")
    lid = _read("s110_camera_basler_south1_8mm_R4.json")
    (tmp_path / "lid.json").write_text(json.dumps(lid))
    (tmp_path / "T.json").write_text(json.dumps({"transformation_matrix_x_to_y": [[1, 0, 0, 0]] * 3 + [[0, 0, 0, 2]]}))
    with pytest.raises(ConfigError, match=r"transformation_matrix_x_to_y\[3\]"):
        load_camera(tmp_path / "lid.json", lidar_to_base=tmp_path / "T.json")
    with pytest.raises(ConfigError, match="lidar_to_base"):
        load_camera(DATA / "s040_camera_basler_north_16mm.json", lidar_to_base=np.eye(4))


# ------------------------------------------------------------------------------------------ DAIR-V2X-I
DAIR = DATA / "dair-v2x-i" / "calib"
ROPE = DATA / "rope3d"


def test_dair_v2x_virtual_lidar_ground():
    intr = json.loads((DAIR / "camera_intrinsic" / "000009.json").read_text())
    ext = json.loads((DAIR / "virtuallidar_to_camera" / "000009.json").read_text())
    cam = load_camera(DAIR / "camera_intrinsic" / "000009.json", image_size_px=(1920, 1080))  # extrinsic: sibling
    assert cam.height_m == pytest.approx(7.5, abs=1e-9)
    K = np.asarray(intr["cam_K"]).reshape(3, 3)
    R, t = np.asarray(ext["rotation"]), np.asarray(ext["translation"]).ravel()
    uv = _pixels(seed=1) * [1.0, 1080 / 1200]
    bp = cam.backproject(uv)
    X = np.c_[bp.xy_world_m[bp.valid], np.zeros(bp.valid.sum())]
    # the file's own projection: virtual LiDAR -> camera -> K with cam_D (OpenCV order)
    uv_file = cv2.projectPoints(X, cv2.Rodrigues(R)[0], t, K, np.asarray(intr["cam_D"]))[0].reshape(-1, 2)
    np.testing.assert_allclose(uv_file, uv[bp.valid], atol=1e-6)
    assert np.abs(cam.backproject(uv_file).xy_world_m - X[:, :2]).max() < 1e-3


def test_dair_v2x_bad_files(tmp_path):
    with pytest.raises(ConfigError, match=r"image size: got 'missing'"):
        load_camera(DAIR / "camera_intrinsic" / "000009.json")
    lone = tmp_path / "000009.json"
    shutil.copy(DAIR / "camera_intrinsic" / "000009.json", lone)
    with pytest.raises(ConfigError, match=r"extrinsic: got 'missing', expected extrinsic="):
        load_camera(lone, image_size_px=(1920, 1080))
    ext = json.loads((DAIR / "virtuallidar_to_camera" / "000009.json").read_text())
    bad = tmp_path / "ext.json"
    bad.write_text(json.dumps({"rotation": ext["rotation"]}))
    with pytest.raises(ConfigError, match="translation: got 'missing'"):
        load_camera(lone, image_size_px=(1920, 1080), extrinsic=bad)
    flipped = dict(ext, translation=[[-v[0]] for v in ext["translation"]])  # camera under the ground
    bad.write_text(json.dumps(flipped))
    with pytest.raises(ConfigError, match="rotation/translation: got 'camera"):
        load_camera(lone, image_size_px=(1920, 1080), extrinsic=bad)
    intr = json.loads(lone.read_text())
    intr["cam_K"] = intr["cam_K"][:8]
    lone.write_text(json.dumps(intr))
    with pytest.raises(ConfigError, match="cam_K"):
        load_camera(lone, image_size_px=(1920, 1080), extrinsic=DAIR / "virtuallidar_to_camera" / "000009.json")


# ------------------------------------------------------------------------------------------ Rope3D
def test_rope3d_denorm_ground():
    calib = next((ROPE / "calib").glob("*.txt"))
    P2 = np.array(calib.read_text().split(":")[1].split(), dtype=float).reshape(3, 4)
    plane = np.array((ROPE / "denorm" / calib.name).read_text().split(), dtype=float)
    cam = load_camera(calib, image_size_px=(1920, 1080))  # denorm: sibling
    assert cam.height_m == pytest.approx(7.5, abs=1e-9) and cam.tilt_deg == pytest.approx(14.0, abs=1e-6)
    uv = _pixels(seed=2) * [1.0, 1080 / 1200]
    bp = cam.backproject(uv)
    Xw = np.c_[bp.xy_world_m[bp.valid], np.zeros(bp.valid.sum())]
    Xc = Xw @ cam.R.T + cam.t
    # on the file's ground plane (to well below 1 mm) and back to the pixel through the file's P2
    assert np.abs(Xc @ plane[:3] + plane[3]).max() / np.linalg.norm(plane[:3]) < 1e-6
    q = np.c_[Xc, np.ones(len(Xc))] @ P2.T
    np.testing.assert_allclose(q[:, :2] / q[:, 2:], uv[bp.valid], atol=1e-6)


def test_rope3d_bad_files(tmp_path):
    calib = next((ROPE / "calib").glob("*.txt"))
    with pytest.raises(ConfigError, match="image size"):
        load_camera(calib)
    (tmp_path / "calib").mkdir()
    (tmp_path / "denorm").mkdir()
    c = tmp_path / "calib" / "x.txt"
    c.write_text(calib.read_text())
    with pytest.raises(ConfigError, match="denorm: got 'missing'"):
        load_camera(c, image_size_px=(1920, 1080))
    (tmp_path / "denorm" / "x.txt").write_text("0 0 0 5\n")
    with pytest.raises(ConfigError, match=r"\(a, b, c\) != 0"):
        load_camera(c, image_size_px=(1920, 1080))
    (tmp_path / "denorm" / "x.txt").write_text("0 1 0\n")
    with pytest.raises(ConfigError, match="4 finite numbers"):
        load_camera(c, image_size_px=(1920, 1080))
    c.write_text("P2: 1 2 3\n")
    with pytest.raises(ConfigError, match="P2: got '1 2 3', expected 12 finite numbers"):
        load_camera(c, image_size_px=(1920, 1080))
