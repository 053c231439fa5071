"""Ground point and 2x2 covariance of every pixel of a grid, or of scattered pixels: the public entries of
the fused kernels.

:func:`covariance_map` and :func:`covariance_points` load the budget, check their inputs, turn camera
and budget into the kernels' constants (:func:`kernel_constants`) and hand arrays to
:mod:`footprint_uq.fast.map_kernels` (the compiled layer, which imports nothing above itself).  The
formulation, its agreement with :func:`footprint_uq.uncertainty.propagation.propagate` (1e-12
relative) and the performance notes are in that module's docstring.
"""

from __future__ import annotations

import numpy as np

from .. import params as P
from .._checks import as_int, as_points, check_cov
from ..cameras.rotation import R_W_C, dR_W_C
from ..errors import InputError
from ..fast import map_kernels as mk
from ..uncertainty.budget import load_budget

__all__ = ["covariance_map", "covariance_points", "kernel_constants"]

# index of the constant state rows for the position/height/ground parameters
_CONST_ROW = {P.XM: 0, P.YM: 1, P.HM: 2, P.GDZ: 3, P.GSX: 4, P.GSY: 5}


def kernel_constants(camera, budget) -> dict:
    """Camera- and budget-level constants the kernels use (exposed for tests and debugging).

    Returns a dict with ``params`` (22,), ``R`` (3, 3) camera->world rotation,
    ``omega`` (3, 3) rotation generators (row k: ``R^T dR/d angle_k`` as a vector),
    the sparse factor ``colptr``, ``rowidx``, ``vals`` of the budget's parameter
    covariance, ``vc`` (r, 6) the constant state rows of each factor column,
    ``Ccc`` (6, 6) their covariance, ``has_qc`` (ray/constant cross-covariance
    present) and ``Suv`` (2, 2) the budget's per-point pixel covariance.
    """
    budget = load_budget(budget)
    p = np.ascontiguousarray(camera.params, dtype=np.float64)
    if p.shape != (P.N_PARAMS,) or not np.all(np.isfinite(p)):
        raise InputError("camera.params", p, f"{P.N_PARAMS} finite numbers")
    ang = (p[P.PAN], p[P.TILT], p[P.ROLL])
    R = np.ascontiguousarray(R_W_C(*ang))
    dR = dR_W_C(*ang)
    omega = np.empty((3, 3))
    for k in range(3):
        A = R.T @ dR[k]
        omega[k] = (A[2, 1], A[0, 2], A[1, 0])
    colptr, rowidx, vals = budget.param_factor()
    r = colptr.size - 1
    vc = np.zeros((r, 6))
    has_qc = False
    for j in range(r):
        ray = False
        const = False
        for nz in range(colptr[j], colptr[j + 1]):
            k = int(rowidx[nz])
            if k in _CONST_ROW:
                vc[j, _CONST_ROW[k]] += vals[nz]
                const = True
            else:
                ray = True
        has_qc = has_qc or (ray and const)
    Ccc = vc.T @ vc
    return dict(params=p, R=R, omega=np.ascontiguousarray(omega), colptr=colptr, rowidx=rowidx, vals=vals,
                vc=np.ascontiguousarray(vc), Ccc=np.ascontiguousarray(Ccc), has_qc=has_qc,
                Suv=np.ascontiguousarray(budget.pixel_covariance()))


def _check_out(out, H, W, get_nonlinearity):
    """``(xy, cov, valid, nonlinearity or None)`` of a caller's ``out`` tuple, checked."""
    n_ok = (3, 4) if get_nonlinearity else (3,)
    if not (isinstance(out, tuple | list) and len(out) in n_ok):
        raise InputError("out", type(out).__name__ if not isinstance(out, tuple | list) else f"{len(out)} arrays",
                         "a tuple (xy_world_m, cov_m2, valid) of preallocated arrays"
                         + (" (and nonlinearity, with get_nonlinearity)" if get_nonlinearity else ""))
    specs = [("out[0] (xy_world_m)", (H, W, 2), np.float64), ("out[1] (cov_m2)", (H, W, 2, 2), np.float64),
             ("out[2] (valid)", (H, W), np.bool_), ("out[3] (nonlinearity)", (H, W), np.float64)]
    for a, (name, shape, dt) in zip(out, specs, strict=False):
        if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dt or not a.flags.c_contiguous \
                or not a.flags.writeable:
            got = (getattr(a, "shape", None), str(getattr(a, "dtype", type(a).__name__)))
            raise InputError(name, got, f"a writeable C-contiguous {np.dtype(dt).name} array of shape {shape}")
    return out[0], out[1], out[2], (out[3] if len(out) == 4 else None)


def covariance_map(camera, budget, step_px: int = 1, *, out=None, get_reason: bool = False,
                   get_nonlinearity: bool = False):
    """Ground point, 2x2 covariance and validity of every pixel of a regular grid.

    Parameters
    ----------
    camera : Camera
        :class:`~footprint_uq.cameras.pantilt.PanTiltCamera` or
        :class:`~footprint_uq.cameras.opencv.OpenCVCamera`.  Cameras with zero
        nominal distortion use the closed-form kernel (per-row polynomials), others
        the general kernel with Newton undistortion.
    budget : ErrorBudget, preset name, path or mapping
        Every source is honoured, including a full parameter covariance; per-point
        imaging and resolution noise come from ``budget.pixel_covariance()``.
    step_px : int
        Grid step: pixel centres ``camera.pixel_grid(step_px)``.
    out : tuple of ndarray, optional
        Preallocated ``(xy_world_m (H, W, 2) float64, cov_m2 (H, W, 2, 2) float64,
        valid (H, W) bool)``, C-contiguous, for the grid's H, W; filled in place.  With
        ``get_nonlinearity`` a fourth array ``nonlinearity (H, W) float64`` may follow.
    get_reason : bool
        Also return the :mod:`footprint_uq.status` code of every pixel.
    get_nonlinearity : bool
        Also return the linearity flag's ``nonlinearity`` of every pixel, computed in the same
        pass (:func:`footprint_uq.fast.core.nonlinearity_point`; the number
        :func:`footprint_uq.propagation.propagate` gives; ``linear_ok = nonlinearity <= threshold``).

    Returns
    -------
    xy_world_m : ndarray (H, W, 2)
        Ground points in W (x east, y north), metres; NaN where invalid.
    cov_m2 : ndarray (H, W, 2, 2)
        Covariance, m^2; NaN where invalid.
    valid : ndarray of bool (H, W)
        False at or above the horizon, or outside the lens's valid domain.
    reason : ndarray of int8 (H, W), with ``get_reason``
        The same codes as :func:`footprint_uq.cameras.general.backproject`.
    nonlinearity : ndarray (H, W), with ``get_nonlinearity``
        Predicted relative error of the linear 1-sigma semi-major axis (dimensionless); NaN where
        not valid.  After ``reason`` when both are asked for.
    """
    step = as_int("step_px", step_px, minimum=1, expected="a positive integer")
    w_img, h_img = camera.image_size_px
    W = (w_img + step - 1) // step
    H = (h_img + step - 1) // step
    if out is None:
        out = (np.empty((H, W, 2)), np.empty((H, W, 2, 2)), np.empty((H, W), dtype=np.bool_))
    xy, cov, valid, nlin = _check_out(out, H, W, get_nonlinearity)
    k = kernel_constants(camera, budget)
    reason = np.empty((H, W), dtype=np.int8) if get_reason else None
    if get_nonlinearity and nlin is None:
        nlin = np.empty((H, W))
    mk.map_into(k, camera.lens_domain.packed, step, xy, cov, valid, reason, nlin)
    res = (xy, cov, valid)
    if get_reason:
        res = res + (reason,)
    if get_nonlinearity:
        res = res + (nlin,)
    return res


def covariance_points(camera, budget, uv_px, pixel_cov_px2=None, *, get_reason: bool = False,
                      get_nonlinearity: bool = False):
    """Ground point, 2x2 covariance and validity of scattered pixels (general kernel).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    uv_px : array_like (..., 2)
        Pixel coordinates (u right, v down); non-finite rows give ``valid = False``.
    pixel_cov_px2 : array_like (2, 2) or (..., 2, 2), optional
        Extra per-point pixel covariance (e.g. a detector's), added to the budget's
        imaging and resolution noise, as in :func:`footprint_uq.uncertainty.propagation.propagate`.
    get_reason : bool
        Also return the :mod:`footprint_uq.status` code of every point.
    get_nonlinearity : bool
        Also return the linearity flag's ``nonlinearity`` of every point (the same number as
        :func:`footprint_uq.propagation.propagate`'s; ``linear_ok = nonlinearity <= threshold``).

    Returns
    -------
    xy_world_m : ndarray (..., 2)
    cov_m2 : ndarray (..., 2, 2)
    valid : ndarray of bool (...)
    reason : ndarray of int8 (...), with ``get_reason``
        The same codes as :func:`footprint_uq.cameras.general.backproject`.
    nonlinearity : ndarray (...), with ``get_nonlinearity``
        Predicted relative error of the linear 1-sigma semi-major axis (dimensionless); NaN where
        not valid.  After ``reason`` when both are asked for.
    """
    budget = load_budget(budget)
    uv = as_points("uv_px", uv_px, 2)
    lead = uv.shape[:-1]
    flat = np.ascontiguousarray(uv.reshape(-1, 2))
    n = flat.shape[0]
    Suv = budget.pixel_covariance()
    if pixel_cov_px2 is not None:
        c = check_cov("pixel_cov_px2", pixel_cov_px2, 2)
        try:
            Suv = np.broadcast_to(Suv + c, lead + (2, 2))
        except ValueError:
            raise InputError("pixel_cov_px2", c.shape, f"a covariance of shape (2, 2) or {lead + (2, 2)}") from None
    Suv = np.ascontiguousarray(np.broadcast_to(Suv, lead + (2, 2)).reshape(n, 2, 2))
    k = kernel_constants(camera, budget)
    xy = np.empty((n, 2))
    cov = np.empty((n, 2, 2))
    valid = np.empty(n, dtype=np.bool_)
    reason = np.empty(n, dtype=np.int8)
    nlin = np.empty(n if get_nonlinearity else 0)
    mk.points_into(k, camera.lens_domain.packed, flat, Suv, xy, cov, valid, reason, nlin)
    out = xy.reshape(lead + (2,)), cov.reshape(lead + (2, 2)), valid.reshape(lead)
    if get_reason:
        out = out + (reason.reshape(lead),)
    if get_nonlinearity:
        out = out + (nlin.reshape(lead),)
    return out
