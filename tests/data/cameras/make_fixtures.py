"""Regenerate the camera-file fixtures of this directory (run from the repository root).

    .venv/bin/python tests/data/cameras/make_fixtures.py

The OpenCV FileStorage files are written by ``cv2.FileStorage`` itself; the other
files are written as text in their formats.  One roadside camera is used
throughout (1920x1200 Basler-like, 8 mm lens, 6.5 m above the road, pan 30 deg,
tilt 12 deg, roll 0.5 deg, at x = 12 m, y = -3.5 m), so that the tests can check
that every format gives the same ground points.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from footprint_uq.cameras.rotation import R_W_C

HERE = Path(__file__).resolve().parent

SIZE = (1920, 1200)
K = np.array([[1402.3, 0.0, 967.8], [0.0, 1400.1, 581.7], [0.0, 0.0, 1.0]])
DIST = np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03])
POSE = {"height_m": 6.5, "pan_deg": 30.0, "tilt_deg": 12.0, "roll_deg": 0.5, "position_m": [12.0, -3.5]}
R = R_W_C(*np.deg2rad([POSE["pan_deg"], POSE["tilt_deg"], POSE["roll_deg"]])).T  # world -> camera
C = np.array([12.0, -3.5, 6.5])
T = -R @ C
RVEC = cv2.Rodrigues(R)[0].ravel()


def opencv_files():
    """As written by OpenCV's calibration sample (samples/cpp/calibration.cpp), plus variants."""
    rng = np.random.default_rng(7)
    board = np.c_[rng.normal(0, 0.3, (12, 3)), rng.normal([0, 0, 2.5], [0.3, 0.2, 0.6], (12, 3))]

    def write(name, extra=None, dist=DIST, fisheye=0):
        fs = cv2.FileStorage(str(HERE / name), cv2.FILE_STORAGE_WRITE)
        fs.write("calibration_time", "Sat 21 Nov 2026 10:12:44 UTC")
        fs.write("nr_of_frames", 12)
        fs.write("image_width", SIZE[0])
        fs.write("image_height", SIZE[1])
        fs.write("board_width", 9)
        fs.write("board_height", 6)
        fs.write("square_size", 0.025)
        fs.write("flags", 0)
        fs.write("fisheye_model", fisheye)
        fs.write("camera_matrix", K)
        fs.write("distortion_coefficients", dist.reshape(-1, 1))
        fs.write("avg_reprojection_error", 0.2873)
        fs.write("extrinsic_parameters", board)
        for k, v in (extra or {}).items():
            fs.write(k, v)
        fs.release()

    write("opencv_calibration.yaml")
    write("opencv_with_pose.yaml", {"rvec": RVEC.reshape(3, 1), "tvec": T.reshape(3, 1)})
    write("opencv_calibration.xml")
    write("broken_opencv_fisheye.yaml", dist=DIST[:4], fisheye=1)
    write("broken_opencv_P_far.yaml", {"R": R, "t": T.reshape(3, 1),
                                       "P": np.diag([1.05, 1.0, 1.0]) @ K @ np.c_[R, T]})


ROS = """image_width: 1920
image_height: 1200
camera_name: s110_camera_south2
camera_matrix:
  rows: 3
  cols: 3
  data: [1402.3, 0, 967.8, 0, 1400.1, 581.7, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.17, 0.12, -0.00012, -0.00235, -0.03]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [1315.2, 0, 962.7, 0, 0, 1362.8, 580.6, 0, 0, 0, 1, 0]
"""

ROS_FISHEYE = ROS.replace("distortion_model: plumb_bob", "distortion_model: equidistant").replace(
    "cols: 5\n  data: [-0.17, 0.12, -0.00012, -0.00235, -0.03]", "cols: 4\n  data: [-0.01, 0.002, 0.0, 0.0]")
ROS_BAD_ROWS = ROS.replace("data: [1402.3, 0, 967.8, 0, 1400.1, 581.7, 0, 0, 1]", "data: [1402.3, 0, 967.8, 0, 1400.1]")

POSE_YAML = """# camera pose for an intrinsics-only calibration (docs/file-formats.md)
height_m: 6.5
pan_deg: 30.0
tilt_deg: 12.0
roll_deg: 0.5
position_m: [12.0, -3.5]
"""

PANTILT_YAML = """# footprint-uq camera file: the paper's pan-tilt camera
model: pan-tilt
image_size_px: [1920, 1200]
focal_px: 1400.0
principal_point_px: [959.5, 599.5]
position_m: [12.0, -3.5]   # x east, y north (world frame W)
height_m: 6.5              # camera centre above the road
pan_deg: 30.0              # compass heading, clockwise from north
tilt_deg: 12.0             # below the horizontal
roll_deg: 0.5
ground_z_m: 0.0
"""


def own_files():
    (HERE / "pantilt.yaml").write_text(PANTILT_YAML)
    pt = {"model": "pan-tilt", "image_size_px": [1920, 1200], "focal_px": 1400.0, "height_m": 6.5, "pan_deg": 30.0,
          "tilt_deg": 12.0, "roll_deg": 0.5, "position_m": [12.0, -3.5]}
    (HERE / "pantilt.json").write_text(json.dumps(pt, indent=2) + "\n")
    oc = {"model": "opencv", "image_size_px": list(SIZE), "K": K.tolist(), "dist": DIST.tolist(), "R": R.tolist(),
          "t": T.tolist(), "ground_z_m": 0.0}
    (HERE / "opencv.json").write_text(json.dumps(oc, indent=2) + "\n")
    import yaml

    (HERE / "opencv.yaml").write_text("# footprint-uq camera file: general OpenCV model, x_cam = R x_world + t\n"
                                      + yaml.safe_dump(oc, sort_keys=False, default_flow_style=None))
    ocP = {"model": "opencv", "image_size_px": list(SIZE), "K": K.tolist(), "dist": DIST.tolist(),
           "P": (K @ np.c_[R, T]).tolist()}
    (HERE / "opencv_P.yaml").write_text("# footprint-uq camera file: pose as a projection matrix P = K [R | t]\n"
                                        + yaml.safe_dump(ocP, sort_keys=False, default_flow_style=None))
    (HERE / "pose.yaml").write_text(POSE_YAML)
    # broken variants of our own format
    broken = {
        "broken_height_no_unit.yaml": PANTILT_YAML.replace("height_m: 6.5 ", "height: 6.5   "),
        "broken_pan_rad.yaml": PANTILT_YAML.replace("pan_deg: 30.0 ", "pan_rad: 0.52 "),
        "broken_negative_focal.yaml": PANTILT_YAML.replace("focal_px: 1400.0", "focal_px: -1400.0"),
        "broken_zero_height.yaml": PANTILT_YAML.replace("height_m: 6.5 ", "height_m: 0.0 "),
        "broken_missing_tilt.yaml": PANTILT_YAML.replace("tilt_deg: 12.0             # below the horizontal\n", ""),
        "broken_pp_outside.yaml": PANTILT_YAML.replace("[959.5, 599.5]", "[1959.5, 599.5]"),
    }
    for name, text in broken.items():
        assert text != PANTILT_YAML, name
        (HERE / name).write_text(text)
    (HERE / "broken_nan.json").write_text(json.dumps({**pt, "tilt_deg": float("nan")}, indent=2) + "\n")
    flip = np.diag([1.0, 1.0, -1.0])
    bad = {
        "broken_det_minus1.yaml": {**oc, "R": (flip @ R).tolist()},
        "broken_K10.yaml": {**oc, "K": [[1402.3, 0.0, 967.8], [3.5, 1400.1, 581.7], [0.0, 0.0, 1.0]]},
        "broken_P_inconsistent.yaml": {**oc, "P": (np.diag([1.05, 1.0, 1.0]) @ K @ np.c_[R, T]).tolist()},
        "broken_not_orthonormal.yaml": {**oc, "R": (R * 1.01).tolist()},
    }
    for name, d in bad.items():
        (HERE / name).write_text(yaml.safe_dump(d, sort_keys=False, default_flow_style=None))
    (HERE / "ros_camera_info.yaml").write_text(ROS)
    (HERE / "broken_ros_fisheye.yaml").write_text(ROS_FISHEYE)
    (HERE / "broken_ros_rows.yaml").write_text(ROS_BAD_ROWS)


def tumtraf_files():
    """Modelled on tum-traffic-dataset-dev-kit/calib/s110_camera_basler_south2_8mm.json (keys, shapes and the
    quirk that projection_matrix = calibrated_intrinsic_camera_matrix [R | t]); the numbers are ours."""
    K_opt = np.array([[1315.2, 0.0, 962.7], [0.0, 1362.8, 580.6], [0.0, 0.0, 1.0]])
    K_cal = np.array([[1029.3, 0.0, 982.0, 0.0], [0.0, 1122.3, 1129.1, 0.0], [0.0, 0.0, 1.0, 0.0]])
    lidar = np.array([[0.2148, -0.9761, 0.0330, -15.87], [0.9763, 0.2155, 0.0209, 2.30],
                      [-0.0275, 0.0277, 0.9992, 7.48], [0.0, 0.0, 0.0, 1.0]])
    Rt = np.c_[R, T]
    d = {
        "image_width": SIZE[0],
        "image_height": SIZE[1],
        "key": "right",
        "info": "right side of image",
        "intrinsic_camera_matrix": K.tolist(),
        "optimal_intrinsic_camera_matrix": K_opt.tolist(),
        "calibrated_intrinsic_camera_matrix": K_cal.tolist(),
        "dist_coefficients": DIST.tolist(),
        "rotation_matrix": R.tolist(),
        "translation_matrix": T.tolist(),
        "transformation_matrix_s110_lidar_ouster_south_to_s110_base": lidar.tolist(),
        "projection_matrix": (K_cal[:, :3] @ Rt).tolist(),
        "relative_vanishing_point": 0.5,
        "projection_from_s110_lidar_ouster_south": (K_cal[:, :3] @ Rt @ np.linalg.inv(lidar)).tolist(),
    }
    (HERE / "tumtraf_s110_camera.json").write_text(json.dumps(d, indent=2) + "\n")
    consistent = {k: v for k, v in d.items() if "calibrated" not in k and "projection_from" not in k}
    consistent["projection_matrix"] = (K @ Rt).tolist()
    (HERE / "tumtraf_consistent.json").write_text(json.dumps(consistent, indent=2) + "\n")
    # the camera pose instead of OpenCV t, under a key whose name implies world -> camera
    pos = {k: v for k, v in consistent.items() if k not in ("translation_matrix", "projection_matrix")}
    pos["rotation_matrix"] = R.T.tolist()
    pos["translation_vector"] = C.tolist()
    (HERE / "broken_tumtraf_position_as_t.json").write_text(json.dumps(pos, indent=2) + "\n")
    # the same pose under 'translation' ({x, y, z}: the sensor pose), which the reader takes as camera -> world
    sensor_pose = dict(pos)
    del sensor_pose["translation_vector"]
    sensor_pose["translation"] = {"x": C[0], "y": C[1], "z": C[2]}
    (HERE / "tumtraf_sensor_pose.json").write_text(json.dumps(sensor_pose, indent=2) + "\n")
    # A9 highway style (s040/s050): 3x4 intrinsics, extrinsics in a z-up sensor frame only -> intrinsics only
    a9 = {
        "image_width": SIZE[0],
        "image_height": SIZE[1],
        "gps_position": {"latitude": 48.2378, "longitude": 11.6375, "altitude": 542.9},
        "translation_sensor_station_base_to_sensor": {"x": -1.67, "y": -12.77, "z": 8.04},
        "rotation_sensor_station_base_to_sensor": {"roll": 1, "pitch": 12.7, "yaw": 64.28},
        "intrinsic_camera_matrix": np.c_[K, np.zeros(3)].tolist(),
        "optimal_intrinsic_camera_matrix": np.c_[K_opt, np.zeros(3)].tolist(),
        "dist_coefficients": DIST.tolist(),
    }
    (HERE / "a9_s040_camera.json").write_text(json.dumps(a9, indent=2) + "\n")
    vehicle = dict(a9)
    vehicle["rotation_matrix"] = [[-1, -1, -1]] * 3
    vehicle["translation_matrix"] = [-1, -1, -1]
    vehicle["projection_matrix"] = [[-1, -1, -1, -1]] * 3
    (HERE / "tumtraf_vehicle_placeholders.json").write_text(json.dumps(vehicle, indent=2) + "\n")


if __name__ == "__main__":
    opencv_files()
    own_files()
    tumtraf_files()
    print("fixtures written to", HERE)
