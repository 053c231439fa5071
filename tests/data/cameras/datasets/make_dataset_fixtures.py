"""Write the dataset calibration fixtures of this directory (run from the repository root).

    .venv/bin/python tests/data/cameras/datasets/make_dataset_fixtures.py

Generated from the public format descriptions (TUMTraf / A9 dev kit ``calib/*.json``,
DAIR-V2X-I ``calib/camera_intrinsic`` + ``calib/virtuallidar_to_camera``, Rope3D
``calib/*.txt`` + ``denorm/*.txt``), with invented numbers: one roadside camera
(1920x1200, f = 1400 px, 7.5 m above the road, heading 60 deg, 14 deg down, roll 0.7 deg)
written the way each file type stores it, so that each reader's ground points can be checked
against the file's own projection.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SIZE = (1920, 1200)
K = np.array([[1400.3, 0.0, 967.8], [0.0, 1403.0, 581.7], [0.0, 0.0, 1.0]])
DIST = [-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03]
C_BASE = np.array([-1.7, 1.15, 7.5])  # camera centre in the station base / s110_base frame (ground z = 0)


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])


def _rot_y(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1.0, 0], [-s, 0, c]])


def _rot_x(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]])


# the A9 sensor frame: x forward, y left, z up; yaw about z (from the base x axis), pitch down positive, roll
YAW, PITCH, ROLL = np.deg2rad([60.0, 14.0, 0.7])
R_BASE_SENSOR = _rot_z(YAW) @ _rot_y(PITCH) @ _rot_x(ROLL)
SENSOR_TO_CV = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
R_BASE_CAM = R_BASE_SENSOR @ SENSOR_TO_CV  # OpenCV camera axes in the base frame
R_CAM_BASE = R_BASE_CAM.T
T_CAM_BASE = -R_CAM_BASE @ C_BASE
# a LiDAR on the same pole, 7.48 m up, turned by 77 deg, slightly tilted
T_BASE_LIDAR = np.eye(4)
T_BASE_LIDAR[:3, :3] = _rot_z(np.deg2rad(77.0)) @ _rot_y(np.deg2rad(1.5)) @ _rot_x(np.deg2rad(-1.6))
T_BASE_LIDAR[:3, 3] = [-15.87, 2.30, 7.48]
SENTINEL_POSE = {"gps_position": {"latitude": -1, "longitude": -1, "altitude": -1},
                 "utm_position": {"north": -1, "east": -1, "zone": "32U"},
                 "translation_sensor_station_base_to_sensor": {"x": -1, "y": -1, "z": -1},
                 "rotation_sensor_station_base_to_sensor": {"roll": -1, "pitch": -1, "yaw": -1},
                 "rotation_quaternion_sensor_station_base_to_sensor": [-1, -1, -1, -1]}
# rotation_matrix/translation_matrix as some released s110 files hold them: a camera looking up and a
# translation in hundreds (not metres); neither direction gives a camera above the road
R_BAD = (_rot_z(np.deg2rad(-104.0)) @ _rot_y(np.deg2rad(-13.0)) @ _rot_x(0.0) @ SENSOR_TO_CV).T
T_BAD = [236.433, 312.179, -987.74]


def _write(name, d):
    (HERE / name).write_text(json.dumps(d, indent=2) + "\n")


def tumtraf():
    P = K @ np.c_[R_CAM_BASE, T_CAM_BASE]
    T_BS = np.eye(4)
    T_BS[:3, :3], T_BS[:3, 3] = R_BASE_SENSOR, C_BASE
    _write("s040_camera_basler_north_16mm.json", {
        "image_width": SIZE[0], "image_height": SIZE[1],
        "gps_position": {"latitude": 48.2378, "longitude": 11.6375, "altitude": 542.9},
        "utm_position": {"north": 5346095.08, "east": 695829.27, "zone": "32U"},
        "translation_sensor_station_base_to_sensor": dict(zip("xyz", C_BASE.tolist(), strict=True)),
        "rotation_sensor_station_base_to_sensor": {"roll": 0.7, "pitch": 14.0, "yaw": 60.0},
        "rotation_matrix_sensor_station_base_to_sensor": R_BASE_SENSOR.tolist(),
        "intrinsic_camera_matrix": np.c_[K, np.zeros(3)].tolist(),
        "dist_coefficients": DIST,
        "transformation_sensor_station_base_to_sensor": T_BS.tolist(),
    })
    P_lidar = P @ T_BASE_LIDAR
    lidar_proj = {
        "image_width": SIZE[0], "image_height": SIZE[1], "intrinsic_matrix": K.tolist(), "dist_coefficients": DIST,
        "rotation_matrix": R_BAD.tolist(), "translation_matrix": T_BAD, "projection_matrix": [],
        "relative_vanishing_point": 0.5, "projection_from_s110_lidar_ouster_south": P_lidar.tolist(),
        "projection_from_s110_lidar_ouster_north": [],
    }
    _write("s110_camera_basler_south1_8mm_R4.json", lidar_proj)
    _write("s110_lidar_ouster_south.json", {
        "projection_matrix_into_s110_camera_basler_south1_8mm": P_lidar.tolist(),
        "transformation_matrix_s110_lidar_ouster_south_to_s110_base": T_BASE_LIDAR.tolist(),
    })
    _write("s110_camera_basler_north_8mm.json", {
        "image_width": SIZE[0], "image_height": SIZE[1], **SENTINEL_POSE,
        "rotation_matrix_sensor_station_base_to_sensor": np.eye(3).tolist(),
        "rotation_matrix": R_BAD.tolist(), "translation_matrix": T_BAD,
        "intrinsic_camera_matrix": K.tolist(), "dist_coefficients": DIST, "projection_matrix": P.tolist(),
    })
    _write("s110_camera_basler_east_8mm.json", {
        "image_width": SIZE[0], "image_height": SIZE[1], **SENTINEL_POSE,
        "rotation_matrix_sensor_station_base_to_sensor": np.eye(3).tolist(),
        "rotation_matrix": R_BAD.tolist(), "translation_matrix": T_BAD,
        "intrinsic_camera_matrix": K.tolist(), "dist_coefficients": DIST, "projection_matrix": [],
    })
    _write("vehicle_camera_basler_16mm.json", {
        "image_width": SIZE[0], "image_height": SIZE[1], **SENTINEL_POSE,
        "rotation_matrix_sensor_station_base_to_sensor": [[-1] * 3] * 3,
        "rotation_matrix": [[-1] * 3] * 3, "translation_matrix": [-1] * 3,
        "intrinsic_camera_matrix": K.tolist(), "dist_coefficients": DIST,
        "transformation_matrix_s110_lidar_ouster_south_to_s110_base": T_BASE_LIDAR.tolist(),
        "projection_matrix": [[-1] * 4] * 3,
    })


K_1080 = np.array([[2183.4, 0.0, 940.6], [0.0, 2179.0, 547.6], [0.0, 0.0, 1.0]])
ROPE3D_ID = "1632_fa2sd4a11North151_420_1613710840_1613716786_1_obstacle"


def dair_v2x():
    """DAIR-V2X-I: calib/camera_intrinsic/<id>.json (cam_K row-major, cam_D) and
    calib/virtuallidar_to_camera/<id>.json (rotation 3x3, translation 3x1; the virtual LiDAR's x-y plane is
    the ground)."""
    root = HERE / "dair-v2x-i" / "calib"
    (root / "camera_intrinsic").mkdir(parents=True, exist_ok=True)
    (root / "virtuallidar_to_camera").mkdir(parents=True, exist_ok=True)
    (root / "camera_intrinsic" / "000009.json").write_text(json.dumps(
        {"cam_D": [-0.25, 0.08, 1.0e-4, -3.0e-4, 0.0], "cam_K": K_1080.ravel().tolist()}, indent=2) + "\n")
    (root / "virtuallidar_to_camera" / "000009.json").write_text(json.dumps(
        {"rotation": R_CAM_BASE.tolist(), "translation": [[v] for v in T_CAM_BASE.tolist()]}, indent=2) + "\n")


def rope3d():
    """Rope3D: calib/<id>.txt ("P2: " 12 numbers, K [I | 0]) and denorm/<id>.txt (a b c d: the ground plane
    in the camera frame; here with the normal pointing down, d < 0, as either sign occurs)."""
    root = HERE / "rope3d"
    (root / "calib").mkdir(parents=True, exist_ok=True)
    (root / "denorm").mkdir(parents=True, exist_ok=True)
    P2 = np.c_[K_1080, np.zeros(3)]
    (root / "calib" / f"{ROPE3D_ID}.txt").write_text("P2: " + " ".join(repr(float(v)) for v in P2.ravel()) + "\n")
    n_up = R_CAM_BASE @ np.array([0.0, 0.0, 1.0])
    plane = -np.r_[n_up, C_BASE[2]]
    (root / "denorm" / f"{ROPE3D_ID}.txt").write_text(" ".join(repr(float(v)) for v in plane) + "\n")


if __name__ == "__main__":
    tumtraf()
    dair_v2x()
    rope3d()
    print("fixtures written to", HERE)
