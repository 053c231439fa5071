"""A frame of checked 2-D boxes through the fused per-frame kernel in ONE compiled call, with only the columns a
service frame writes coming back (:meth:`footprint_uq.products.frame_processor.FrameProcessor.boxes2d_columns`).

:func:`boxes2d_columns` forms the contact pixels of the boxes (the arithmetic of
``products.footprint_geometry.box2d_contact_points_checked``), checks the detector's 2x2 pixel covariances
(:func:`.cov_checks.first_bad_cov2`), runs :func:`.footprint_kernels.process_corners` on output arrays it
allocates itself (small: a frame's; the per-corner coordinates, covariances and the joint covariance are not
formed; the per-object rows and, for the tracker, the centres' shared Jacobians are the caller's arrays), counts
the centres whose V2X fields the policy would sample (:func:`.footprint_kernels.v2x_source_and_flagged`) and
copies the record's five float columns (centre and covariance) into the first rows of one ``(q, N)`` block.
The Python of one frame is then a handful of ``np.empty`` and one call (``process_corners`` itself: ~3 us of
argument unboxing per call, its 13 output arrays and the camera's 20-field structure among them; here the camera
travels as four arrays and is put together inside).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .cov_checks import first_bad_cov2
from .footprint_kernels import OBJ_ROW, KernelCamera, process_corners

__all__ = ["boxes2d_columns", "camera_parts", "COLUMN_ROWS", "CAMERA_SCALARS"]

#: rows of :func:`boxes2d_columns`' ``values`` (m, m^2): what a compact record writes per object, in its order
COLUMN_ROWS = ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2")
_VALUE_OBJ_ROWS = tuple(OBJ_ROW[k] for k in COLUMN_ROWS)
_O_NL = OBJ_ROW["nonlinearity"]
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


@njit(cache=True, error_model="numpy", nogil=True)
def boxes2d_columns(boxes, bottom_corners, cov, has_cov, cam_f, has_dist, dist, R, dom, dR, Lr, Lc, Lv, r, spx,
                    no_det, allow_outside, ch, sh, flag, threshold, cov_tol, values, v2x, largest_index,
                    centre_reason, centre_bad_corner, obj, shared, S):  # pragma: no cover - compiled
    """One frame of checked 2-D boxes (float64 ``(N, 4)``, finite, corners in order) through
    :func:`~.footprint_kernels.process_corners`, its columns into the caller's arrays.

    Parameters
    ----------
    boxes : (N, 4) float64, C-contiguous
        u_min, v_min, u_max, v_max (px).
    bottom_corners : bool
        The contact: the bottom corners (K = 2), else the bottom centre (K = 1).
    cov, has_cov : (N, 2, 2) float64 C-contiguous, bool
        The detector's pixel covariance per box (px^2); ``has_cov`` False: none (``cov`` is not read).
    cam_f, has_dist, dist, R, dom :
        :func:`camera_parts` of the processor's camera.
    dR, Lr, Lc, Lv, r, spx, allow_outside, ch, sh, flag :
        As :func:`~.footprint_kernels.process_corners` takes them; ``no_det`` its 4-D array for "no detector
        covariance".
    threshold : float
        ``linear_ok`` = nonlinearity <= threshold (the V2X policy's test).
    cov_tol : float
        :func:`~.cov_checks.first_bad_cov2`'s relative tolerance.
    values : (q, N) float64, q >= 5
        Out: :data:`COLUMN_ROWS` of every centre (m, m^2) in its first five rows (the rest is the caller's: the
        tracked record's motion columns).
    v2x : (7, N) int32
        Out: the V2X codes (``FootprintEstimate.v2x_codes`` transposed).
    largest_index, centre_reason, centre_bad_corner : (N,) int64, int32, int64
        Out: as the estimate's.
    obj : (len(OBJ_ROWS), N) float64
        Out: the fused kernel's per-object rows (``FootprintEstimate.object_rows``: the estimate's centre and
        covariance are views of it).
    shared : (N, 2, r) or (0, 2, 0) float64
        Out: the centres' whitened parameter Jacobians ``centre_shared_m`` (the tracker's), as the kernel writes
        them (rows of centres not found are not set to NaN here); ``(0, 2, 0)``: not formed.
    S : the per-thread scratch (``footprint_kernels.SCRATCH_SHAPE``).

    Returns
    -------
    ``(bad_cov, n_over, n_valid, n_flagged)``: the first covariance :func:`first_bad_cov2` refuses (-1: none;
    then nothing else is computed), the number of computed values that are not finite (``mark_overflow``'s
    work, almost always 0), the centres found, the valid centres that are not ``linear_ok`` (NaN counts; 0
    without ``flag``).
    """
    n = boxes.shape[0]
    if has_cov:
        bad = first_bad_cov2(cov, cov_tol)
        if bad >= 0:
            return bad, 0, 0, 0
        det, mode = cov.reshape((n, 1, 2, 2)), 1
    else:
        det, mode = no_det, 0
    uv = _contact_pixels(boxes, bottom_corners)
    K = uv.shape[1]
    out = (np.empty((0, K, 2)), np.empty((0, K, 2, 2)), np.empty((0, 2 * K, 2 * K)), np.empty((n, K), np.int8),
           np.empty((n, K), np.bool_), largest_index, np.empty((0, 2, 2)), centre_reason, centre_bad_corner, obj, v2x,
           np.empty((0, K)), shared)
    cam = _camera(cam_f, has_dist, dist, R, dom)
    n_over = process_corners(uv, np.zeros((0, 0), np.int8), np.zeros((0, 7)), False, True, cam, dR, Lr, Lc, Lv, r,
                             spx, det, mode, allow_outside, ch, sh, flag, out, S)
    n_valid = n_flagged = 0
    for i in range(n):
        for q in range(5):
            values[q, i] = obj[_VALUE_OBJ_ROWS[q], i]
        if centre_reason[i] == 0:
            n_valid += 1
            if flag and not obj[_O_NL, i] <= threshold:
                n_flagged += 1
    return -1, n_over, n_valid, n_flagged

