"""Camera pose (and focal length) from ground control points, with the full covariance of the solve.

A ground control point (GCP) is a pixel ``uv_px`` clicked in the image and the same
point's world coordinates ``xyz_world_m`` (frame W, docs/conventions.md) from a survey
or a map.  From four or more GCPs and known intrinsics the pose follows (PnP); from six
or more not on one line the focal length too (square pixels, principal point at the image
centre, no distortion).

Solve
-----
Starts: the PnP solution family -- OpenCV's SQPnP, EPnP and IPPE (both planar solutions; on
the points flattened to ``z = 0`` for uneven ground), each refined by
:func:`cv2.solvePnPRefineLM`; candidates putting a point behind the camera or the camera
below the ground plane are dropped, up to :data:`MAX_STARTS` distinct ones kept (without
intrinsics: the same over a grid of focal lengths).  Then a Levenberg-Marquardt refinement
from every start at once in the library's own parameters (``x_m, y_m, height_m, pan_rad,
tilt_rad, roll_rad`` [, the focal length, moving ``fx_px`` and ``fy_px`` together] [, ``k1``:
with ``solve_k1``, or without intrinsics under a zero-mean prior of ``lens_k1_sigma``]) with the
library's own projection (:func:`footprint_uq.cameras.general.project`) minimises

    sum_i r_i^T S_i^-1 r_i,   r_i = uv_i - project(xyz_i),
    S_i = sigma_px,i^2 I_2 + sigma_m,i^2 (d uv / d xyz)_i (d uv / d xyz)_i^T

(the *effective variance*: the survey noise of each point mapped through the derivative of
its projection).  It stops when the Gauss-Newton step is below 1e-6 of every parameter's
standard deviation.

Covariance
----------
First order at the solution: ``C_theta = H^-1`` with ``H = sum J_i^T S_i^-1 J_i`` (the
normal matrix; pixel and survey noise both enter through ``S_i``).  Given intrinsics with
a covariance ``C_int`` (13 x 13 over ``fx_px .. k6``) add their effect: the pose moves by
``G d_int`` with ``G = -H^-1 sum J_i^T S_i^-1 (d uv / d int)_i``, so the full 22 x 22
parameter covariance is ``A C_theta A^T + B C_int B^T`` with ``A`` placing theta in the
parameter vector and ``B = A G + E_int`` (``E_int`` placing the intrinsics).  The stated
sigmas are used as they are (not rescaled by the residuals); the reduced chi-square of the
fit says whether they were realistic.  Ground-plane parameters are 0: the GCPs define the
ground ``z = 0`` of W.

Weak geometry
-------------
:func:`_diagnose` flags a result it cannot support (``GCPSolution.flags``, ``usable``): another
minimum within :data:`AMBIGUOUS_DELTA_CHI2`; the k1 score test (known lens); the chi-square and
the normalised leave-one-out residuals; a cost that is not quadratic over the 95 % region
(:func:`_nonlinearity`, which inflates the covariance where that suffices).  docs/calibration.md,
section 5, has the measured table.  Support of a pixel: :mod:`footprint_uq.products.gcp_support`.
"""

from __future__ import annotations

import csv
import hashlib
import math
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from scipy.stats import chi2

from .. import params as P
from .._checks import check_cov
from .._files import read_input_text
from ..cameras import general
from ..cameras.lens_domain import lens_domain
from ..cameras.opencv import OpenCVCamera
from ..cameras.rotation import R_W_C, pan_tilt_roll_from_R_W_C
from ..errors import ConsistencyWarning, InputError
from ..products.gcp_support import leverage_px2, support_of
from ..products.geo import GeoReference
from ..uncertainty.budget import MAX_SIGMA, ErrorBudget
from .extrinsics import load_intrinsics

__all__ = ["GCPSet", "GCPSolution", "read_gcp_csv", "solve_gcp", "POSE_NAMES", "GCP_COLUMNS", "MAX_POINTS"]

#: the estimated pose parameters, in :data:`footprint_uq.params.PARAM_NAMES` order
POSE_NAMES = ("x_m", "y_m", "height_m", "pan_rad", "tilt_rad", "roll_rad")
#: columns a GCP CSV may have
GCP_COLUMNS = ("name", "u_px", "v_px", "x_m", "y_m", "z_m", "lat_deg", "lon_deg", "alt_m", "sigma_px", "sigma_m")
_POSE_IDX = P.param_index(POSE_NAMES)
#: indices of the 13 intrinsic parameters fx_px .. k6 in the parameter vector
INTRINSIC_IDX = np.arange(P.SKEW + 1 + 8)
_INT_IDX = INTRINSIC_IDX
MIN_POINTS_POSE = 4
MIN_POINTS_FOCAL = 6
_CONV_SIGMA = 1e-6  # stop when the Gauss-Newton step is below this many standard deviations
_ROUNDOFF_SIGMA = 1e-3  # ... or below this many when no step lowers the cost (round-off limited)
_ROUNDOFF_RTOL = 1e-13  # a cost decrease below this fraction of the cost is round-off, not progress
_COLLINEAR_RTOL = 1e-3  # second singular value / first below this: the points are on one line
#: most ground control points one solve takes (the solve is O(N) in memory and time; beyond this a
#: table is a point cloud, not a survey: thin it)
MAX_POINTS = 10_000
#: smallest non-zero point sigma (px or m); below it the weights 1/sigma^2 overflow the normal matrix
MIN_POINT_SIGMA = 1e-6
#: largest point sigma (px or m): the budget files' limit (:data:`footprint_uq.uncertainty.budget.MAX_SIGMA`)
MAX_POINT_SIGMA = MAX_SIGMA
#: leave-one-out re-solves only up to this many points (above it the linearised leave-one-out residuals alone)
MAX_LOO_POINTS = 400
#: an other pose minimum whose cost exceeds the best one's by less than this is reported as ambiguous
AMBIGUOUS_DELTA_CHI2 = 25.0
#: a start whose cost is this far above the best start's is refined to 1e-3 sigma only (a far worse minimum)
_FAR_MINIMUM_DELTA_CHI2 = 40.0 * AMBIGUOUS_DELTA_CHI2
#: p-values below which the residual tests (chi-square, normalised leave-one-out) flag the result
RESIDUAL_TEST_P = 1e-3
#: p-value below which the k1 score test flags the lens model
LENS_TEST_P = 1e-2
#: largest covariance inflation for a cost that rises slower than quadratic; beyond it the result is flagged
MAX_INFLATION = 4.0
#: largest ratio of the cost's rise to its quadratic model on the 95 % region's axes; beyond it the result is flagged
MAX_COST_RATIO = 2.0
#: without intrinsics the lens is unknown: k1 is solved with a zero-mean prior of this standard deviation
LENS_K1_SIGMA = 0.1
MAX_STARTS = 4  # distinct PnP starts refined by Levenberg-Marquardt (the other pose minima among them)
#: the PnP starts are computed from at most this many points (evenly spread over the table's rows): a start is
#: only where Levenberg-Marquardt on every point begins, and OpenCV's refinement of the 45 focal-length grid's
#: candidates on 10,000 points was 70 % of such a solve (issue 35: 10,000 points in well under a minute)
START_POINTS = 1000
_LOO_CHUNK = 200_000  # problems x points per batched leave-one-out run (bounds its memory to ~100 MB)
#: lat/lon tables: farthest point from the origin of W (m); the local frame ignores the Earth's curvature
#: (0.31 m drop at 2 km)
MAX_ORIGIN_DISTANCE_M = 2000.0


# ---------------------------------------------------------------------------------------------
# input
# ---------------------------------------------------------------------------------------------
@dataclass
class GCPSet:
    """Ground control points in the world frame W.

    Attributes
    ----------
    uv_px : ndarray (N, 2)
        Pixels (u right, v down).
    xyz_world_m : ndarray (N, 3)
        World points (x east, y north, z up), metres; the ground plane is ``z = 0``.
    sigma_px : ndarray (N,)
        1-sigma pixel noise of each point (per image axis).
    sigma_m : ndarray (N,)
        1-sigma survey noise of each point (per world axis x, y, z).
    names : list of str
    georef : dict
        ``origin_lat_deg``, ``origin_lon_deg``, ``origin_alt_m`` of W when known (else empty).
    """

    uv_px: np.ndarray
    xyz_world_m: np.ndarray
    sigma_px: np.ndarray
    sigma_m: np.ndarray
    names: list = field(default_factory=list)
    georef: dict = field(default_factory=dict)

    def __post_init__(self):
        self.uv_px = np.asarray(self.uv_px, dtype=np.float64).reshape(-1, 2)
        n = len(self.uv_px)
        self.xyz_world_m = np.asarray(self.xyz_world_m, dtype=np.float64).reshape(n, 3)
        self.sigma_px = np.broadcast_to(np.asarray(self.sigma_px, dtype=np.float64), (n,)).copy()
        self.sigma_m = np.broadcast_to(np.asarray(self.sigma_m, dtype=np.float64), (n,)).copy()
        if not self.names:
            self.names = [str(i + 1) for i in range(n)]


def _float_cell(path, row_no, col, text):
    try:
        x = float(text)
    except (TypeError, ValueError):
        raise InputError(f"{path}: row {row_no} {col}", text, "a number") from None
    if not math.isfinite(x):
        raise InputError(f"{path}: row {row_no} {col}", text, "a finite number")
    return x


def _read_gcp_rows(p: Path) -> list[list[str]]:
    """The CSV rows of a GCP table (header first), comments and blank lines dropped."""
    try:
        text = read_input_text(p, "--points", encoding="utf-8-sig")  # a FIFO: a stream
    except OSError as e:
        raise InputError("--points", str(p), f"a readable CSV file ({e.strerror or e})") from None
    except UnicodeDecodeError:
        raise InputError("--points", str(p), "a UTF-8 text CSV file") from None
    lines = [line for line in text.splitlines() if line.strip() and not line.lstrip().startswith("#")]
    if len(lines) - 1 > MAX_POINTS:
        raise InputError(f"{p}: rows", len(lines) - 1, f"at most {MAX_POINTS} ground control points (thin the table)")
    rows = list(csv.reader(lines))
    if not rows:
        raise InputError(str(p), "an empty file", "a header row u_px, v_px, x_m, y_m[, z_m] and one row per point")
    return rows


def _check_gcp_header(p: Path, header: list[str]) -> bool:
    """Check the header's columns; True for world coordinates (x_m, y_m), False for lat_deg/lon_deg."""
    unknown = [h for h in header if h not in GCP_COLUMNS]
    if unknown:
        raise InputError(f"{p}: column", unknown[0], f"one of {', '.join(GCP_COLUMNS)} (units in the names)")
    if len(set(header)) != len(header):
        raise InputError(f"{p}: header", header, "each column once")
    has_xy = "x_m" in header or "y_m" in header
    has_ll = "lat_deg" in header or "lon_deg" in header
    if has_xy == has_ll:
        raise InputError(f"{p}: header", header, "either x_m, y_m[, z_m] (world frame) or lat_deg, lon_deg[, alt_m]")
    need = ["u_px", "v_px"] + (["x_m", "y_m"] if has_xy else ["lat_deg", "lon_deg"])
    for c in need:
        if c not in header:
            raise InputError(f"{p}: header", header, f"a column {c}")
    if has_xy and "alt_m" in header or has_ll and "z_m" in header:
        raise InputError(f"{p}: header", header, "z_m with x_m/y_m, alt_m with lat_deg/lon_deg")
    return has_xy


def _local_from_wgs84(p: Path, a: dict, n: int, origin_lat_deg, origin_lon_deg, origin_alt_m):
    """World points ``(n, 3)`` m in the local east/north/up frame of the origin, and the georeference."""
    lat, lon = a["lat_deg"], a["lon_deg"]
    if np.any(np.abs(lat) > 90) or np.any(np.abs(lon) > 180):
        raise InputError(f"{p}: lat_deg/lon_deg", (lat.tolist()[:3], lon.tolist()[:3]),
                         "latitudes in [-90, 90] and longitudes in [-180, 180] degrees")
    olat = float(np.mean(lat)) if origin_lat_deg is None else float(origin_lat_deg)
    olon = _mean_longitude_deg(lon) if origin_lon_deg is None else float(origin_lon_deg)
    g = GeoReference(origin_lat_deg=olat, origin_lon_deg=olon)
    xy = g.from_wgs84(lat, lon)
    far = np.flatnonzero(~(np.hypot(*xy.T) <= MAX_ORIGIN_DISTANCE_M))
    if far.size:
        raise InputError(f"{p}: row {far[0] + 2} lat_deg/lon_deg",
                         f"{float(np.hypot(*xy[far[0]])):.4g} m from the origin ({olat:.6f}, {olon:.6f})",
                         f"points within {MAX_ORIGIN_DISTANCE_M:g} m of the origin (the local frame is flat)")
    if "alt_m" in a:
        oalt = float(np.median(a["alt_m"])) if origin_alt_m is None else float(origin_alt_m)
        z = a["alt_m"] - oalt
    else:
        oalt = None if origin_alt_m is None else float(origin_alt_m)
        z = np.zeros(n)
    georef = {"origin_lat_deg": olat, "origin_lon_deg": olon}
    if oalt is not None:
        georef["origin_alt_m"] = oalt
    return np.concatenate([xy, z[:, None]], -1), georef


def read_gcp_csv(path, *, pixel_sigma_px: float = 1.0, survey_sigma_m: float = 0.05, origin_lat_deg=None,
                 origin_lon_deg=None, origin_alt_m=None) -> GCPSet:
    """Read a GCP table.

    Columns (header row, any order): ``u_px, v_px`` and either ``x_m, y_m[, z_m]`` (world
    frame W, metres) or ``lat_deg, lon_deg[, alt_m]`` (WGS84; converted to a local
    east/north/up frame by pyproj, azimuthal equidistant about the origin); optional
    ``sigma_px``, ``sigma_m`` (per point, override the defaults) and ``name``.

    Parameters
    ----------
    path : str or Path
    pixel_sigma_px, survey_sigma_m : float
        Default 1-sigma pixel noise (per image axis) and survey noise (per world axis).
    origin_lat_deg, origin_lon_deg : float, optional
        Geodetic origin of W (default: the mean latitude/longitude of the points).
    origin_alt_m : float, optional
        Altitude of the ground plane ``z = 0`` (default: the median ``alt_m`` of the points).
    """
    p = Path(path)
    rows = _read_gcp_rows(p)
    header = [h.strip().lower() for h in rows[0]]
    has_xy = _check_gcp_header(p, header)
    col = {h: i for i, h in enumerate(header)}
    data = {h: [] for h in header if h != "name"}
    names = []
    for k, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise InputError(f"{p}: row {k}", r, f"{len(header)} cells like the header")
        for h in data:
            data[h].append(_float_cell(p, k, h, r[col[h]].strip()))
        names.append(r[col["name"]].strip() if "name" in col else str(k - 1))
    n = len(names)
    if n == 0:
        raise InputError(str(p), "no data rows", "one row per ground control point")
    a = {h: np.asarray(v) for h, v in data.items()}
    uv = np.stack([a["u_px"], a["v_px"]], -1)
    georef = {}
    if has_xy:
        z = a.get("z_m", np.zeros(n))
        xyz = np.stack([a["x_m"], a["y_m"], z], -1)
        if origin_lat_deg is not None:
            georef = {"origin_lat_deg": float(origin_lat_deg), "origin_lon_deg": float(origin_lon_deg)}
    else:
        xyz, georef = _local_from_wgs84(p, a, n, origin_lat_deg, origin_lon_deg, origin_alt_m)
    spx = a.get("sigma_px", np.full(n, float(pixel_sigma_px)))
    sm = a.get("sigma_m", np.full(n, float(survey_sigma_m)))
    _check_sigmas(spx, sm, lambda k: f"{p}: row {k + 2}")
    return GCPSet(uv, xyz, spx, sm, names, georef)


def _mean_longitude_deg(lon_deg) -> float:
    """The circular mean of longitudes (degrees, in [-180, 180)): right on both sides of 180 deg."""
    lam = np.deg2rad(np.asarray(lon_deg, dtype=np.float64))
    m = math.degrees(math.atan2(float(np.mean(np.sin(lam))), float(np.mean(np.cos(lam)))))
    return float((m + 180.0) % 360.0 - 180.0)


def _check_sigmas(sigma_px, sigma_m, where) -> None:
    """Each sigma 0 or in [MIN_POINT_SIGMA, MAX_POINT_SIGMA], and not both 0; ``where(k)`` names point k."""
    lo, hi = MIN_POINT_SIGMA, MAX_POINT_SIGMA
    for name, s in (("sigma_px", sigma_px), ("sigma_m", sigma_m)):
        bad = np.flatnonzero(~((s == 0) | ((s >= lo) & (s <= hi))))
        if bad.size:
            raise InputError(f"{where(bad[0])} {name}", float(s[bad[0]]),
                             f"a standard deviation of 0 or in [{lo:g}, {hi:g}]")
    both = np.flatnonzero((sigma_px == 0) & (sigma_m == 0))
    if both.size:
        raise InputError(f"{where(both[0])} sigma_px/sigma_m", (0.0, 0.0), "pixel or survey noise > 0")


# ---------------------------------------------------------------------------------------------
# checks
# ---------------------------------------------------------------------------------------------
def _check_geometry(uv, xyz, image_size_px, estimate_focal, extra: int = 0):
    n = len(uv)
    need = (MIN_POINTS_FOCAL if estimate_focal else MIN_POINTS_POSE) + extra
    if n < need:
        what = "focal length and pose (no intrinsics given)" if estimate_focal else "a pose"
        raise InputError("ground control points", n, f"at least {need} points for {what}")
    if n > MAX_POINTS:
        raise InputError("ground control points", n, f"at most {MAX_POINTS} points (thin the table)")
    bad = np.flatnonzero(~np.isfinite(uv).all(-1) | ~np.isfinite(xyz).all(-1))
    if bad.size:
        raise InputError(f"ground control point {bad[0] + 1}", (uv[bad[0]].tolist(), xyz[bad[0]].tolist()),
                         "finite pixel and world coordinates")
    w, h = image_size_px
    out = np.flatnonzero((uv[:, 0] < -0.5) | (uv[:, 0] > w - 0.5) | (uv[:, 1] < -0.5) | (uv[:, 1] > h - 0.5))
    if out.size:
        raise InputError(f"ground control point {out[0] + 1} pixel", uv[out[0]].tolist(),
                         f"inside the {w}x{h} image ([-0.5, {w - 0.5}] x [-0.5, {h - 0.5}])")
    for what, pts in (("world points", xyz), ("pixels", uv)):
        s = np.linalg.svd(pts - pts.mean(0), compute_uv=False)
        if s[0] == 0 or s[1] < _COLLINEAR_RTOL * s[0]:
            raise InputError(f"ground control points ({what})", f"singular values {np.round(s, 6).tolist()}",
                             "points not all on one line (spread them across the scene)")
    if len(np.unique(np.round(xyz, 9), axis=0)) < n:
        raise InputError("ground control points (world points)", "repeated points", "distinct points")


def _coplanar(xyz) -> bool:
    s = np.linalg.svd(xyz - xyz.mean(0), compute_uv=False)
    return bool(s[2] < 1e-6 * s[0])


# ---------------------------------------------------------------------------------------------
# parameters
# ---------------------------------------------------------------------------------------------
def _param_map(estimate_focal: bool, estimate_k1: bool = False) -> np.ndarray:
    """``A`` (22, k): theta -> parameter increments (focal first when estimated, k1 last when estimated)."""
    k = 6 + int(estimate_focal) + int(estimate_k1)
    A = np.zeros((P.N_PARAMS, k))
    j = 0
    if estimate_focal:
        A[P.FX, 0] = A[P.FY, 0] = 1.0
        j = 1
    for i, idx in enumerate(_POSE_IDX):
        A[idx, j + i] = 1.0
    if estimate_k1:
        A[P.K1, -1] = 1.0
    return A


def _params_from_Rt(K, dist, R, t) -> np.ndarray:
    p = np.zeros(P.N_PARAMS)
    p[[P.FX, P.FY, P.CX, P.CY, P.SKEW]] = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
    d = np.zeros(8)
    d[:len(dist)] = dist
    p[P.DIST_SLICE] = d
    C = -R.T @ t
    p[[P.XM, P.YM, P.HM]] = C
    p[[P.PAN, P.TILT, P.ROLL]] = pan_tilt_roll_from_R_W_C(R.T)
    return p


def _camera_from_params(p, image_size_px) -> OpenCVCamera:
    K = np.array([[p[P.FX], p[P.SKEW], p[P.CX]], [0.0, p[P.FY], p[P.CY]], [0.0, 0.0, 1.0]])
    d = p[P.DIST_SLICE]
    R = R_W_C(p[P.PAN], p[P.TILT], p[P.ROLL]).T
    t = -R @ p[[P.XM, P.YM, P.HM]]
    return OpenCVCamera(K, d if np.any(d[5:]) else d[:5], R, t, image_size_px)


# ---------------------------------------------------------------------------------------------
# start: OpenCV PnP
# ---------------------------------------------------------------------------------------------
def _pnp_candidates(xyz, uv, K, dist):
    """Refined PnP solutions ``(R, t, rms_px, n_behind, below_ground)`` from SQPnP, EPnP and IPPE."""

    obj = np.ascontiguousarray(xyz, dtype=np.float64).reshape(-1, 1, 3)
    img = np.ascontiguousarray(uv, dtype=np.float64).reshape(-1, 1, 2)
    dist = np.asarray(dist, dtype=np.float64)
    flat = obj.copy()
    flat[..., 2] = 0.0  # planar starts even for uneven ground: IPPE's two solutions are the two pose minima
    runs = [(cv2.SOLVEPNP_SQPNP, obj), (cv2.SOLVEPNP_EPNP, obj)]
    runs += [(cv2.SOLVEPNP_IPPE, obj)] if _coplanar(xyz) else [(cv2.SOLVEPNP_IPPE, flat)]
    out = []
    for fl, o in runs:
        try:
            n, rvecs, tvecs, _ = cv2.solvePnPGeneric(o, img, K, dist, flags=fl)
        except cv2.error:
            continue
        for rv, tv in zip(rvecs[:n], tvecs[:n], strict=True):
            try:
                rv, tv = cv2.solvePnPRefineLM(obj, img, K, dist, rv.copy(), tv.copy())
            except cv2.error:
                pass
            if not (np.all(np.isfinite(rv)) and np.all(np.isfinite(tv))):
                continue
            R = cv2.Rodrigues(rv)[0]
            t = tv.ravel()
            zc = xyz @ R[2] + t[2]
            proj = cv2.projectPoints(obj, rv, tv, K, dist)[0].reshape(-1, 2)
            rms = float(np.sqrt(np.mean(np.sum((proj - uv) ** 2, -1))))
            out.append((R, t, rms, int(np.sum(zc <= 0)), bool((-R.T @ t)[2] <= 0)))
    return out


def _usable_candidates(cands):
    ok = [c for c in cands if c[3] == 0 and not c[4] and np.isfinite(c[2])]
    if ok:
        return sorted(ok, key=lambda c: c[2])
    if any(c[3] == 0 for c in cands):
        raise InputError("ground control points", "every pose that fits puts the camera below the ground plane z = 0",
                         "world heights (z_m / alt_m) relative to the ground, and pixels matching their points")
    raise InputError("ground control points", "every pose that fits puts points behind the camera",
                     "pixels matching their world points (check the order of the rows and of u/v, x/y)")


def _initial_params(uv, xyz, image_size_px, K, dist, max_starts: int = MAX_STARTS) -> np.ndarray:
    """Starting parameter vectors (S, 22), best first: the PnP solution family with K (SQPnP, EPnP, and
    IPPE's two planar solutions on the points and on the points flattened to z = 0), or with K from a grid
    of focal lengths; every distinct start up to ``max_starts`` (the other pose minima are among them).  Above
    :data:`START_POINTS` points the starts come from that many, evenly spread over the rows."""
    if len(uv) > START_POINTS:  # the starts from a spread subset; the refinement uses every point
        sel = np.unique(np.linspace(0, len(uv) - 1, START_POINTS).round().astype(np.int64))
        uv, xyz = uv[sel], xyz[sel]
    if K is not None:
        grid = [(K, dist)]
    else:
        w, h = image_size_px
        grid = []
        for hfov in np.deg2rad(np.linspace(8.0, 140.0, 45)):
            f = (w / 2.0) / math.tan(hfov / 2.0)
            grid.append((np.array([[f, 0.0, (w - 1) / 2.0], [0.0, f, (h - 1) / 2.0], [0.0, 0.0, 1.0]]), np.zeros(5)))
    cands = []
    for Kg, dg in grid:
        cands += [(c, Kg, dg) for c in _pnp_candidates(xyz, uv, Kg, dg)]
    ok = {id(c) for c in _usable_candidates([c for c, _, _ in cands])}
    ranked = sorted([t for t in cands if id(t[0]) in ok], key=lambda t: t[0][2])
    starts = []
    for c, Kg, dg in ranked:
        p = _params_from_Rt(Kg, dg, c[0], c[1])
        if not any(np.abs(p - q)[[P.XM, P.YM, P.HM]].max() < 1e-3 * (1 + np.abs(q[P.HM])) and
                   np.abs(p - q)[[P.PAN, P.TILT, P.ROLL]].max() < 1e-4 for q in starts):
            starts.append(p)
        if len(starts) >= max_starts:
            break
    return np.array(starts)


# ---------------------------------------------------------------------------------------------
# Levenberg-Marquardt on the library's parameters, batched over problems
# ---------------------------------------------------------------------------------------------
def _project_batch(params, xyz):
    """``general.project`` of B parameter vectors (B, 22) over points (1 or B, N, 3), with gradients.

    The lens's valid domain is that of the coefficients rounded to 1e-3 (a domain is built per distinct
    lens, ~20 ms: one per Levenberg-Marquardt step when k1 is solved); the fold of a lens moves
    smoothly with its coefficients, far outside the image for such a change.
    """
    dq = np.round(params[:, P.DIST_SLICE], 3)
    if not np.isfinite(dq).all():
        return general.project(params[:, None, :], xyz, get_gradients=True)
    uniq, inv = np.unique(dq, axis=0, return_inverse=True)
    inv = inv.ravel()
    if len(uniq) == 1:
        return general.project(params[:, None, :], xyz, get_gradients=True, domain=lens_domain(uniq[0]))
    parts = [(np.flatnonzero(inv == j), u) for j, u in enumerate(uniq)]
    subs = [general.project(params[rows, None, :], xyz if xyz.shape[0] == 1 else xyz[rows], get_gradients=True,
                            domain=lens_domain(u)) for rows, u in parts]
    fields = []
    for f in range(len(subs[0])):
        out = np.empty((len(params),) + subs[0][f].shape[1:], subs[0][f].dtype)
        for (rows, _), sub in zip(parts, subs, strict=True):
            out[rows] = sub[f]
        fields.append(out)
    return general.Projection(*fields)


def _point_covariance(params, xyz, s_px2, s_m2, mask):
    """Per-point residual covariance ``S`` (B, N, 2, 2): pixel noise plus survey noise mapped by d uv / d xyz."""
    pr = _project_batch(params, xyz)
    Jx = np.where((mask & pr.valid)[..., None, None], pr.duv_dxyz, 0.0)
    S = s_px2[..., None, None] * np.eye(2) + s_m2[..., None, None] * (Jx @ np.swapaxes(Jx, -1, -2))
    return np.where(mask[..., None, None], S, np.eye(2))


def _normal_equations(params, uv, xyz, S, mask, A, prior=None):
    """Cost (B,), normal matrix H (B, k, k), gradient g (B, k), ok (B,) and the per-point pieces, for fixed S."""
    pr = _project_batch(params, xyz)
    ok = (pr.valid | ~mask).all(-1)
    r = np.where(mask[..., None], uv - pr.uv_px, 0.0)
    det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    Si = np.stack([np.stack([S[..., 1, 1], -S[..., 0, 1]], -1), np.stack([-S[..., 1, 0], S[..., 0, 0]], -1)], -2)
    Si = Si / det[..., None, None] * mask[..., None, None]
    Jp = np.where(mask[..., None, None], pr.duv_dp, 0.0)
    Jt = Jp @ A  # (B, N, 2, k)
    SiJ = Si @ Jt
    H = np.einsum("bnik,bnil->bkl", Jt, SiJ)
    g = np.einsum("bnik,bni->bk", SiJ, r)
    cost = np.einsum("bni,bnij,bnj->b", r, Si, r)
    if prior is not None:  # a Gaussian prior on theta: mean (k,), precision (k,) (0 where none)
        d = prior[0] - params @ np.linalg.pinv(A).T
        cost = cost + np.sum(prior[1] * d * d, -1)
        H = H + np.diag(prior[1])
        g = g + prior[1] * d
    cost = np.where(ok, cost, np.inf)
    return cost, H, g, ok, (r, Si, Jp, SiJ)


def _pinv(H):
    """``pinv`` of each (k, k) matrix of H (B, k, k); NaN where H is not finite (never an SVD failure)."""
    fin = np.isfinite(H).all((-1, -2))
    out = np.full_like(H, np.nan)
    with np.errstate(all="ignore"):
        try:
            out[fin] = np.linalg.pinv(H[fin])
        except np.linalg.LinAlgError:  # SVD did not converge on one of them (extreme scaling): one by one
            for b in np.flatnonzero(fin):
                try:
                    out[b] = np.linalg.pinv(H[b])
                except np.linalg.LinAlgError:
                    pass
    return out


def _gn_step_sigma(H, g):
    """Largest Gauss-Newton step component in standard deviations (B,); inf where H or g is not finite."""
    Hi = _pinv(H)
    with np.errstate(all="ignore"):
        gn = np.einsum("bkl,bl->bk", Hi, g)
        sig = np.sqrt(np.clip(np.diagonal(Hi, axis1=1, axis2=2), 1e-300, None))
        out = np.max(np.abs(gn) / sig, -1)
    return np.where(np.isfinite(out), out, np.inf)


def _lm_fixed(theta, base, A, uv, xyz, S, mask, max_iter, active0, prior, tol):
    """Levenberg-Marquardt with the point covariances S held fixed; B problems at once (``tol`` (B,): the
    Gauss-Newton step, in sigmas, at which each has converged)."""
    B, k = theta.shape
    cost, H, g, _, _ = _normal_equations(base + theta @ A.T, uv, xyz, S, mask, A, prior)
    lam = np.full(B, 1e-3)
    conv = ~active0.copy()
    failed = active0 & ~np.isfinite(cost)
    iters = np.zeros(B, int)
    eye = np.eye(k)
    for _ in range(max_iter):
        conv |= ~failed & (_gn_step_sigma(H, g) < tol)
        active = ~conv & ~failed
        if not active.any():
            break
        iters += active
        D = np.diagonal(H, axis1=1, axis2=2)[:, None, :] * eye + 1e-300 * eye
        with np.errstate(all="ignore"):
            step = np.einsum("bkl,bl->bk", _pinv(H + lam[:, None, None] * D), g)
        step = np.where(active[:, None] & np.isfinite(step).all(-1, keepdims=True), step, 0.0)
        new = theta + step
        c2, H2, g2, ok2, _ = _normal_equations(base + new @ A.T, uv, xyz, S, mask, A, prior)
        better = active & ok2 & (c2 <= cost)
        # a decrease within round-off is no progress: lambda grows, so a run whose Gauss-Newton step
        # is just above the tolerance but at the round-off floor ends as 'stuck' instead of cycling
        progress = better & (cost - c2 > _ROUNDOFF_RTOL * np.abs(cost))
        theta[better], cost[better], H[better], g[better] = new[better], c2[better], H2[better], g2[better]
        lam = np.where(progress, np.maximum(lam / 10.0, 1e-12), np.where(active, lam * 10.0, lam))
        stuck = active & (lam > 1e12)
        # no step lowers the cost any more: at the minimum to round-off if the Gauss-Newton step is tiny
        conv |= stuck & (_gn_step_sigma(H, g) < _ROUNDOFF_SIGMA)
        failed |= stuck & ~conv
    return theta, conv & ~failed, iters


def _lm(theta, base, A, uv, xyz, s_px2, s_m2, mask, max_iter=100, max_outer=20, prior=None, loose_above=None):
    """Minimise the effective-variance cost for B problems at once.

    The point covariances S depend (weakly) on the pose through d uv / d xyz: they are held
    fixed during a Levenberg-Marquardt run, recomputed at its solution, and the run repeated
    until the Gauss-Newton step with the updated S is below 1e-6 sigma (Orear's effective
    variance iteration; 2-3 rounds).

    ``loose_above`` (chi-square): the B rows are starts of one problem, and a row whose cost is more
    than this above the lowest is refined to 1e-3 sigma only (a far worse minimum: its position and
    cost serve the diagnostics, and its effective-variance rounds converge slowly).

    Returns theta (B, k), converged (B,), iterations (B,), and the normal equations at the end.
    """
    theta = np.array(theta, dtype=np.float64)
    B = theta.shape[0]
    iters = np.zeros(B, int)
    active = np.ones(B, bool)
    conv = np.zeros(B, bool)
    for _ in range(max_outer):
        S = _point_covariance(base + theta @ A.T, xyz, s_px2, s_m2, mask)
        cost, H, g, ok, _ = _normal_equations(base + theta @ A.T, uv, xyz, S, mask, A, prior)
        tol = np.full(B, _CONV_SIGMA)
        if loose_above is not None and np.isfinite(cost).any():
            tol[cost > np.min(cost) + loose_above] = _ROUNDOFF_SIGMA
        done = ok & (_gn_step_sigma(H, g) < tol)
        conv |= active & done
        active &= ~done
        if not active.any():
            break
        before = theta.copy()
        theta, c, it = _lm_fixed(theta, base, A, uv, xyz, S, mask, max_iter, active, prior, tol)
        iters += it
        still = np.all(theta == before, -1)  # converged without moving: at the round-off limit
        conv |= active & c & still
        active &= c & ~still  # a failed inner run stays failed
    S = _point_covariance(base + theta @ A.T, xyz, s_px2, s_m2, mask)
    ne = _normal_equations(base + theta @ A.T, uv, xyz, S, mask, A, prior)
    return theta, conv, iters, ne


# ---------------------------------------------------------------------------------------------
# result
# ---------------------------------------------------------------------------------------------
@dataclass
class GCPSolution:
    """A camera solved from ground control points, with the covariance of the solve.

    Attributes
    ----------
    camera : OpenCVCamera
        The solved camera (world frame W of the GCPs, ground ``z = 0``).
    params : ndarray (22,)
        Its parameter vector (:data:`footprint_uq.params.PARAM_NAMES`).
    cov_params : ndarray (22, 22)
        Full first-order covariance of the solve (pixel and survey noise, plus the
        given intrinsics' covariance); zero for parameters that were neither solved
        nor uncertain.
    estimated : tuple of str
        The solved parameters (``focal_px`` stands for ``fx_px = fy_px``).
    cov_theta : ndarray (k, k)
        Covariance of the solved parameters alone (pixel and survey noise only).
    gcps : GCPSet
    uv_fit_px, residual_px : ndarray (N, 2)
        Reprojected GCPs and ``uv_px - uv_fit_px``.
    residual_sigma : ndarray (N,)
        Whitened residual norm ``sqrt(r^T S^-1 r)`` (about 1.4 on average for a correct model).
    loo_residual_px : ndarray (N, 2)
        Leave-one-out: the point's pixel minus its projection by the camera solved without it (NaN
        where the others do not determine a camera; ``loo_status`` says why).
    loo_ground_error_m : ndarray (N, 2)
        Leave-one-out: the point's pixel back-projected by that camera onto the horizontal plane of
        the point, minus its surveyed x, y.
    chi2, dof : float, int
        ``sum r^T S^-1 r`` and ``2 N - k``.
    iterations : int
    """

    camera: OpenCVCamera
    params: np.ndarray
    cov_params: np.ndarray
    estimated: tuple
    cov_theta: np.ndarray
    gcps: GCPSet
    uv_fit_px: np.ndarray
    residual_px: np.ndarray
    residual_sigma: np.ndarray
    chi2: float
    dof: int
    iterations: int
    image_size_px: tuple
    intrinsics_cov_given: bool = False
    loo_residual_px: np.ndarray | None = None
    loo_ground_error_m: np.ndarray | None = None
    loo_status: list = field(default_factory=list)
    param_map: np.ndarray | None = None
    flags: list = field(default_factory=list)
    alternatives: list = field(default_factory=list)
    tests: dict = field(default_factory=dict)
    loo_normalised: np.ndarray | None = None
    nonlinearity: dict = field(default_factory=dict)
    inflation: float = 1.0
    prior: tuple | None = None
    k1_prior_sigma: float | None = None

    @property
    def usable(self) -> bool:
        """False when the solve flagged itself (``flags`` says why): its covariance cannot be trusted."""
        return not self.flags

    @property
    def estimated_param_names(self) -> list:
        """The solved parameters as :data:`footprint_uq.params.PARAM_NAMES` entries (focal -> ``fx_px``)."""
        return [{"focal_px": "fx_px"}.get(n, n) for n in self.estimated]

    def support(self, uv_px) -> dict:
        """Per pixel ``(..., 2)``: how far the control points support it (module doc, *Support*).

        Returns ``inside_hull`` (inside the convex hull of the control points' pixels), ``leverage_ratio``
        (the solve's own pixel variance at the pixel's ground point, over its largest value at a control
        point: <= 1 within the support, growing with extrapolation) and ``supported`` (either).
        """
        return support_of(self.params, self.cov_params, self.support_data(), uv_px)

    def support_data(self) -> dict:
        """What :func:`support_of` needs besides the camera and covariance (written to summary.json)."""
        g = self.gcps
        k = cv2.convexHull(np.ascontiguousarray(g.uv_px, dtype=np.float32), returnPoints=False).ravel()
        hull = g.uv_px[k]  # the points themselves (float64), in the hull's order
        lev = leverage_px2(self.params, self.cov_params, g.xyz_world_m)
        return {"hull_uv_px": hull.astype(float).tolist(), "leverage_max_px2": float(np.max(lev))}

    @property
    def rms_px(self) -> float:
        """Root-mean-square reprojection error (px, over both axes of all points)."""
        return float(np.sqrt(np.mean(self.residual_px**2) * 2))

    @property
    def reduced_chi2(self) -> float:
        return float(self.chi2 / self.dof) if self.dof > 0 else math.nan

    def sigma_params(self) -> np.ndarray:
        """1-sigma of every parameter (22,)."""
        return np.sqrt(np.clip(np.diagonal(self.cov_params), 0.0, None))

    def pose_table(self) -> list[dict]:
        """One row per solved parameter: value and 1-sigma (angles in degrees)."""
        s = self.sigma_params()
        rows = []
        names = (("focal_px", P.FX),) if "focal_px" in self.estimated else ()
        names += tuple((n, P.IDX[n]) for n in POSE_NAMES)
        for n, i in names:
            v, e = self.params[i], s[i]
            if n.endswith("_rad"):
                n, v, e = n[:-4] + "_deg", math.degrees(v), math.degrees(e)
            rows.append({"parameter": n, "value": float(v), "sigma": float(e)})
        return rows

    def budget(self, name: str = "gcp"):
        """The error budget: the full covariance over every parameter with a non-zero variance."""

        var = np.diagonal(self.cov_params)
        idx = np.flatnonzero(var > 0)
        C = self.cov_params[np.ix_(idx, idx)]
        C = 0.5 * (C + C.T)
        desc = (f"ground-control-point solve: {len(self.gcps.uv_px)} points, RMS {self.rms_px:.3g} px, "
                f"reduced chi-square {self.reduced_chi2:.3g}; solved {', '.join(self.estimated)}"
                + ("; intrinsics covariance included" if self.intrinsics_cov_given else "")
                + (f"; k1 with a prior sigma {self.k1_prior_sigma:g}" if self.k1_prior_sigma else "")
                + (f"; covariance inflated x{self.inflation:.3g} (nonlinear)" if self.inflation > 1 else "")
                + ("".join(f"; NOT USABLE: {f}" for f in self.flags)))
        return ErrorBudget(covariance_names=tuple(P.PARAM_NAMES[i] for i in idx), covariance_matrix=C, name=name,
                           description=desc)

    def ground_covariance_m2(self, uv_px):
        """Ground points ``(..., 2)`` and their covariance ``(..., 2, 2)`` (m^2) from the solve alone.

        Only the calibration part (shared by all pixels of the image); add the per-pixel noise
        of your detector with :func:`footprint_uq.propagate` and :meth:`budget`.
        """
        bp = general.backproject(self.params, np.asarray(uv_px, dtype=np.float64), get_gradients=True)
        J = bp.dxy_dp
        return bp.xy_world_m, J @ self.cov_params @ np.swapaxes(J, -1, -2)

    def residual_rows(self) -> list[dict]:
        g = self.gcps
        rows = []
        for i in range(len(g.uv_px)):
            row = {"name": g.names[i], "u_px": g.uv_px[i, 0], "v_px": g.uv_px[i, 1], "x_m": g.xyz_world_m[i, 0],
                   "y_m": g.xyz_world_m[i, 1], "z_m": g.xyz_world_m[i, 2], "sigma_px": g.sigma_px[i],
                   "sigma_m": g.sigma_m[i], "u_fit_px": self.uv_fit_px[i, 0], "v_fit_px": self.uv_fit_px[i, 1],
                   "du_px": self.residual_px[i, 0], "dv_px": self.residual_px[i, 1],
                   "residual_px": float(np.hypot(*self.residual_px[i])),
                   "residual_sigma": self.residual_sigma[i]}
            if self.loo_normalised is not None:
                row["loo_normalised"] = float(self.loo_normalised[i])
            if self.loo_residual_px is not None:
                lr, le = self.loo_residual_px[i], self.loo_ground_error_m[i]
                row.update({"loo_du_px": lr[0], "loo_dv_px": lr[1], "loo_residual_px": float(np.hypot(*lr)),
                            "loo_dx_m": le[0], "loo_dy_m": le[1], "loo_ground_error_m": float(np.hypot(*le)),
                            "loo_status": self.loo_status[i]})
            rows.append({k: (float(v) if isinstance(v, np.floating) else v) for k, v in row.items()})
        return rows

    @property
    def solve_id(self) -> str:
        """16 hex digits naming this solve: a hash of its numbers (same inputs, same id)."""
        data = np.concatenate([self.params, self.cov_params.ravel(), self.gcps.uv_px.ravel(),
                               self.gcps.xyz_world_m.ravel(), [self.chi2]])
        return hashlib.sha256(np.ascontiguousarray(data, dtype="<f8").tobytes()).hexdigest()[:16]

    def summary(self) -> dict:
        return {
            "solve_id": self.solve_id, "n_points": int(len(self.gcps.uv_px)), "image_size_px": list(self.image_size_px),
            "estimated": list(self.estimated), "rms_px": self.rms_px, "chi2": float(self.chi2), "dof": int(self.dof),
            "reduced_chi2": self.reduced_chi2, "iterations": int(self.iterations),
            "intrinsics_covariance_included": self.intrinsics_cov_given,
            "pose": self.pose_table(), "georef": dict(self.gcps.georef),
            "parameter_names": list(P.PARAM_NAMES), "cov_params": self.cov_params.tolist(),
            "usable": self.usable, "flags": list(self.flags), "alternatives": self.alternatives,
            "tests": self.tests, "nonlinearity": self.nonlinearity, "covariance_inflation": self.inflation,
            "support": self.support_data(), "k1_prior_sigma": self.k1_prior_sigma,
        }


# ---------------------------------------------------------------------------------------------
# the solve
# ---------------------------------------------------------------------------------------------
def solve_gcp(gcps: GCPSet, image_size_px, *, intrinsics=None, intrinsics_cov=None, leave_one_out: bool = True,
              max_iter: int = 100, solve_k1: bool = False, lens_k1_sigma: float = LENS_K1_SIGMA) -> GCPSolution:
    """Solve the camera from ground control points (see the module doc).

    Parameters
    ----------
    gcps : GCPSet
        Pixels ``(N, 2)``, world points ``(N, 3)`` and their sigmas.
    image_size_px : (int, int)
        (width, height).
    intrinsics : optional
        ``K`` and ``dist`` (an :class:`footprint_uq.calibration.extrinsics.Intrinsics`, a camera, or a
        camera file); None solves the focal length too (``fx = fy``, principal point at the image
        centre, no distortion), which needs at least 6 points.
    intrinsics_cov : array_like (13, 13), optional
        Covariance of ``fx_px .. k6`` (PARAM_NAMES order) of the given intrinsics.
    leave_one_out : bool
        Also re-solve without each point in turn (residuals.csv's ``loo_*`` columns).
    max_iter : int
        Levenberg-Marquardt iterations allowed.
    solve_k1 : bool
        Also solve the radial distortion ``k1`` freely (one more point needed).
    lens_k1_sigma : float
        Without intrinsics (and without ``solve_k1``): the lens is unknown, so ``k1`` is solved too with a
        zero-mean Gaussian prior of this standard deviation (0: assume no distortion at all).

    Raises
    ------
    InputError
        Fewer than 4 (6) points, points on one line, repeated points, pixels outside the
        image, every fitting pose puts points behind the camera or the camera below the
        ground, the focal length is not observable, or the solve does not converge.
    """
    w, h = (int(v) for v in image_size_px)
    size = (w, h)
    K = dist = None
    if intrinsics is not None:
        intr = load_intrinsics(intrinsics)
        if tuple(intr.image_size_px) != size:
            raise InputError("--intrinsics image size", list(intr.image_size_px), f"the image size {w}x{h}")
        K, dist = intr.K, intr.dist
    estimate_focal = K is None
    uv, xyz = gcps.uv_px, gcps.xyz_world_m
    _check_geometry(uv, xyz, size, estimate_focal, int(solve_k1))
    if not (0.0 <= lens_k1_sigma <= 1.0):
        raise InputError("lens k1 sigma", lens_k1_sigma, "a standard deviation in [0, 1]")
    k1_prior = estimate_focal and not solve_k1 and lens_k1_sigma > 0
    _check_sigmas(gcps.sigma_px, gcps.sigma_m, lambda k: f"ground control point {k + 1}")
    if intrinsics_cov is not None:
        if estimate_focal:
            raise InputError("intrinsics covariance", "given without intrinsics", "intrinsics with it")
        intrinsics_cov = check_cov("intrinsics covariance", intrinsics_cov, 13)
    starts = _initial_params(uv, xyz, size, K, dist)
    A = _param_map(estimate_focal, solve_k1 or k1_prior)
    prior = None
    if k1_prior:
        prior = (np.zeros(A.shape[1]), np.zeros(A.shape[1]))
        prior[1][-1] = 1.0 / lens_k1_sigma**2
    used = np.any(A != 0, 1)
    base = np.where(used, 0.0, starts[0])
    theta0 = starts @ np.linalg.pinv(A).T  # the estimated parameters of each start (A's columns are 0/1)
    minima = _minima(theta0, base, A, gcps, max_iter, prior)
    theta, (cost, H, r, Si, Jp, SiJ), iters = minima[0]
    p = base + A @ theta
    C_theta = _covariance_theta(H, estimate_focal)
    cov = _full_covariance(A, C_theta, SiJ, Jp, intrinsics_cov)
    cam = _camera_from_params(p, size)
    uv_fit = general.project(p, xyz).uv_px
    rs = np.sqrt(np.einsum("ni,nij,nj->n", r, Si, r))
    names = (("focal_px",) if estimate_focal else ()) + POSE_NAMES + (("k1",) if solve_k1 or k1_prior else ())
    dof = 2 * len(uv) - A.shape[1] + int(k1_prior)  # the prior is one more observation
    sol = GCPSolution(cam, p, cov, names, C_theta, gcps, uv_fit, uv - uv_fit, rs, float(cost), dof, iters, size,
                      intrinsics_cov is not None)
    sol.param_map, sol.prior = A, prior
    sol.k1_prior_sigma = float(lens_k1_sigma) if k1_prior else None
    _diagnose(sol, minima, base, A, (r, Si, Jp, SiJ), test_k1=not (solve_k1 or k1_prior) and intrinsics_cov is None)
    if leave_one_out:
        _leave_one_out(sol, base, A, theta, max_iter, estimate_focal, prior)
    _warn_residuals(sol)
    return sol


def _minima(theta0, base, A, gcps, max_iter, prior=None) -> list:
    """Refine every start; the distinct minima ``(theta, (cost, H, r, Si, Jp, SiJ), iterations)``, best first."""
    S = len(theta0)
    n = len(gcps.uv_px)
    mask = np.ones((1, n), bool)
    th, conv, iters = np.empty_like(theta0), np.empty(S, bool), np.empty(S, int)
    step = max(1, _LOO_CHUNK // n)  # starts per batched run: memory O(step * n)
    for i0 in range(0, S, step):
        sl = slice(i0, min(S, i0 + step))
        th[sl], conv[sl], iters[sl], _ = _lm(theta0[sl], np.repeat(base[None], len(theta0[sl]), 0), A,
                                             gcps.uv_px[None], gcps.xyz_world_m[None], gcps.sigma_px[None] ** 2,
                                             gcps.sigma_m[None] ** 2, mask, max_iter, prior=prior,
                                             loose_above=_FAR_MINIMUM_DELTA_CHI2)
    ja = [int(np.argmax(A[a])) for a in (P.PAN, P.TILT, P.ROLL)]
    for b in range(len(th)):  # the same camera in the canonical angles (|tilt| <= 90 deg, as PnP's starts)
        if np.isfinite(th[b, ja]).all():
            th[b, ja] = pan_tilt_roll_from_R_W_C(R_W_C(*th[b, ja]))
    pb = np.repeat(base[None], S, 0) + th @ A.T  # the normal equations in those angles (H depends on them)
    Sc = _point_covariance(pb, gcps.xyz_world_m[None], gcps.sigma_px[None] ** 2, gcps.sigma_m[None] ** 2, mask)
    cost, H, _, ok, (r, Si, Jp, SiJ) = _normal_equations(pb, gcps.uv_px[None], gcps.xyz_world_m[None], Sc, mask, A,
                                                         prior)
    height = (base + th @ A.T)[:, P.HM]
    good = np.flatnonzero(conv & ok & (height > 0) & np.isfinite(cost))
    if good.size == 0:
        if not conv.any():
            raise InputError("ground control point solve", f"no convergence in {int(iters.max())} iterations",
                             "a consistent set of points (check for mismatched or swapped rows)")
        if not (conv & ok).any():
            raise InputError("ground control points", "a point behind the solved camera",
                             "points in front of the camera")
        raise InputError("ground control point solve", f"camera height {height[conv][0]:.3g} m",
                         "a camera above the ground plane z = 0")
    out, cams = [], []
    for b in good[np.argsort(cost[good])]:
        d = th[b] - np.array([m[0] for m in out]) if out else np.zeros((0, th.shape[1]))
        if out and np.min(np.einsum("mk,kl,ml->m", d, H[b], d)) < 1.0:  # within 1 sigma of a kept one: the same
            continue
        pb = base + A @ th[b]  # the same camera written with other angles (pan + 360 deg, ...)
        cam = np.concatenate([R_W_C(pb[P.PAN], pb[P.TILT], pb[P.ROLL]).ravel(), pb[[P.XM, P.YM, P.HM]] * 1e-3,
                              pb[_INT_IDX] * 1e-3])
        if any(np.abs(cam - c).max() < 1e-7 for c in cams):
            continue
        cams.append(cam)
        out.append((th[b], (float(cost[b]), H[b], r[b], Si[b], Jp[b], SiJ[b]), int(iters[b])))
    return out


def _covariance_theta(H, estimate_focal) -> np.ndarray:
    """``H^-1`` (k, k) by the scaled inverse; InputError when H is not finite or its condition number > 1e12."""
    wH = np.sqrt(np.diagonal(H))
    with np.errstate(all="ignore"):
        Hn = H / np.outer(wH, wH)
    cond = np.linalg.cond(Hn) if np.isfinite(Hn).all() else math.inf
    if not np.isfinite(cond) or cond > 1e12:
        what = "focal length and pose" if estimate_focal else "pose"
        raise InputError("ground control points", f"normal-matrix condition number {cond:.3g}",
                         f"points that determine the {what} (spread them in depth and across the image"
                         + (", or give --intrinsics)" if estimate_focal else ")"))
    C = np.linalg.inv(Hn) / np.outer(wH, wH)
    return 0.5 * (C + C.T)


def _full_covariance(A, C_theta, SiJ, Jp, intrinsics_cov) -> np.ndarray:
    """The 22 x 22 covariance: the solve's, plus the given intrinsics' effect (module doc)."""
    cov = A @ C_theta @ A.T
    if intrinsics_cov is not None:
        Hti = np.einsum("nik,nil->kl", SiJ, Jp[..., _INT_IDX])  # (k, 13)
        Bm = A @ (-C_theta @ Hti)
        Bm[_INT_IDX, np.arange(13)] += 1.0
        cov = cov + Bm @ intrinsics_cov @ Bm.T
    return 0.5 * (cov + cov.T)


def _diagnose(sol, minima, base, A, pieces, *, test_k1: bool) -> None:
    """What the solve says about its own weakness (module doc, *Weak geometry*): ``sol.flags`` (the reasons the
    result is not usable), ``sol.alternatives``, ``sol.inflation``, ``sol.tests``, ``sol.loo_normalised``."""
    r, Si, Jp, SiJ = pieces
    k = A.shape[1]
    theta = minima[0][0]
    flags, tests = [], {}
    # other pose minima with a comparable cost
    sol.alternatives = []
    for th, ne, _ in minima[1:]:
        d = th - theta
        p_alt = base + A @ th
        sol.alternatives.append({"delta_chi2": ne[0] - sol.chi2, "distance_sigma": float(np.sqrt(d @ ne[1] @ d)),
                                 "pose": {n: float(p_alt[P.IDX[n]]) for n in POSE_NAMES}})
    close = [a for a in sol.alternatives if a["delta_chi2"] < AMBIGUOUS_DELTA_CHI2]
    if close:
        a = close[0]
        flags.append(f"ambiguous pose: another minimum {a['distance_sigma']:.3g} sigma away fits almost as well "
                     f"(chi-square + {a['delta_chi2']:.3g}; {len(close)} such); add points spread across the image")
    # the residuals: overall chi-square, normalised leave-one-out residuals, the lens (k1 score test)
    Jt = Jp @ A
    Pcov = Jt @ sol.cov_theta @ Jt.transpose(0, 2, 1)  # (N, 2, 2) the fit's share of each residual
    Rcov = np.linalg.inv(Si) - Pcov
    with np.errstate(all="ignore"):
        t = np.einsum("ni,ni->n", r, np.linalg.solve(Rcov, r[..., None])[..., 0])
    sol.loo_normalised = np.where(np.isfinite(t) & (t >= 0), t, np.nan)
    if sol.dof > 0:
        tests["chi2_p"] = float(chi2.sf(sol.chi2, sol.dof))
        if tests["chi2_p"] < RESIDUAL_TEST_P:
            flags.append(f"residuals: reduced chi-square {sol.reduced_chi2:.3g} (p = {tests['chi2_p']:.2g}); the "
                         "stated sigmas are too small or a point is wrong")
    tm = np.nanmax(sol.loo_normalised) if np.isfinite(sol.loo_normalised).any() else np.nan
    if np.isfinite(tm) and sol.dof > 0:
        tests["loo_max_p"] = float(min(1.0, len(r) * chi2.sf(tm, 2)))  # Bonferroni over the points
        if tests["loo_max_p"] < RESIDUAL_TEST_P:
            worst = sol.gcps.names[int(np.nanargmax(sol.loo_normalised))]
            flags.append(f"outlier: point {worst}'s normalised leave-one-out residual {tm:.3g} "
                         f"(p = {tests['loo_max_p']:.2g} over {len(r)} points)")
    if test_k1 and sol.dof > 1:
        jk = Jp[..., P.K1]  # (N, 2) d uv / d k1
        sk = np.einsum("ni,nij->nj", jk, Si)
        g = float(np.einsum("ni,ni->", sk, r))
        cross = np.einsum("ni,nik->k", sk, Jt)
        v = float(np.einsum("ni,ni->", sk, jk)) - cross @ sol.cov_theta @ cross
        if v > 0:
            tests["k1_score"] = g * g / v
            tests["k1_p"] = float(chi2.sf(tests["k1_score"], 1))
            if tests["k1_p"] < LENS_TEST_P:
                flags.append(f"lens model: the residuals ask for radial distortion (k1 score test "
                             f"{tests['k1_score']:.3g}, p = {tests['k1_p']:.2g}); solve k1 (--solve-k1) or give "
                             "calibrated --intrinsics")
    sol.tests = tests
    flags.sort(key=lambda f: not f.startswith(("ambiguous", "lens model")))  # the specific diagnosis first
    flags += _nonlinearity(sol, base, A, k)
    sol.flags = flags


def _nonlinearity(sol, base, A, k) -> list:
    """The cost at both ends of each principal axis of the 95 % region against its quadratic model.

    ``ratio`` = cost rise / chi2_95 (1 for a quadratic cost).  The covariance is inflated by
    ``max(1 / min ratio, sqrt(max over axes of the larger / smaller end's ratio))`` (a region wider than
    its ellipse, and a lopsided one: the estimate is biased along that axis); the result is flagged
    where the cost rises more than MAX_COST_RATIO times its model (a curved valley), or the inflation
    would exceed MAX_INFLATION, or an end is not a camera that sees every point.
    """
    lam, V = np.linalg.eigh(sol.cov_theta)
    c2 = float(chi2.ppf(0.95, k))
    steps = np.sqrt(np.clip(lam, 0, None) * c2)[:, None] * V.T  # (k, k) rows: the axes' half-lengths
    theta = sol.params @ np.linalg.pinv(A).T
    g = sol.gcps
    mask = np.ones((1, len(g.uv_px)), bool)
    pts = base + (theta + np.concatenate([steps, -steps])) @ A.T
    S = _point_covariance(pts, g.xyz_world_m[None], g.sigma_px[None] ** 2, g.sigma_m[None] ** 2, mask)
    cost = _normal_equations(pts, g.uv_px[None], g.xyz_world_m[None], S, mask, A, sol.prior)[0]
    ratio = (cost - sol.chi2) / c2
    if not np.all(np.isfinite(ratio)):
        sol.nonlinearity = {"cost_ratio_min": None, "cost_ratio_max": None, "lopsided": None}
        return ["weak geometry: the 95 % region is not an ellipse (at its edge a point leaves the camera's view); "
                "add points, spread them across the image and in depth"]
    rp, rm = ratio[:k], ratio[k:]
    with np.errstate(all="ignore"):
        lop = float(np.max(np.maximum(rp, rm) / np.minimum(rp, rm)))
    lo, hi = float(ratio.min()), float(ratio.max())
    sol.nonlinearity = {"cost_ratio_min": lo, "cost_ratio_max": hi, "lopsided": lop}
    if hi > MAX_COST_RATIO:
        return [f"weak geometry: the 95 % region is not an ellipse (the cost rises {hi:.3g} times its quadratic "
                "model along an axis: a curved valley); add points, spread them across the image and in depth"]
    f = max(1.0, 1.0 / lo if lo > 0 else math.inf, math.sqrt(lop) if lo > 0 else math.inf)
    if f > MAX_INFLATION:
        return [f"weak geometry: the 95 % region is not an ellipse (its covariance would need inflating x{f:.3g}); "
                "add points, spread them across the image and in depth"]
    sol.inflation = f  # the solve's own share only: a given intrinsics covariance stays as given
    sol.cov_params = sol.cov_params + (f - 1.0) * (A @ sol.cov_theta @ A.T)
    sol.cov_theta = sol.cov_theta * f
    return []


def _leave_one_out(sol, base, A, theta, max_iter, estimate_focal, prior=None):
    g = sol.gcps
    n = len(g.uv_px)
    need = MIN_POINTS_FOCAL if estimate_focal else MIN_POINTS_POSE
    sol.loo_residual_px = np.full((n, 2), np.nan)
    sol.loo_ground_error_m = np.full((n, 2), np.nan)
    if n - 1 < need:
        sol.loo_status = [f"too few points without it ({n - 1} < {need})"] * n
        return
    if n > MAX_LOO_POINTS:
        sol.loo_status = [f"not re-solved (more than {MAX_LOO_POINTS} points)"] * n
        return
    th, conv = np.empty((n, len(theta))), np.empty(n, bool)
    step = max(1, _LOO_CHUNK // n)  # problems per batched run: memory O(step * n), never O(n^2)
    for i0 in range(0, n, step):
        m = min(step, n - i0)
        mask = np.ones((m, n), bool)
        mask[np.arange(m), i0 + np.arange(m)] = False
        th[i0:i0 + m], conv[i0:i0 + m], _, _ = _lm(
            np.repeat(theta[None], m, 0), np.repeat(base[None], m, 0), A, g.uv_px[None], g.xyz_world_m[None],
            g.sigma_px[None] ** 2, g.sigma_m[None] ** 2, mask, max_iter, prior=prior)
    pl = base + th @ A.T  # (n, 22)
    pred = general.project(pl, g.xyz_world_m)
    ph = pl.copy()
    ph[:, P.HM] -= g.xyz_world_m[:, 2]  # back-project onto the horizontal plane through the point
    bp = general.backproject(ph, g.uv_px)
    ok = conv & pred.valid & bp.valid
    sol.loo_residual_px = np.where(ok[:, None], g.uv_px - pred.uv_px, np.nan)
    sol.loo_ground_error_m = np.where(ok[:, None], bp.xy_world_m - g.xyz_world_m[:, :2], np.nan)
    sol.loo_status = ["ok" if o else ("no convergence" if not c else "not visible / above the horizon")
                      for o, c in zip(ok, conv, strict=True)]


def _warn_residuals(sol):

    if sol.dof > 0:
        pval = chi2.sf(sol.chi2, sol.dof)
        if pval < 1e-3:
            warnings.warn(f"GCP residuals are larger than the stated sigmas explain (reduced chi-square "
                          f"{sol.reduced_chi2:.3g}, p = {pval:.2g}): the covariance is optimistic; raise "
                          "--pixel-sigma-px/--survey-sigma-m or check residuals.csv for a wrong point",
                          ConsistencyWarning, stacklevel=3)
    worst = int(np.argmax(sol.residual_sigma))
    if sol.residual_sigma[worst] > 5.0:
        warnings.warn(f"GCP {sol.gcps.names[worst]}: residual {sol.residual_sigma[worst]:.3g} sigma "
                      f"({np.hypot(*sol.residual_px[worst]):.3g} px); a mismatched point?",
                      ConsistencyWarning, stacklevel=3)
