"""OpenCV FileStorage calibration files (YAML ``%YAML:1.0``/``%YAML 1.2``, XML or JSON).

Read with OpenCV's own reader (:class:`cv2.FileStorage`).  The keys written by
OpenCV's calibration samples (``samples/cpp/calibration.cpp``,
``tutorial_code/calib3d/camera_calibration``) are understood:

==========================  ==========================================================
key (aliases)               use
==========================  ==========================================================
camera_matrix               K, 3x3 ``!!opencv-matrix`` (aliases cameraMatrix, K,
                            intrinsic_matrix)
distortion_coefficients     1xN or Nx1, N in 4, 5, 8 (12/14 accepted when the thin-prism
                            and tilt terms are 0) (aliases distCoeffs, dist_coeffs, D)
image_width, image_height   image size in pixels (or image_size / imageSize: [w, h])
fisheye_model               must be 0/absent: the fisheye model is not supported
rvec + tvec, or R + t / T   optional camera pose, world -> camera (x_cam = R x_world + t)
P / projection_matrix       optional 3x4 ``K [R | t]`` (checked against K, R, t)
extrinsic_parameters        NOT a camera pose: the per-view poses of the calibration
                            board (N x 6); never used as the camera pose
==========================  ==========================================================

A file without a pose needs one from elsewhere (``pose=``), see
:func:`footprint_uq.io.pose.camera_from_intrinsics_and_pose`.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..cameras.opencv import OpenCVCamera
from ..errors import ConfigError, InputError
from . import _common as C
from .pose import (
    NO_POSE_HELP,
    camera_from_intrinsics_and_pose,
    pose_camera,
    read_pose,
    resolve_ground_z,
    resolve_image_size,
)

__all__ = ["read_opencv_file", "camera_from_opencv_file"]

_K_KEYS = ("camera_matrix", "cameraMatrix", "K", "intrinsic_matrix")
_D_KEYS = ("distortion_coefficients", "distCoeffs", "dist_coeffs", "D")
_POSE_PAIRS = (("rvec", "tvec"), ("R", "t"), ("R", "T"))
_P_KEYS = ("P", "projection_matrix")


def _open(path: Path):

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as e:  # parse errors surface as SystemError wrapping cv2.error
        cause = e.__cause__ if isinstance(e, SystemError) and e.__cause__ is not None else e
        msg = str(cause).strip().splitlines()[-1] if str(cause).strip() else type(cause).__name__
        raise ConfigError(str(path), "unreadable", f"an OpenCV FileStorage file ({msg[-160:]})") from None
    if not fs.isOpened():
        raise ConfigError(str(path), "unreadable", "an OpenCV FileStorage file (YAML/XML/JSON)")
    return fs


def _node_value(where: str, key: str, node):
    """The numeric content of a FileStorage node (matrix, sequence or number); None if absent."""

    if node.isNone():
        return None
    if node.isMap():
        try:
            m = node.mat()
        except (cv2.error, SystemError):
            raise ConfigError(C.label(where, key), "malformed matrix",
                              "an !!opencv-matrix whose rows x cols match its data") from None
        if m is None:
            raise ConfigError(C.label(where, key), "a mapping", "a matrix (!!opencv-matrix)")
        return np.asarray(m, dtype=np.float64)
    if node.isSeq():
        vals = []
        for i in range(node.size()):
            item = node.at(i)
            if not (item.isInt() or item.isReal()):
                raise ConfigError(C.label(where, f"{key}[{i}]"), item.string() if item.isString() else "non-number",
                                  "a number")
            vals.append(item.real())
        return np.asarray(vals, dtype=np.float64)
    if node.isInt() or node.isReal():
        return np.float64(node.real())
    raise ConfigError(C.label(where, key), node.string() if node.isString() else "non-numeric", "a number or matrix")


def read_opencv_file(path) -> dict:
    """Read an OpenCV FileStorage calibration file.

    Returns
    -------
    dict
        ``K`` (3, 3); ``dist`` (n,) n in {0, 4, 5, 8}; ``image_size_px`` (w, h) or None;
        ``R``, ``t`` (world -> camera) or None; ``P`` (3, 4) or None; ``n_board_views``
        (rows of ``extrinsic_parameters``, 0 if absent); ``where`` (file name).
    """
    p = Path(path)
    if not p.is_file():
        raise ConfigError("camera file", str(path), "an existing file")
    where = str(p)
    fs = _open(p)
    try:
        keys = set(fs.root().keys()) if fs.root().isMap() else set()

        def get(key):
            return _node_value(where, key, fs.getNode(key)) if key in keys else None

        out: dict = {"where": where}
        kkey = next((k for k in _K_KEYS if k in keys), None)
        if kkey is None:
            raise ConfigError(C.label(where, "camera_matrix"), "missing",
                              f"a 3x3 camera matrix under one of {list(_K_KEYS)} (keys found: {sorted(keys)[:10]})")
        out["K"] = C.check_K(where, kkey, C.as_matrix(where, kkey, get(kkey), [(3, 3), (3, 4)]))
        dkey = next((k for k in _D_KEYS if k in keys), None)
        dist = np.zeros(0) if dkey is None else np.asarray(get(dkey), dtype=np.float64).ravel()
        if dkey is not None:
            if dist.size in (12, 14):
                if np.any(dist[8:] != 0):
                    raise ConfigError(C.label(where, dkey), dist.tolist(),
                                      "at most 8 non-zero coefficients (thin-prism s1..s4 and tilt tx, ty are not "
                                      "supported)")
                dist = dist[:8]
            dist = C.as_vector(where, dkey, dist, (0, 4, 5, 8), "distortion coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6]])")
        out["dist"] = dist
        fish = get("fisheye_model")
        if fish is not None and float(fish) != 0:
            raise ConfigError(C.label(where, "fisheye_model"), float(fish),
                              "0: the fisheye (equidistant) model is not supported")
        w, h = get("image_width"), get("image_height")
        size = get("image_size") if "image_size" in keys else get("imageSize")
        if w is not None or h is not None:
            if w is None or h is None:
                raise ConfigError(C.label(where, "image_width" if w is None else "image_height"), "missing",
                                  "both image_width and image_height")
            out["image_size_px"] = C.as_image_size(where, "image_width, image_height", [float(w), float(h)])
        elif size is not None:
            out["image_size_px"] = C.as_image_size(where, "image_size", np.ravel(size).tolist())
        else:
            out["image_size_px"] = None
        out["R"] = out["t"] = None
        for a, b in _POSE_PAIRS:
            if a in keys or b in keys:
                if a not in keys or b not in keys:
                    raise ConfigError(C.label(where, b if a in keys else a), "missing", f"both {a} and {b}")
                tv = C.as_vector(where, b, get(b), 3, "numbers (metres)")
                if a == "rvec":

                    out["R"] = cv2.Rodrigues(C.as_vector(where, a, get(a), 3, "numbers (radians)").reshape(3, 1))[0]
                else:
                    out["R"] = C.as_matrix(where, a, get(a), (3, 3))
                out["t"] = tv
                out["pose_keys"] = (a, b)
                break
        pkey = next((k for k in _P_KEYS if k in keys), None)
        out["P"] = None if pkey is None else C.as_matrix(where, pkey, get(pkey), (3, 4))
        out["P_key"] = pkey
        ext = get("extrinsic_parameters")
        out["n_board_views"] = 0 if ext is None else int(np.atleast_2d(ext).shape[0])
        gz = get("ground_z_m")
        out["ground_z_m"] = None if gz is None else C.as_number(where, "ground_z_m", float(gz))
        return out
    finally:
        fs.release()


def camera_from_opencv_file(path, *, ground_z_m=None, image_size_px=None, pose=None):
    """An :class:`OpenCVCamera` from an OpenCV FileStorage file (plus ``pose`` when the file has none)."""
    d = read_opencv_file(path)
    where = d["where"]
    size = resolve_image_size(where, d["image_size_px"], image_size_px)
    gz = resolve_ground_z(where, d.get("ground_z_m"), ground_z_m)
    gz0 = 0.0 if gz is None else gz
    if d["R"] is not None:
        if pose is not None:
            raise ConfigError(C.label(where, "pose"), "given as argument",
                              f"no pose argument: the file has one ({', '.join(d['pose_keys'])})")
        cam = camera_from_intrinsics_and_pose(d["K"], d["dist"], size, R=d["R"], t=d["t"], ground_z_m=gz0,
                                              where=where)
        if d["P"] is not None:
            C.check_projection_matrix(where, d["P_key"], d["P"], cam)
        return cam
    if pose is None and d["P"] is not None:

        try:
            fromP = OpenCVCamera.from_projection_matrix(d["P"], size, None, gz0)
            cam = OpenCVCamera(d["K"], d["dist"], fromP.R, fromP.t, size, gz0)
        except InputError as e:
            raise C.rewrap(e, where) from None
        C.check_projection_matrix(where, d["P_key"], d["P"], cam)
        return cam
    if pose is None:
        board = (f" (its extrinsic_parameters are the {d['n_board_views']} calibration-board poses, not the "
                 "camera's pose in the world)" if d["n_board_views"] else "")
        raise ConfigError(C.label(where, "pose"), "the file has intrinsics only", NO_POSE_HELP + board)
    kw = read_pose(pose)
    return pose_camera(d["K"], d["dist"], size, kw, gz, where)
