"""ROS ``sensor_msgs/CameraInfo`` calibration YAML (``camera_calibration_parsers`` format).

As written by the ROS ``camera_calibration`` package (``ost.yaml``) and read by
``camera_info_manager``::

    image_width: 1920
    image_height: 1200
    camera_name: roadside_cam
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob            # or rational_polynomial (8 coefficients)
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
    rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
    projection_matrix: {rows: 3, cols: 4, data: [fx', 0, cx', Tx, 0, fy', cy', Ty, 0, 0, 1, 0]}

Used: ``camera_matrix`` (K of the raw image), ``distortion_model`` and
``distortion_coefficients``, ``image_width``/``image_height``.  The
``projection_matrix`` of a CameraInfo is the intrinsic matrix of the *rectified*
image (not a world pose) and is not used; a non-identity ``rectification_matrix``
(a stereo pair) is reported with a :class:`ConsistencyWarning`, since the raw-image
intrinsics used here ignore it.  CameraInfo carries no world pose: pass ``pose=``.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import ConfigError, ConsistencyWarning
from . import _common as C
from .pose import NO_POSE_HELP, pose_camera, read_pose, resolve_ground_z, resolve_image_size

__all__ = ["read_ros_camera_info", "ros_camera_info", "camera_from_ros_info", "camera_from_ros_file",
           "ROS_DISTORTION_MODELS"]

#: distortion_model -> accepted numbers of coefficients
ROS_DISTORTION_MODELS = {"plumb_bob": (0, 4, 5), "rational_polynomial": (0, 8), "": (0,)}


def _ros_matrix(where, key, node, shape=None):
    if not isinstance(node, dict) or "data" not in node:
        if isinstance(node, (list, tuple)):  # flat CameraInfo message dump (K: [9 numbers])
            data = node
            rows = cols = None
        else:
            raise ConfigError(C.label(where, key), node, "a mapping {rows, cols, data}")
    else:
        data = node["data"]
        rows, cols = node.get("rows"), node.get("cols")
    try:
        a = np.asarray(data if data is not None else [], dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise ConfigError(C.label(where, f"{key}.data"), data, "a list of numbers") from None
    if rows is not None and cols is not None:
        r, c = int(C.as_number(where, f"{key}.rows", rows)), int(C.as_number(where, f"{key}.cols", cols))
        if r * c != a.size:
            raise ConfigError(C.label(where, f"{key}.data"), f"{a.size} numbers",
                              f"rows x cols = {r} x {c} = {r * c} numbers")
        if shape is not None and (r, c) != shape:
            raise ConfigError(C.label(where, key), f"{r}x{c}", f"a {shape[0]}x{shape[1]} matrix")
        a = a.reshape(r, c)
    elif shape is not None:
        if a.size != shape[0] * shape[1]:
            raise ConfigError(C.label(where, key), f"{a.size} numbers", f"{shape[0] * shape[1]} numbers")
        a = a.reshape(shape)
    if not np.all(np.isfinite(a)):
        raise ConfigError(C.label(where, f"{key}.data"), a.ravel().tolist(), "finite numbers")
    return a


def read_ros_camera_info(path) -> dict:
    """Read a ROS CameraInfo YAML: ``{"K", "dist", "image_size_px", "camera_name", "where"}``."""
    p, d = C.read_mapping(path)
    return ros_camera_info(d, str(p))


def ros_camera_info(d: dict, where: str) -> dict:
    """The CameraInfo mapping ``d`` (a YAML file's, or a ``sensor_msgs/msg/CameraInfo`` message's fields ``k``,
    ``d``, ``r``, ``distortion_model``, ``width``, ``height``) checked: ``{"K", "dist", "image_size_px",
    "camera_name", "where"}`` (errors name ``where``)."""
    kkey = "camera_matrix" if "camera_matrix" in d else ("K" if "K" in d else "k" if "k" in d else None)
    if kkey is None:
        raise ConfigError(C.label(where, "camera_matrix"), "missing", "a {rows: 3, cols: 3, data: [9 numbers]} "
                          "mapping (ROS CameraInfo)")
    K = C.check_K(where, kkey, _ros_matrix(where, kkey, d[kkey], (3, 3)))
    model = d.get("distortion_model", "plumb_bob")
    model = "" if model is None else str(model)
    dkey = next((k for k in ("distortion_coefficients", "D", "d") if k in d), None)
    dist = np.zeros(0) if dkey is None or d[dkey] is None else _ros_matrix(where, dkey, d[dkey]).ravel()
    if model not in ROS_DISTORTION_MODELS:
        raise ConfigError(C.label(where, "distortion_model"), model,
                          f"one of {sorted(k for k in ROS_DISTORTION_MODELS if k)} (the equidistant/fisheye model "
                          "is not supported)")
    if dist.size not in ROS_DISTORTION_MODELS[model] and not (model == "" and not np.any(dist)):
        raise ConfigError(C.label(where, dkey or "distortion_coefficients"), dist.tolist(),
                          f"{' or '.join(map(str, ROS_DISTORTION_MODELS[model]))} coefficients for "
                          f"distortion_model {model!r}")
    if model == "" and dist.size and not np.any(dist):
        dist = np.zeros(0)
    w = d.get("image_width", d.get("width"))
    h = d.get("image_height", d.get("height"))
    if w is None or h is None or (w == 0 and h == 0):  # 0 x 0: size not set (an uncalibrated CameraInfo)
        size = None
    else:
        size = C.as_image_size(where, "image_width, image_height", [w, h])
    rkey = next((k for k in ("rectification_matrix", "R", "r") if k in d), None)
    if rkey is not None and d[rkey] is not None:
        Rr = _ros_matrix(where, rkey, d[rkey], (3, 3))
        if np.abs(Rr - np.eye(3)).max() > 1e-9:
            warnings.warn(f"{C.label(where, rkey)} is not the identity (a stereo rectification): ignored; the camera "
                          "uses camera_matrix and distortion of the raw image", ConsistencyWarning, stacklevel=2)
    if size is not None:
        C.check_principal_point(where, K[0, 2], K[1, 2], size)
    return {"K": K, "dist": dist, "image_size_px": size, "camera_name": d.get("camera_name"), "where": where}


def camera_from_ros_file(path, *, ground_z_m=None, image_size_px=None, pose=None):
    """An :class:`OpenCVCamera` from a ROS CameraInfo YAML and a ``pose`` (CameraInfo has none)."""
    return camera_from_ros_info(read_ros_camera_info(path), ground_z_m=ground_z_m, image_size_px=image_size_px,
                                pose=pose)


def camera_from_ros_info(d: dict, *, ground_z_m=None, image_size_px=None, pose=None):
    """An :class:`OpenCVCamera` from a checked CameraInfo (:func:`ros_camera_info`) and a ``pose``."""
    where = d["where"]
    size = resolve_image_size(where, d["image_size_px"], image_size_px)
    if pose is None:
        raise ConfigError(C.label(where, "pose"), "a ROS CameraInfo file has intrinsics only", NO_POSE_HELP)
    return pose_camera(d["K"], d["dist"], size, read_pose(pose), resolve_ground_z(where, None, ground_z_m), where)
