"""``model: homography`` camera files: a 3x3 ``H_ground_image`` (and optionally ``K``, the points it
came from with their sigmas, or the 9x9 covariance of H); see docs/file-formats.md."""

from __future__ import annotations

import warnings
from typing import NamedTuple

import numpy as np

from ..cameras.homography import HomographyCamera, apply_homography, camera_from_homography, fit_homography
from ..errors import ConfigError, ConsistencyWarning, InputError
from . import _common as C

__all__ = ["HOMOGRAPHY_KEYS", "HomographyFile", "homography_file_from_dict", "load_homography"]

#: keys of a ``model: homography`` camera file: required, optional
HOMOGRAPHY_KEYS = (("model", "image_size_px", "H_ground_image"),
                   ("K", "dist", "ground_z_m", "points", "cov_H", "name", "description"))
_POINT_KEYS = ("uv_px", "xy_world_m", "sigma_px", "sigma_m")
#: the range of the largest entry of a file's H (scale-free; beyond it its products under- or overflow)
H_SCALE_RANGE = (1e-100, 1e100)


class HomographyFile(NamedTuple):
    """A ``model: homography`` file: the plane mapping, the camera (with ``K``, else None) and the
    6x6 covariance of its pose (``x_m, y_m, height_m, pan_rad, tilt_rad, roll_rad``; None without a
    covariance of H)."""

    homography: HomographyCamera
    camera: object
    cov_pose: np.ndarray | None


def homography_file_from_dict(d: dict, *, where: str = "") -> HomographyFile:
    """Parse a ``model: homography`` mapping (see docs/file-formats.md); ConfigError names the field."""


    for k in d:
        if k not in HOMOGRAPHY_KEYS[0] + HOMOGRAPHY_KEYS[1]:
            raise ConfigError(C.label(where, str(k)), d[k],
                              f"one of the keys {list(HOMOGRAPHY_KEYS[0] + HOMOGRAPHY_KEYS[1])} (homography file)")
    for k in HOMOGRAPHY_KEYS[0]:
        if d.get(k) is None:
            raise ConfigError(C.label(where, k), "missing", f"a value for '{k}' (homography camera file)")
    size = C.as_image_size(where, "image_size_px", d["image_size_px"])
    H = C.as_matrix(where, "H_ground_image", d["H_ground_image"], (3, 3))
    top = float(np.abs(H).max())
    if not H_SCALE_RANGE[0] <= top <= H_SCALE_RANGE[1]:
        raise ConfigError(C.label(where, "H_ground_image"), f"largest entry {top:.3g}",
                          f"a matrix scaled to a largest entry between {H_SCALE_RANGE[0]:g} and {H_SCALE_RANGE[1]:g} "
                          "(a homography is defined up to scale: divide it by its largest entry; beyond, its "
                          "products under- or overflow)")
    gz = C.as_number(where, "ground_z_m", d.get("ground_z_m", 0.0), unit=" (metres)")
    points, cov = None, None
    if d.get("points") is not None:
        pts = d["points"]
        if not isinstance(pts, dict) or any(k not in _POINT_KEYS for k in pts) or "uv_px" not in pts \
                or "xy_world_m" not in pts:
            raise ConfigError(C.label(where, "points"), pts if not isinstance(pts, dict) else sorted(pts),
                              "a mapping with uv_px (N x 2), xy_world_m (N x 2) [, sigma_px, sigma_m]")
        uv = _rows(where, "points.uv_px", pts["uv_px"])
        xy = _rows(where, "points.xy_world_m", pts["xy_world_m"])
        if len(uv) != len(xy):
            raise ConfigError(C.label(where, "points"), f"{len(uv)} pixels, {len(xy)} ground points", "pairs")
        spx, sm = pts.get("sigma_px", 1.0), pts.get("sigma_m", 0.05)
        for name, s in (("points.sigma_px", spx), ("points.sigma_m", sm)):
            a = np.asarray(s, dtype=np.float64) if _numeric(s) else None
            if a is None or a.ndim > 1 or (a.ndim == 1 and a.size != len(uv)) or np.any(~(a >= 0)):
                raise ConfigError(C.label(where, name), s, f"a standard deviation >= 0 or {len(uv)} of them")
        points = {"uv_px": uv, "xy_world_m": xy, "sigma_px": spx, "sigma_m": sm}
        try:
            Hf, cov, _ = fit_homography(uv, xy, sigma_px=spx, sigma_m=sm)
        except InputError as e:
            raise C.rewrap(e, where) from None
        Hn = H / np.linalg.norm(H)
        Hn = Hn if np.sum(Hn * Hf) > 0 else -Hn
        d_m = np.hypot(*(apply_homography(Hn, uv, False)[1] - apply_homography(Hf, uv, False)[1]).T).max()
        sig = np.sqrt(np.max(np.linalg.eigvalsh(apply_homography(Hf, uv, True)[3] @ cov @ np.swapaxes(
            apply_homography(Hf, uv, True)[3], -1, -2)), -1)).max()
        if d_m > 3 * max(sig, 1e-9):
            warnings.warn(f"{where}: H_ground_image differs from the fit of its points by up to {d_m:.3g} m "
                          f"({d_m / max(sig, 1e-12):.3g} sigma); the fit's covariance is used around the file's H",
                          ConsistencyWarning, stacklevel=3)
    if d.get("cov_H") is not None:
        if points is not None:
            raise ConfigError(C.label(where, "cov_H"), "given with points", "cov_H or points (the fit gives it)")
        cov = C.as_matrix(where, "cov_H", d["cov_H"], (9, 9))
    try:
        hc = HomographyCamera(H, size, cov_h=cov, ground_z_m=gz, points=points,
                              ground_side_uv_px=None if points is None else points["uv_px"])
        cam, cov_pose = None, None
        if d.get("K") is not None:
            K = C.check_K(where, "K", C.as_matrix(where, "K", d["K"], (3, 3)))
            dist = None if d.get("dist") is None else C.as_vector(where, "dist", d["dist"], (0, 4, 5, 8),
                                                                   "distortion coefficients")
            cam, cov_pose = camera_from_homography(hc, K, size, dist=dist, cov_h=hc.cov_h, ground_z_m=gz)
            _check_K_explains_H(hc, cam, where)
        elif d.get("dist") is not None:
            raise ConfigError(C.label(where, "dist"), d["dist"], "dist only with K")
    except InputError as e:
        if isinstance(e, ConfigError):
            raise
        raise C.rewrap(e, where) from None
    return HomographyFile(hc, cam, cov_pose)


def _check_K_explains_H(hc: HomographyCamera, cam, where: str) -> None:
    """The camera decomposed with ``K`` must reproduce the file's H: pixels of the image's lower half mapped to
    the ground by H and back through ``K [R | t]``.  Beyond :data:`footprint_uq.io._common.P_FAR_PX` the
    file is refused (K and H describe two different mappings: which one is meant cannot be told), above
    0.05 px it is warned about; the camera (K, R, t) is what every command then uses."""
    w, h = hc.image_size_px
    uv = np.array([[u * (w - 1), v * (h - 1)] for v in (0.6, 0.8, 1.0) for u in (0.0, 0.5, 1.0)])
    H = hc.H_ground_image
    q = np.c_[uv, np.ones(len(uv))] @ H.T
    front = np.abs(q[:, 2]) > 1e-12 * np.abs(q).max()
    if not front.any():
        return
    xy = q[front, :2] / q[front, 2:3]
    X = np.c_[xy, np.full(len(xy), cam.ground_z_m), np.ones(len(xy))]
    p = X @ cam.P.T
    ok = p[:, 2] > 0
    if not ok.any():
        raise ConfigError(C.label(where, "K"), "the ground of H_ground_image behind the camera decomposed with K",
                          "a K that belongs to this homography")
    d_px = np.full(len(p), np.inf)
    d_px[ok] = np.hypot(*(p[ok, :2] / p[ok, 2:3] - uv[front][ok]).T)
    worst = int(np.argmax(d_px))
    u, v = uv[front][worst]
    off = f"{d_px[worst]:.3g} px off H_ground_image at pixel ({u:.6g}, {v:.6g})"
    why = (f"H maps that pixel to ({xy[worst, 0]:.4g}, {xy[worst, 1]:.4g}) m, which the camera decomposed with K "
           "sees elsewhere")
    if d_px[worst] > C.P_FAR_PX:
        raise ConfigError(C.label(where, "K"), off,
                          f"a K that explains H within {C.P_FAR_PX:g} px ({why}: K and H are two different mappings; "
                          "drop K to use H alone: load_homography)")
    if d_px[worst] > C.P_WARN_PX:
        warnings.warn(f"{C.label(where, 'K')}: {off} ({why}); using the camera of K (its pose from H)",
                      ConsistencyWarning, stacklevel=4)


def _numeric(s) -> bool:
    try:
        np.asarray(s, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


def _rows(where, field, value) -> np.ndarray:

    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(C.label(where, field), value, "a list of [a, b] pairs") from None
    if a.ndim != 2 or a.shape[1] != 2 or not np.all(np.isfinite(a)):
        raise ConfigError(C.label(where, field), value, "a list of finite [a, b] pairs")
    return a


def load_homography(path) -> HomographyFile:
    """Read a ``model: homography`` camera file (YAML/JSON); see :func:`homography_file_from_dict`."""

    p, d = C.read_mapping(path)
    if not isinstance(d, dict) or str(d.get("model", "")).strip().lower() != "homography":
        raise ConfigError(C.label(str(p), "model"), d.get("model") if isinstance(d, dict) else d, "'homography'")
    return homography_file_from_dict(d, where=str(p))
