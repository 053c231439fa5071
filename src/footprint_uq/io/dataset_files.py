"""Roadside-dataset calibration JSON: TUMTraf (TUM Traffic) / A9 / Providentia++.

The TUM Traffic dev kit (``tum-traffic-dataset-dev-kit/calib/*.json``) ships one
JSON file per sensor.  Two generations exist:

* **s110 intersection** (TUMTraf Intersection / V2X; ``s110_camera_basler_*_8mm.json``)::

      image_width, image_height            1920, 1200
      intrinsic_camera_matrix              3x3 K of the raw (distorted) image
      dist_coefficients                    [k1, k2, p1, p2, k3]
      rotation_matrix, translation_matrix  world (s110_base, z up) -> camera, OpenCV:
                                           x_cam = R x_world + t
      projection_matrix                    3x4; in the released files it is
                                           calibrated_intrinsic_camera_matrix [R | t],
                                           NOT intrinsic_camera_matrix [R | t]
      optimal_intrinsic_camera_matrix,     other 3x3 / 3x4 intrinsic matrices (undistorted
      calibrated_intrinsic_camera_matrix   images, re-projection); not used

* **A9 highway** (``s040_*/s050_*``, R0/R1 releases): ``intrinsic_camera_matrix`` as
  3x4 with a zero last column, ``dist_coefficients``, and the sensor pose as
  ``rotation_*``/``translation_sensor_station_base_to_sensor`` in a z-up *sensor*
  frame (x forward), not an OpenCV camera frame; these extrinsics are not read:
  such files are intrinsics-only here, the pose must be given (``pose=``).

What is read, in this order:

==============================================  ==============================================
keys                                            meaning
==============================================  ==============================================
intrinsic_camera_matrix | intrinsic_matrix |    K (3x3, or 3x4 with zero last column)
intrinsic | camera_matrix
dist_coefficients | distortion_coefficients |   4, 5 or 8 coefficients (absent: no distortion)
dist_coeffs
image_width, image_height                       image size
rotation_matrix + translation_matrix            world -> camera (OpenCV R, t)
rotation_matrix + translation_vector            world -> camera (OpenCV R, t)
rotation_matrix + translation ({x, y, z}|[3])   camera pose: rotation camera -> world and
                                                camera centre in the world (the inverse)
extrinsic_matrix | transformation_matrix        3x4 / 4x4 world -> camera
projection_matrix                               3x4, checked against K [R | t]; used for the
                                                pose only when no R, t are given
==============================================  ==============================================

``pose_convention="camera_to_world"`` / ``"world_to_camera"`` overrides the
direction implied by the key names.  When the implied direction puts the camera
under the ground or makes it look up while the other direction gives a
plausible roadside camera, a :class:`ConfigError` says so (never a silent flip).
Matrices filled with -1 (placeholders in the dev kit's vehicle files) count as absent.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..cameras.opencv import OpenCVCamera
from ..errors import ConfigError, ConsistencyWarning, InputError
from . import _common as C
from .pose import NO_POSE_HELP, camera_from_intrinsics_and_pose, read_pose

__all__ = ["read_tumtraf_calibration", "camera_from_tumtraf_file", "POSE_CONVENTIONS"]

POSE_CONVENTIONS = ("world_to_camera", "camera_to_world")
_K_KEYS = ("intrinsic_camera_matrix", "intrinsic_matrix", "intrinsic", "camera_matrix")
_D_KEYS = ("dist_coefficients", "distortion_coefficients", "dist_coeffs")
#: (rotation key, translation key, direction implied by the names)
_RT_PAIRS = (("rotation_matrix", "translation_matrix", "world_to_camera"),
             ("rotation_matrix", "translation_vector", "world_to_camera"),
             ("rotation_matrix", "translation", "camera_to_world"))
_T_KEYS = ("extrinsic_matrix", "transformation_matrix")


def _placeholder(value) -> bool:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return a.size > 1 and bool(np.all(a == -1))


def _translation(where, key, value):
    if isinstance(value, dict):
        missing = [k for k in ("x", "y", "z") if k not in value]
        if missing:
            raise ConfigError(C.label(where, f"{key}.{missing[0]}"), "missing", "a mapping {x, y, z} (metres)")
        value = [value["x"], value["y"], value["z"]]
    return C.as_vector(where, key, value, 3, "numbers (metres)")


def read_tumtraf_calibration(path, *, pose_convention: str | None = None) -> dict:
    """Read a TUMTraf/A9-style calibration JSON.

    Returns
    -------
    dict
        ``K`` (3, 3), ``dist`` (n,), ``image_size_px`` or None, ``R``/``t`` (world ->
        camera, OpenCV) or None, ``pose_keys`` (the keys they came from) and
        ``convention``, ``P`` (3, 4) or None, ``alt_K`` (other intrinsic matrices of the
        file by key), ``placeholders`` (keys holding -1 placeholders), ``where``.
    """
    if pose_convention is not None and pose_convention not in POSE_CONVENTIONS:
        raise ConfigError("pose_convention", pose_convention, f"one of {POSE_CONVENTIONS} or None (from the keys)")
    p, d = C.read_mapping(path)
    where = str(p)
    placeholders = sorted(k for k, v in d.items() if _placeholder(v))
    kkey = next((k for k in _K_KEYS if k in d and k not in placeholders), None)
    if kkey is None:
        raise ConfigError(C.label(where, "intrinsic_camera_matrix"), "missing",
                          f"a 3x3 intrinsic matrix under one of {list(_K_KEYS)}")
    out: dict = {"where": where, "placeholders": placeholders, "K_key": kkey}
    out["K"] = C.check_K(where, kkey, C.as_matrix(where, kkey, d[kkey], [(3, 3), (3, 4)]))
    dkey = next((k for k in _D_KEYS if k in d), None)
    out["dist"] = (np.zeros(0) if dkey is None or d[dkey] is None else
                   C.as_vector(where, dkey, d[dkey], (0, 4, 5, 8), "distortion coefficients (k1 k2 p1 p2 [k3 ...])"))
    if "image_width" in d or "image_height" in d:
        out["image_size_px"] = C.as_image_size(where, "image_width, image_height",
                                               [d.get("image_width"), d.get("image_height")])
    else:
        out["image_size_px"] = None
    out["alt_K"] = {}
    for k, v in d.items():
        if k != kkey and "intrinsic" in k and "matrix" in k and k not in placeholders:
            try:
                a = np.asarray(v, dtype=np.float64)
            except (TypeError, ValueError):
                continue
            if a.shape in ((3, 3), (3, 4)) and np.all(np.isfinite(a)):
                out["alt_K"][k] = a[:, :3]
    out["R"] = out["t"] = None
    out["pose_keys"] = None
    for rk, tk, conv in _RT_PAIRS:
        if rk in d and tk in d and rk not in placeholders and tk not in placeholders:
            Rm = C.as_matrix(where, rk, d[rk], (3, 3))
            tv = _translation(where, tk, d[tk])
            out["pose_keys"] = (rk, tk)
            out["convention"] = pose_convention or conv
            out["implied_convention"] = conv
            out["R_file"], out["t_file"] = Rm, tv
            break
    if out["pose_keys"] is None:
        for tk in _T_KEYS:
            if tk in d and tk not in placeholders:
                T = C.as_matrix(where, tk, d[tk], [(4, 4), (3, 4)])
                if T.shape == (4, 4) and np.any(T[3] != [0, 0, 0, 1]):
                    raise ConfigError(C.label(where, f"{tk}[3]"), T[3].tolist(), "[0, 0, 0, 1]")
                out["pose_keys"] = (tk,)
                out["convention"] = pose_convention or "world_to_camera"
                out["implied_convention"] = "world_to_camera"
                out["R_file"], out["t_file"] = T[:3, :3], T[:3, 3]
                break
    if out["pose_keys"] is not None:
        out["R"], out["t"] = _to_world_to_camera(out["R_file"], out["t_file"], out["convention"])
    pk = "projection_matrix"
    out["P"] = C.as_matrix(where, pk, d[pk], (3, 4)) if pk in d and pk not in placeholders else None
    return out


def _to_world_to_camera(R, t, convention):
    if convention == "world_to_camera":
        return R, t
    Rw = R.T
    return Rw, -Rw @ t


def _plausible(R, t, gz) -> tuple[bool, float, float]:
    """(camera above the ground and looking below the horizon, height_m, tilt_deg)."""
    Cw = -R.T @ t
    fwd = R[2]  # boresight in the world
    tilt = float(np.degrees(np.arcsin(np.clip(-fwd[2] / max(np.linalg.norm(fwd), 1e-300), -1, 1))))
    h = float(Cw[2] - gz)
    return h > 0 and tilt > 0, h, tilt


def camera_from_tumtraf_file(path, *, ground_z_m=None, image_size_px=None, pose=None,
                             pose_convention: str | None = None, use: str | None = None):
    """An :class:`OpenCVCamera` from a TUMTraf/A9 calibration JSON.

    Parameters
    ----------
    path : str or Path
    ground_z_m : float, optional
        Height of the road in the file's world frame (e.g. ``s110_base``); default 0.
    image_size_px : (int, int), optional
        Only needed when the file lacks ``image_width``/``image_height``.
    pose : mapping or path, optional
        For files without usable extrinsics (see :func:`footprint_uq.io.load_camera`).
    pose_convention : {None, "world_to_camera", "camera_to_world"}
        Direction of ``rotation_matrix``/translation; None: implied by the key names.
    use : {None, "extrinsics", "projection_matrix"}
        Which pose to use when the file has both R, t and a projection matrix
        (default: the extrinsics, with K and dist; P is then only checked).  With
        ``"projection_matrix"`` the camera is the pinhole ``P`` (K, R, t by RQ
        decomposition) and the file's distortion is not applied (warned if non-zero).
    """
    from .opencv_files import _resolve_size, _with_pose

    if use not in (None, "extrinsics", "projection_matrix"):
        raise ConfigError("use", use, "None, 'extrinsics' or 'projection_matrix'")
    d = read_tumtraf_calibration(path, pose_convention=pose_convention)
    where = d["where"]
    size = _resolve_size(where, d["image_size_px"], image_size_px)
    gz = 0.0 if ground_z_m is None else C.as_number("argument", "ground_z_m", ground_z_m)
    C.check_principal_point(where, d["K"][0, 2], d["K"][1, 2], size)
    has_pose = d["R"] is not None or d["P"] is not None
    if pose is not None:
        if has_pose:
            keys = d["pose_keys"] or ("projection_matrix",)
            raise ConfigError(C.label(where, "pose"), "given as argument",
                              f"no pose argument: the file has one ({', '.join(keys)})")
        return _with_pose(d["K"], d["dist"], size, read_pose(pose), gz, where)
    if not has_pose:
        ph = f" (the file holds placeholders of -1 in {', '.join(d['placeholders'])})" if d["placeholders"] else ""
        raise ConfigError(C.label(where, "pose"), "no usable extrinsics in the file", NO_POSE_HELP + ph)
    if use == "extrinsics" and d["R"] is None:
        raise ConfigError(C.label(where, "rotation_matrix"), "missing", "extrinsics (use='extrinsics')")
    if use == "projection_matrix" and d["P"] is None:
        raise ConfigError(C.label(where, "projection_matrix"), "missing", "a 3x4 projection matrix "
                          "(use='projection_matrix')")
    if d["R"] is not None and use != "projection_matrix":
        cam = _camera_from_extrinsics(d, size, gz, where)
        if d["P"] is not None:
            C.check_projection_matrix(where, "projection_matrix", d["P"], cam, alt_K=d["alt_K"])
        return cam
    try:
        cam = OpenCVCamera.from_projection_matrix(d["P"], size, None, gz)
    except InputError as e:
        raise C.rewrap(e, where) from None
    if d["dist"].size and np.any(d["dist"]):
        warnings.warn(f"{where}: camera taken from projection_matrix (pinhole); the file's distortion "
                      f"{d['dist'].tolist()} is not applied", ConsistencyWarning, stacklevel=2)
    if d["R"] is not None:  # use == "projection_matrix": report how the extrinsics differ
        Rx, tx = d["R"], d["t"]
        ang = float(np.degrees(np.arccos(np.clip((np.trace(cam.R.T @ Rx) - 1) / 2, -1, 1))))
        dC = float(np.linalg.norm(cam.position_world_m - (-Rx.T @ tx)))
        if ang > 1e-6 or dC > 1e-6:
            warnings.warn(f"{where}: projection_matrix pose differs from {'/'.join(d['pose_keys'])} by "
                          f"{ang:.3g} deg and {dC:.3g} m; using projection_matrix", ConsistencyWarning, stacklevel=2)
    return cam


def _camera_from_extrinsics(d, size, gz, where):
    R, t = d["R"], d["t"]
    keys = "/".join(d["pose_keys"])
    ok, h, tilt = _plausible(R, t, gz)
    if not ok:
        other = "camera_to_world" if d["convention"] == "world_to_camera" else "world_to_camera"
        R2, t2 = _to_world_to_camera(d["R_file"], d["t_file"], other)
        ok2, h2, tilt2 = _plausible(R2, t2, gz)
        if ok2:
            raise ConfigError(C.label(where, keys), f"read as {d['convention']}: camera height {h:.3g} m, tilt "
                              f"{tilt:.3g} deg", f"a camera above the ground looking down; read as {other} they give "
                              f"height {h2:.3g} m, tilt {tilt2:.3g} deg: pass pose_convention='{other}'")
    try:
        C.check_rotation(where, d["pose_keys"][0], d["R_file"])
        cam = camera_from_intrinsics_and_pose(d["K"], d["dist"], size, R=R, t=t, ground_z_m=gz, where=where)
    except ConfigError as e:
        raise ConfigError(e.field if where in e.field else C.label(where, keys), e.value, e.expected) from None
    if tilt <= 0:
        warnings.warn(f"{C.label(where, keys)}: the camera looks {-tilt:.3g} deg above the horizon "
                      "(ground points only in the lower image part, if any); check the pose convention",
                      ConsistencyWarning, stacklevel=3)
    return cam
