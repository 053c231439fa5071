"""Intrinsics from one place, pose from another: :func:`camera_from_intrinsics_and_pose`.

Calibration tools (OpenCV's calibration samples, ROS ``camera_calibration``) write
only the intrinsics; the camera's pose in the world comes from a survey, a PnP
solution or the mounting plan.  A pose is either

* ``R``, ``t``: OpenCV world -> camera (``x_cam = R x_world + t``), or ``rvec``, ``tvec``
  (Rodrigues vector and translation, as returned by ``cv2.solvePnP``), or
* ``height_m``, ``pan_deg``, ``tilt_deg`` [, ``roll_deg``, ``position_m``]: the paper's
  parametrisation (pan = compass heading, tilt positive down, see ``docs/conventions.md``),

with an optional ``ground_z_m``.  A pose file is a YAML/JSON mapping of these keys.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from ..cameras.opencv import OpenCVCamera
from ..cameras.rotation import R_W_C
from ..errors import ConfigError, InputError
from . import _common as C

__all__ = ["camera_from_intrinsics_and_pose", "read_pose", "POSE_KEYS"]

POSE_KEYS = ("R", "t", "rvec", "tvec", "height_m", "pan_deg", "tilt_deg", "roll_deg", "position_m", "ground_z_m")

NO_POSE_HELP = ("a camera pose: on the command line --pose-file FILE, or --height-m H --pan-deg P --tilt-deg T "
                "[--roll-deg R --position-m X Y] (or `footprint-uq camera compose` to write a full camera file); "
                "in Python pose={'height_m': .., 'pan_deg': .., 'tilt_deg': .., ['roll_deg', 'position_m']} or "
                "pose={'R': 3x3, 't': 3} (world -> camera), or pose='pose.yaml' with those keys "
                "(docs/file-formats.md)")


def read_pose(pose, *, where: str = "pose") -> dict:
    """Validate a pose mapping (or read a pose file) into keyword arguments of
    :func:`camera_from_intrinsics_and_pose`."""
    if isinstance(pose, (str, Path)):
        p, d = C.read_mapping(pose, what="pose file")
        where = str(p)
    elif isinstance(pose, dict):
        d = pose
    else:
        raise ConfigError(where, type(pose).__name__, "a pose mapping or the path of a YAML/JSON pose file")
    for k in d:
        if k not in POSE_KEYS:
            raise ConfigError(C.label(where, str(k)), d[k], C.suggest_key(k, POSE_KEYS) + " (pose)")
    out = {k: v for k, v in d.items() if v is not None}
    out["where"] = where
    return out


def camera_from_intrinsics_and_pose(K, dist, image_size_px, *, R=None, t=None, rvec=None, tvec=None,
                                    height_m=None, pan_deg=None, tilt_deg=None, roll_deg=0.0,
                                    position_m=(0.0, 0.0), ground_z_m=0.0, where: str = "") -> OpenCVCamera:
    """An :class:`OpenCVCamera` from intrinsics and a pose given separately.

    Parameters
    ----------
    K : array_like (3, 3)
        Intrinsic matrix, pixels.
    dist : array_like (0, 4, 5 or 8,) or None
        OpenCV distortion coefficients (k1, k2, p1, p2[, k3[, k4, k5, k6]]).
    image_size_px : (int, int)
        (width, height).
    R, t : array_like (3, 3), (3,), optional
        World -> camera rotation and translation (OpenCV, metres); world frame W Z up.
    rvec, tvec : array_like (3,), optional
        The same pose as a Rodrigues vector (radians) and translation.
    height_m, pan_deg, tilt_deg, roll_deg, position_m : optional
        The same pose in the paper's terms: camera centre ``height_m`` above the
        ground plane at ``position_m`` (x east, y north), pan = compass heading,
        tilt positive down (degrees).
    ground_z_m : float
        Height of the ground plane in W.
    where : str
        Prefix of error messages (file name).

    Exactly one of (R, t), (rvec, tvec), (height_m, pan_deg, tilt_deg) must be given.

    Returns
    -------
    OpenCVCamera
    """
    groups = {"R, t": (R, t), "rvec, tvec": (rvec, tvec), "height_m, pan_deg, tilt_deg": (height_m, pan_deg, tilt_deg)}
    given = [name for name, vals in groups.items() if any(v is not None for v in vals)]
    if not given:
        raise ConfigError(C.label(where, "pose"), "missing", NO_POSE_HELP)
    if len(given) > 1:
        raise ConfigError(C.label(where, "pose"), f"both {given[0]} and {given[1]}", "one pose only")
    name = given[0]
    missing = [n for n, v in zip(name.split(", "), groups[name], strict=True) if v is None]
    if missing:
        raise ConfigError(C.label(where, missing[0]), "missing", f"all of {name} together")
    size = C.as_image_size(where, "image_size_px", image_size_px)
    K = C.check_K(where, "K", C.as_matrix(where, "K", K, [(3, 3), (3, 4)]))
    if dist is not None:
        dist = C.as_vector(where, "dist", dist, (0, 4, 5, 8), "distortion coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6]])")
    gz = C.as_number(where, "ground_z_m", ground_z_m, unit=" (metres)")
    if name == "R, t":
        R = C.as_matrix(where, "R", R, (3, 3))
        t = C.as_vector(where, "t", t, 3, "numbers (metres)")
    elif name == "rvec, tvec":

        rv = C.as_vector(where, "rvec", rvec, 3, "numbers (Rodrigues vector, radians)")
        t = C.as_vector(where, "tvec", tvec, 3, "numbers (metres)")
        R = cv2.Rodrigues(rv.reshape(3, 1))[0]
    else:
        h = C.as_number(where, "height_m", height_m, positive=True, unit=" (metres above the ground)")
        pan = C.as_number(where, "pan_deg", pan_deg, lo=-360, hi=360, unit=" (degrees)")
        tilt = C.as_number(where, "tilt_deg", tilt_deg, lo=-90, hi=90, unit=" (degrees)")
        roll = C.as_number(where, "roll_deg", roll_deg, lo=-180, hi=180, unit=" (degrees)")
        xy = C.as_vector(where, "position_m", position_m, 2, "numbers (metres)")
        R = R_W_C(*np.deg2rad([pan, tilt, roll])).T
        t = -R @ np.array([xy[0], xy[1], gz + h])
    C.check_rotation(where, "R", R)
    C.check_principal_point(where, K[0, 2], K[1, 2], size)
    try:
        return OpenCVCamera(K, dist, R, t, size, gz)
    except InputError as e:
        raise C.rewrap(e, where) from None


def pose_camera(K, dist, size, kw: dict, gz, where):
    """The camera of intrinsics ``K``, ``dist`` and image ``size`` at the pose ``kw`` (:func:`read_pose`);
    a ground height in the pose must agree with ``gz`` (the file's or the caller's)."""
    pose_where = kw.pop("where", "pose")
    if "ground_z_m" in kw:
        gz_pose = C.as_number(pose_where, "ground_z_m", kw.pop("ground_z_m"))
        if gz is not None and gz_pose != gz:
            raise ConfigError(C.label(pose_where, "ground_z_m"), gz_pose, f"the same ground_z_m as given ({gz})")
        gz = gz_pose
    try:
        return camera_from_intrinsics_and_pose(K, dist, size, ground_z_m=0.0 if gz is None else gz,
                                               where=pose_where, **kw)
    except TypeError as e:  # pragma: no cover - read_pose filters the keys
        raise ConfigError(pose_where, str(e), "pose keys") from None


def resolve_image_size(where, from_file, given):
    """The image size: the file's, the caller's, or both when they agree (else :class:`ConfigError`)."""
    if from_file is None and given is None:
        raise ConfigError(C.label(where, "image size"), "missing", "image_size_px=(width, height) as argument "
                          "(the file does not state the image size)")
    if given is None:
        return from_file
    g = C.as_image_size("argument", "image_size_px", given)
    if from_file is not None and g != tuple(from_file):
        raise ConfigError(C.label(where, "image size"), list(from_file),
                          f"the image_size_px given as argument {list(g)} (intrinsics are calibrated for one "
                          "resolution; rescale K explicitly for another)")
    return g


def resolve_ground_z(where, from_file, given):
    """The ground height: the file's, the caller's, or both when they agree (else :class:`ConfigError`)."""
    if given is None:
        return from_file
    g = C.as_number("argument", "ground_z_m", given)
    if from_file is not None and g != from_file:
        raise ConfigError(C.label(where, "ground_z_m"), from_file, f"the ground_z_m given as argument ({g})")
    return g
