"""Shared helpers of the file readers: reading YAML/JSON, field checks, consistency checks.

Every error names the file and the field (``"cam.yaml: K"``) and what was expected;
every inconsistency that is tolerated is reported as a
:class:`~footprint_uq.errors.ConsistencyWarning`, never dropped silently.
"""

from __future__ import annotations

import difflib
import math
import warnings
from pathlib import Path

import numpy as np

from .._files import file_kind, read_input_text
from .._parse import load_yaml_or_json
from ..errors import ConfigError, ConsistencyWarning, InputError

__all__ = [
    "label", "read_mapping", "as_matrix", "as_vector", "as_number", "as_image_size", "rewrap",
    "check_K", "check_rotation", "check_principal_point", "projection_discrepancy_px",
    "check_projection_matrix", "P_RTOL", "P_FAR_PX", "P_WARN_PX", "sanitize",
]

#: relative tolerance (Frobenius, after normalising the scale) under which P == K [R | t] silently
P_RTOL = 1e-6
#: largest pixel discrepancy between P and K [R | t] that is only a warning; beyond it a ConfigError
P_FAR_PX = 5.0
#: smallest focal length of a camera file, pixels: below one pixel the image spans nearly 180 degrees in every
#: direction and the kernels' products underflow (focal_px 1e-300 ran with 15 RuntimeWarnings)
MIN_FOCAL_PX = 1.0
#: pixel discrepancy (everywhere) below which P is taken as K [R | t] printed with fewer digits
P_WARN_PX = 0.05
#: largest magnitude of any number of a camera or pose file (metres, pixels, degrees): beyond it
#: products overflow to inf and results turn into "valid" NaNs (issue 11); projected map
#: coordinates (UTM, ECEF: ~1e7 m) stay far below it
MAX_MAGNITUDE = 1e9
#: largest image side accepted, pixels
MAX_IMAGE_SIDE_PX = 1_000_000


def label(where: str, field: str) -> str:
    """``"file: field"`` or ``"field"``."""
    return f"{where}: {field}" if where else field


def rewrap(e: InputError, where: str) -> ConfigError:
    """An InputError from a camera constructor as a ConfigError naming the file."""
    return ConfigError(label(where, e.field), e.value, e.expected)


def read_text(path) -> tuple[Path, str]:
    p = Path(path)
    if file_kind(p) not in ("regular file", "FIFO"):  # a FIFO: read once, as a stream (never a hang)
        raise ConfigError("camera file", str(path), "an existing file" if not p.exists() else
                          f"a regular file or a FIFO (got a {file_kind(p) or 'path that cannot be read'})")
    try:
        return p, read_input_text(p, "camera file")
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(str(p), type(e).__name__, f"a readable UTF-8 text file ({e})") from None


def parse_mapping(text: str, path: Path, *, what: str = "camera file") -> dict:
    """Parse YAML or JSON text (by extension; YAML otherwise) into a mapping."""
    try:
        data = load_yaml_or_json(text, str(path), is_json=path.suffix.lower() == ".json")
    except ConfigError:  # alias bomb, duplicate key, too large: already named
        raise
    except Exception as e:  # yaml.YAMLError / json.JSONDecodeError, with their one-line reason
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ConfigError(str(path), type(e).__name__, f"a valid {'JSON' if path.suffix.lower() == '.json' else 'YAML'}"
                          f" {what} ({first})") from None
    if not isinstance(data, dict):
        raise ConfigError(str(path), type(data).__name__, f"a mapping of keys ({what})")
    return data


def read_mapping(path, *, what: str = "camera file") -> tuple[Path, dict]:
    p, text = read_text(path)
    return p, parse_mapping(text, p, what=what)


def as_matrix(where: str, field: str, value, shapes) -> np.ndarray:
    """A finite float matrix of one of ``shapes`` (a flat list of the right size is reshaped to the first)."""
    shapes = [shapes] if isinstance(shapes[0], int) else list(shapes)
    desc = " or ".join(f"{r}x{c}" for r, c in shapes)
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(label(where, field), value, f"a numeric {desc} matrix") from None
    if a.shape not in shapes:
        match = [s for s in shapes if a.size == s[0] * s[1]]
        if a.ndim == 1 and match:
            a = a.reshape(match[0])
        else:
            raise ConfigError(label(where, field), f"shape {a.shape}", f"a {desc} matrix")
    if not np.all(np.isfinite(a)):
        bad = tuple(int(i) for i in np.argwhere(~np.isfinite(a))[0])
        raise ConfigError(label(where, f"{field}[{', '.join(map(str, bad))}]"), float(a[bad]), "a finite number")
    _check_magnitude(where, field, a)
    return a


def _check_magnitude(where: str, field: str, a: np.ndarray) -> None:
    big = np.abs(a) > MAX_MAGNITUDE
    if np.any(big):
        i = tuple(int(k) for k in np.argwhere(big)[0])
        name = f"{field}[{', '.join(map(str, i))}]" if a.ndim else field
        raise ConfigError(label(where, name), float(a[i]), f"a number of magnitude <= {MAX_MAGNITUDE:g}")


def as_vector(where: str, field: str, value, sizes, what: str = "numbers") -> np.ndarray:
    sizes = (sizes,) if isinstance(sizes, int) else tuple(sizes)
    desc = " or ".join(map(str, sizes))
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(label(where, field), value, f"a list of {desc} {what}") from None
    if a.ndim == 2 and 1 in a.shape:
        a = a.ravel()
    if a.ndim != 1 or a.size not in sizes:
        raise ConfigError(label(where, field), value if a.size < 20 else f"shape {a.shape}", f"a list of {desc} {what}")
    if not np.all(np.isfinite(a)):
        i = int(np.argwhere(~np.isfinite(a))[0, 0])
        raise ConfigError(label(where, f"{field}[{i}]"), float(a[i]), "a finite number")
    _check_magnitude(where, field, a)
    return a


def as_number(where: str, field: str, value, *, positive: bool = False, lo=None, hi=None, unit: str = "") -> float:
    if isinstance(value, bool) or value is None or isinstance(value, (list, dict, tuple)):
        raise ConfigError(label(where, field), value, f"a number{unit}")
    try:
        x = float(value)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(label(where, field), value, f"a number{unit}") from None
    if not math.isfinite(x):
        raise ConfigError(label(where, field), value, f"a finite number{unit}")
    if abs(x) > MAX_MAGNITUDE:
        raise ConfigError(label(where, field), value, f"a number of magnitude <= {MAX_MAGNITUDE:g}{unit}")
    if positive and not x > 0:
        raise ConfigError(label(where, field), value, f"a number > 0{unit}")
    if lo is not None and x < lo:
        raise ConfigError(label(where, field), value, f"a number >= {lo}{unit}")
    if hi is not None and x > hi:
        raise ConfigError(label(where, field), value, f"a number <= {hi}{unit}")
    return x


def as_image_size(where: str, field: str, value) -> tuple[int, int]:
    expected = "[width, height]: two positive integers (pixels)"
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != 2:
        raise ConfigError(label(where, field), value, expected)
    out = []
    for v in value:
        if isinstance(v, bool):
            raise ConfigError(label(where, field), value, expected)
        try:
            f = float(v)
        except (TypeError, ValueError, OverflowError):
            raise ConfigError(label(where, field), value, expected) from None
        if not math.isfinite(f) or f != int(f) or f <= 0 or f > MAX_IMAGE_SIDE_PX:
            raise ConfigError(label(where, field), value, f"{expected}, at most {MAX_IMAGE_SIDE_PX}")
        out.append(int(f))
    return out[0], out[1]


# -- consistency checks -------------------------------------------------------------------
def check_K(where: str, field: str, K: np.ndarray) -> np.ndarray:
    """Validate an intrinsic matrix (3x3, or 3x4 with a zero last column); return the 3x3 K.

    ``K[1, 0]``, ``K[2, 0]``, ``K[2, 1]`` must be 0 and ``K[2, 2]`` 1.  Round-off residue
    (below 1e-9 of the focal length) is set to 0 with a :class:`ConsistencyWarning`;
    anything larger is a :class:`ConfigError` (such a matrix is not a pinhole K).
    """
    K = np.array(K, dtype=np.float64)
    if K.shape == (3, 4):
        if np.any(K[:, 3] != 0):
            raise ConfigError(label(where, field), K.tolist(),
                              "a 3x3 intrinsic matrix, or 3x4 with a zero last column")
        K = K[:, :3].copy()
    if K.shape != (3, 3):
        raise ConfigError(label(where, field), f"shape {K.shape}", "a 3x3 intrinsic matrix")
    if not np.all(np.isfinite(K)):
        raise ConfigError(label(where, field), K.tolist(), "finite numbers")
    if K[2, 2] != 1.0 and K[2, 2] > 0 and abs(K[2, 2] - 1.0) <= 1e-12:
        K[2, 2] = 1.0
    fx, fy = K[0, 0], K[1, 1]
    if not (fx >= MIN_FOCAL_PX and fy >= MIN_FOCAL_PX):
        raise ConfigError(label(where, f"{field} (fx, fy)"), (float(fx), float(fy)),
                          f"focal lengths >= {MIN_FOCAL_PX:g} px")
    scale = max(fx, fy)
    if K[2, 2] != 1.0:
        raise ConfigError(label(where, f"{field}[2][2]"), float(K[2, 2]), "1 ([[fx, s, cx], [0, fy, cy], [0, 0, 1]])")
    for (i, j), ref in (((1, 0), scale), ((2, 0), 1.0), ((2, 1), 1.0)):
        v = K[i, j]
        if v == 0:
            continue
        if abs(v) <= 1e-9 * ref:
            warnings.warn(f"{label(where, field)}[{i}][{j}] = {v:.3g} (round-off) set to 0", ConsistencyWarning,
                          stacklevel=3)
            K[i, j] = 0.0
        else:
            raise ConfigError(label(where, f"{field}[{i}][{j}]"), float(v),
                              "0: an intrinsic matrix is upper triangular [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
    return K


def check_rotation(where: str, field: str, R: np.ndarray, *, tol: float = 1e-3) -> None:
    """Reject reflections (det = -1) and clearly non-orthonormal matrices with a one-line ConfigError.

    Small departures (up to ``tol``) are left to :class:`OpenCVCamera`, which warns and re-orthonormalises.
    """
    err = float(np.abs(R @ R.T - np.eye(3)).max())
    det = float(np.linalg.det(R))
    if det < 0:
        raise ConfigError(label(where, field), f"det = {det:.4g}",
                          "a rotation (det +1); det -1 is a reflection: a left-handed frame (e.g. y down or "
                          "north-east-down world) must be converted to the Z-up world first")
    if err > tol:
        raise ConfigError(label(where, field), f"|R R^T - I| = {err:.3g}", f"an orthonormal rotation matrix "
                          f"(|R R^T - I| <= {tol:g})")


def check_principal_point(where: str, cx: float, cy: float, image_size_px) -> None:
    w, h = image_size_px
    if not (-0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        warnings.warn(f"{label(where, 'principal point')} ({cx:g}, {cy:g}) px lies outside the "
                      f"{w}x{h} image: wrong image size or intrinsics of another resolution?",
                      ConsistencyWarning, stacklevel=3)


def _test_points(image_size_px) -> np.ndarray:
    w, h = image_size_px
    return np.array([[(w - 1) / 2, (h - 1) / 2], [0.0, h - 1.0], [w - 1.0, h - 1.0], [0.0, (h - 1) / 2],
                     [w - 1.0, (h - 1) / 2]])


def projection_discrepancy_px(P_file: np.ndarray, P_model: np.ndarray, image_size_px, C: np.ndarray,
                              ground_z_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Where two projection matrices disagree, in pixels, at a few ground points.

    The test points are the ground points seen by ``P_model`` at the image centre,
    bottom corners and left/right middle (those below the horizon; otherwise points
    at 10 and 30 m in front of the camera).  Returns ``(uv_model (n, 2), distance_px (n,))``.
    """
    M = P_model[:, :3]
    uv = _test_points(image_size_px)
    rays = np.linalg.solve(M, np.c_[uv, np.ones(len(uv))].T).T  # directions in world
    # orient the rays forward (positive depth)
    depth = (P_model[2, :3] @ rays.T)
    rays = rays * np.sign(depth)[:, None]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (ground_z_m - C[2]) / rays[:, 2]
    ok = np.isfinite(s) & (s > 0)
    X = C + s[:, None] * rays
    if not np.any(ok):
        fwd = P_model[2, :3] / np.linalg.norm(P_model[2, :3])
        X = np.array([C + d * fwd for d in (10.0, 30.0)])
    else:
        X = X[ok]
    Xh = np.c_[X, np.ones(len(X))]

    def proj(Pm):
        q = Xh @ Pm.T
        return q[:, :2] / q[:, 2:3]

    a, b = proj(P_model), proj(P_file)
    return a, np.linalg.norm(a - b, axis=1)


def check_projection_matrix(where: str, field: str, P_file: np.ndarray, camera, *, alt_K: dict | None = None,
                            far_px: float = P_FAR_PX, other_K_ok: bool = False) -> None:
    """Compare a file's 3x4 ``P`` with ``K [R | t]`` of ``camera``.

    ``P`` is normalised to the scale of ``K [R | t]`` (its sign and magnitude are
    free in homogeneous coordinates).  Within :data:`P_RTOL` (relative) nothing is
    said; otherwise the discrepancy in pixels at a few image points decides: up to
    ``far_px`` a :class:`ConsistencyWarning`, beyond a :class:`ConfigError`.  When
    ``alt_K`` maps other intrinsic-matrix keys of the file to their matrices and one
    of them explains ``P`` exactly, the message says so.  With ``other_K_ok`` (TUMTraf s110 files, whose P is
    documented as another intrinsic matrix times [R | t]) a P with exactly the camera's pose and another
    intrinsic matrix is warned about, not refused, even when the file does not hold that matrix.
    """
    P_model = camera.P
    scale = float(np.sum(P_model * P_file) / np.sum(P_file * P_file))
    Pn = P_file * scale
    rel = float(np.linalg.norm(Pn - P_model) / np.linalg.norm(P_model))
    if rel <= P_RTOL:
        return
    uv, d = projection_discrepancy_px(Pn, P_model, camera.image_size_px, camera.position_world_m,
                                      camera.ground_z_m)
    if d.max() <= P_WARN_PX:  # print precision of P: below 0.05 px everywhere
        return
    detail = ", ".join(f"({round(u)}, {round(v)}): {e:.3g} px" for (u, v), e in zip(uv, d, strict=True))
    explained = ""
    for key, K_alt in (alt_K or {}).items():
        try:
            P_alt = K_alt @ np.hstack([camera.R, camera.t[:, None]])
        except ValueError:
            continue
        s = float(np.sum(P_alt * P_file) / np.sum(P_file * P_file))
        if np.linalg.norm(P_file * s - P_alt) <= 1e-6 * np.linalg.norm(P_alt):
            explained = f"; {field} equals {key} [R | t] instead"
            break
    if not explained and other_K_ok:
        explained = _same_pose_other_K(P_file, camera, field)
    if d.max() <= far_px or explained:
        warnings.warn(f"{label(where, field)} differs from K [R | t] (relative {rel:.2g}; at ground points seen at "
                      f"pixels {detail}){explained}; using K, dist, R, t", ConsistencyWarning, stacklevel=3)
        return
    raise ConfigError(label(where, field), f"{d.max():.3g} px away from K [R | t]",
                      f"a projection matrix consistent with K [R | t] within {far_px:g} px (ground points seen at "
                      f"pixels {detail})")


def _same_pose_other_K(P_file, camera, field) -> str:
    """``"; FIELD has the pose R, t exactly ..."`` when the RQ decomposition of ``P_file`` gives the camera's
    rotation and centre (1e-9 relative) with another intrinsic matrix (the 2023 TUMTraf south2 file: P is
    the later releases' calibrated_intrinsic_camera_matrix [R | t], a key that file does not have); else ``""``."""
    M = np.asarray(P_file, dtype=np.float64)[:, :3]
    if not np.all(np.isfinite(M)) or abs(np.linalg.det(M)) < 1e-300:
        return ""
    Kp, Rp = np.linalg.qr(np.linalg.inv(M))  # inv(M) = inv(R) inv(K): Q = R^T, upper triangular = inv(K)
    Rq = Kp.T
    K_p = np.linalg.inv(Rp)
    sign = np.diag(np.sign(np.diag(K_p)))  # positive focal lengths
    K_p, Rq = K_p @ sign, sign @ Rq
    if np.linalg.det(Rq) < 0:
        Rq, K_p = -Rq, -K_p
    C_p = -np.linalg.solve(M, np.asarray(P_file, dtype=np.float64)[:, 3])
    C_m = camera.position_world_m
    same = (np.allclose(Rq, camera.R, rtol=0, atol=1e-9)
            and np.linalg.norm(C_p - C_m) <= 1e-9 * max(1.0, float(np.linalg.norm(C_m))))
    if not same:
        return ""
    K_p = K_p / K_p[2, 2]
    return (f"; {field} has the pose R, t exactly, with another intrinsic matrix (fx {K_p[0, 0]:.6g}, fy "
            f"{K_p[1, 1]:.6g}, cx {K_p[0, 2]:.6g}, cy {K_p[1, 2]:.6g} px)")


def sanitize(obj):
    """numpy scalars/arrays -> plain Python floats/ints/lists (for YAML/JSON writers)."""
    if isinstance(obj, dict):
        return {str(k): sanitize(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [sanitize(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return sanitize(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj)
    return obj


#: unit suffixes of keys and what they spell
UNITS = {"m": "metres", "mm": "millimetres", "cm": "centimetres", "km": "kilometres", "ft": "feet",
          "px": "pixels", "pix": "pixels", "pixel": "pixels", "pixels": "pixels", "deg": "degrees",
          "degrees": "degrees", "rad": "radians", "radians": "radians", "meters": "metres", "metres": "metres",
          "meter": "metres", "metre": "metres"}
KEY_UNIT = {"image_size_px": "px", "focal_px": "px", "principal_point_px": "px", "position_m": "m",
             "height_m": "m", "pan_deg": "deg", "tilt_deg": "deg", "roll_deg": "deg", "ground_z_m": "m"}
ALIASES = {
    "focal": "focal_px", "focal_length": "focal_px", "focal_length_px": "focal_px", "f": "focal_px",
    "f_px": "focal_px", "fx": "focal_px", "fy": "focal_px", "focal_length_mm": "focal_px",
    "height": "height_m", "camera_height": "height_m", "mounting_height": "height_m", "h": "height_m",
    "altitude": "height_m", "pan": "pan_deg", "yaw": "pan_deg", "heading": "pan_deg", "azimuth": "pan_deg",
    "tilt": "tilt_deg", "pitch": "tilt_deg", "roll": "roll_deg", "position": "position_m", "xy": "position_m",
    "location": "position_m", "principal_point": "principal_point_px", "pp": "principal_point_px",
    "cx": "principal_point_px", "cy": "principal_point_px", "center": "principal_point_px",
    "image_size": "image_size_px", "resolution": "image_size_px", "size": "image_size_px",
    "width": "image_size_px", "image_width": "image_size_px", "image_height": "image_size_px",
    "ground_z": "ground_z_m", "ground_height": "ground_z_m", "ground": "ground_z_m",
    "camera_matrix": "K", "intrinsics": "K", "intrinsic_matrix": "K", "k": "K",
    "distortion": "dist", "dist_coeffs": "dist", "distortion_coefficients": "dist", "d": "dist",
    "rotation": "R", "rotation_matrix": "R", "r": "R", "translation": "t", "tvec": "t", "T": "t",
    "translation_vector": "t", "projection_matrix": "P", "p": "P", "type": "model", "camera_model": "model",
}


def suggest_key(key: str, allowed) -> str:
    """What to write instead of an unknown key: the key with the right unit, an alias or a close match."""
    allowed = list(allowed)
    k = str(key)
    kl = k.lower()
    base, _, unit = kl.rpartition("_")
    if not base or unit not in UNITS:
        base, unit = kl, ""
    candidates = [a for a in allowed if a.rpartition("_")[0] == base or a == base]
    target = candidates[0] if candidates else ALIASES.get(kl) or ALIASES.get(base) or ALIASES.get(k)
    if target and target in allowed:
        want = KEY_UNIT.get(target)
        if target == "focal_px" and kl in ("fx", "fy"):
            return "a known key: use 'focal_px' (one focal length; model: opencv with K when fx != fy)"
        if want and unit and UNITS.get(unit) != UNITS[want]:
            note = " = focal length / pixel pitch" if target == "focal_px" and unit in ("mm", "m", "cm") else ""
            return (f"a known key: use '{target}' ({UNITS[want]}{note}) instead; '{k}' is in {UNITS[unit]}, "
                    "convert the value")
        if want and not unit:
            return f"a known key with its unit: use '{target}' ({UNITS[want]})"
        return f"a known key: use '{target}'"
    close = difflib.get_close_matches(k, allowed, n=1, cutoff=0.6)
    if close:
        return f"a known key: did you mean '{close[0]}'?"
    return f"one of the keys {allowed}"
