"""Roadside-dataset calibration files: TUMTraf (TUM Traffic) / A9 / Providentia++, DAIR-V2X-I, Rope3D.

The TUMTraf part is described below; DAIR-V2X-I and Rope3D at :func:`camera_from_dair_v2x` and
:func:`camera_from_rope3d`; every format in ``docs/file-formats.md``.

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
                                           NOT intrinsic_camera_matrix [R | t] (also in the
                                           2023 south2 file that lacks that key: a P with
                                           exactly the pose R, t and another K is warned about)
      optimal_intrinsic_camera_matrix,     other 3x3 / 3x4 intrinsic matrices (undistorted
      calibrated_intrinsic_camera_matrix   images, re-projection); not used

* **A9 highway** (``s040_*/s050_*``, R0/R1 releases): ``intrinsic_camera_matrix`` as
  3x4 with a zero last column, ``dist_coefficients``, and the sensor pose in the
  station-base frame: ``rotation_matrix_sensor_station_base_to_sensor`` (sensor -> base,
  sensor axes x forward, y left, z up) and ``translation_sensor_station_base_to_sensor``
  (the sensor's position, metres); the ground is z = 0 of the base frame.
* **A9 R0** (``s040_*/s050_*`` of the dev kit's 2024-03-06 .. 2024-04-29 releases): ``intrinsic_matrix``,
  ``extrinsic_matrix`` (3x4 world -> camera), ``projection_matrix``, and ``rotation_matrix`` (= the
  extrinsic rotation transposed) with a ``translation`` {x, y, z} given in another frame (its x, y are not
  the camera centre of ``extrinsic_matrix``; its z is the height the projection matrix was built with).
  The pose is ``extrinsic_matrix``; ``translation`` is not used.  In two of the five distinct files the
  projection matrix is ``K extrinsic_matrix`` exactly; in the other three it disagrees by 30-58 px at
  ground points (a 0.1-0.3 deg different rotation, the camera 0.1-0.4 m lower): ``extrinsic_matrix`` is
  used all the same (warned), because its rotation is the file's ``rotation_matrix`` exactly and the
  2024-04-29 release replaced the projection matrix of ``s040_camera_basler_north_16mm`` by
  ``K extrinsic_matrix``, i.e. the authors corrected P towards the extrinsics, not the other way.
* **LiDAR-relative** (``*_R3/_R4``): ``projection_from_<lidar>`` (LiDAR frame -> pixels),
  moved into the base frame with ``transformation_matrix_<lidar>_to_<base>`` (in the file,
  in ``<lidar>.json`` next to it, or ``lidar_to_base=``); the 2023 release's LiDAR files name it
  ``transformation_matrix_into_<base>`` (the LiDAR is the file's own sensor).

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
Matrices filled with -1 (placeholders in the dev kit's vehicle files), mappings whose values are
all -1 and empty lists count as absent; when rotation_matrix/translation give no camera above the
ground (below 300 m) looking down in either direction, another pose of the file is used (warned) or
the file is refused; a ``vehicle_*`` file without a pose is refused as a vehicle camera.
"""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..cameras.opencv import OpenCVCamera
from ..errors import ConfigError, ConsistencyWarning, InputError
from . import _common as C
from .pose import NO_POSE_HELP, camera_from_intrinsics_and_pose, pose_camera, read_pose, resolve_image_size

__all__ = ["read_tumtraf_calibration", "camera_from_tumtraf_file", "POSE_CONVENTIONS", "read_dair_v2x_intrinsics",
           "read_dair_v2x_extrinsics", "camera_from_dair_v2x", "read_rope3d_calibration", "read_denorm",
           "camera_from_rope3d"]

POSE_CONVENTIONS = ("world_to_camera", "camera_to_world")
_K_KEYS = ("intrinsic_camera_matrix", "intrinsic_matrix", "intrinsic", "camera_matrix")
_D_KEYS = ("dist_coefficients", "distortion_coefficients", "dist_coeffs")
#: (rotation key, translation key, direction implied by the names)
_RT_PAIRS = (("rotation_matrix", "translation_matrix", "world_to_camera"),
             ("rotation_matrix", "translation_vector", "world_to_camera"),
             ("rotation_matrix", "translation", "camera_to_world"))
_T_KEYS = ("extrinsic_matrix", "transformation_matrix")


def _placeholder(value) -> bool:
    """A -1 sentinel: every number of a list, or every value of a mapping, is -1 (the dev kit's "absent")."""
    if isinstance(value, dict):
        nums = [v for v in value.values() if not isinstance(v, str)]
        return bool(nums) and all(_placeholder([v]) if not isinstance(v, dict) else _placeholder(v) for v in nums)
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return a.size >= 1 and bool(np.all(a == -1)) and (a.size > 1 or a.ndim >= 1)


def _empty(value) -> bool:
    """An empty list (``"projection_matrix": []``): absent."""
    return isinstance(value, list) and len(value) == 0


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
    empty = sorted(k for k, v in d.items() if _empty(v))
    placeholders_or_empty = set(placeholders) | set(empty)
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
    out["a9_r0"] = _a9_r0_layout(d, where, placeholders)
    for rk, tk, conv in _RT_PAIRS:
        if out["a9_r0"] and tk == "translation":
            continue  # another frame's translation: the pose is extrinsic_matrix (module docstring, "A9 R0")
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
    out["P"] = C.as_matrix(where, pk, d[pk], (3, 4)) if pk in d and pk not in placeholders_or_empty else None
    out["empty"] = empty
    out.update(_station_base(d, where, placeholders_or_empty))
    out["lidar_projections"] = {k[len("projection_from_"):]: C.as_matrix(where, k, v, (3, 4)) for k, v in d.items()
                                if k.startswith("projection_from_") and k not in placeholders_or_empty}
    out["lidar_transforms"] = _lidar_transforms(d, where, placeholders_or_empty)
    out["gps_position"] = (None if "gps_position" not in d or "gps_position" in placeholders
                           else _gps(where, d["gps_position"]))
    out["utm_position"] = (None if "utm_position" not in d or _placeholder(d["utm_position"])
                           else d["utm_position"])
    return out


#: the A9 sensor frame (x forward, y left, z up) -> OpenCV camera axes (x right, y down, z forward):
#: columns of R_world_cam are (-y_sensor, -z_sensor, x_sensor) in the world
_SENSOR_TO_CV = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def _station_base(d, where, absent):
    """The A9 station-base pose: ``rotation_matrix_sensor_station_base_to_sensor`` (sensor -> base rotation,
    sensor axes x forward, y left, z up) and ``translation_sensor_station_base_to_sensor`` (the sensor's
    position in the base frame, metres)."""
    rk, tk = "rotation_matrix_sensor_station_base_to_sensor", "translation_sensor_station_base_to_sensor"
    if rk not in d or tk not in d or rk in absent or tk in absent:
        return {"station_base": None, "station_base_rpy_deg": None}
    Rs = C.as_matrix(where, rk, d[rk], (3, 3))
    C.check_rotation(where, rk, Rs)
    Cb = _translation(where, tk, d[tk])
    R_world_cam = Rs @ _SENSOR_TO_CV
    rpy = d.get("rotation_sensor_station_base_to_sensor")
    rpy = ([C.as_number(where, f"rotation_sensor_station_base_to_sensor.{k}", rpy[k]) for k in ("roll", "pitch", "yaw")]
           if isinstance(rpy, dict) and all(k in rpy for k in ("roll", "pitch", "yaw")) and not _placeholder(rpy)
           else None)
    return {"station_base": (R_world_cam.T, -R_world_cam.T @ Cb), "station_base_rpy_deg": rpy}


def _a9_r0_layout(d, where, placeholders) -> bool:
    """The A9 R0 layout: ``rotation_matrix`` and ``translation`` beside an ``extrinsic_matrix`` whose rotation is
    ``rotation_matrix`` transposed (then ``translation`` is in another frame and the pose is the extrinsic)."""
    keys = ("rotation_matrix", "translation", "extrinsic_matrix")
    if any(k not in d or k in placeholders for k in keys):
        return False
    Rm = C.as_matrix(where, "rotation_matrix", d["rotation_matrix"], (3, 3))
    E = C.as_matrix(where, "extrinsic_matrix", d["extrinsic_matrix"], [(3, 4), (4, 4)])
    return bool(np.allclose(E[:3, :3], Rm.T, rtol=0, atol=1e-6))


def _lidar_transforms(d, where, absent, own_name: str | None = None):
    """``transformation_matrix_<lidar>_to_<base>`` 4x4 (LiDAR -> base) found in a mapping, by LiDAR name; in a
    LiDAR's own file (``own_name``) also the 2023 release's ``transformation_matrix_into_<base>``."""
    out = {}
    for k, v in d.items():
        into = k.startswith("transformation_matrix_into_")
        if into and own_name is None:
            continue
        if k.startswith("transformation_matrix_") and ("_to_" in k or into) and k not in absent:
            if into:
                src, dst = own_name, k[len("transformation_matrix_into_"):]
            else:
                src, _, dst = k[len("transformation_matrix_"):].partition("_to_")
            T = C.as_matrix(where, k, v, (4, 4))
            if np.any(T[3] != [0, 0, 0, 1]):
                raise ConfigError(C.label(where, f"{k}[3]"), T[3].tolist(), "[0, 0, 0, 1]")
            C.check_rotation(where, k, T[:3, :3])
            out[src] = (dst, T)
    return out


def _gps(where, g):
    if not isinstance(g, dict) or any(k not in g for k in ("latitude", "longitude")):
        raise ConfigError(C.label(where, "gps_position"), g, "a mapping {latitude, longitude[, altitude]}")
    return {k: C.as_number(where, f"gps_position.{k}", g[k]) for k in ("latitude", "longitude", "altitude")
            if k in g}


def _to_world_to_camera(R, t, convention):
    if convention == "world_to_camera":
        return R, t
    Rw = R.T
    return Rw, -Rw @ t


#: a camera higher than this above the road is not a roadside camera (translations in cm or mm)
MAX_PLAUSIBLE_HEIGHT_M = 300.0


def _plausible(R, t, gz) -> tuple[bool, float, float]:
    """(camera above the ground (below 300 m) and looking below the horizon, height_m, tilt_deg)."""
    Cw = -R.T @ t
    fwd = R[2]  # boresight in the world
    tilt = float(np.degrees(np.arcsin(np.clip(-fwd[2] / max(np.linalg.norm(fwd), 1e-300), -1, 1))))
    h = float(Cw[2] - gz)
    return 0 < h < MAX_PLAUSIBLE_HEIGHT_M and tilt > 0, h, tilt


_USES = (None, "extrinsics", "projection_matrix", "station_base", "lidar_projection")


def _refuse_no_pose(d: dict, where: str):
    """Raise the error of a file without a usable pose (a vehicle camera, placeholders, or nothing)."""
    if Path(where).name.lower().startswith("vehicle"):
        raise ConfigError(C.label(where, "pose"), "a vehicle camera",
                          "a camera with a fixed ground pose (a vehicle-mounted camera moves with the vehicle: "
                          "its files hold -1 placeholders; give a per-frame pose with pose=)")
    ph = f" (the file holds placeholders of -1 in {', '.join(d['placeholders'])})" if d["placeholders"] else ""
    raise ConfigError(C.label(where, "pose"), "no usable extrinsics in the file", NO_POSE_HELP + ph)


def _check_use(use, d: dict, where: str, lidar) -> None:
    """The pose asked for by ``use`` must be in the file."""
    if use == "extrinsics" and d["R"] is None:
        raise ConfigError(C.label(where, "rotation_matrix"), "missing", "extrinsics (use='extrinsics')")
    if use == "projection_matrix" and d["P"] is None:
        raise ConfigError(C.label(where, "projection_matrix"), "missing", "a 3x4 projection matrix "
                          "(use='projection_matrix')")
    if use == "station_base" and d["station_base"] is None:
        raise ConfigError(C.label(where, "rotation_matrix_sensor_station_base_to_sensor"), "missing",
                          "the station-base pose (use='station_base')")
    if use == "lidar_projection" and lidar is None:
        _require_lidar(d, where)


def _camera_from_file_extrinsics(d: dict, size, gz: float, where: str, use, lidar):
    """The camera of the file's ``rotation_matrix``/translation, or, when they give no camera above the
    ground looking down, of its other pose (warned), or refused."""
    R, t = d["R"], d["t"]
    ok, h, tilt = _plausible(R, t, gz)
    other = "camera_to_world" if d["convention"] == "world_to_camera" else "world_to_camera"
    ok2 = _plausible(*_to_world_to_camera(d["R_file"], d["t_file"], other), gz)[0]
    alt = ("projection_matrix", None) if d["P"] is not None else (
        ("station_base", None) if d["station_base"] is not None else lidar)
    if ok or use == "extrinsics" or (ok2 and alt is None):
        cam = _camera_from_extrinsics(d, size, gz, where)
        if d["P"] is not None and d["a9_r0"]:
            _check_a9_projection(d["P"], cam, where)
        elif d["P"] is not None:
            C.check_projection_matrix(where, "projection_matrix", d["P"], cam, alt_K=d["alt_K"], other_K_ok=True)
        return cam
    # the implied direction gives no camera above the ground looking down: another pose of the file, or refuse
    keys = "/".join(d["pose_keys"])
    scale = float(np.abs(d["t_file"]).max())
    why = f"camera {h:.4g} m above the ground, tilt {tilt:.3g} deg"
    hint = f" (translation values up to {scale:.4g}: not metres?)" if scale > 100 else ""
    if alt is None:
        if d["lidar_projections"]:
            _require_lidar(d, where)
        raise ConfigError(C.label(where, keys), why, "a camera above the ground looking down" + hint +
                          f"; the file has no other pose ({', '.join(d['empty']) or 'no projection_matrix'} "
                          "empty): pass pose=")
    cam = (_camera_from_station_base(d, size, gz, where) if alt[0] == "station_base" else
           _camera_from_P(d["P"] if alt[1] is None else alt[1], size, gz, where, d, alt[0]))
    warnings.warn(f"{where}: {keys} not used ({why}{hint}); camera from {alt[0]}", ConsistencyWarning,
                  stacklevel=3)
    return cam


def _camera_from_file_projection(d: dict, size, gz: float, where: str, use):
    """The pinhole camera of the file's ``projection_matrix``; with ``use="projection_matrix"`` and
    extrinsics in the file too, warns how far their pose differs."""
    cam = _camera_from_P(d["P"], size, gz, where, d, "projection_matrix")
    if d["R"] is not None and use == "projection_matrix":  # report how the extrinsics differ
        Rx, tx = d["R"], d["t"]
        ang = float(np.degrees(np.arccos(np.clip((np.trace(cam.R.T @ Rx) - 1) / 2, -1, 1))))
        dC = float(np.linalg.norm(cam.position_world_m - (-Rx.T @ tx)))
        if ang > 1e-6 or dC > 1e-6:
            warnings.warn(f"{where}: projection_matrix pose differs from {'/'.join(d['pose_keys'])} by "
                          f"{ang:.3g} deg and {dC:.3g} m; using projection_matrix", ConsistencyWarning, stacklevel=3)
    return cam


def camera_from_tumtraf_file(path, *, ground_z_m=None, image_size_px=None, pose=None,
                             pose_convention: str | None = None, use: str | None = None, lidar_to_base=None):
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
    use : {None, "extrinsics", "projection_matrix", "station_base", "lidar_projection"}
        Which pose to use when the file has several (default: the first plausible one of
        rotation_matrix/translation, projection_matrix, the station-base pose, a LiDAR projection).
        With ``"projection_matrix"`` (or a LiDAR projection) the camera is the pinhole of the 3x4
        matrix (K, R, t by RQ decomposition) and the file's distortion is not applied (warned).
    lidar_to_base : path or array_like (4, 4), optional
        For ``projection_from_<lidar>`` matrices: the LiDAR's calibration JSON (with
        ``transformation_matrix_<lidar>_to_<base>``) or the 4x4 LiDAR -> base transform; the
        camera is then in the base frame (e.g. ``s110_base``, ground ``z = 0``).
    """

    if use not in _USES:
        raise ConfigError("use", use, "None, 'extrinsics', 'projection_matrix', 'station_base' or "
                          "'lidar_projection'")
    d = read_tumtraf_calibration(path, pose_convention=pose_convention)
    where = d["where"]
    size = resolve_image_size(where, d["image_size_px"], image_size_px)
    gz = 0.0 if ground_z_m is None else C.as_number("argument", "ground_z_m", ground_z_m)
    C.check_principal_point(where, d["K"][0, 2], d["K"][1, 2], size)
    lidar = _lidar_projection(d, where, lidar_to_base)
    has_pose = (d["R"] is not None or d["P"] is not None or d["station_base"] is not None
                or bool(d["lidar_projections"]))
    if pose is not None:
        if has_pose:
            keys = d["pose_keys"] or ("projection_matrix",)
            raise ConfigError(C.label(where, "pose"), "given as argument",
                              f"no pose argument: the file has one ({', '.join(keys)})")
        return pose_camera(d["K"], d["dist"], size, read_pose(pose), gz, where)
    if not has_pose:
        _refuse_no_pose(d, where)
    _check_use(use, d, where, lidar)
    if use == "station_base":
        return _camera_from_station_base(d, size, gz, where)
    if use == "lidar_projection":
        return _camera_from_P(lidar[1], size, gz, where, d, lidar[0])
    if d["R"] is not None and use != "projection_matrix":
        return _camera_from_file_extrinsics(d, size, gz, where, use, lidar)
    if d["P"] is None:
        if d["station_base"] is not None:
            return _camera_from_station_base(d, size, gz, where)
        if lidar is None:
            _require_lidar(d, where)
        return _camera_from_P(lidar[1], size, gz, where, d, lidar[0])
    return _camera_from_file_projection(d, size, gz, where, use)


def _check_a9_projection(P_file, cam, where):
    """An A9 R0 file's projection matrix against ``K extrinsic_matrix``: silent when equal, else a warning that
    says which is used and why (module docstring, "A9 R0")."""
    P_model = cam.P
    Pn = P_file * float(np.sum(P_model * P_file) / np.sum(P_file * P_file))
    if np.linalg.norm(Pn - P_model) <= C.P_RTOL * np.linalg.norm(P_model):
        return
    _, dpx = C.projection_discrepancy_px(Pn, P_model, cam.image_size_px, cam.position_world_m, cam.ground_z_m)
    if dpx.max() <= C.P_WARN_PX:
        return
    other = OpenCVCamera.from_projection_matrix(P_file, cam.image_size_px, None, cam.ground_z_m)
    warnings.warn(f"{where}: projection_matrix differs from K extrinsic_matrix by up to {dpx.max():.3g} px at ground "
                  f"points (its camera {other.height_m:.3g} m high, tilt {other.tilt_deg:.3g} deg; the extrinsic's "
                  f"{cam.height_m:.3g} m, {cam.tilt_deg:.3g} deg); using K, dist, extrinsic_matrix: its rotation is "
                  "the file's rotation_matrix exactly (translation is in another frame), and the dev kit's "
                  "2024-04-29 release corrected s040_camera_basler_north_16mm's projection_matrix to K "
                  "extrinsic_matrix", ConsistencyWarning, stacklevel=3)


def _camera_from_P(Pm, size, gz, where, d, key):
    """The camera of a 3x4 projection (world frame = its frame).  When its intrinsics are the file's K the
    file's distortion applies; otherwise it is the pinhole of P and the distortion is not applied (warned)."""
    try:
        cam = OpenCVCamera.from_projection_matrix(Pm, size, None, gz)
        _check_roadside(cam, where, key)
        if np.allclose(cam.K, d["K"], rtol=1e-6, atol=1e-6 * abs(d["K"][0, 0])):
            return OpenCVCamera(d["K"], d["dist"], cam.R, cam.t, size, gz)
    except InputError as e:
        if isinstance(e, ConfigError):
            raise
        raise ConfigError(C.label(where, key), e.value, e.expected) from None
    if d["dist"].size and np.any(d["dist"]):
        warnings.warn(f"{where}: camera taken from {key} (pinhole); the file's distortion "
                      f"{d['dist'].tolist()} is not applied", ConsistencyWarning, stacklevel=3)
    return cam


def _check_roadside(cam, where, key):
    """A camera from a matrix of the file must look down at the road from below 300 m, else its frame is not
    the z-up ground frame the reader assumes: refuse, naming the matrix."""
    if cam.height_m >= MAX_PLAUSIBLE_HEIGHT_M:
        raise ConfigError(C.label(where, key), f"camera {cam.height_m:.4g} m above the ground",
                          "a roadside camera (translations in metres?)")
    if cam.tilt_deg <= 0:
        raise ConfigError(C.label(where, key), f"camera looking {-cam.tilt_deg:.3g} deg above the horizon",
                          "a camera looking down at the road (the matrix's frame is not z-up with the road at "
                          "z = 0): pass pose=")


def _camera_from_station_base(d, size, gz, where):
    R, t = d["station_base"]
    key = "rotation_matrix_sensor_station_base_to_sensor"
    try:
        cam = camera_from_intrinsics_and_pose(d["K"], d["dist"], size, R=R, t=t, ground_z_m=gz, where=where)
    except ConfigError as e:
        raise ConfigError(C.label(where, "translation_sensor_station_base_to_sensor"), e.value, e.expected) from None
    _check_roadside(cam, where, key)
    rpy = d.get("station_base_rpy_deg")
    if rpy is not None:
        Rs = R.T @ _SENSOR_TO_CV.T  # sensor -> base
        zyx = np.degrees([np.arctan2(Rs[2, 1], Rs[2, 2]), -np.arcsin(np.clip(Rs[2, 0], -1, 1)),
                          np.arctan2(Rs[1, 0], Rs[0, 0])])
        diff = np.abs((np.asarray(rpy) - zyx + 180.0) % 360.0 - 180.0)
        if diff.max() > 0.5:
            warnings.warn(f"{where}: rotation_sensor_station_base_to_sensor (roll, pitch, yaw) = {list(rpy)} deg "
                          f"disagrees with {key} (z-y-x angles {np.round(zyx, 2).tolist()} deg, up to "
                          f"{diff.max():.3g} deg); the matrix is used", ConsistencyWarning, stacklevel=3)
    return cam


def _load_lidar_transforms(spec):
    """``{lidar: (base, T 4x4)}`` from a LiDAR calibration JSON path or a 4x4 matrix (name None)."""

    if isinstance(spec, (str, Path)):
        p, m = C.read_mapping(spec, what="LiDAR calibration file")
        out = _lidar_transforms(m, str(p), {k for k, v in m.items() if _placeholder(v) or _empty(v)},
                                own_name=p.stem)
        if not out:
            raise ConfigError(C.label(str(p), "transformation_matrix_<lidar>_to_<base>"), "missing",
                              "the LiDAR -> base 4x4 transform (or transformation_matrix_into_<base>)")
        return out
    T = C.as_matrix("lidar_to_base", "T", spec, (4, 4))
    if np.any(T[3] != [0, 0, 0, 1]):
        raise ConfigError("lidar_to_base[3]", T[3].tolist(), "[0, 0, 0, 1]")
    C.check_rotation("lidar_to_base", "T", T[:3, :3])
    return {None: (None, T)}


def _lidar_projection(d, where, lidar_to_base):
    """``(key, P_base)``: a ``projection_from_<lidar>`` moved into the base frame, or None."""
    if not d["lidar_projections"]:
        if lidar_to_base is not None:
            raise ConfigError("lidar_to_base", str(lidar_to_base)[:60], f"a file with a projection_from_<lidar> "
                              f"matrix ({where} has none)")
        return None
    transforms = dict(d["lidar_transforms"])
    if lidar_to_base is not None:
        transforms.update(_load_lidar_transforms(lidar_to_base))

    for name in d["lidar_projections"]:
        sibling = Path(where).parent / f"{name}.json"  # the dev kit's calib/ folder holds the LiDAR's file
        if name not in transforms and lidar_to_base is None and sibling.is_file():
            transforms.update(_load_lidar_transforms(sibling))
    for name, Pl in d["lidar_projections"].items():
        T = transforms.get(name) or (transforms.get(None) if len(d["lidar_projections"]) == 1 else None)
        if T is not None:
            return f"projection_from_{name}", Pl @ np.linalg.inv(T[1])
    return None


def _require_lidar(d, where):
    names = ", ".join(f"projection_from_{n}" for n in d["lidar_projections"]) or "projection_from_<lidar>"
    lid = next(iter(d["lidar_projections"]), "<lidar>")
    raise ConfigError(C.label(where, names), "a projection from a LiDAR frame only",
                      f"the LiDAR -> ground-frame transform: lidar_to_base='{lid}.json' (the LiDAR's calibration "
                      f"file with transformation_matrix_{lid}_to_<base>) or a 4x4 matrix; the LiDAR frame's ground "
                      "is not z = 0")


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


# ---------------------------------------------------------------------------------------------
# DAIR-V2X-I: calib/camera_intrinsic/{id}.json + calib/virtuallidar_to_camera/{id}.json
# ---------------------------------------------------------------------------------------------
def _sibling(path, folder: str, suffix: str | None = None):
    """``<dataset>/calib/<folder>/<id>`` next to ``<dataset>/calib/<this folder>/<id>`` (None if absent)."""

    p = Path(path)
    cand = p.parent.parent / folder / (p.name if suffix is None else p.stem + suffix)
    return cand if cand.is_file() else None


def read_dair_v2x_intrinsics(path) -> dict:
    """DAIR-V2X-I ``camera_intrinsic`` JSON: ``cam_K`` (9 numbers, row-major K), ``cam_D`` (k1 k2 p1 p2 k3,
    OpenCV order), optional ``width``/``height``.  Returns ``K``, ``dist``, ``image_size_px`` (or None)."""
    p, d = C.read_mapping(path)
    where = str(p)
    for k in ("cam_K",):
        if k not in d or _empty(d[k]):
            raise ConfigError(C.label(where, k), "missing", "the 9 numbers of K (row-major), DAIR-V2X camera_intrinsic")
    K = C.check_K(where, "cam_K", C.as_matrix(where, "cam_K", d["cam_K"], (3, 3)))
    dist = (np.zeros(0) if d.get("cam_D") is None or _empty(d["cam_D"]) else
            C.as_vector(where, "cam_D", d["cam_D"], (4, 5, 8), "distortion coefficients (k1 k2 p1 p2 [k3 ...])"))
    size = None
    if d.get("width") is not None or d.get("height") is not None:
        size = C.as_image_size(where, "width, height", [d.get("width"), d.get("height")])
    return {"where": where, "K": K, "dist": dist, "image_size_px": size}


def read_dair_v2x_extrinsics(path) -> dict:
    """DAIR-V2X-I ``virtuallidar_to_camera`` JSON: ``rotation`` (3x3) and ``translation`` (3x1) mapping the
    virtual-LiDAR frame to the camera (``x_cam = R x_lidar + t``, metres)."""
    p, d = C.read_mapping(path, what="extrinsic file")
    where = str(p)
    for k in ("rotation", "translation"):
        if k not in d or _empty(d[k]) or _placeholder(d[k]):
            raise ConfigError(C.label(where, k), "missing", "rotation (3x3) and translation (3x1) of "
                              "virtuallidar_to_camera")
    R = C.as_matrix(where, "rotation", d["rotation"], (3, 3))
    C.check_rotation(where, "rotation", R)
    t = C.as_vector(where, "translation", np.asarray(d["translation"], dtype=object).ravel().tolist()
                    if isinstance(d["translation"], list) else d["translation"], 3, "numbers (metres)")
    return {"where": where, "R": R, "t": t}


def camera_from_dair_v2x(path, *, extrinsic=None, image_size_px=None, ground_z_m=None, pose=None):
    """An :class:`OpenCVCamera` from a DAIR-V2X-I camera: intrinsic JSON + ``virtuallidar_to_camera`` JSON.

    The world frame is the *virtual LiDAR* frame, whose x-y plane is the ground (z up): ground points come
    out in it.  ``extrinsic`` defaults to ``../virtuallidar_to_camera/<same name>`` (the dataset's layout).
    """

    d = read_dair_v2x_intrinsics(path)
    where = d["where"]
    size = resolve_image_size(where, d["image_size_px"], image_size_px)
    gz = 0.0 if ground_z_m is None else C.as_number("argument", "ground_z_m", ground_z_m)
    if pose is not None:
        return pose_camera(d["K"], d["dist"], size, read_pose(pose), gz, where)
    ext = extrinsic if extrinsic is not None else _sibling(path, "virtuallidar_to_camera")
    if ext is None:
        raise ConfigError(C.label(where, "extrinsic"), "missing",
                          "extrinsic='.../virtuallidar_to_camera/<id>.json' (not found next to calib/camera_intrinsic) "
                          "or pose=")
    e = read_dair_v2x_extrinsics(ext)
    ok, h, tilt = _plausible(e["R"], e["t"], gz)
    if not ok:
        raise ConfigError(C.label(e["where"], "rotation/translation"), f"camera {h:.4g} m above the ground, tilt "
                          f"{tilt:.3g} deg", "a camera above the virtual-LiDAR ground (z = 0) looking down")
    return camera_from_intrinsics_and_pose(d["K"], d["dist"], size, R=e["R"], t=e["t"], ground_z_m=gz, where=where)


# ---------------------------------------------------------------------------------------------
# Rope3D: calib/{id}.txt (KITTI-style "P2: 12 numbers") + denorm/{id}.txt (ground plane a b c d)
# ---------------------------------------------------------------------------------------------
def _numbers_line(where, field, text, n):
    try:
        vals = [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise ConfigError(C.label(where, field), text.strip()[:60], f"{n} numbers") from None
    if len(vals) != n or not np.all(np.isfinite(vals)):
        raise ConfigError(C.label(where, field), text.strip()[:60], f"{n} finite numbers")
    if np.any(np.abs(vals) > C.MAX_MAGNITUDE):  # the camera files' limit: beyond it products overflow
        raise ConfigError(C.label(where, field), text.strip()[:60], f"{n} numbers of magnitude <= {C.MAX_MAGNITUDE:g}")
    return np.array(vals)


def read_rope3d_calibration(path) -> dict:
    """Rope3D / KITTI calibration text: the line ``P2: p00 ... p23`` (3x4, camera frame -> pixels)."""
    p, text = C.read_text(path)
    where = str(p)
    lines = {ln.split(":", 1)[0].strip(): ln.split(":", 1)[1] for ln in text.splitlines() if ":" in ln}
    if "P2" not in lines:
        raise ConfigError(C.label(where, "P2"), "missing", "a line 'P2: ' with the 12 numbers of the 3x4 projection")
    P2 = _numbers_line(where, "P2", lines["P2"], 12).reshape(3, 4)
    return {"where": where, "P2": P2}


def read_denorm(path) -> np.ndarray:
    """Rope3D ``denorm`` text: the ground plane ``a x + b y + c z + d = 0`` in the camera frame (4 numbers),
    normalised to a unit normal pointing to the camera's side (``d > 0`` is the camera height)."""
    p, text = C.read_text(path)
    where = str(p)
    g = _numbers_line(where, "denorm", text, 4)
    n = np.linalg.norm(g[:3])
    if n == 0:
        raise ConfigError(C.label(where, "denorm"), g.tolist(), "a plane a b c d with (a, b, c) != 0")
    g = g / n
    if g[3] == 0:
        raise ConfigError(C.label(where, "denorm"), g.tolist(), "a ground plane not through the camera (d != 0)")
    return g if g[3] > 0 else -g


def camera_from_rope3d(path, *, denorm=None, image_size_px=None, ground_z_m=None):
    """An :class:`OpenCVCamera` from a Rope3D camera: ``calib/<id>.txt`` (P2) + ``denorm/<id>.txt``.

    The world frame W is built from the ground plane: z up along the plane's normal, origin at the
    camera's foot point, +y (north, pan 0) the boresight's direction on the ground, +x to its right;
    the camera is ``d`` metres above the plane.  ``P2`` must be ``K [I | t]`` (a camera-frame projection).
    ``denorm`` defaults to ``../denorm/<same name>``; the image size is not in the files (Rope3D: 1920x1080)
    and must be given.
    """

    d = read_rope3d_calibration(path)
    where = d["where"]
    size = resolve_image_size(where, None, image_size_px)
    if ground_z_m not in (None, 0, 0.0):
        raise ConfigError("ground_z_m", ground_z_m, "none: the ground of a Rope3D camera is its denorm plane (z = 0)")
    dn = denorm if denorm is not None else _sibling(path, "denorm")
    if dn is None:
        raise ConfigError(C.label(where, "denorm"), "missing",
                          "denorm='.../denorm/<id>.txt' (the ground plane; not found next to calib/)")
    g = read_denorm(dn)
    P2 = d["P2"]
    K = P2[:, :3].copy()
    if abs(K[1, 0]) > 1e-9 * abs(K[0, 0]) or abs(K[2, 0]) > 1e-12 or abs(K[2, 1]) > 1e-12 or K[2, 2] <= 0:
        raise ConfigError(C.label(where, "P2"), P2.tolist(), "K [I | t] with an upper-triangular K (a projection "
                          "from the camera frame)")
    K = K / K[2, 2]
    c_ref = -np.linalg.solve(P2[:, :3], P2[:, 3])  # the camera centre in the reference (denorm) frame
    n, h = g[:3], float(g[:3] @ c_ref + g[3])
    if h <= 0:
        raise ConfigError(C.label(str(dn), "denorm"), f"camera {h:.4g} m above the plane", "a camera above the ground")
    fwd = np.array([0.0, 0.0, 1.0]) - n[2] * n  # boresight projected on the ground
    if np.linalg.norm(fwd) < 1e-6:
        raise ConfigError(C.label(str(dn), "denorm"), g.tolist(), "a camera not looking straight down")
    fwd /= np.linalg.norm(fwd)
    B = np.column_stack([np.cross(fwd, n), fwd, n])  # world axes (east, north, up) in the camera frame
    if B[:, 1] @ np.array([0.0, 0.0, 1.0]) <= 0 or np.array([0.0, 0.0, 1.0]) @ n >= 0:
        raise ConfigError(C.label(str(dn), "denorm"), g.tolist(), "a camera looking down at the plane")
    # x_ref = B x_world + (c_ref - h n) (the foot point), x_cam = x_ref - c_ref: world -> camera is (B, -h n)
    try:
        return OpenCVCamera(K, None, B, -h * n, size, 0.0)
    except InputError as e:
        raise C.rewrap(e, where) from None
