"""Fused numba kernels for :class:`footprint_uq.products.footprints.FrameProcessor`.

One call processes a frame (or a batch chunk).  Objects go through in chunks of
``_M_TARGET // K`` (16 boxes of 4 corners), corner-major (column ``k * nob + i`` is corner
k of object i) in one scratch buffer ``S`` whose rows sit at compile-time offsets
(``_U``, ``_JP``, ...): every access is "one base pointer + a constant", so LLVM proves
the rows independent and vectorises each stage, a straight loop over the chunk's
corners or objects:

* :func:`_stage_project` (3D boxes) -- the four bottom corners of each box into the image;
* :func:`_stage_undistort` -- pixel -> normalised coordinates, OpenCV undistortion (Newton,
  all corners together, each stopping when converged, as
  :func:`footprint_uq.cameras.distortion.undistort`) and its implicit-function Jacobians;
* :func:`_stage_ground` -- ray / perturbed-ground intersection with the full d(x, y)/d(params)
  (2 x 22) and d(x, y)/d(u, v) Jacobians (the math of
  :func:`footprint_uq.cameras.general.backproject`);
* :func:`_stage_corner_flags`, :func:`_stage_centroid` -- status per corner (outside the
  image, 3D projection), the centre (vertex mean), its Jacobian and the polygon's area;
* :func:`_stage_whiten` -- ``J L`` with the sparse factor ``L L^T`` of the 22x22 parameter
  covariance (:meth:`footprint_uq.uncertainty.budget.ErrorBudget.param_factor`; only non-zero entries are
  touched): the parameter part of every corner's and of the centre's covariance;
* :func:`_stage_corner_cov`, :func:`_stage_select`, :func:`_stage_centre_cov` -- per-point
  pixel noise (budget + detector), the largest point;
* :func:`_stage_v2x` -- 1-sigma ellipse and the CPM / J2735 integer fields.

libm calls (cos/sin, ``atan2``, ``hypot``) run in loops of their own; rows chosen at run
time are indexed with unsigned offsets.  Outputs go to arrays the caller allocates
(:func:`alloc_outputs`); the per-object numbers are contiguous rows (:data:`OBJ_ROWS`).
The numpy reference is :func:`footprint_uq.products.footprints.footprints_from_corners`; the tests
hold the two to 1e-9 relative and the V2X fields equal.

Camera constants travel in one named structure ``cam`` (:class:`KernelCamera`) and
the rotation derivatives in ``dR`` (3 angles, 3, 3), both prepared once per
camera by the processor.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from .. import params as P
from .. import status
from .. import v2x_codes as v2x
from . import core
from .rotation import R_W_C, dR_W_C


class KernelCamera(NamedTuple):
    """Camera constants the kernels read (one per :class:`~footprint_uq.products.footprints.FrameProcessor`).

    Numba passes it by value as a struct; fields are read by name (``cam.fx``).  Units as in
    :data:`footprint_uq.params.PARAM_NAMES`; ``R`` is ``R_W_C`` row-major (9,); ``dom`` the packed
    lens domain (:mod:`footprint_uq.cameras.lens_domain`).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    skew: float
    ifx: float  # 1 / fx
    ify: float  # 1 / fy
    dist: np.ndarray  # (8,) k1 k2 p1 p2 k3 k4 k5 k6
    has_dist: bool
    x0: float  # camera position in W, m
    y0: float
    h: float  # height above the nominal ground, m
    gdz: float  # ground offset and slopes (nominal)
    gsx: float
    gsy: float
    R: np.ndarray  # (9,)
    width_px: float
    height_px: float
    ground_z_m: float
    dom: np.ndarray


# status codes (footprint_uq.status) and the V2X constants (footprint_uq.products.v2x), frozen at compile time
_OK, _ABOVE, _NOTFIN, _UNDIST = status.OK, status.ABOVE_HORIZON, status.NOT_FINITE, status.UNDISTORT_FAILED
_OUTSIDE, _BEHIND, _DEGENERATE = status.OUTSIDE_IMAGE, status.BEHIND_CAMERA, status.DEGENERATE
_Z95, _K95_2D, _GUARD, _CIRC = v2x.Z95_1D, v2x.K95_2D, v2x.STEP_GUARD, v2x.CIRCULAR_RTOL
_CPM_UNIT, _CPM_MAX_M = v2x.CPM_COORD_UNIT_M, v2x.CPM_COORD_MAX_M
_CPM_OOR, _CPM_UNAV = float(v2x.CPM_COORD_OUT_OF_RANGE), float(v2x.CPM_COORD_UNAVAILABLE)
_CORR_UNAV = float(v2x.CPM_CORR_UNAVAILABLE)
_AX_UNIT, _AX_MAX, _AX_MAX_M = v2x.J2735_AXIS_UNIT_M, float(v2x.J2735_AXIS_MAX), v2x.J2735_AXIS_MAX_M
_AX_UNAV = float(v2x.J2735_AXIS_UNAVAILABLE)
_ORIENT_UNIT, _ORIENT_UNAV = v2x.J2735_ORIENTATION_UNIT_DEG, float(v2x.J2735_ORIENTATION_UNAVAILABLE)

#: the stages of :func:`process_corners` are inlined into it (numba IR): a call between compiled functions
#: passes every array as a reference-counted struct (S, the camera, the factor, the 12 outputs), and those
#: calls, ~20 per chunk, cost ~15 % of the per-frame kernel (measured: 100 3D boxes 37.8 -> 33.8 us
#: without the linearity flag, 48.6 -> 43.4 us with it; the first compilation takes ~20 s longer).
#: Measured again 2026-11-26 (2-core VM, load average 6-8, best of 3 interleaved runs, joint covariance off):
#: without inlining 100 boxes take 9-19 % longer (pan-tilt 87.9 -> 99.6 us with the flag, 68.7 -> 81.6 us
#: without; OpenCV 106.9 -> 117.1, 90.9 -> 99.2 us) and the objects group compiles in 55 instead of 135 CPU
#: seconds.  Kept: a command no longer waits for this compile (it runs in the background while the command
#: takes the reference path: products.warmup.KernelGate), the per-frame time is what a service pays forever.
_STAGE = dict(cache=True, error_model="numpy", nogil=True, inline="always")

# Chunk scratch: ONE float64 buffer; row r of a chunk is S[r * _ST : r * _ST + m].  Every access
# is "one base pointer + a compile-time offset", so LLVM proves the rows independent and vectorises
# the corner loops (with a dozen separate arrays it gives up on the run-time alias checks).
# Corner k of object i of a chunk of nob objects is column j = k * nob + i (corner-major), so the
# per-object stages also run straight over contiguous columns.
_ST = 264  # row stride = most corners in a chunk (not a power of two: keeps rows in different cache sets)
_M_TARGET = 64  # corners per chunk (a chunk's working set stays in L1/L2)
MAX_CORNERS = _ST  # footprints with more corners per object go to the numpy reference
def _layout(blocks) -> tuple[dict[str, int], int]:
    """Row offsets of consecutive named blocks ``[(name, rows, meaning), ...]`` and the total."""
    off, n = {}, 0
    for name, rows, _meaning in blocks:
        off[name] = n
        n += rows
    return off, n


#: the scratch rows, in order: (name, rows, meaning); offsets are generated from this table
SCRATCH_ROWS = (
    ("U", 1, "corner pixel u"), ("V", 1, "corner pixel v"),
    ("XD", 1, "distorted normalised x"), ("YD", 1, "distorted normalised y"),
    ("XN", 1, "undistorted normalised x"), ("YN", 1, "undistorted normalised y"),
    ("CONV", 1, "1.0 where undistortion answered"),
    ("INV", 4, "d(undistorted)/d(distorted) 00 01 10 11"),
    ("JK", 16, "d x_d / d k (8), d y_d / d k (8)"),
    ("X", 1, "ground x"), ("Y", 1, "ground y"), ("CODE", 1, "status code"),
    ("JP", 44, "d(x, y)/d(params), row i * 22 + param"),
    ("JUV", 4, "d(x, y)/d(u, v)"),
    ("B4", 4, "d(x, y)/d(x_n)"),
    ("AW", 44, "J L (2 r <= 44 rows)"),
    ("C3", 3, "parameter part of each corner covariance (xx, xy, yy)"),
    ("P4", 4, "pixel covariance of each corner (budget + detector)"),
    ("CC", 3, "corner covariance (xx, xy, yy), NaN if not computed"),
    ("SSEL", 1, "semi-axis if usable else -1"), ("RC", 1, "final code"), ("US", 1, "usable"),
    ("XX", 1, "x (NaN if not computed)"), ("YY", 1, "y (NaN if not computed)"),
    ("Q", 2, "corner minus vertex mean"), ("QN", 2, "the same of the next corner"),
    ("G", 4, "d centre / d corner (cx/x, cx/y, cy/x, cy/y)"),
    ("T0", 1, "per-corner temporary"), ("T1", 1, "per-corner temporary"), ("T2", 1, "per-corner temporary"),
    # per-object rows (columns 0 .. nob - 1)
    ("BEST", 1, "largest corner"), ("BSEMI", 1, "its semi-axis"), ("FBAD", 1, "first unusable corner"),
    ("MX", 1, "vertex mean x"), ("MY", 1, "vertex mean y"), ("SS", 1, "sum"), ("A2", 1, "twice the area"),
    ("B0", 1, "pixel-noise part 00"), ("B1", 1, "pixel-noise part 01"), ("B2", 1, "pixel-noise part 11"),
    ("E00", 1, "centre covariance xx"), ("E01", 1, "centre covariance xy"), ("E11", 1, "centre covariance yy"),
    ("CXC", 1, "centre x"), ("CYC", 1, "centre y"), ("AREA", 1, "signed area"), ("DEG", 1, "degenerate"),
    ("ANG", 1, "ellipse angle"),
    ("PC", 1, "3D boxes: projection code per corner"), ("CS", 1, "cos yaw"), ("SN", 1, "sin yaw"),
    ("BX", 7, "the chunk's boxes"),
    ("VX", 7, "V2X fields of each object"),
    # the linearity flag (docs/uncertainty-model.md, "The linearity flag"; fast.core.nonlinearity_point)
    ("GD", 22, "dDn/d(params), row = param (0 for x_m, y_m, height_m, ground_dz_m)"),
    ("GUV", 2, "dDn/d(u, v)"), ("DN", 1, "ray denominator Dn"), ("LAM", 1, "lam = N / Dn, m"),
    ("DXY", 2, "horizontal part of the world ray"),
    ("JG", 2, "J Sigma g (parameters; + pixel in _stage_flag)"), ("GAM", 1, "g^T Sigma g"),
    ("XP", 4, "J Sigma E (00 01 10 11), E the camera position"), ("GPS", 2, "E^T Sigma g"),
    ("FA", 2, "one factor column of J L being formed"), ("FT", 1, "the same of L^T g"),
    ("NL", 1, "nonlinearity per corner"), ("NLC", 1, "nonlinearity of the centre (largest of its corners')"),
)
_ROW, _NROWS = _layout(SCRATCH_ROWS)
_U, _V, _XD, _YD, _XN, _YN, _CONV, _INV, _JK = (_ROW[k] for k in ("U", "V", "XD", "YD", "XN", "YN", "CONV", "INV",
                                                                  "JK"))
_X, _Y, _CODE, _JP, _JUV, _B4, _AW, _C3, _P4, _CC = (_ROW[k] for k in ("X", "Y", "CODE", "JP", "JUV", "B4", "AW",
                                                                       "C3", "P4", "CC"))
_SSEL, _RC, _US, _XX, _YY, _Q, _QN, _G = (_ROW[k] for k in ("SSEL", "RC", "US", "XX", "YY", "Q", "QN", "G"))
_T0, _T1, _T2 = _ROW["T0"], _ROW["T1"], _ROW["T2"]
_BEST, _BSEMI, _FBAD, _MX, _MY, _SS, _A2 = (_ROW[k] for k in ("BEST", "BSEMI", "FBAD", "MX", "MY", "SS", "A2"))
_B0, _B1, _B2, _E00, _E01, _E11, _CXC, _CYC, _AREA, _DEG = (_ROW[k] for k in ("B0", "B1", "B2", "E00", "E01", "E11",
                                                                              "CXC", "CYC", "AREA", "DEG"))
_ANG, _PC, _CS, _SN, _BX, _VX = (_ROW[k] for k in ("ANG", "PC", "CS", "SN", "BX", "VX"))
_GD, _GUV, _DN, _LAM, _DXY, _JG, _GAM, _XP, _GPS, _FA, _FT, _NL, _NLC = (
    _ROW[k] for k in ("GD", "GUV", "DN", "LAM", "DXY", "JG", "GAM", "XP", "GPS", "FA", "FT", "NL", "NLC"))

# rows of the per-object output block ``obj`` (13, N), named as the batch's output columns (FootprintEstimate
# views them, the batch writes them; cov_yx_m2 = cov_xy_m2 completes the 2x2 view)
OBJ_ROWS = ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yx_m2", "cov_yy_m2", "sigma_major_m",
            "sigma_minor_m", "orientation_deg", "largest_sigma_major_m", "largest_x_m", "largest_y_m", "area_m2",
            "nonlinearity", "largest_nonlinearity")
#: row of each name in ``obj``
OBJ_ROW = {name: i for i, name in enumerate(OBJ_ROWS)}
(_O_CX, _O_CY, _O_C00, _O_C01, _O_C10, _O_C11, _O_SMAJ, _O_SMIN, _O_ORI, _O_LSEMI, _O_LX, _O_LY, _O_AREA, _O_NL,
 _O_LNL) = (OBJ_ROW[k] for k in OBJ_ROWS)


def camera_constants(camera) -> tuple[KernelCamera, np.ndarray]:
    """``(cam, dR)`` for the kernels from a :class:`~footprint_uq.cameras.base.Camera`."""
    p = np.asarray(camera.params, dtype=np.float64)
    ang = p[P.PAN], p[P.TILT], p[P.ROLL]
    w, h = camera.image_size_px
    cam = KernelCamera(
        fx=float(p[P.FX]), fy=float(p[P.FY]), cx=float(p[P.CX]), cy=float(p[P.CY]), skew=float(p[P.SKEW]),
        ifx=1.0 / p[P.FX], ify=1.0 / p[P.FY], dist=_writable(p[P.DIST_SLICE]),
        has_dist=bool(np.any(p[P.DIST_SLICE] != 0)), x0=float(p[P.XM]), y0=float(p[P.YM]), h=float(p[P.HM]),
        gdz=float(p[P.GDZ]), gsx=float(p[P.GSX]), gsy=float(p[P.GSY]), R=np.ascontiguousarray(R_W_C(*ang).ravel()),
        width_px=float(w), height_px=float(h), ground_z_m=float(camera.ground_z_m),
        dom=_writable(camera.lens_domain.packed))
    return cam, _writable(dR_W_C(*ang))


def _writable(a) -> np.ndarray:
    """A writable C-contiguous float64 copy: numba types a read-only array (an OpenCV camera's lens domain,
    a read-only ``params``) as another type, so every camera's constants would compile the kernels again."""
    return np.array(a, dtype=np.float64, order="C", copy=True)


@njit(cache=True, error_model="numpy", nogil=True)
def _distort(x, y, cam, J, Jk, want_k):
    """Distorted (xd, yd) (:func:`footprint_uq.fast.core.distort_jac`); fills J (2, 2) and, if want_k, Jk (2, 8)."""
    xd, yd, J[0, 0], J[0, 1], J[1, 0], J[1, 1], rad, den = core.distort_jac(x, y, cam.dist)
    r2 = x * x + y * y
    iden = 1.0 / den
    num = rad * den
    if want_k:
        r4 = r2 * r2
        r6 = r4 * r2
        nd2 = -num * iden * iden
        dr0, dr1, dr4 = r2 * iden, r4 * iden, r6 * iden
        dr5, dr6, dr7 = nd2 * r2, nd2 * r4, nd2 * r6
        Jk[0, 0], Jk[1, 0] = x * dr0, y * dr0
        Jk[0, 1], Jk[1, 1] = x * dr1, y * dr1
        Jk[0, 2], Jk[1, 2] = 2.0 * x * y, r2 + 2.0 * y * y
        Jk[0, 3], Jk[1, 3] = r2 + 2.0 * x * x, 2.0 * x * y
        Jk[0, 4], Jk[1, 4] = x * dr4, y * dr4
        Jk[0, 5], Jk[1, 5] = x * dr5, y * dr5
        Jk[0, 6], Jk[1, 6] = x * dr6, y * dr6
        Jk[0, 7], Jk[1, 7] = x * dr7, y * dr7
    return xd, yd


@njit(**_STAGE)
def _stage_undistort(S, m, cam, Jd, Jk, need):
    """Pixels (rows U, V) -> distorted (XD, YD) and undistorted (XN, YN) normalised coordinates.

    Also fills CONV (1.0 where undistortion converged), INV (d(undistorted)/d(distorted)) and
    JK (rows 0..7: d x_d / d k, rows 8..15: d y_d / d k).  Without distortion the loops are
    straight-line and vectorise; with it the corners go through the scalar core
    (:func:`footprint_uq.fast.core.undistort_vec`), inside the lens's valid domain as in
    :func:`footprint_uq.cameras.distortion.undistort`.  ``need`` as in :func:`_stage_ground`:
    without distortion, JK rows nobody reads are skipped.
    """
    cx, cy, sk = cam.cx, cam.cy, cam.skew
    ifx, ify = cam.ifx, cam.ify
    for j in range(m):
        yd = (S[_V * _ST + j] - cy) * ify
        S[_XD * _ST + j] = (S[_U * _ST + j] - cx - sk * yd) * ifx
        S[_YD * _ST + j] = yd
    if not cam.has_dist:
        for j in range(m):
            x, y = S[_XD * _ST + j], S[_YD * _ST + j]
            S[_XN * _ST + j], S[_YN * _ST + j] = x, y
            S[_CONV * _ST + j] = 1.0 if (math.isfinite(x) & math.isfinite(y)) else 0.0
            S[_INV * _ST + j], S[(_INV + 1) * _ST + j] = 1.0, 0.0
            S[(_INV + 2) * _ST + j], S[(_INV + 3) * _ST + j] = 0.0, 1.0
        if need[5]:
            for j in range(m):
                x, y = S[_XD * _ST + j], S[_YD * _ST + j]
                r2 = x * x + y * y
                r4 = r2 * r2
                r6 = r4 * r2
                S[_JK * _ST + j], S[(_JK + 8) * _ST + j] = x * r2, y * r2
                S[(_JK + 1) * _ST + j], S[(_JK + 9) * _ST + j] = x * r4, y * r4
                S[(_JK + 2) * _ST + j], S[(_JK + 10) * _ST + j] = 2.0 * x * y, r2 + 2.0 * y * y
                S[(_JK + 3) * _ST + j], S[(_JK + 11) * _ST + j] = r2 + 2.0 * x * x, 2.0 * x * y
                S[(_JK + 4) * _ST + j], S[(_JK + 12) * _ST + j] = x * r6, y * r6
        if need[10]:
            for j in range(m):
                x, y = S[_XD * _ST + j], S[_YD * _ST + j]
                r2 = x * x + y * y
                r4 = r2 * r2
                r6 = r4 * r2
                S[(_JK + 5) * _ST + j], S[(_JK + 13) * _ST + j] = -x * r2, -y * r2
                S[(_JK + 6) * _ST + j], S[(_JK + 14) * _ST + j] = -x * r4, -y * r4
                S[(_JK + 7) * _ST + j], S[(_JK + 15) * _ST + j] = -x * r6, -y * r6
        return
    # the scalar core's undistortion, vectorised over the chunk's corners (same answer as the reference)
    dist = cam.dist
    ok = np.empty(m, dtype=np.bool_)
    for j in range(m):
        S[_XN * _ST + j], S[_YN * _ST + j] = S[_XD * _ST + j], S[_YD * _ST + j]
    core.undistort_vec(cam.dom, dist, S[_XD * _ST:_XD * _ST + m], S[_YD * _ST:_YD * _ST + m],
                       S[_XN * _ST:_XN * _ST + m], S[_YN * _ST:_YN * _ST + m],
                       S[_INV * _ST:_INV * _ST + m], S[(_INV + 1) * _ST:(_INV + 1) * _ST + m],
                       S[(_INV + 2) * _ST:(_INV + 2) * _ST + m], S[(_INV + 3) * _ST:(_INV + 3) * _ST + m],
                       S[_T0 * _ST:_T0 * _ST + m], ok)
    for j in range(m):
        S[_CONV * _ST + j] = 1.0 if ok[j] else 0.0
        _distort(S[_XN * _ST + j], S[_YN * _ST + j], cam, Jd, Jk, True)
        for kk in range(8):
            S[(_JK + kk) * _ST + j] = Jk[0, kk]
            S[(_JK + 8 + kk) * _ST + j] = Jk[1, kk]


@njit(**_STAGE)
def _stage_ground(S, m, cam, dR, need):
    """Ray / ground intersection and all Jacobians over the corners of a chunk.

    Mirrors :func:`footprint_uq.cameras.general.backproject` with gradients: rows X, Y the
    ground point, CODE the status, JP (44 rows) = d(x, y)/d(params) (row ``i * 22 + param``),
    JUV (4 rows) = d(x, y)/d(u, v) (00, 01, 10, 11).  Invalid corners carry NaN or meaningless
    numbers here; the caller masks them by CODE.  The main loop is branch-free straight-line
    code (it vectorises) and writes every JP row except the distortion ones; those follow (only
    if ``need``, the (22,) mask of parameters with variance, asks for them) in one short loop
    per coefficient, from d(x, y)/d(x_n) kept in rows B4.
    """
    D0, D1, D2 = _mat9(dR[0]), _mat9(dR[1]), _mat9(dR[2])  # d R / d (pan, tilt, roll)
    sk, ifx, ify = cam.skew, cam.ifx, cam.ify
    skf = sk * ify * ifx
    R0, R1, R2, R3, R4, R5, R6, R7, R8 = (cam.R[0], cam.R[1], cam.R[2], cam.R[3], cam.R[4],
                                          cam.R[5], cam.R[6], cam.R[7], cam.R[8])
    gdz, gx, gy = cam.gdz, cam.gsx, cam.gsy
    Hn = cam.h - gdz
    n0, n1 = R6 - gx * R0 - gy * R3, R7 - gx * R1 - gy * R4  # n . R[:, 0], n . R[:, 1]
    hR00, hR01, hR10, hR11 = Hn * R0, Hn * R1, Hn * R3, Hn * R4
    X0, Y0 = cam.x0, cam.y0
    for j in range(m):
        u, v = S[_U * _ST + j], S[_V * _ST + j]
        xd, yd, xn, yn = S[_XD * _ST + j], S[_YD * _ST + j], S[_XN * _ST + j], S[_YN * _ST + j]
        i00, i01 = S[_INV * _ST + j], S[(_INV + 1) * _ST + j]
        i10, i11 = S[(_INV + 2) * _ST + j], S[(_INV + 3) * _ST + j]
        finite = math.isfinite(u) & math.isfinite(v)
        dx = R0 * xn + R1 * yn + R2
        dy = R3 * xn + R4 * yn + R5
        dz = R6 * xn + R7 * yn + R8
        Dn = dz - gx * dx - gy * dy
        inv = 1.0 / Dn
        # the ground point and b = dxy/dxn (the scalar core)
        lam, ox, oy, b00, b01, b10, b11 = core.ground_of_ray(Hn, hR00, hR01, hR10, hR11, n0, n1, dx, dy, Dn)
        vg = (Dn < 0.0) & (Hn > 0.0) & math.isfinite(lam)
        rc = _OK if vg else _ABOVE
        rc = _UNDIST if S[_CONV * _ST + j] == 0.0 else rc
        rc = rc if finite else _NOTFIN
        S[_CODE * _ST + j] = rc
        S[_X * _ST + j] = X0 + ox
        S[_Y * _ST + j] = Y0 + oy
        # dxy/dray (2, 3) = lam I + d_xy dlam/dray, dlam/dray = (-lam/Dn) (-gx, -gy, 1) (for the angles)
        f = -lam * inv
        l0, l1, l2 = -gx * f, -gy * f, f
        a00, a01, a02 = lam + dx * l0, dx * l1, dx * l2
        a10, a11, a12 = dy * l0, lam + dy * l1, dy * l2
        # dxy/dxd = dxy/dxn @ dxn/dxd
        S[_B4 * _ST + j], S[(_B4 + 1) * _ST + j], S[(_B4 + 2) * _ST + j], S[(_B4 + 3) * _ST + j] = b00, b01, b10, b11
        c00 = b00 * i00 + b01 * i10
        c01 = b00 * i01 + b01 * i11
        c10 = b10 * i00 + b11 * i10
        c11 = b10 * i01 + b11 * i11
        # intrinsics: dxd/dk (fx, fy, cx, cy, skew), see pinhole.pixel_to_normalised
        dy_dfy = -yd * ify
        kx0, kx1, kx2, kx3, kx4 = -xd * ifx, -sk * ifx * dy_dfy, -ifx, skf, -yd * ifx
        ky1, ky3 = dy_dfy, -ify
        S[_JP * _ST + j], S[(_JP + 22) * _ST + j] = c00 * kx0, c10 * kx0
        S[(_JP + 1) * _ST + j], S[(_JP + 23) * _ST + j] = c00 * kx1 + c01 * ky1, c10 * kx1 + c11 * ky1
        S[(_JP + 2) * _ST + j], S[(_JP + 24) * _ST + j] = c00 * kx2, c10 * kx2
        S[(_JP + 3) * _ST + j], S[(_JP + 25) * _ST + j] = c00 * kx3 + c01 * ky3, c10 * kx3 + c11 * ky3
        S[(_JP + 4) * _ST + j], S[(_JP + 26) * _ST + j] = c00 * kx4, c10 * kx4
        # camera position
        S[(_JP + 13) * _ST + j], S[(_JP + 14) * _ST + j], S[(_JP + 15) * _ST + j] = 1.0, 0.0, -dx * inv
        S[(_JP + 35) * _ST + j], S[(_JP + 36) * _ST + j], S[(_JP + 37) * _ST + j] = 0.0, 1.0, -dy * inv
        # angles: dxy/dray @ (dR_k @ ray_c)
        _angle_rows(S, j, _JP + 16, D0, xn, yn, a00, a01, a02, a10, a11, a12)
        _angle_rows(S, j, _JP + 17, D1, xn, yn, a00, a01, a02, a10, a11, a12)
        _angle_rows(S, j, _JP + 18, D2, xn, yn, a00, a01, a02, a10, a11, a12)
        # ground: d_xy dlam/dg, dlam/dg = (1/Dn, lam dx/Dn, lam dy/Dn)
        g1, g2 = lam * dx * inv, lam * dy * inv
        S[(_JP + 19) * _ST + j], S[(_JP + 20) * _ST + j], S[(_JP + 21) * _ST + j] = dx * inv, dx * g1, dx * g2
        S[(_JP + 41) * _ST + j], S[(_JP + 42) * _ST + j], S[(_JP + 43) * _ST + j] = dy * inv, dy * g1, dy * g2
        # dxy/duv = dxy/dxd @ dxd/duv
        S[_JUV * _ST + j] = c00 * ifx
        S[(_JUV + 1) * _ST + j] = -c00 * skf + c01 * ify
        S[(_JUV + 2) * _ST + j] = c10 * ifx
        S[(_JUV + 3) * _ST + j] = -c10 * skf + c11 * ify
    _stage_ground_distortion(S, m, need)


@njit(**_STAGE)
def _mat9(A):
    """A (3, 3) as a row-major 9-tuple (constants the loops read without touching an array)."""
    return A[0, 0], A[0, 1], A[0, 2], A[1, 0], A[1, 1], A[1, 2], A[2, 0], A[2, 1], A[2, 2]


@njit(**_STAGE)
def _mat9_ray(D, x, y):
    """``D (x, y, 1)`` for a row-major 9-tuple ``D``."""
    return D[0] * x + D[1] * y + D[2], D[3] * x + D[4] * y + D[5], D[6] * x + D[7] * y + D[8]


@njit(**_STAGE)
def _angle_rows(S, j, row, D, xn, yn, a00, a01, a02, a10, a11, a12):
    """JP rows ``row`` (x) and ``row + 22`` (y) of one angle: ``dxy/dray @ (dR_k @ (x_n, y_n, 1))``."""
    q0, q1, q2 = _mat9_ray(D, xn, yn)
    S[row * _ST + j] = a00 * q0 + a01 * q1 + a02 * q2
    S[(row + 22) * _ST + j] = a10 * q0 + a11 * q1 + a12 * q2


@njit(**_STAGE)
def _stage_ground_distortion(S, m, need):
    """JP rows of the distortion coefficients (only those ``need`` asks for), one short loop each:
    ``dxy/dxn @ (-(dxd/dxn)^-1 dxd/dk)`` from rows B4, INV and JK (k1 k2 p1 p2 k3, then k4 k5 k6)."""
    if not need[5]:
        return
    for kk in range(8 if need[10] else 5):
        for j in range(m):
            jx, jy = S[(_JK + kk) * _ST + j], S[(_JK + 8 + kk) * _ST + j]
            e0 = -(S[_INV * _ST + j] * jx + S[(_INV + 1) * _ST + j] * jy)
            e1 = -(S[(_INV + 2) * _ST + j] * jx + S[(_INV + 3) * _ST + j] * jy)
            S[(_JP + 5 + kk) * _ST + j] = S[_B4 * _ST + j] * e0 + S[(_B4 + 1) * _ST + j] * e1
            S[(_JP + 27 + kk) * _ST + j] = S[(_B4 + 2) * _ST + j] * e0 + S[(_B4 + 3) * _ST + j] * e1


@njit(**_STAGE)
def _stage_ray_denominator(S, m, cam, dR, need):
    """The linearity flag's per-corner inputs: rows DN, LAM, DXY, GD = dDn/d(params) and GUV = dDn/d(u, v).

    ``Dn = n . d`` is the world ray ``d = R (x_n, y_n, 1)`` along the ground's upward normal
    ``n = (-s_x, -s_y, 1)`` (< 0 where the ray meets the ground), ``lam = N / Dn`` with ``N =
    ground_dz - h``; the gradients follow the chain of :func:`_stage_ground` contracted with ``n``
    instead of ``dxy/dray`` (numpy reference: :func:`footprint_uq.propagation.ray_denominator`).
    Rows of parameters ``Dn`` does not depend on (x_m, y_m, height_m, ground_dz_m) are zero.
    """
    R0, R1, R2, R3, R4, R5, R6, R7, R8 = (cam.R[0], cam.R[1], cam.R[2], cam.R[3], cam.R[4],
                                          cam.R[5], cam.R[6], cam.R[7], cam.R[8])
    gx, gy = cam.gsx, cam.gsy
    n0, n1, n2 = R6 - gx * R0 - gy * R3, R7 - gx * R1 - gy * R4, R8 - gx * R2 - gy * R5  # n . R[:, c]
    d0, d1, d2 = dR[0], dR[1], dR[2]  # n . dR_a[:, c] for the three angles
    a00, a01, a02 = (d0[2, 0] - gx * d0[0, 0] - gy * d0[1, 0], d0[2, 1] - gx * d0[0, 1] - gy * d0[1, 1],
                     d0[2, 2] - gx * d0[0, 2] - gy * d0[1, 2])
    a10, a11, a12 = (d1[2, 0] - gx * d1[0, 0] - gy * d1[1, 0], d1[2, 1] - gx * d1[0, 1] - gy * d1[1, 1],
                     d1[2, 2] - gx * d1[0, 2] - gy * d1[1, 2])
    a20, a21, a22 = (d2[2, 0] - gx * d2[0, 0] - gy * d2[1, 0], d2[2, 1] - gx * d2[0, 1] - gy * d2[1, 1],
                     d2[2, 2] - gx * d2[0, 2] - gy * d2[1, 2])
    sk, ifx, ify = cam.skew, cam.ifx, cam.ify
    skf = sk * ify * ifx
    Nn = cam.gdz - cam.h
    for j in range(m):
        xd, yd, xn, yn = S[_XD * _ST + j], S[_YD * _ST + j], S[_XN * _ST + j], S[_YN * _ST + j]
        i00, i01 = S[_INV * _ST + j], S[(_INV + 1) * _ST + j]
        i10, i11 = S[(_INV + 2) * _ST + j], S[(_INV + 3) * _ST + j]
        dx = R0 * xn + R1 * yn + R2
        dy = R3 * xn + R4 * yn + R5
        dn = n0 * xn + n1 * yn + n2
        S[_DN * _ST + j], S[_LAM * _ST + j] = dn, Nn / dn
        S[_DXY * _ST + j], S[(_DXY + 1) * _ST + j] = dx, dy
        e0 = n0 * i00 + n1 * i10  # dDn/dx_d
        e1 = n0 * i01 + n1 * i11
        dy_dfy = -yd * ify
        S[_GD * _ST + j] = -e0 * xd * ifx
        S[(_GD + 1) * _ST + j] = -e0 * sk * ifx * dy_dfy + e1 * dy_dfy
        S[(_GD + 2) * _ST + j] = -e0 * ifx
        S[(_GD + 3) * _ST + j] = e0 * skf - e1 * ify
        S[(_GD + 4) * _ST + j] = -e0 * yd * ifx
        S[(_GD + 13) * _ST + j], S[(_GD + 14) * _ST + j] = 0.0, 0.0
        S[(_GD + 15) * _ST + j], S[(_GD + 19) * _ST + j] = 0.0, 0.0
        S[(_GD + 16) * _ST + j] = a00 * xn + a01 * yn + a02
        S[(_GD + 17) * _ST + j] = a10 * xn + a11 * yn + a12
        S[(_GD + 18) * _ST + j] = a20 * xn + a21 * yn + a22
        S[(_GD + 20) * _ST + j], S[(_GD + 21) * _ST + j] = -dx, -dy
        S[_GUV * _ST + j] = e0 * ifx
        S[(_GUV + 1) * _ST + j] = -e0 * skf + e1 * ify
    # distortion: n . R[:, :2] (dx_n/dk), dx_n/dk = -(dx_d/dx_n)^-1 dx_d/dk
    for kk in range(8):
        if (kk < 5 and need[5]) or (kk >= 5 and need[10]):
            for j in range(m):
                jx, jy = S[(_JK + kk) * _ST + j], S[(_JK + 8 + kk) * _ST + j]
                e0 = -(S[_INV * _ST + j] * jx + S[(_INV + 1) * _ST + j] * jy)
                e1 = -(S[(_INV + 2) * _ST + j] * jx + S[(_INV + 3) * _ST + j] * jy)
                S[(_GD + 5 + kk) * _ST + j] = n0 * e0 + n1 * e1
        else:
            for j in range(m):
                S[(_GD + 5 + kk) * _ST + j] = 0.0


@njit(cache=True, error_model="numpy", nogil=True)
def _pos_cov(Lr, Lc, Lv):
    """``Sigma_pos`` (00, 01, 11) of the camera position (x_m, y_m) from the sparse factor (sorted by column)."""
    s00, s01, s11 = 0.0, 0.0, 0.0
    px, py = 0.0, 0.0
    ne = Lr.shape[0]
    for e in range(ne):
        if e == 0 or Lc[e - 1] != Lc[e]:
            px, py = 0.0, 0.0
        if Lr[e] == 13:
            px = Lv[e]
        elif Lr[e] == 14:
            py = Lv[e]
        if e == ne - 1 or Lc[e + 1] != Lc[e]:
            s00 += px * px
            s01 += px * py
            s11 += py * py
    return s00, s01, s11


@njit(inline="always", cache=True, error_model="numpy", nogil=True)
def _factor_column(S, j, f0, f1, ft, i0, i1, ig, w, val):
    """Corner ``j`` of the factor column being formed, with the entry ``val`` of parameter rows ``i0, i1``
    (``J``) and ``ig`` (``g``) added: ``(J L)_0, (J L)_1, (L^T g)`` (the rows FA, FT restart where ``w`` is 0)."""
    keep = w != 0.0
    return ((S[f0 + j] if keep else 0.0) + S[i0 + j] * val, (S[f1 + j] if keep else 0.0) + S[i1 + j] * val,
            (S[ft + j] if keep else 0.0) + S[ig + j] * val)


@njit(**_STAGE)
def _stage_flag_params(S, m, Lr, Lc, Lv):
    """The parameter part of the flag's forms over the corners of a chunk, with ``Sigma = L L^T``:
    rows JG = ``J Sigma g`` = sum_c (J L)_c (L^T g)_c, GAM = ``g^T Sigma g``, XP = ``J Sigma E`` and
    GPS = ``E^T Sigma g`` (``E`` the camera position x_m, y_m).

    One pass per factor entry, as :func:`_stage_whiten`: a column is formed in rows FA (``J L``) and
    FT (``L^T g``); the pass of its last entry adds it to JG and GAM (if ``Dn`` depends on the column)
    and, for a column with a position entry, to XP and GPS.
    """
    for j in range(m):
        S[_JG * _ST + j], S[(_JG + 1) * _ST + j], S[_GAM * _ST + j] = 0.0, 0.0, 0.0
        S[_XP * _ST + j], S[(_XP + 1) * _ST + j], S[(_XP + 2) * _ST + j], S[(_XP + 3) * _ST + j] = 0.0, 0.0, 0.0, 0.0
        S[_GPS * _ST + j], S[(_GPS + 1) * _ST + j] = 0.0, 0.0
    ne = Lr.shape[0]
    mu = np.uint64(m)
    f0, f1, ft = np.uint64(_FA * _ST), np.uint64((_FA + 1) * _ST), np.uint64(_FT * _ST)
    jg0, jg1, gam = np.uint64(_JG * _ST), np.uint64((_JG + 1) * _ST), np.uint64(_GAM * _ST)
    x00, x01, x10, x11 = (np.uint64(_XP * _ST), np.uint64((_XP + 1) * _ST), np.uint64((_XP + 2) * _ST),
                          np.uint64((_XP + 3) * _ST))
    gp0, gp1 = np.uint64(_GPS * _ST), np.uint64((_GPS + 1) * _ST)
    px, py, hasg = 0.0, 0.0, False
    for e in range(ne):
        c, p, val = Lc[e], Lr[e], Lv[e]
        first = e == 0 or Lc[e - 1] != c
        last = e == ne - 1 or Lc[e + 1] != c
        if first:
            px, py, hasg = 0.0, 0.0, False
        px = val if p == 13 else px
        py = val if p == 14 else py
        hasg = hasg or not (p == 13 or p == 14 or p == 15 or p == 19)
        i0, i1, ig = np.uint64((_JP + p) * _ST), np.uint64((_JP + 22 + p) * _ST), np.uint64((_GD + p) * _ST)
        w = 0.0 if first else 1.0  # (GD rows of the parameters Dn does not depend on are zero)
        if not last:
            for j in range(mu):
                S[f0 + j], S[f1 + j], S[ft + j] = _factor_column(S, j, f0, f1, ft, i0, i1, ig, w, val)
            continue
        if hasg:
            for j in range(mu):
                a0, a1, t = _factor_column(S, j, f0, f1, ft, i0, i1, ig, w, val)
                S[jg0 + j] += a0 * t
                S[jg1 + j] += a1 * t
                S[gam + j] += t * t
        if px != 0.0 or py != 0.0:
            for j in range(mu):
                a0, a1, t = _factor_column(S, j, f0, f1, ft, i0, i1, ig, w, val)
                S[x00 + j] += a0 * px
                S[x01 + j] += a0 * py
                S[x10 + j] += a1 * px
                S[x11 + j] += a1 * py
                S[gp0 + j] += px * t
                S[gp1 + j] += py * t


@njit(**_STAGE)
def _stage_flag(S, m, sp00, sp01, sp11):
    """Per corner: the nonlinearity (row NL; NaN where the corner was not computed) from its covariance
    CC, the parameter forms of :func:`_stage_flag_params` plus the pixel part (JUV, P4, GUV) and
    ``Sigma_pos`` (:func:`footprint_uq.fast.core.nonlinearity_point`)."""
    for j in range(m):
        g0, g1 = S[_GUV * _ST + j], S[(_GUV + 1) * _ST + j]
        v0 = S[_P4 * _ST + j] * g0 + S[(_P4 + 1) * _ST + j] * g1  # P g_uv
        v1 = S[(_P4 + 2) * _ST + j] * g0 + S[(_P4 + 3) * _ST + j] * g1
        jg0 = S[_JG * _ST + j] + S[_JUV * _ST + j] * v0 + S[(_JUV + 1) * _ST + j] * v1
        jg1 = S[(_JG + 1) * _ST + j] + S[(_JUV + 2) * _ST + j] * v0 + S[(_JUV + 3) * _ST + j] * v1
        gam = S[_GAM * _ST + j] + g0 * v0 + g1 * v1
        S[_NL * _ST + j] = core.nonlinearity_point(
            S[_CC * _ST + j], S[(_CC + 1) * _ST + j], S[(_CC + 2) * _ST + j], S[_DN * _ST + j], S[_LAM * _ST + j],
            S[_DXY * _ST + j], S[(_DXY + 1) * _ST + j], jg0, jg1, gam, S[_GPS * _ST + j], S[(_GPS + 1) * _ST + j],
            S[_XP * _ST + j], S[(_XP + 1) * _ST + j], S[(_XP + 2) * _ST + j], S[(_XP + 3) * _ST + j], sp00, sp01, sp11)


@njit(**_STAGE)
def _stage_flag_objects(S, nob, K):
    """Per object: NLC = the largest nonlinearity of its corners (NaN if any is NaN) -- the centre's
    flag (docs/uncertainty-model.md)."""
    nan = math.nan
    for i in range(nob):
        S[_NLC * _ST + i] = -math.inf
    for k in range(K):
        o = np.uint64(_NL * _ST + k * nob)
        d = np.uint64(_NLC * _ST)
        for i in range(np.uint64(nob)):
            v, cur = S[o + i], S[d + i]
            S[d + i] = nan if (v != v) | (cur != cur) else max(v, cur)


@njit(**_STAGE)
def _heading(c00, c01, c11, ch, sh, rot):
    """R C R^T with R = [[ch, sh], [-sh, ch]] (the covariance in east/north axes), or C if not ``rot``."""
    if not rot:
        return c00, c01, c11
    a00 = ch * c00 + sh * c01
    a01 = ch * c01 + sh * c11
    a10 = -sh * c00 + ch * c01
    a11 = -sh * c01 + ch * c11
    e00 = a00 * ch + a01 * sh
    e01 = -a00 * sh + a01 * ch
    e10 = a10 * ch + a11 * sh
    e11 = -a10 * sh + a11 * ch
    return e00, 0.5 * (e01 + e10), e11


@njit(**_STAGE)
def _stage_v2x(S, nob, ch, sh, out, n0, obj):
    """CPM and J2735 integer fields of the centre covariances (rows E00, E01, E11; NaN: unavailable)
    into ``out[:, n0 + i]`` (7, N) -- the mirror of :mod:`footprint_uq.products.v2x` -- and the 1-sigma
    ellipse (:func:`footprint_uq.uncertainty.ellipse.ellipse_axes`) into the rows SMAJ, SMIN, ORI of ``obj``
    (if it has N columns).

    The libm ``atan2`` runs in a loop of its own and the fields are formed in scratch rows (one
    buffer, constant offsets), so the rest -- square roots, roundings, the level count -- vectorises.
    """
    rot = sh != 0.0 or ch != 1.0
    want_obj = obj.shape[1] > 0
    for i in range(nob):
        c00, c01, c11 = S[_E00 * _ST + i], S[_E01 * _ST + i], S[_E11 * _ST + i]
        d00, d01, d11 = _heading(c00, c01, c11, ch, sh, rot)
        S[_ANG * _ST + i] = ang = math.atan2(2.0 * d01, d00 - d11)
        if want_obj:  # the ellipse in W (hypot and atan2, as ellipse_axes)
            mean = 0.5 * (c00 + c11)
            rad = math.hypot(0.5 * (c00 - c11), c01)
            if rot:
                ang = math.atan2(2.0 * c01, c00 - c11)
            ori = 0.5 * math.degrees(ang)
            n = n0 + i
            obj[_O_SMAJ, n] = math.sqrt(mean + rad)
            obj[_O_SMIN, n] = math.sqrt(max(mean - rad, 0.0)) if mean - rad == mean - rad else math.nan
            obj[_O_ORI, n] = ori + 180.0 if ori <= -90.0 else ori
    g = 1.0 - _GUARD
    for i in range(nob):
        c00, c01, c11 = S[_E00 * _ST + i], S[_E01 * _ST + i], S[_E11 * _ST + i]
        fin = math.isfinite(c00) & math.isfinite(c01) & math.isfinite(c11)
        d00, d01, d11 = _heading(c00, c01, c11, ch, sh, rot)
        # CPM: per-axis 95 % confidence in cm, 1..4094, 4095 out of range
        cx = _Z95 * math.sqrt(max(d00, 0.0))
        cy = _Z95 * math.sqrt(max(d11, 0.0))
        vx = _CPM_OOR if cx > _CPM_MAX_M else min(max(np.ceil(cx / _CPM_UNIT * g), 1.0), _CPM_OOR - 1.0)
        vy = _CPM_OOR if cy > _CPM_MAX_M else min(max(np.ceil(cy / _CPM_UNIT * g), 1.0), _CPM_OOR - 1.0)
        # correlation in percent (101: unavailable)
        pos = (d00 > 0.0) & (d11 > 0.0)
        rho = d01 / math.sqrt(d00 * d11)
        vr = min(max(np.rint(rho * 100.0), -100.0), 100.0) if pos else _CORR_UNAV
        # J2735: 1-sigma axes in 5 cm (254: 12.70 m or more), orientation of the major axis from north
        mean = 0.5 * (d00 + d11)
        rad = math.sqrt(0.25 * (d00 - d11) * (d00 - d11) + d01 * d01)
        a = math.sqrt(mean + rad)
        b = math.sqrt(max(mean - rad, 0.0))
        va = _AX_MAX if a >= _AX_MAX_M else min(max(np.ceil(a / _AX_UNIT * g), 0.0), _AX_MAX)
        vb = _AX_MAX if b >= _AX_MAX_M else min(max(np.ceil(b / _AX_UNIT * g), 0.0), _AX_MAX)
        bearing = 90.0 - 0.5 * math.degrees(S[_ANG * _ST + i])
        bearing = bearing - 180.0 * np.floor(bearing / 180.0)
        bearing = bearing - 180.0 if bearing >= 180.0 else bearing
        bearing = 0.0 if a * a - b * b <= _CIRC * (a * a + b * b) else bearing  # circular: report north
        vo = np.rint(bearing / _ORIENT_UNIT)
        # PositionConfidence: how many levels (500 m ... 1 cm) the 95 % radius stays within
        r95 = _K95_2D * a * g
        cnt = ((500.0 >= r95) * 1.0 + (200.0 >= r95) + (100.0 >= r95) + (50.0 >= r95) + (20.0 >= r95)
               + (10.0 >= r95) + (5.0 >= r95) + (2.0 >= r95) + (1.0 >= r95) + (0.5 >= r95) + (0.2 >= r95)
               + (0.1 >= r95) + (0.05 >= r95) + (0.02 >= r95) + (0.01 >= r95))  # the 15 levels, unrolled
        S[_VX * _ST + i] = vx if fin else _CPM_UNAV
        S[(_VX + 1) * _ST + i] = vy if fin else _CPM_UNAV
        S[(_VX + 2) * _ST + i] = vr if fin else _CORR_UNAV
        S[(_VX + 3) * _ST + i] = va if fin else _AX_UNAV
        S[(_VX + 4) * _ST + i] = vb if fin else _AX_UNAV
        S[(_VX + 5) * _ST + i] = vo if fin else _ORIENT_UNAV
        S[(_VX + 6) * _ST + i] = cnt if fin else 0.0
    for f in range(7):
        o = np.uint64((_VX + f) * _ST)
        for i in range(nob):
            out[f, n0 + i] = np.int32(S[o + np.uint64(i)])


@njit(cache=True, error_model="numpy", nogil=True)
def v2x_codes(c00, c01, c11, ch, sh):
    """The kernel's V2X fields (7, n) int32 of covariances given by their entries (n,) each (for tests
    and for callers with covariances of their own); ``ch, sh``: cos, sin of the heading offset."""
    n = c00.shape[0]
    out = np.empty((7, n), dtype=np.int32)
    S = np.empty(_NROWS * _ST)
    for n0 in range(0, n, _M_TARGET):
        nob = min(_M_TARGET, n - n0)
        for i in range(nob):
            S[_E00 * _ST + i], S[_E01 * _ST + i], S[_E11 * _ST + i] = c00[n0 + i], c01[n0 + i], c11[n0 + i]
        _stage_v2x(S, nob, ch, sh, out, n0, np.empty((0, 0)))
    return out


@njit(**_STAGE)
def _stage_corner_flags(S, m, W, Himg, allow_outside):
    """Per corner: final code (outside the image), usable flag, ground point (NaN where it could not
    be computed)."""
    nan = math.nan
    for j in range(m):
        u, v = S[_U * _ST + j], S[_V * _ST + j]
        rc = S[_CODE * _ST + j]
        inside = (u >= -0.5) & (u <= W - 0.5) & (v >= -0.5) & (v <= Himg - 0.5)
        rc = _OUTSIDE if ((rc == _OK) & (not inside)) else rc
        computed = (rc == _OK) | (rc == _OUTSIDE)
        us = (rc == _OK) | ((rc == _OUTSIDE) & allow_outside)
        S[_RC * _ST + j] = rc
        S[_US * _ST + j] = 1.0 if us else 0.0
        S[_XX * _ST + j] = S[_X * _ST + j] if computed else nan
        S[_YY * _ST + j] = S[_Y * _ST + j] if computed else nan


@njit(**_STAGE)
def _whiten_entry(S, e, mu, Lr, Lc, Lv):
    """Entry ``e`` of the factor (:func:`_stage_whiten`): its column ``c`` and value, whether it is the column's
    first and last entry, the rows ``o0, o1`` of ``J L``'s column ``c`` and ``i0, i1`` of ``J``'s parameter; an
    entry that is not its column's last is added into rows ``o0, o1`` over the ``mu`` corners here (the column's
    first entry written), the last is left to the caller."""
    ne = Lr.shape[0]
    c, p, val = Lc[e], Lr[e], Lv[e]
    first = e == 0 or Lc[e - 1] != c
    last = e == ne - 1 or Lc[e + 1] != c
    o0, o1 = np.uint64((_AW + 2 * c) * _ST), np.uint64((_AW + 2 * c + 1) * _ST)
    i0, i1 = np.uint64((_JP + p) * _ST), np.uint64((_JP + 22 + p) * _ST)
    if not last:
        if first:
            for j in range(mu):
                S[o0 + j] = S[i0 + j] * val
                S[o1 + j] = S[i1 + j] * val
        else:
            for j in range(mu):
                S[o0 + j] += S[i0 + j] * val
                S[o1 + j] += S[i1 + j] * val
    return c, val, first, last, o0, o1, i0, i1


@njit(**_STAGE)
def _column_at(S, j, first, o0, o1, i0, i1, val):
    """Column ``c`` of ``J L`` at corner ``j`` once its last entry (value ``val``, parameter rows ``i0, i1``) is
    added: that entry's products alone for a single-entry column (``first``), else the sum so far in rows ``o0,
    o1`` (:func:`_whiten_entry`) plus them."""
    if first:
        return S[i0 + j] * val, S[i1 + j] * val
    return S[o0 + j] + S[i0 + j] * val, S[o1 + j] + S[i1 + j] * val


@njit(**_STAGE)
def _g_times(S, j, g0, g1, g2, g3, a0, a1):
    """``G_j (a0, a1)``: corner ``j``'s centroid weights (rows ``g0 .. g3``, :func:`_stage_centroid`) times a column
    of ``J L`` at it."""
    return S[g0 + j] * a0 + S[g1 + j] * a1, S[g2 + j] * a0 + S[g3 + j] * a1


@njit(**_STAGE)
def _stage_whiten(S, m, nob, K, Lr, Lc, Lv, keep_aw, shared, n0):
    """Rows AW = J L (row ``2 c + i``; single-entry columns only with ``keep_aw``, for the joint
    covariance), C3 (3 rows) = the parameter part (J L)(J L)^T of each corner's
    covariance, and the parameter part of each object's centre covariance into E00, E01, E11:
    B B^T with B = sum_k G_k (J_k L) (G from :func:`_stage_centroid`).  ``shared`` (N, 2, r), if it has
    rows, receives B itself (the centre's whitened parameter Jacobian ``dC/dp L``, object ``n0 + i``).

    The factor's entries come sorted by column (``Lc`` non-decreasing).  A column is formed in
    one pass per entry; the pass of its last entry also adds it to C3, so a diagonal factor costs
    one pass per parameter.  Only non-zero entries are touched.  Rows chosen at run time are
    indexed with unsigned offsets (no negative-index test, no array views with their reference
    counting), so the loops vectorise.
    """
    for j in range(m):
        S[_C3 * _ST + j], S[(_C3 + 1) * _ST + j], S[(_C3 + 2) * _ST + j] = 0.0, 0.0, 0.0
    for i in range(nob):
        S[_E00 * _ST + i], S[_E01 * _ST + i], S[_E11 * _ST + i] = 0.0, 0.0, 0.0
    ne = Lr.shape[0]
    mu = np.uint64(m)
    c0, c1, c2 = np.uint64(_C3 * _ST), np.uint64((_C3 + 1) * _ST), np.uint64((_C3 + 2) * _ST)
    t0, t1 = np.uint64(_T0 * _ST), np.uint64(_T1 * _ST)
    g0, g1 = np.uint64(_G * _ST), np.uint64((_G + 1) * _ST)
    g2, g3 = np.uint64((_G + 2) * _ST), np.uint64((_G + 3) * _ST)
    for e in range(ne):
        c, val, first, last, o0, o1, i0, i1 = _whiten_entry(S, e, mu, Lr, Lc, Lv)
        if not last:
            continue
        # the last entry completes column c: in one pass, add it to C3 and form G_k (J_k L)_c (a
        # single-entry column, the common case, keeps J L in registers unless the joint needs it)
        w = 0.0 if first else 1.0
        if first and not keep_aw:
            for j in range(mu):
                a0, a1 = _column_at(S, j, True, o0, o1, i0, i1, val)
                S[c0 + j] += a0 * a0
                S[c1 + j] += a0 * a1
                S[c2 + j] += a1 * a1
                S[t0 + j], S[t1 + j] = _g_times(S, j, g0, g1, g2, g3, a0, a1)
        else:
            for j in range(mu):
                a0 = (S[o0 + j] if w != 0.0 else 0.0) + S[i0 + j] * val
                a1 = (S[o1 + j] if w != 0.0 else 0.0) + S[i1 + j] * val
                S[o0 + j], S[o1 + j] = a0, a1
                S[c0 + j] += a0 * a0
                S[c1 + j] += a0 * a1
                S[c2 + j] += a1 * a1
                S[t0 + j], S[t1 + j] = _g_times(S, j, g0, g1, g2, g3, a0, a1)
        _sum_corners(S, _T0, _B0, nob, K)
        _sum_corners(S, _T1, _B1, nob, K)
        for i in range(nob):
            b0, b1 = S[_B0 * _ST + i], S[_B1 * _ST + i]
            S[_E00 * _ST + i] += b0 * b0
            S[_E01 * _ST + i] += b0 * b1
            S[_E11 * _ST + i] += b1 * b1
        if shared.shape[0] > 0:
            for i in range(nob):
                shared[n0 + i, 0, c], shared[n0 + i, 1, c] = S[_B0 * _ST + i], S[_B1 * _ST + i]


@njit(**_STAGE)
def _stage_whiten_b(S, m, Lr, Lc, Lv, shared, n0):
    """:func:`_stage_whiten`'s ``B`` alone, for one-corner objects (``K = 1``; :func:`point_jacobian_into`): each
    column ``c`` of ``J L`` formed as there without the joint's rows (:func:`_column_at`: the same products, sums
    and order), then ``G (J L)_c`` (:func:`_g_times`) straight into ``shared[n0 + j, :, c]`` -- without the
    corners' and the centres' covariance sums (C3, E) and the rows T, B that a one-corner sum only copies."""
    ne = Lr.shape[0]
    mu = np.uint64(m)
    g0, g1 = np.uint64(_G * _ST), np.uint64((_G + 1) * _ST)
    g2, g3 = np.uint64((_G + 2) * _ST), np.uint64((_G + 3) * _ST)
    for e in range(ne):
        c, val, first, last, o0, o1, i0, i1 = _whiten_entry(S, e, mu, Lr, Lc, Lv)
        if not last:
            continue
        for j in range(mu):
            a0, a1 = _column_at(S, j, first, o0, o1, i0, i1, val)
            shared[n0 + j, 0, c], shared[n0 + j, 1, c] = _g_times(S, j, g0, g1, g2, g3, a0, a1)


@njit(**_STAGE)
def _stage_corner_cov(S, m):
    """Per corner: covariance C3 + J_uv P J_uv^T and its semi-major axis (rows CC, SSEL); NaN where
    the corner could not be computed, SSEL -1 where it is not usable."""
    nan = math.nan
    for j in range(m):
        rc = S[_RC * _ST + j]
        computed = (rc == _OK) | (rc == _OUTSIDE)
        j00, j01 = S[_JUV * _ST + j], S[(_JUV + 1) * _ST + j]
        j10, j11 = S[(_JUV + 2) * _ST + j], S[(_JUV + 3) * _ST + j]
        p00, p01 = S[_P4 * _ST + j], S[(_P4 + 1) * _ST + j]
        p10, p11 = S[(_P4 + 2) * _ST + j], S[(_P4 + 3) * _ST + j]
        m00, m01 = j00 * p00 + j01 * p10, j00 * p01 + j01 * p11
        m10, m11 = j10 * p00 + j11 * p10, j10 * p01 + j11 * p11
        c00 = S[_C3 * _ST + j] + m00 * j00 + m01 * j01
        c01 = S[(_C3 + 1) * _ST + j] + m00 * j10 + m01 * j11
        c11 = S[(_C3 + 2) * _ST + j] + m10 * j10 + m11 * j11
        semi = math.sqrt(0.5 * (c00 + c11) + math.sqrt(0.25 * (c00 - c11) * (c00 - c11) + c01 * c01))
        S[_CC * _ST + j] = c00 if computed else nan
        S[(_CC + 1) * _ST + j] = c01 if computed else nan
        S[(_CC + 2) * _ST + j] = c11 if computed else nan
        S[_SSEL * _ST + j] = semi if S[_US * _ST + j] != 0.0 else -1.0


@njit(**_STAGE)
def _sum_corners(S, src, dst, nob, K):
    """Per object: row dst[i] = sum over corners k of row src[k * nob + i] (k in order)."""
    d = np.uint64(dst * _ST)
    s0 = np.uint64(src * _ST)
    nu = np.uint64(nob)
    for i in range(nu):
        S[d + i] = S[s0 + i]
    for k in range(1, K):
        sk = np.uint64(src * _ST + k * nob)
        for i in range(nu):
            S[d + i] += S[sk + i]


@njit(**_STAGE)
def _to_corners(S, src, dst, nob, K, shift):
    """Per corner: row dst[k * nob + i] = row src[((k + shift) mod K) * nob + i] if src is a corner row,
    or src[i] (per-object row) with ``shift < 0``."""
    nu = np.uint64(nob)
    for k in range(K):
        d = np.uint64(dst * _ST + k * nob)
        s0 = np.uint64(src * _ST + (0 if shift < 0 else ((k + shift) % K) * nob))
        for i in range(nu):
            S[d + i] = S[s0 + i]


@njit(**_STAGE)
def _stage_select(S, nob, K):
    """Per object: the largest usable corner (BEST, BSEMI; -1 if none; first wins a tie) and the
    first unusable corner (FBAD, -1 if all are usable)."""
    for i in range(nob):
        S[_BEST * _ST + i], S[_BSEMI * _ST + i], S[_FBAD * _ST + i] = -1.0, -1.0, -1.0
    nu = np.uint64(nob)
    bst, bsm, fbd = np.uint64(_BEST * _ST), np.uint64(_BSEMI * _ST), np.uint64(_FBAD * _ST)
    for k in range(K):
        ss, us = np.uint64(_SSEL * _ST + k * nob), np.uint64(_US * _ST + k * nob)
        kf = float(k)
        for i in range(nu):
            s = S[ss + i]
            better = s > S[bsm + i]
            S[bst + i] = kf if better else S[bst + i]
            S[bsm + i] = s if better else S[bsm + i]
            fb = S[fbd + i]
            S[fbd + i] = kf if ((fb < 0.0) & (S[us + i] == 0.0)) else fb


@njit(**_STAGE)
def _stage_centroid(S, nob, K):
    """Per object: the centre (CXC, CYC) = the vertex mean of the corners, AREA (signed shoelace area, K >= 3),
    DEG (zero area, K >= 3) and the centre's Jacobian G (4 rows: d cx/d x_k, d cx/d y_k, d cy/d x_k,
    d cy/d y_k; the constant 1/K, 0, 0, 1/K).  Computed for every object; objects with an unusable corner
    carry NaN and are masked by the caller (numpy reference:
    :func:`footprint_uq.products.footprints.footprint_centre`).

    Per-object sums over corners and per-corner uses of per-object numbers go through
    :func:`_sum_corners` / :func:`_to_corners`, so every loop runs straight over columns.
    """
    m = K * nob
    _sum_corners(S, _XX, _MX, nob, K)
    _sum_corners(S, _YY, _MY, nob, K)
    ik = 1.0 / K
    for j in range(m):
        S[_G * _ST + j], S[(_G + 1) * _ST + j] = ik, 0.0
        S[(_G + 2) * _ST + j], S[(_G + 3) * _ST + j] = 0.0, ik
    for i in range(nob):
        S[_MX * _ST + i] /= K
        S[_MY * _ST + i] /= K
    if K < 3:
        for i in range(nob):
            S[_CXC * _ST + i], S[_CYC * _ST + i] = S[_MX * _ST + i], S[_MY * _ST + i]
            S[_AREA * _ST + i], S[_DEG * _ST + i] = 0.0, 0.0
        return
    # q = corner - vertex mean (the area is formed relative to the mean: no cancellation)
    _to_corners(S, _MX, _T0, nob, K, -1)
    _to_corners(S, _MY, _T1, nob, K, -1)
    for j in range(m):
        q0 = S[_XX * _ST + j] - S[_T0 * _ST + j]
        q1 = S[_YY * _ST + j] - S[_T1 * _ST + j]
        S[_Q * _ST + j], S[(_Q + 1) * _ST + j] = q0, q1
        S[_T2 * _ST + j] = q0 * q0 + q1 * q1
    _sum_corners(S, _T2, _SS, nob, K)
    # shoelace terms with the next corner
    _to_corners(S, _Q, _QN, nob, K, 1)
    _to_corners(S, _Q + 1, _QN + 1, nob, K, 1)
    for j in range(m):
        S[_T0 * _ST + j] = S[_Q * _ST + j] * S[(_QN + 1) * _ST + j] - S[_QN * _ST + j] * S[(_Q + 1) * _ST + j]
    _sum_corners(S, _T0, _A2, nob, K)
    for i in range(nob):
        area = 0.5 * S[_A2 * _ST + i]
        deg = not (abs(area) > 1e-12 * max(S[_SS * _ST + i], 1e-300))
        S[_AREA * _ST + i], S[_DEG * _ST + i] = area, 1.0 if deg else 0.0
        S[_CXC * _ST + i], S[_CYC * _ST + i] = S[_MX * _ST + i], S[_MY * _ST + i]


@njit(**_STAGE)
def _h(S, j):
    """H = G J_uv (2 x 2) of scratch column j: d centre / d (u, v) of that corner."""
    g00, g01, g10, g11 = S[_G * _ST + j], S[(_G + 1) * _ST + j], S[(_G + 2) * _ST + j], S[(_G + 3) * _ST + j]
    u00, u01, u10, u11 = S[_JUV * _ST + j], S[(_JUV + 1) * _ST + j], S[(_JUV + 2) * _ST + j], S[(_JUV + 3) * _ST + j]
    return g00 * u00 + g01 * u10, g00 * u01 + g01 * u11, g10 * u00 + g11 * u10, g10 * u01 + g11 * u11


@njit(**_STAGE)
def _stage_centre_cov(S, nob, K):
    """Per object: adds the pixel part sum_k H_k P_k H_k^T, H_k = G_k J_uv,k, to the centre covariance
    (E00, E01, E11; the parameter part is :func:`_stage_whiten`'s, detector cross terms between
    corners are added by the caller)."""
    m = K * nob
    for j in range(m):
        h00, h01, h10, h11 = _h(S, j)
        p00, p01 = S[_P4 * _ST + j], S[(_P4 + 1) * _ST + j]
        p10, p11 = S[(_P4 + 2) * _ST + j], S[(_P4 + 3) * _ST + j]
        m00, m01 = h00 * p00 + h01 * p10, h00 * p01 + h01 * p11
        m10, m11 = h10 * p00 + h11 * p10, h10 * p01 + h11 * p11
        S[_T0 * _ST + j] = m00 * h00 + m01 * h01
        S[_T1 * _ST + j] = m00 * h10 + m01 * h11
        S[_T2 * _ST + j] = m10 * h10 + m11 * h11
    _sum_corners(S, _T0, _B0, nob, K)
    _sum_corners(S, _T1, _B1, nob, K)
    _sum_corners(S, _T2, _B2, nob, K)
    for i in range(nob):
        S[_E00 * _ST + i] += S[_B0 * _ST + i]
        S[_E01 * _ST + i] += S[_B1 * _ST + i]
        S[_E11 * _ST + i] += S[_B2 * _ST + i]


def alloc_outputs(N: int, K: int, *, joint: bool = False, corners: bool = True, alloc=np.empty,
                  shared_rank: int | None = None):
    """Output arrays of :func:`process_corners` for N objects of K corners (allocated here, by numpy:
    numba's own allocations of large arrays are fresh pages every call, ~40 % of the kernel's time).

    ``corners=False`` gives (0, ...) per-corner coordinate/covariance/nonlinearity arrays: the kernel then
    skips them.  ``shared_rank`` r (the factor's rank) adds the centre's whitened parameter Jacobian
    (N, 2, r) (the camera-level part of its covariance is ``B B^T``; the tracker needs B itself); None gives
    (0, 2, 0): not written.
    ``alloc(shape, dtype)`` may supply the memory (default :func:`numpy.empty`).
    """
    nc = N if corners else 0
    return (alloc((nc, K, 2), np.float64), alloc((nc, K, 2, 2), np.float64),
            alloc((N if joint else 0, 2 * K, 2 * K), np.float64), alloc((N, K), np.int8), alloc((N, K), np.bool_),
            alloc((N,), np.int64), alloc((nc, 2, 2), np.float64), alloc((N,), np.int32), alloc((N,), np.int64),
            alloc((len(OBJ_ROWS), N), np.float64), alloc((7, N), np.int32), alloc((nc, K), np.float64),
            alloc((0, 2, 0) if shared_rank is None else (N, 2, shared_rank), np.float64))


def outputs_max_bytes(N: int, K: int, *, joint: bool = False, shared_rank: int | None = None) -> int:
    """Bytes of the largest array of :func:`alloc_outputs` (N, K, joint, shared_rank) and of the (N, K, 2)
    pixels: one number for an allocation policy that decides once per frame instead of once per array."""
    return 8 * N * max(4 * K, 4 * K * K if joint else 0, len(OBJ_ROWS), 7, 2 * (shared_rank or 0))


#: shape of the scratch buffer ``S`` of :func:`process_corners` (float64; one per call or per thread)
SCRATCH_SHAPE = (_NROWS * _ST,)


@njit(cache=True, error_model="numpy", nogil=True)
def _needed_params(Lr):
    """(22,) bool: parameters with a non-zero row in the factor.  Flags for groups of them: if any of
    k1..k6 is needed, ``need[5]`` (k1..k3, p1, p2) stands for the group, ``need[10]`` for k4..k6."""
    need = np.zeros(22, dtype=np.bool_)
    for e in range(Lr.shape[0]):
        need[Lr[e]] = True
    kd = False
    for e in range(5, 13):
        kd = kd or need[e]
    need[5] = kd
    need[10] = need[10] or need[11] or need[12]
    return need


@njit(**_STAGE)
def _chunk_pixels(S, uv, boxes, yaw_deg, bottom_on_ground, cam, n0, nob, K):
    """Rows U, V of a chunk: the corners of ``uv`` or the projected bottom corners of ``boxes`` (then
    also copied to ``uv`` if it has a row per box)."""
    if boxes.shape[0] > 0:
        _stage_project(S, boxes, n0, nob, cam, yaw_deg, bottom_on_ground)
        if uv.shape[0] == boxes.shape[0]:
            for k in range(K):
                for i in range(nob):
                    uv[n0 + i, k, 0], uv[n0 + i, k, 1] = S[_U * _ST + k * nob + i], S[_V * _ST + k * nob + i]
    else:
        for k in range(K):
            for i in range(nob):
                S[_U * _ST + k * nob + i] = uv[n0 + i, k, 0]
                S[_V * _ST + k * nob + i] = uv[n0 + i, k, 1]


@njit(**_STAGE)
def _chunk_codes(S, extra_reason, from_boxes, n0, nob, K):
    """Codes of the 3D projection (row PC) or the caller's ``extra_reason`` override OK in row CODE."""
    m = nob * K
    if from_boxes:
        for j in range(m):
            pc = S[_PC * _ST + j]
            S[_CODE * _ST + j] = S[_CODE * _ST + j] if pc == _OK else pc
    if extra_reason.shape[0] > 0:
        for k in range(K):
            for i in range(nob):
                ex = extra_reason[n0 + i, k]
                if ex != _OK:
                    S[_CODE * _ST + k * nob + i] = ex


@njit(**_STAGE)
def _chunk_pixel_cov(S, spx, det, det_mode, n0, nob, K):
    """Rows P4: each corner's pixel covariance, the budget's ``spx`` plus the detector's ``det``
    (``det_mode`` 1 per detection, 2 per corner, 3 the diagonal blocks of the full form)."""
    s00, s01, s10, s11 = spx[0, 0], spx[0, 1], spx[1, 0], spx[1, 1]
    for j in range(nob * K):
        S[_P4 * _ST + j], S[(_P4 + 1) * _ST + j], S[(_P4 + 2) * _ST + j], S[(_P4 + 3) * _ST + j] = (s00, s01,
                                                                                                   s10, s11)
    if det_mode == 0:
        return
    for k in range(K):
        for i in range(nob):
            j, n = k * nob + i, n0 + i
            if det_mode == 1:
                d00, d01, d10, d11 = det[n, 0, 0, 0], det[n, 0, 0, 1], det[n, 0, 1, 0], det[n, 0, 1, 1]
            elif det_mode == 2:
                d00, d01, d10, d11 = det[n, k, 0, 0], det[n, k, 0, 1], det[n, k, 1, 0], det[n, k, 1, 1]
            else:
                d00, d01 = det[n, 0, 2 * k, 2 * k], det[n, 0, 2 * k, 2 * k + 1]
                d10, d11 = det[n, 0, 2 * k + 1, 2 * k], det[n, 0, 2 * k + 1, 2 * k + 1]
            S[_P4 * _ST + j] += d00
            S[(_P4 + 1) * _ST + j] += d01
            S[(_P4 + 2) * _ST + j] += d10
            S[(_P4 + 3) * _ST + j] += d11


@njit(**_STAGE)
def _out_corners(S, out, n0, nob, K):
    """Per-corner outputs of a chunk: codes and usable flags; ground points, covariances and the flag
    where the per-corner arrays have rows."""
    xy, ccov, reason, usable, cnl = out[0], out[1], out[3], out[4], out[11]
    for k in range(K):
        for i in range(nob):
            j, n = k * nob + i, n0 + i
            reason[n, k] = np.int8(S[_RC * _ST + j])
            usable[n, k] = S[_US * _ST + j] != 0.0
    if xy.shape[0] == 0:
        return
    for k in range(K):
        for i in range(nob):
            j, n = k * nob + i, n0 + i
            xy[n, k, 0], xy[n, k, 1] = S[_XX * _ST + j], S[_YY * _ST + j]
            c01 = S[(_CC + 1) * _ST + j]
            ccov[n, k, 0, 0], ccov[n, k, 0, 1] = S[_CC * _ST + j], c01
            ccov[n, k, 1, 0], ccov[n, k, 1, 1] = c01, S[(_CC + 2) * _ST + j]
            cnl[n, k] = S[_NL * _ST + j]


@njit(**_STAGE)
def _out_largest(S, out, n0, nob):
    """Per object: the largest point (index, semi-axis, position, flag; its covariance if asked), NaN / -1
    without a usable corner."""
    largest_index, largest_cov, obj = out[5], out[6], out[9]
    want_cov = largest_cov.shape[0] > 0
    nan = math.nan
    for i in range(nob):
        n = n0 + i
        best = int(S[_BEST * _ST + i])
        largest_index[n] = best
        if best >= 0:
            jb = best * nob + i
            obj[_O_LSEMI, n] = S[_BSEMI * _ST + i]
            obj[_O_LNL, n] = S[_NL * _ST + jb]
            obj[_O_LX, n], obj[_O_LY, n] = S[_XX * _ST + jb], S[_YY * _ST + jb]
            c00, c01, c11 = S[_CC * _ST + jb], S[(_CC + 1) * _ST + jb], S[(_CC + 2) * _ST + jb]
        else:
            obj[_O_LSEMI, n] = nan
            obj[_O_LNL, n] = nan
            obj[_O_LX, n], obj[_O_LY, n] = nan, nan
            c00, c01, c11 = nan, nan, nan
        if want_cov:
            largest_cov[n, 0, 0], largest_cov[n, 0, 1] = c00, c01
            largest_cov[n, 1, 0], largest_cov[n, 1, 1] = c01, c11


@njit(**_STAGE)
def _det_cross(S, det, n, i, nob, K):
    """Detector cross terms between the corners of object ``i`` (full form): sum_{k != l} H_k P_kl H_l^T."""
    e00, e01, e11 = 0.0, 0.0, 0.0
    for k in range(K):
        hk00, hk01, hk10, hk11 = _h(S, k * nob + i)
        for l in range(K):
            if l == k:
                continue
            hl00, hl01, hl10, hl11 = _h(S, l * nob + i)
            q00, q01 = det[n, 0, 2 * k, 2 * l], det[n, 0, 2 * k, 2 * l + 1]
            q10, q11 = det[n, 0, 2 * k + 1, 2 * l], det[n, 0, 2 * k + 1, 2 * l + 1]
            m00, m01 = hk00 * q00 + hk01 * q10, hk00 * q01 + hk01 * q11
            m10 = hk10 * q00 + hk11 * q10
            m11 = hk10 * q01 + hk11 * q11
            e00 += m00 * hl00 + m01 * hl01
            e01 += m00 * hl10 + m01 * hl11
            e11 += m10 * hl10 + m11 * hl11
    return e00, e01, e11


@njit(**_STAGE)
def _out_centre(S, out, det, det_mode, n0, nob, K):
    """Per object: the centre's code (first unusable corner, DEGENERATE, OK), position, covariance (with the
    detector's cross terms in the full form), flag and area; rows E00, E01, E11 hold the final covariance
    (NaN without a centre) for :func:`_stage_v2x`."""
    centre_reason, centre_bad, obj = out[7], out[8], out[9]
    nan = math.nan
    n_over = 0
    for i in range(nob):
        n = n0 + i
        fb = int(S[_FBAD * _ST + i])
        if fb >= 0:
            code = int(S[_RC * _ST + fb * nob + i])
            centre_bad[n] = fb
            obj[_O_AREA, n] = nan
        else:
            code = _DEGENERATE if S[_DEG * _ST + i] != 0.0 else _OK
            centre_bad[n] = -1
            obj[_O_AREA, n] = S[_AREA * _ST + i]
        centre_reason[n] = code
        if code == _OK:
            e00, e01, e11 = S[_E00 * _ST + i], S[_E01 * _ST + i], S[_E11 * _ST + i]
            if det_mode == 3:
                d00, d01, d11 = _det_cross(S, det, n, i, nob, K)
                e00, e01, e11 = e00 + d00, e01 + d01, e11 + d11
            obj[_O_CX, n], obj[_O_CY, n] = S[_CXC * _ST + i], S[_CYC * _ST + i]
            obj[_O_NL, n] = S[_NLC * _ST + i]
            fin = (math.isfinite(e00) & math.isfinite(e01) & math.isfinite(e11) & math.isfinite(obj[_O_CX, n])
                   & math.isfinite(obj[_O_CY, n]))
            n_over += 0 if fin else 1
        else:
            e00, e01, e11 = nan, nan, nan
            obj[_O_CX, n], obj[_O_CY, n] = nan, nan
            obj[_O_NL, n] = nan
        obj[_O_C00, n], obj[_O_C01, n], obj[_O_C10, n], obj[_O_C11, n] = e00, e01, e01, e11
        S[_E00 * _ST + i], S[_E01 * _ST + i], S[_E11 * _ST + i] = e00, e01, e11
    return n_over


@njit(**_STAGE)
def _count_corner_overflow(S, m):
    """Corners whose ground point or covariance was computed but is not finite (OVERFLOW candidates)."""
    n_over = 0
    for j in range(m):
        rc = S[_RC * _ST + j]
        fin = (math.isfinite(S[_XX * _ST + j]) & math.isfinite(S[_YY * _ST + j]) & math.isfinite(S[_CC * _ST + j])
               & math.isfinite(S[(_CC + 1) * _ST + j]) & math.isfinite(S[(_CC + 2) * _ST + j]))
        n_over += 1 if (((rc == _OK) | (rc == _OUTSIDE)) & (not fin)) else 0
    return n_over


@njit(**_STAGE)
def _out_joint(S, joint, reason, det, det_mode, r, n0, nob, K):
    """The joint covariance (2K x 2K) of each object: diagonal blocks = corner covariances, off-diagonal
    blocks = the shared parameter part ``(J_k L)(J_l L)^T`` (+ detector cross terms in the full form)."""
    nan = math.nan
    for i in range(nob):
        n = n0 + i
        for k in range(K):
            jk = k * nob + i
            ck = reason[n, k] == _OK or reason[n, k] == _OUTSIDE
            for l in range(k, K):
                jl = l * nob + i
                cl = reason[n, l] == _OK or reason[n, l] == _OUTSIDE
                if not (ck and cl):
                    v00, v01, v10, v11 = nan, nan, nan, nan
                elif k == l:
                    v00, v01 = S[_CC * _ST + jk], S[(_CC + 1) * _ST + jk]
                    v10, v11 = v01, S[(_CC + 2) * _ST + jk]
                else:
                    v00, v01, v10, v11 = 0.0, 0.0, 0.0, 0.0
                    for c in range(r):
                        a0k, a1k = S[(_AW + 2 * c) * _ST + jk], S[(_AW + 2 * c + 1) * _ST + jk]
                        a0l, a1l = S[(_AW + 2 * c) * _ST + jl], S[(_AW + 2 * c + 1) * _ST + jl]
                        v00 += a0k * a0l
                        v01 += a0k * a1l
                        v10 += a1k * a0l
                        v11 += a1k * a1l
                    if det_mode == 3:
                        for a in range(2):
                            for b in range(2):
                                p = det[n, 0, 2 * k + a, 2 * l + b]
                                v00 += S[(_JUV + a) * _ST + jk] * p * S[(_JUV + b) * _ST + jl]
                                v01 += S[(_JUV + a) * _ST + jk] * p * S[(_JUV + 2 + b) * _ST + jl]
                                v10 += S[(_JUV + 2 + a) * _ST + jk] * p * S[(_JUV + b) * _ST + jl]
                                v11 += S[(_JUV + 2 + a) * _ST + jk] * p * S[(_JUV + 2 + b) * _ST + jl]
                joint[n, 2 * k, 2 * l], joint[n, 2 * k, 2 * l + 1] = v00, v01
                joint[n, 2 * k + 1, 2 * l], joint[n, 2 * k + 1, 2 * l + 1] = v10, v11
                joint[n, 2 * l, 2 * k], joint[n, 2 * l + 1, 2 * k] = v00, v01
                joint[n, 2 * l, 2 * k + 1], joint[n, 2 * l + 1, 2 * k + 1] = v10, v11


@njit(cache=True, error_model="numpy", nogil=True)
def process_corners(uv, extra_reason, boxes, yaw_deg, bottom_on_ground, cam, dR, Lr, Lc, Lv, r, spx, det, det_mode,
                    allow_outside, ch, sh, flag, out, S):
    """The fused per-frame kernel on corners in pixels ``uv`` (N, K, 2), K <= :data:`MAX_CORNERS`.

    extra_reason : (N, K) int8 codes overriding OK, or shape (0, 0)
    boxes, yaw_deg, bottom_on_ground : 3D boxes (N, 7) whose bottom corners are the corners (then
        ``uv`` (N, 4, 2) receives their pixels, or has 0 rows), or shape (0, 7) (corners from ``uv``)
    Lr, Lc, Lv, r : sparse factor of the parameter covariance (:func:`footprint_uq.uncertainty.budget.psd_factor`)
    spx : (2, 2) budget pixel covariance;  det : 4-D detector covariance with det_mode
        0 none (any 4-D array), 1 (N, 1, 2, 2) per detection, 2 (N, K, 2, 2) per corner,
        3 (N, 1, 2K, 2K) full
    ch, sh : cos, sin of the heading offset (V2X fields)
    flag : compute the linearity flag (per corner, the largest point's and the centre's ``nonlinearity``;
        NaN without it)
    out : the arrays of :func:`alloc_outputs` (filled here): xy, ccov, joint, reason, usable,
        largest_index, largest_cov, centre_reason, centre_bad, obj (:data:`OBJ_ROWS`, N), v2x (7, N),
        cnl (N, K) per-corner nonlinearity, shared (N, 2, r) the centre's whitened parameter Jacobian.
        A joint with 0 rows is not formed; xy / ccov / largest_cov / cnl / shared with 0 rows are not written.
    S : :func:`scratch`

    Returns the number of corners and centres that were computed but are not finite (0 almost always;
    the caller then marks them OVERFLOW, ``products.footprints._mark_overflow``).
    """
    from_boxes = boxes.shape[0] > 0
    N, K = (boxes.shape[0], 4) if from_boxes else (uv.shape[0], uv.shape[1])
    joint, reason = out[2], out[3]
    want_joint = joint.shape[0] == N and N > 0
    extra = extra_reason if (extra_reason.shape[0] == N and N > 0) else extra_reason[:0]
    Jd, Jk = np.empty((2, 2)), np.empty((2, 8))
    need = _needed_params(Lr)
    sp00, sp01, sp11 = _pos_cov(Lr, Lc, Lv)
    nob_max = max(1, _M_TARGET // K)
    n_over = 0
    for n0 in range(0, N, nob_max):
        nob = min(N - n0, nob_max)
        m = nob * K
        # corners -> ground, with every Jacobian and the status codes
        _chunk_pixels(S, uv, boxes, yaw_deg, bottom_on_ground, cam, n0, nob, K)
        _stage_undistort(S, m, cam, Jd, Jk, need)
        _stage_ground(S, m, cam, dR, need)
        _chunk_codes(S, extra, from_boxes, n0, nob, K)
        _chunk_pixel_cov(S, spx, det, det_mode, n0, nob, K)
        _stage_corner_flags(S, m, cam.width_px, cam.height_px, allow_outside)
        # covariances of corners and centre, the linearity flag, the largest point
        _stage_centroid(S, nob, K)
        _stage_whiten(S, m, nob, K, Lr, Lc, Lv, want_joint, out[12], n0)
        _stage_corner_cov(S, m)
        if flag:
            _stage_ray_denominator(S, m, cam, dR, need)
            _stage_flag_params(S, m, Lr, Lc, Lv)
            _stage_flag(S, m, sp00, sp01, sp11)
        else:
            for j in range(m):
                S[_NL * _ST + j] = math.nan
        _stage_flag_objects(S, nob, K)
        _stage_select(S, nob, K)
        _stage_centre_cov(S, nob, K)
        # outputs
        _out_corners(S, out, n0, nob, K)
        _out_largest(S, out, n0, nob)
        n_over += _out_centre(S, out, det, det_mode, n0, nob, K) + _count_corner_overflow(S, m)
        _stage_v2x(S, nob, ch, sh, out[10], n0, out[9])
        if want_joint:
            _out_joint(S, joint, reason, det, det_mode, r, n0, nob, K)
    return n_over


@njit(**_STAGE)
def _stage_project(S, boxes, n0, nob, cam, yaw_deg, bottom_on_ground):
    """Bottom corners of boxes n0 .. n0 + nob - 1 (N, 7) projected into rows U, V (corner-major, 4
    corners) with their codes in row PC (OK, BEHIND_CAMERA, NOT_FINITE, UNDISTORT_FAILED past the lens's
    fold; NaN pixels unless OK); rows XD, YD are used as scratch.

    The arithmetic of :func:`footprint_uq.cameras.general.project` and of
    :func:`footprint_uq.products.footprints.box3d_bottom_corners`, branch-free; the boxes are first copied
    into scratch rows and the yaw's cos/sin (libm calls) run in a loop of their own, so the
    projection loop vectorises.
    """
    for c in range(7):
        o = np.uint64((_BX + c) * _ST)
        for i in range(nob):
            S[o + np.uint64(i)] = boxes[n0 + i, c]
    ysc = math.pi / 180.0
    for i in range(nob):
        yaw = S[(_BX + 6) * _ST + i] * ysc if yaw_deg else S[(_BX + 6) * _ST + i]
        S[_CS * _ST + i], S[_SN * _ST + i] = math.cos(yaw), math.sin(yaw)
    fx, fy, cx, cy, skw = cam.fx, cam.fy, cam.cx, cam.cy, cam.skew
    d = cam.dist
    kt = (d[0], d[1], d[2], d[3], d[4], d[5], d[6], d[7])  # scalars: no reload from memory S may alias
    X0, Y0, H = cam.x0, cam.y0, cam.h
    R0, R1, R2, R3, R4, R5, R6, R7, R8 = (cam.R[0], cam.R[1], cam.R[2], cam.R[3], cam.R[4],
                                          cam.R[5], cam.R[6], cam.R[7], cam.R[8])
    g0 = cam.ground_z_m
    nan = math.nan
    nu = np.uint64(nob)
    for k in range(4):
        sl = -1.0 if (k == 0) | (k == 3) else 1.0
        sw = -1.0 if k < 2 else 1.0
        ou, ov, oc = np.uint64(_U * _ST + k * nob), np.uint64(_V * _ST + k * nob), np.uint64(_PC * _ST + k * nob)
        ox, oy = np.uint64(_XD * _ST + k * nob), np.uint64(_YD * _ST + k * nob)
        for i in range(nu):
            c, s_ = S[np.uint64(_CS * _ST) + i], S[np.uint64(_SN * _ST) + i]
            dl = sl * (0.5 * S[np.uint64((_BX + 3) * _ST) + i])
            dw = sw * (0.5 * S[np.uint64((_BX + 4) * _ST) + i])
            X = S[np.uint64(_BX * _ST) + i] + c * dl - s_ * dw
            Y = S[np.uint64((_BX + 1) * _ST) + i] + s_ * dl + c * dw
            zb = 0.0 if bottom_on_ground else (S[np.uint64((_BX + 2) * _ST) + i]
                                               - 0.5 * S[np.uint64((_BX + 5) * _ST) + i]) - g0
            Z = zb if (math.isfinite(X) & math.isfinite(Y)) else nan
            rx, ry, rz = X - X0, Y - Y0, Z - H
            pcx = R0 * rx + R3 * ry + R6 * rz
            pcy = R1 * rx + R4 * ry + R7 * rz
            pcz = R2 * rx + R5 * ry + R8 * rz
            finite = math.isfinite(X) & math.isfinite(Y) & math.isfinite(Z)
            x, y = pcx / pcz, pcy / pcz
            xd, yd = core.distort_point(x, y, kt)
            ok = finite & (pcz > 0.0)
            S[ou + i] = fx * xd + skw * yd + cx if ok else nan
            S[ov + i] = fy * yd + cy if ok else nan
            S[oc + i] = _OK if ok else (_BEHIND if finite else _NOTFIN)
            S[ox + i], S[oy + i] = x, y
    if cam.has_dist:
        # past the lens's fold a world point maps to a meaningless pixel: no answer, as the reference
        dom = cam.dom
        for j in range(4 * nob):
            if S[_PC * _ST + j] == _OK and not core.in_domain_undistorted(dom, S[_XD * _ST + j], S[_YD * _ST + j]):
                S[_PC * _ST + j] = _UNDIST
                S[_U * _ST + j], S[_V * _ST + j] = nan, nan


@njit(cache=True, nogil=True)
def v2x_source_and_flagged(valid, nl, threshold, linear, unavailable, src):
    """The V2X source of every centre before the policy (``linear`` where valid, else ``unavailable``) into
    ``src``; returns how many valid centres are not ``linear_ok`` (``nl > threshold`` or NaN).  ``nl`` with
    0 rows: no flag, none.  (One compiled pass instead of four numpy calls of ~1 us each per frame.)"""
    has = nl.shape[0] == valid.shape[0]
    n = 0
    for i in range(valid.shape[0]):
        src[i] = linear if valid[i] else unavailable
        if has and valid[i] and not nl[i] <= threshold:
            n += 1
    return n


@njit(cache=True, error_model="numpy", nogil=True)
def first_negative_size(boxes):
    """First row of boxes (N, 7) with a negative length, width or height (-1 if none)."""
    for n in range(boxes.shape[0]):
        if boxes[n, 3] < 0.0 or boxes[n, 4] < 0.0 or boxes[n, 5] < 0.0:
            return n
    return -1


@njit(cache=True, error_model="numpy", nogil=True)
def process_boxes3d(boxes, yaw_deg, bottom_on_ground, cam, dR, Lr, Lc, Lv, r, spx, det, det_mode, allow_outside,
                    ch, sh, flag, uv, out, S):
    """:func:`process_corners` on the projected bottom corners of 3D boxes (N, 7) (C- or F-ordered);
    the pixels go to ``uv`` (N, 4, 2) if it has N rows.  Returns ``(bad, n_over)``: the first row with a
    negative size (-1 if none; nothing else is done then) and :func:`process_corners`'s count."""
    bad = first_negative_size(boxes)
    n_over = 0
    if bad < 0:
        n_over = process_corners(uv, np.zeros((0, 0), dtype=np.int8), boxes, yaw_deg, bottom_on_ground, cam, dR, Lr,
                                 Lc, Lv, r, spx, det, det_mode, allow_outside, ch, sh, flag, out, S)
    return bad, n_over


@njit(cache=True, error_model="numpy", nogil=True)
def point_outputs(N, r):
    """:func:`alloc_outputs` ``(N, 1, corners=False, shared_rank=r)``, allocated in compiled code (one-point
    footprints whose only wanted output is the centre's whitened Jacobian; the arrays are small, so numba's
    allocator reuses its memory)."""
    return (np.empty((0, 1, 2)), np.empty((0, 1, 2, 2)), np.empty((0, 2, 2)), np.empty((N, 1), np.int8),
            np.empty((N, 1), np.bool_), np.empty(N, np.int64), np.empty((0, 2, 2)), np.empty(N, np.int32),
            np.empty(N, np.int64), np.empty((len(OBJ_ROWS), N)), np.empty((7, N), np.int32), np.empty((0, 1)),
            np.empty((N, 2, r)))


@njit(cache=True, error_model="numpy", nogil=True)
def point_shared_jacobian(uv, no_extra, no_boxes, yaw_deg, on_ground, cam, dR, Lr, Lc, Lv, r, spx, no_det, det_mode,
                          allow_outside, ch, sh, flag, S):
    """The centre's whitened parameter Jacobian ``B`` (N, 2, r) of one-point footprints ``uv`` (N, 1, 2) (pixels
    outside the image included), NaN where a pixel has no ground point: :func:`process_corners` with
    :func:`point_outputs`, in one call (the tracker asks for it at every track's predicted position in every
    frame).  ``no_extra`` (0, 0) int8, ``no_boxes`` (0, 7), ``no_det`` any 4-D array: the processor's empties;
    ``yaw_deg, on_ground, det_mode, allow_outside, flag`` must be False, True, 0, True, False -- arguments, not
    constants, so that the call below has the argument types of the processor's own calls and reuses that
    compiled :func:`process_corners` (a literal would make numba compile a second one, ~1 min)."""
    out = point_outputs(uv.shape[0], r)
    process_corners(uv, no_extra, no_boxes, yaw_deg, on_ground, cam, dR, Lr, Lc, Lv, r, spx, no_det, det_mode,
                    allow_outside, ch, sh, flag, out, S)
    shared, creason = out[12], out[7]
    for i in range(uv.shape[0]):
        if creason[i] != _OK:
            for a in range(2):
                for c in range(r):
                    shared[i, a, c] = math.nan
    return shared


@njit(cache=True, error_model="numpy", nogil=True)
def point_jacobian_into(uv, cam, dR, Lr, Lc, Lv, shared, S):
    """:func:`point_shared_jacobian` without the rest of a footprint: ``B`` (N, 2, r) of the ground points of
    pixels ``uv`` (N, 2) (pixels outside the image included) into ``shared`` (N, 2, r), NaN where a pixel has no
    ground point.  Only the stages of :func:`process_corners` that form ``B`` run, in its chunks and order
    (pixels, undistortion, ground and Jacobians, the codes, the centre's Jacobian, the whitening -- of ``B``
    alone, :func:`_stage_whiten_b`), so ``B`` is the same to the bit; the covariances, ellipses, flags and V2X
    codes of a one-point footprint, and the outputs :func:`point_outputs` allocated for them, are not formed (the
    tracker asks for ``B`` at every track's predicted position in every frame).  ``S``: :func:`scratch`."""
    N = uv.shape[0]
    Jd, Jk = np.empty((2, 2)), np.empty((2, 8))
    need = _needed_params(Lr)
    nan = math.nan
    for n0 in range(0, N, _M_TARGET):
        nob = min(N - n0, _M_TARGET)
        for i in range(nob):
            S[_U * _ST + i], S[_V * _ST + i] = uv[n0 + i, 0], uv[n0 + i, 1]
        _stage_undistort(S, nob, cam, Jd, Jk, need)
        _stage_ground(S, nob, cam, dR, need)
        _stage_corner_flags(S, nob, cam.width_px, cam.height_px, True)
        _stage_centroid(S, nob, 1)
        _stage_whiten_b(S, nob, Lr, Lc, Lv, shared, n0)  # (B alone: ~0.8 us less per 87 points)
        for i in range(nob):
            if S[_US * _ST + i] == 0.0:  # (one corner: the centre's code is the corner's; usable = OK or outside)
                for a in range(2):
                    for c in range(shared.shape[2]):
                        shared[n0 + i, a, c] = nan
