"""A frame of checked 2-D boxes through the fused per-frame kernel in ONE compiled call, with only the columns a
service frame writes coming back (:meth:`footprint_uq.products.frame_processor.FrameProcessor.boxes2d_columns`).

:func:`boxes2d_columns` forms the contact pixels of the boxes (the arithmetic of
``products.footprint_geometry.box2d_contact_points_checked``), checks the detector's 2x2 pixel covariances
(:func:`.cov_checks.first_bad_cov2`), runs :func:`.footprint_kernels.process_corners` on output arrays it
allocates itself (small: a frame's; the per-corner coordinates, covariances and the joint covariance are not
formed; the per-object rows and, for the tracker, the centres' shared Jacobians are the caller's arrays), declines
a frame with a centre whose V2X fields the policy would sample (:func:`.footprint_kernels.v2x_source_and_flagged`'s
test) and
copies the record's five float columns (centre and covariance) into the first rows of a ``(q + R, N)`` block
followed by the per-object rows and two int64 rows.  The Python of one frame is then two ``np.empty`` (a float64
and an int32 block: every output a view of one of them) and one call of 10 arguments: the processor's
constants travel as two arrays packed once (:func:`columns_constants`; a numba call costs ~40 ns per argument,
and ``process_corners`` called from Python ~3 us of argument unboxing, its 13 output arrays and the camera's
20-field structure among them), taken apart inside (:func:`unpack_constants`: views of the same types).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .cov_checks import first_bad_cov2
from .footprint_kernels import OBJ_ROW, KernelCamera, process_corners

__all__ = ["boxes2d_columns", "camera_parts", "columns_constants", "unpack_constants", "COLUMN_ROWS",
           "CAMERA_SCALARS", "N_OBJ_ROWS", "TAIL_ROWS", "INT32_ROWS"]

#: rows of :func:`boxes2d_columns`' ``values`` (m, m^2): what a compact record writes per object, in its order
COLUMN_ROWS = ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2")
_VALUE_OBJ_ROWS = tuple(OBJ_ROW[k] for k in COLUMN_ROWS)
_O_NL = OBJ_ROW["nonlinearity"]
#: rows of the fused kernel's per-object block (``OBJ_ROWS``)
N_OBJ_ROWS = len(OBJ_ROW)
#: rows of :func:`boxes2d_columns`' ``floats`` after the caller's q value rows: the per-object rows, then
#: ``largest_index`` and ``centre_bad_corner`` (int64, stored in a float64 row each: the same width, one block)
TAIL_ROWS = N_OBJ_ROWS + 2
#: rows of :func:`boxes2d_columns`' int32 block: the seven V2X code rows, then ``centre_reason``
INT32_ROWS = 8
#: the scalar fields of :class:`~.footprint_kernels.KernelCamera`, in the order of :func:`camera_parts`' vector
CAMERA_SCALARS = ("fx", "fy", "cx", "cy", "skew", "ifx", "ify", "x0", "y0", "h", "gdz", "gsx", "gsy", "width_px",
                  "height_px", "ground_z_m")


def camera_parts(cam: KernelCamera) -> tuple[np.ndarray, bool, np.ndarray, np.ndarray, np.ndarray]:
    """``(scalars (16,), has_dist, dist, R, dom)``: the camera structure as :func:`boxes2d_columns` takes it (four
    arrays and a flag unbox in a fraction of the structure's ~1 us per call); the arrays are the structure's own."""
    return (np.array([getattr(cam, k) for k in CAMERA_SCALARS], dtype=np.float64), bool(cam.has_dist), cam.dist,
            cam.R, cam.dom)


@njit(cache=True, nogil=True, inline="always")
def _camera(f, has_dist, dist, R, dom):  # pragma: no cover - compiled
    """The :class:`KernelCamera` of :func:`camera_parts`' pieces (the same values, the same numba type)."""
    return KernelCamera(f[0], f[1], f[2], f[3], f[4], f[5], f[6], dist, has_dist, f[7], f[8], f[9], f[10], f[11],
                        f[12], R, f[13], f[14], f[15], dom)


@njit(cache=True, nogil=True, inline="always")
def _contact_pixels(boxes, bottom_corners):  # pragma: no cover - compiled
    """The contact pixels ``(N, K, 2)`` of boxes ``(N, 4)`` (u_min, v_min, u_max, v_max): the bottom centre
    ``((u_min + u_max) / 2, v_max)`` (K = 1) or the bottom corners ``(u_min, v_max), (u_max, v_max)`` (K = 2), as
    ``boxes @ A.T`` forms them (its products by 0.5 and 1 are exact and its zeros add nothing: one rounding of
    the sum; ``+ 0.0`` as the zeros' terms give -0.0 its sign)."""
    n = boxes.shape[0]
    if bottom_corners:
        uv = np.empty((n, 2, 2))
        for i in range(n):
            v = boxes[i, 3] + 0.0
            uv[i, 0, 0], uv[i, 0, 1] = boxes[i, 0] + 0.0, v
            uv[i, 1, 0], uv[i, 1, 1] = boxes[i, 2] + 0.0, v
        return uv
    uv = np.empty((n, 1, 2))
    for i in range(n):
        uv[i, 0, 0] = (0.5 * boxes[i, 0] + 0.5 * boxes[i, 2]) + 0.0
        uv[i, 0, 1] = boxes[i, 3] + 0.0
    return uv


# :func:`columns_constants`' layout.  floats: the camera's scalars (CAMERA_SCALARS), then the processor's scalars,
# the budget's pixel covariance (2x2), "no detector covariance" (1x1x2x2 zeros), R (9), dR (3x3x3), then the
# variable parts: the distortion (n_dist), the factor's values Lv (nnz) and the lens domain (the rest).
_F_CH, _F_SH, _F_THRESHOLD, _F_COV_TOL = 16, 17, 18, 19
_F_SPX, _F_NO_DET, _F_R, _F_DR, _F_DIST = 20, 24, 28, 37, 64
# ints: the flags and sizes, then the factor's row and column indices Lr, Lc (nnz each)
_I_HAS_DIST, _I_RANK, _I_ALLOW_OUTSIDE, _I_FLAG, _I_DECLINE_FLAGGED, _I_NNZ, _I_NDIST, _I_L = range(8)


def columns_constants(cam: KernelCamera, dR: np.ndarray, Lr: np.ndarray, Lc: np.ndarray, Lv: np.ndarray, r: int,
                      spx: np.ndarray, *, allow_outside: bool, ch: float, sh: float, flag: bool, threshold: float,
                      cov_tol: float, decline_flagged: bool) -> tuple[np.ndarray, np.ndarray]:
    """A processor's constants as :func:`boxes2d_columns` takes them: ``(floats, ints)``, two arrays packed once
    (a numba call costs ~40 ns per argument: 2 arguments for these 18; :func:`unpack_constants` takes them apart
    inside the kernel, the same values and numba types).

    Parameters
    ----------
    cam, dR, Lr, Lc, Lv, r, spx, allow_outside, ch, sh, flag :
        As :func:`~.footprint_kernels.process_corners` takes them (the camera structure, its rotation's
        derivatives (3, 3, 3), the parameter covariance's sparse factor: int64 rows and columns, float64 values,
        its rank; the budget's pixel covariance (2, 2) px^2; the heading offset's cos / sin; the linearity flag).
    threshold : float
        ``linear_ok`` = nonlinearity <= threshold (the V2X policy's test).
    cov_tol : float
        :func:`~.cov_checks.first_bad_cov2`'s relative tolerance.
    decline_flagged : bool
        Decline a frame with a valid centre that is not ``linear_ok`` (a V2X policy other than "linear").
    """
    nnz = Lv.shape[0]
    if Lr.shape != (nnz,) or Lc.shape != (nnz,) or cam.R.shape != (9,) or dR.shape != (3, 3, 3):
        raise ValueError(f"constants of other sizes than the layout's: Lr {Lr.shape}, Lc {Lc.shape}, Lv {Lv.shape}, "
                         f"R {cam.R.shape}, dR {dR.shape}")
    floats = np.concatenate([camera_parts(cam)[0], [ch, sh, threshold, cov_tol], np.ravel(spx), np.zeros(4),
                             np.ravel(cam.R), np.ravel(dR), cam.dist, Lv, cam.dom]).astype(np.float64)
    ints = np.concatenate([[cam.has_dist, r, allow_outside, flag, decline_flagged, nnz, cam.dist.shape[0]],
                           Lr, Lc]).astype(np.int64)
    return floats, ints


@njit(cache=True, nogil=True, inline="always")
def unpack_constants(cf, ci):  # pragma: no cover - compiled
    """:func:`columns_constants`' arrays taken apart (views, no copies): ``(cam, dR, Lr, Lc, Lv, r, spx, no_det,
    allow_outside, ch, sh, flag, threshold, cov_tol, decline_flagged)``, of the types
    :func:`~.footprint_kernels.process_corners` is compiled for."""
    nd, nnz = ci[_I_NDIST], ci[_I_NNZ]
    a = _F_DIST + nd
    b = a + nnz
    cam = _camera(cf, ci[_I_HAS_DIST] != 0, cf[_F_DIST:a], cf[_F_R:_F_DR], cf[b:])
    return (cam, cf[_F_DR:_F_DIST].reshape((3, 3, 3)), ci[_I_L:_I_L + nnz], ci[_I_L + nnz:_I_L + 2 * nnz], cf[a:b],
            ci[_I_RANK], cf[_F_SPX:_F_NO_DET].reshape((2, 2)), cf[_F_NO_DET:_F_R].reshape((1, 1, 2, 2)),
            ci[_I_ALLOW_OUTSIDE] != 0, cf[_F_CH], cf[_F_SH], ci[_I_FLAG] != 0, cf[_F_THRESHOLD], cf[_F_COV_TOL],
            ci[_I_DECLINE_FLAGGED] != 0)


@njit(cache=True, error_model="numpy", nogil=True)
def boxes2d_columns(boxes, bottom_corners, cov, has_cov, cf, ci, floats, ints32, shared, S):  # pragma: no cover
    """One frame of checked 2-D boxes (float64 ``(N, 4)``, finite, corners in order) through
    :func:`~.footprint_kernels.process_corners`, its columns into the caller's two blocks.

    Parameters
    ----------
    boxes : (N, 4) float64, C-contiguous
        u_min, v_min, u_max, v_max (px).
    bottom_corners : bool
        The contact: the bottom corners (K = 2), else the bottom centre (K = 1).
    cov, has_cov : (N, 2, 2) float64 C-contiguous, bool
        The detector's pixel covariance per box (px^2); ``has_cov`` False: none (``cov`` is not read).
    cf, ci : (F,) float64, (I,) int64
        :func:`columns_constants` of the processor.
    floats : (q + TAIL_ROWS, N) float64, q >= 5, C-contiguous
        Out: :data:`COLUMN_ROWS` of every centre (m, m^2) in its first five rows (rows 5 to q - 1 are the
        caller's: the tracked record's motion columns), then the fused kernel's per-object rows (``OBJ_ROWS``:
        ``FootprintEstimate.object_rows``), then ``largest_index`` and ``centre_bad_corner`` as the estimate's
        (int64: each row read as int64).
    ints32 : (INT32_ROWS, N) int32, C-contiguous
        Out: the V2X codes (``FootprintEstimate.v2x_codes`` transposed) in its first seven rows, then
        ``centre_reason``.
    shared : (N, 2, r) or (0, 2, 0) float64
        Out: the centres' whitened parameter Jacobians ``centre_shared_m`` (the tracker's), NaN where no centre
        (as ``FrameProcessor._pack``); ``(0, 2, 0)``: not formed.
    S : the per-thread scratch (``footprint_kernels.SCRATCH_SHAPE``).

    Returns
    -------
    The number of centres found (>= 0), or -1: the frame is declined (the caller's ``boxes2d`` is needed) -- a
    covariance :func:`first_bad_cov2` refuses (then nothing else is computed), a computed value that is not finite
    (``mark_overflow``'s work), or, with ``decline_flagged``, a valid centre that is not ``linear_ok`` (NaN counts).
    """
    n = boxes.shape[0]
    cam, dR, Lr, Lc, Lv, r, spx, no_det, allow_outside, ch, sh, flag, threshold, cov_tol, decline_flagged = \
        unpack_constants(cf, ci)
    if has_cov:
        if first_bad_cov2(cov, cov_tol) >= 0:
            return -1
        det, mode = cov.reshape((n, 1, 2, 2)), 1
    else:
        det, mode = no_det, 0
    uv = _contact_pixels(boxes, bottom_corners)
    K = uv.shape[1]
    t = floats.shape[0] - TAIL_ROWS
    obj = floats[t:t + N_OBJ_ROWS]
    centre_reason = ints32[INT32_ROWS - 1]
    out = (np.empty((0, K, 2)), np.empty((0, K, 2, 2)), np.empty((0, 2 * K, 2 * K)), np.empty((n, K), np.int8),
           np.empty((n, K), np.bool_), floats[t + N_OBJ_ROWS].view(np.int64), np.empty((0, 2, 2)), centre_reason,
           floats[t + N_OBJ_ROWS + 1].view(np.int64), obj, ints32[:INT32_ROWS - 1], np.empty((0, K)), shared)
    if process_corners(uv, np.zeros((0, 0), np.int8), np.zeros((0, 7)), False, True, cam, dR, Lr, Lc, Lv, r, spx,
                       det, mode, allow_outside, ch, sh, flag, out, S):
        return -1
    n_valid = 0
    for i in range(n):
        for q in range(5):
            floats[q, i] = obj[_VALUE_OBJ_ROWS[q], i]
        if centre_reason[i] == 0:
            n_valid += 1
            if flag and decline_flagged and not obj[_O_NL, i] <= threshold:
                return -1
        elif shared.shape[0] == n:
            shared[i] = np.nan
    return n_valid
