"""footprint-uq's own camera files (YAML or JSON), :func:`load_camera` and the writers.

Two models, keys with units in their names (full description: ``docs/file-formats.md``)::

    model: pan-tilt                     # the paper's camera
    image_size_px: [1920, 1080]         # [width, height]
    focal_px: 1400.0
    principal_point_px: [959.5, 539.5]  # optional, default: image centre
    position_m: [0.0, 0.0]              # optional, camera foot point [x east, y north] in W
    height_m: 6.5                       # above the ground plane
    pan_deg: 30.0                       # compass heading, clockwise from north
    tilt_deg: 12.0                      # below the horizontal
    roll_deg: 0.0                       # optional
    ground_z_m: 0.0                     # optional, height of the ground plane in W

    model: opencv                       # the general model, OpenCV conventions
    image_size_px: [1920, 1200]
    K: [[fx, s, cx], [0, fy, cy], [0, 0, 1]]
    dist: [k1, k2, p1, p2, k3]          # optional: 4, 5 or 8 coefficients
    R: [[...], [...], [...]]            # world -> camera: x_cam = R x_world + t
    t: [tx, ty, tz]                     # (or P: 3x4 = K [R | t] instead of R and t)
    ground_z_m: 0.0                     # optional

:func:`load_camera` also reads OpenCV FileStorage, ROS CameraInfo and TUMTraf/A9
calibration files (format detected from the content); see
:mod:`footprint_uq.io.opencv_files`, :mod:`footprint_uq.io.ros_files` and
:mod:`footprint_uq.io.dataset_files`.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from ..cameras.base import Camera
from ..cameras.opencv import OpenCVCamera
from ..cameras.pantilt import PanTiltCamera
from ..errors import ConfigError, InputError
from ..uncertainty.budget import load_budget
from . import _common as C
from .atomic import atomic_write_text
from .dataset_files import camera_from_dair_v2x, camera_from_rope3d, camera_from_tumtraf_file, read_tumtraf_calibration
from .homography_files import homography_file_from_dict
from .opencv_files import camera_from_opencv_file, read_opencv_file
from .pose import NO_POSE_HELP, pose_camera, read_pose
from .ros_files import camera_from_ros_file, read_ros_camera_info

__all__ = ["load_camera", "load_intrinsics", "save_camera", "save_budget", "camera_from_dict", "camera_to_dict",
           "detect_format", "FORMATS", "PANTILT_KEYS", "OPENCV_KEYS"]

#: formats understood by :func:`load_camera`
FORMATS = ("footprint-uq", "opencv", "ros", "tumtraf", "dair-v2x", "rope3d")

#: keys of a pan-tilt camera file: required, optional
PANTILT_KEYS = (("model", "image_size_px", "focal_px", "height_m", "pan_deg", "tilt_deg"),
                ("principal_point_px", "position_m", "roll_deg", "ground_z_m", "name", "description"))
#: keys of an opencv camera file: required (plus R and t, or P), optional
OPENCV_KEYS = (("model", "image_size_px", "K"), ("dist", "R", "t", "P", "ground_z_m", "name", "description"))

_MODEL_ALIASES = {"pan-tilt": "pan-tilt", "pantilt": "pan-tilt", "pan_tilt": "pan-tilt", "paper": "pan-tilt",
                  "opencv": "opencv", "open-cv": "opencv", "pinhole": "opencv", "homography": "homography"}







def _check_keys(d: dict, where: str, required, optional, model: str) -> None:
    allowed = list(required) + list(optional)
    for k in d:
        if k not in allowed:
            raise ConfigError(C.label(where, str(k)), d[k], C.suggest_key(k, allowed) + f" ({model} camera file)")
    for k in required:
        if k not in d or d[k] is None:
            raise ConfigError(C.label(where, k), "missing", f"a value for '{k}' ({model} camera file, "
                              f"see docs/file-formats.md)")


def _pair(where, field, value):
    return tuple(float(v) for v in C.as_vector(where, field, value, 2))


def camera_from_dict(d: dict, *, where: str = "", ground_z_m=None, image_size_px=None) -> Camera:
    """Build a camera from the content of one of our camera files.

    Parameters
    ----------
    d : dict
        The mapping (see the module docstring / ``docs/file-formats.md``).
    where : str
        Where the mapping came from (file name), prefixed to error messages.
    ground_z_m, image_size_px : optional
        Values to use when the mapping does not give them; a conflicting value is a ConfigError.

    Returns
    -------
    PanTiltCamera or OpenCVCamera

    Raises
    ------
    ConfigError
        Unknown or missing keys (with a suggestion for keys with a wrong or missing
        unit), non-numbers, NaN, zero or negative focal length / height, inconsistent P.
    """
    if not isinstance(d, dict):
        raise ConfigError(where or "camera", type(d).__name__, "a mapping of camera keys")
    if "model" not in d:
        hint = next((f"; did you mean '{C.ALIASES[k]}'?" for k in d if k in ("type", "camera_model")), "")
        raise ConfigError(C.label(where, "model"), "missing", f"'model: pan-tilt' or 'model: opencv'{hint}")
    model = _MODEL_ALIASES.get(str(d["model"]).strip().lower())
    if model is None:
        raise ConfigError(C.label(where, "model"), d["model"], "'pan-tilt', 'opencv' or 'homography'")
    d = dict(d)
    d = _merge_arg(d, "ground_z_m", ground_z_m, where)
    d = _merge_arg(d, "image_size_px", image_size_px, where)
    if model == "pan-tilt":
        return _pantilt_from_dict(d, where)
    if model == "homography":
        return _homography_camera(d, where)
    return _opencv_from_dict(d, where)


def _homography_camera(d, where):
    """``model: homography`` with K: the decomposed camera (footprint_uq.cameras.homography)."""

    f = homography_file_from_dict(d, where=where)
    if f.camera is None:
        raise ConfigError(C.label(where, "K"), "missing",
                          "K to decompose the homography into a camera; a plane mapping without K has no "
                          "22-parameter budget: use footprint_uq.io.homography_files.load_homography")
    return f.camera


def _merge_arg(d, key, value, where):
    if value is None:
        return d
    if d.get(key) is None:
        d[key] = list(value) if key == "image_size_px" else value
        return d
    same = (C.as_image_size(where, key, d[key]) == C.as_image_size("argument", key, value) if key == "image_size_px"
            else C.as_number(where, key, d[key]) == C.as_number("argument", key, value))
    if not same:
        raise ConfigError(C.label(where, key), d[key], f"the value given as argument ({value!r}) or no {key} in "
                          "the file (they conflict)")
    return d


def _pantilt_from_dict(d, where):
    _check_keys(d, where, *PANTILT_KEYS, model="pan-tilt")
    size = C.as_image_size(where, "image_size_px", d["image_size_px"])
    kw = dict(
        focal_px=C.as_number(where, "focal_px", d["focal_px"], positive=True, lo=C.MIN_FOCAL_PX, unit=" (pixels)"),
        image_size_px=size,
        height_m=C.as_number(where, "height_m", d["height_m"], positive=True, unit=" (metres above the ground)"),
        pan_deg=C.as_number(where, "pan_deg", d["pan_deg"], lo=-360, hi=360, unit=" (degrees)"),
        tilt_deg=C.as_number(where, "tilt_deg", d["tilt_deg"], lo=-90, hi=90, unit=" (degrees)"),
        roll_deg=C.as_number(where, "roll_deg", d.get("roll_deg", 0.0), lo=-180, hi=180, unit=" (degrees)"),
        position_m=_pair(where, "position_m", d.get("position_m", (0.0, 0.0))),
        principal_point_px=(None if d.get("principal_point_px") is None
                            else _pair(where, "principal_point_px", d["principal_point_px"])),
        ground_z_m=C.as_number(where, "ground_z_m", d.get("ground_z_m", 0.0), unit=" (metres)"),
    )
    if kw["principal_point_px"] is not None:
        C.check_principal_point(where, *kw["principal_point_px"], size)
    try:
        return PanTiltCamera(**kw)
    except InputError as e:
        raise C.rewrap(e, where) from None


def _opencv_intrinsics_from_dict(d, where):
    """``(K, dist, image_size_px, ground_z_m)`` of a ``model: opencv`` mapping, pose not required."""
    _check_keys(d, where, *OPENCV_KEYS, model="opencv")
    size = C.as_image_size(where, "image_size_px", d["image_size_px"])
    K = C.check_K(where, "K", C.as_matrix(where, "K", d["K"], [(3, 3), (3, 4)]))
    dist = None if d.get("dist") is None else C.as_vector(where, "dist", d["dist"], (0, 4, 5, 8),
                                                           "distortion coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6]])")
    gz = C.as_number(where, "ground_z_m", d.get("ground_z_m", 0.0), unit=" (metres)")
    C.check_principal_point(where, K[0, 2], K[1, 2], size)
    return K, dist, size, gz


def _opencv_from_dict(d, where, pose=None):
    K, dist, size, gz = _opencv_intrinsics_from_dict(d, where)
    has_rt = d.get("R") is not None or d.get("t") is not None
    P = None if d.get("P") is None else C.as_matrix(where, "P", d["P"], (3, 4))
    if pose is not None:
        if has_rt or P is not None:
            raise ConfigError(C.label(where, "pose"), "given as argument",
                              "no pose argument: the file has one (R, t or P)")

        return pose_camera(K, np.zeros(0) if dist is None else dist, size, read_pose(pose),
                          gz if "ground_z_m" in d else None, where)
    if not has_rt and P is None:

        raise ConfigError(C.label(where, "R, t"), "missing",
                          "the pose: R (3x3) and t (3), or P (3x4) in the file, or " + NO_POSE_HELP)
    try:
        if has_rt:
            for k in ("R", "t"):
                if d.get(k) is None:
                    raise ConfigError(C.label(where, k), "missing", "both R (3x3) and t (3) (world -> camera)")
            R = C.as_matrix(where, "R", d["R"], (3, 3))
            t = C.as_vector(where, "t", d["t"], 3, "numbers (metres)")
            C.check_rotation(where, "R", R)
            cam = OpenCVCamera(K, dist, R, t, size, gz)
            if P is not None:
                C.check_projection_matrix(where, "P", P, cam)
            return cam
        cam = OpenCVCamera.from_projection_matrix(P, size, dist, gz)
        C.check_projection_matrix(where, "P", P, _replace_K(cam, K))
        return _replace_K(cam, K)
    except InputError as e:
        if isinstance(e, ConfigError):
            raise
        raise C.rewrap(e, where) from None


def _replace_K(cam: OpenCVCamera, K) -> OpenCVCamera:
    """``cam`` with intrinsic matrix K (same pose and distortion)."""
    return OpenCVCamera(K, cam.dist, cam.R, cam.t, cam.image_size_px, cam.ground_z_m)


# -- writing ----------------------------------------------------------------------------
def _exact_deg(rad: float) -> float:
    """A degree value d with ``deg2rad(d) == rad`` exactly, the shortest such decimal if several.

    ``np.rad2deg`` and ``np.deg2rad`` are not exact inverses in floating point; the
    camera stores radians, the file speaks degrees, and a save/load round trip must
    reproduce the parameters bit for bit.
    """
    rad = float(rad)
    d0 = float(np.rad2deg(rad))
    cands = [d0]
    lo = hi = d0
    for _ in range(64):
        lo, hi = float(np.nextafter(lo, -np.inf)), float(np.nextafter(hi, np.inf))
        cands += [lo, hi]
    exact = [c for c in cands if float(np.deg2rad(c)) == rad]
    if not exact:  # not representable: the closest value (an error of at most 1 ulp of the radians)
        return d0
    return min(exact, key=lambda c: (len(repr(c)), abs(c - d0)))


def camera_to_dict(camera: Camera) -> dict:
    """The camera-file mapping of ``camera`` (plain Python numbers; see ``docs/file-formats.md``)."""
    if isinstance(camera, PanTiltCamera):
        p = camera.params
        return {
            "model": "pan-tilt",
            "image_size_px": [int(v) for v in camera.image_size_px],
            "focal_px": float(p[0]),
            "principal_point_px": [float(p[2]), float(p[3])],
            "position_m": [float(p[13]), float(p[14])],
            "height_m": float(p[15]),
            "pan_deg": _exact_deg(p[16]),
            "tilt_deg": _exact_deg(p[17]),
            "roll_deg": _exact_deg(p[18]),
            "ground_z_m": float(camera.ground_z_m),
        }
    if isinstance(camera, OpenCVCamera):
        dist = camera.dist
        n = 8 if np.any(dist[5:]) else 5
        return {
            "model": "opencv",
            "image_size_px": [int(v) for v in camera.image_size_px],
            "K": camera.K.tolist(),
            "dist": dist[:n].tolist(),
            "R": camera.R.tolist(),
            "t": camera.t.tolist(),
            "ground_z_m": float(camera.ground_z_m),
        }
    to_dict = getattr(camera, "to_dict", None)
    if callable(to_dict):
        return C.sanitize(to_dict())
    raise InputError("camera", type(camera).__name__, "a PanTiltCamera or OpenCVCamera (or a camera with to_dict())")


def _write_mapping(data: dict, path, header: str) -> Path:
    p = Path(path)
    data = C.sanitize(data)
    suffix = p.suffix.lower()
    if suffix == ".json":
        text = json.dumps(data, indent=2, allow_nan=False) + "\n"
    elif suffix in (".yaml", ".yml"):

        text = f"# {header}\n" + yaml.safe_dump(data, sort_keys=False, default_flow_style=None, width=100)
    else:
        raise InputError("path", str(path), "a file name ending in .yaml, .yml or .json")
    p.parent.mkdir(parents=True, exist_ok=True)

    atomic_write_text(p, text)
    return p


def save_camera(camera: Camera, path) -> Path:
    """Write ``camera`` as our camera file, YAML (``.yaml``/``.yml``) or JSON (``.json``).

    The round trip is exact: ``load_camera(save_camera(cam, p)).params`` equals
    ``cam.params`` bit for bit (numbers are written with Python's shortest
    round-tripping representation; angles as the degree values that convert back
    to the stored radians exactly).  Returns the path written.
    """
    return _write_mapping(camera_to_dict(camera), path, "footprint-uq camera file (docs/file-formats.md)")


def save_budget(budget, path) -> Path:
    """Write an error budget (an ErrorBudget, a preset name or a budget mapping) as YAML or JSON.

    Read it back with :func:`footprint_uq.uncertainty.budget.load_budget`.  Returns the path written.
    """

    return _write_mapping(load_budget(budget).to_dict(), path,
                          "footprint-uq error budget: 1-sigma values, units in the key names (docs/file-formats.md)")


# -- reading ----------------------------------------------------------------------------
def detect_format(path, text: str | None = None) -> str:
    """The format of a camera file: one of :data:`FORMATS`, from its content (and extension)."""
    p = Path(path)
    if text is None:
        p, text = C.read_text(p)
    head = text.lstrip()[:200]
    if head.startswith("%YAML:1.") or head.startswith("<?xml") or head.startswith("<opencv_storage") \
            or "!!opencv-matrix" in text or '"opencv-matrix"' in text:
        return "opencv"
    data = C.parse_mapping(text, p)
    return _detect_mapping(data, p)


def _detect_mapping(data: dict, p: Path) -> str:
    if "model" in data:
        return "footprint-uq"
    cm = data.get("camera_matrix")
    if isinstance(cm, dict) and "data" in cm or "distortion_model" in data or "camera_name" in data:
        return "ros"
    tum = ("intrinsic_camera_matrix", "intrinsic_matrix", "intrinsic", "dist_coefficients", "rotation_matrix",
           "translation_matrix", "projection_matrix")
    if any(k in data for k in tum):
        return "tumtraf"
    if "cam_K" in data:
        return "dair-v2x"
    if "P2" in data:
        return "rope3d"
    raise ConfigError(str(p), f"keys {sorted(map(str, data))[:8]}",
                      "a camera file in one of the formats " + ", ".join(FORMATS) +
                      " (ours needs 'model: pan-tilt' or 'model: opencv'; see docs/file-formats.md)")


def load_camera(path, *, format: str | None = None, ground_z_m=None, image_size_px=None, pose=None, **options):
    """Read a camera from a calibration file.

    Parameters
    ----------
    path : str or Path
        The file.
    format : {None, "footprint-uq", "opencv", "ros", "tumtraf"}
        None detects it from the content (OpenCV FileStorage header/tags, our
        ``model`` key, ROS CameraInfo keys, TUMTraf/A9 keys).
    ground_z_m : float, optional
        Height of the ground plane in the file's world frame (default 0 when the
        file does not say; a value conflicting with the file's is a ConfigError).
    image_size_px : (int, int), optional
        (width, height) for files that do not state it; conflicting values raise.
    pose : mapping or path, optional
        The camera pose for intrinsics-only files (OpenCV calibration output, ROS
        CameraInfo, TUMTraf files without extrinsics): a mapping or a YAML/JSON file
        with either ``R`` and ``t`` (world -> camera, OpenCV), ``rvec`` and ``tvec``,
        or ``height_m``, ``pan_deg``, ``tilt_deg`` [, ``roll_deg``, ``position_m``]
        [, ``ground_z_m``].  See :func:`footprint_uq.io.pose.camera_from_intrinsics_and_pose`.
    **options
        Format-specific options (e.g. ``pose_convention`` and ``use`` for TUMTraf files).

    Returns
    -------
    PanTiltCamera or OpenCVCamera

    Raises
    ------
    ConfigError
        Naming the file, the field and what was expected.

    Warns
    -----
    ConsistencyWarning
        For tolerated inconsistencies (P slightly different from K [R | t], principal
        point outside the image, round-off in K, slightly non-orthonormal R).
    """
    p, text = C.read_text(path)
    fmt = format if format is not None else detect_format(p, text)
    if fmt not in FORMATS:
        raise ConfigError("format", format, f"one of {FORMATS} or None (auto-detect)")
    if fmt == "footprint-uq":
        if options:
            raise ConfigError("load_camera options", sorted(options), "no options for our own camera files")
        data = C.parse_mapping(text, p)
        if pose is not None:
            # an intrinsics-only file of ours (e.g. `calibrate intrinsics` output) plus a pose
            if not (isinstance(data, dict) and _MODEL_ALIASES.get(str(data.get("model", "")).strip().lower())
                    == "opencv"):
                raise ConfigError(C.label(str(p), "pose"), "given as argument",
                                  "no pose argument: pan-tilt camera files contain the pose")
            d = _merge_arg(dict(data), "ground_z_m", ground_z_m, str(p))
            d = _merge_arg(d, "image_size_px", image_size_px, str(p))
            return _opencv_from_dict(d, str(p), pose=pose)
        return camera_from_dict(data, where=str(p), ground_z_m=ground_z_m, image_size_px=image_size_px)
    if fmt == "opencv":

        return camera_from_opencv_file(p, ground_z_m=ground_z_m, image_size_px=image_size_px, pose=pose, **options)
    if fmt == "ros":

        return camera_from_ros_file(p, ground_z_m=ground_z_m, image_size_px=image_size_px, pose=pose, **options)
    if fmt == "dair-v2x":

        return camera_from_dair_v2x(p, ground_z_m=ground_z_m, image_size_px=image_size_px, pose=pose, **options)
    if fmt == "rope3d":

        if pose is not None:
            raise ConfigError(C.label(str(p), "pose"), "given as argument", "no pose: the denorm plane gives it")
        return camera_from_rope3d(p, ground_z_m=ground_z_m, image_size_px=image_size_px, **options)

    return camera_from_tumtraf_file(p, ground_z_m=ground_z_m, image_size_px=image_size_px, pose=pose, **options)


def load_intrinsics(path, *, format: str | None = None):
    """The intrinsics of any supported camera file: ``(K (3, 3), dist (n,), image_size_px or None)``.

    For intrinsics-only formats (OpenCV calibration output, ROS CameraInfo, TUMTraf
    files without extrinsics); ``dist`` has the file's length (0, 4, 5 or 8) and
    ``image_size_px`` is None when the file does not state it.  Combine with a pose
    via :func:`footprint_uq.io.camera_from_intrinsics_and_pose`.
    """
    p, text = C.read_text(path)
    fmt = format if format is not None else detect_format(p, text)
    if fmt == "opencv":

        d = read_opencv_file(p)
    elif fmt == "ros":

        d = read_ros_camera_info(p)
    elif fmt == "tumtraf":

        d = read_tumtraf_calibration(p)
    elif fmt == "footprint-uq":
        data = C.parse_mapping(text, p)
        if isinstance(data, dict) and _MODEL_ALIASES.get(str(data.get("model", "")).strip().lower()) == "opencv":
            K, dist, size, _ = _opencv_intrinsics_from_dict(data, str(p))  # the pose may be absent
            return K.copy(), np.zeros(0) if dist is None else np.asarray(dist, dtype=np.float64), tuple(size)
        cam = camera_from_dict(data, where=str(p))
        dist = cam.dist
        return cam.K, dist[: 8 if np.any(dist[5:]) else 5], tuple(cam.image_size_px)
    else:
        raise ConfigError("format", format, f"one of {FORMATS} or None (auto-detect)")
    size = d["image_size_px"]
    return d["K"].copy(), np.asarray(d["dist"], dtype=np.float64).copy(), None if size is None else tuple(size)
