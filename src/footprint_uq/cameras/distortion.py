"""OpenCV lens distortion (radial k1..k6, tangential p1, p2) with Jacobians.

Normalised image coordinates ``xy_n = (X/Z, Y/Z)`` of the OpenCV camera frame are
distorted as in OpenCV (``cv2.projectPoints``)::

    r2 = x^2 + y^2
    radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    x_d = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    y_d = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

Coefficients travel as ``(..., 8)`` arrays in OpenCV order (k1, k2, p1, p2, k3, k4, k5, k6).
Undistortion is the scalar core's (:func:`footprint_uq.fast.core.undistort_point`), inside
the lens's valid domain (:mod:`footprint_uq.cameras.lens_domain`); its Jacobians follow
from the implicit-function theorem: ``dx/dx_d = (ddistort/dx)^-1`` and
``dx/dk = -(ddistort/dx)^-1 ddistort/dk``.
"""

from __future__ import annotations

import numpy as np

from .._notices import before_kernels
from ..fast import core
from ..fast.python_twins import TWIN_ERRORS, python_twin
from .lens_domain import lens_domain

__all__ = ["distort", "undistort", "in_principal_region"]


def _fj(x, y, k, jac=True):
    """Distorted coordinates and, with ``jac``, the Jacobian entries, as separate arrays.

    Returns ``(xd, yd, rad, den)`` or ``(xd, yd, rad, den, a, b, c, d)`` with
    ``[[a, b], [c, d]] = d(xd, yd)/d(x, y)``; no stacking (fast on large grids).
    """
    k1, k2, p1, p2, k3, k4, k5, k6 = (k[..., i] for i in range(8))
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = num / den
    xy2 = 2.0 * x * y
    xd = x * rad + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + p2 * xy2
    if not jac:
        return xd, yd, rad, den
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d num / d r2
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (dnum * den - num * dden) / (den * den)  # d rad / d r2;  d r2 / dx = 2x
    off = xy2 * drad + 2.0 * p1 * x + 2.0 * p2 * y
    a = rad + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
    d = rad + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
    return xd, yd, rad, den, a, off, off, d


def distort(xy_n, dist, *, get_gradients=False):
    """Distort normalised coordinates.

    Parameters
    ----------
    xy_n : array_like, shape (..., 2)
        Undistorted normalised coordinates (dimensionless).
    dist : array_like, shape (..., 8)
        k1, k2, p1, p2, k3, k4, k5, k6.
    get_gradients : bool
        Also return ``dxyd_dxyn`` (..., 2, 2) and ``dxyd_ddist`` (..., 2, 8).

    Returns
    -------
    xy_d : ndarray, shape (..., 2)
    """
    xy_n = np.asarray(xy_n, dtype=np.float64)
    k = np.asarray(dist, dtype=np.float64)
    x, y = xy_n[..., 0], xy_n[..., 1]
    if not get_gradients:
        xd, yd = _fj(x, y, k, jac=False)[:2]
        return np.stack(np.broadcast_arrays(xd, yd), axis=-1)
    xd, yd, rad, den, a, b, c, d = _fj(x, y, k)
    out = np.stack([xd, yd], axis=-1)
    J = np.stack([np.stack([a, b], -1), np.stack([c, d], -1)], -2)
    r2 = x * x + y * y
    num = rad * den
    r4, r6 = r2 * r2, r2 * r2 * r2
    zero = np.zeros_like(rad)
    # d rad / d k_i
    dr = [r2 / den, r4 / den, zero, zero, r6 / den,
          -num * r2 / den**2, -num * r4 / den**2, -num * r6 / den**2]
    dxk = [x * dd for dd in dr]
    dyk = [y * dd for dd in dr]
    dxk[2], dyk[2] = 2.0 * x * y + zero, r2 + 2.0 * y * y + zero
    dxk[3], dyk[3] = r2 + 2.0 * x * x + zero, 2.0 * x * y + zero
    Jk = np.stack([np.stack(dxk, -1), np.stack(dyk, -1)], -2)
    return out, J, Jk


def _groups(kf: np.ndarray, domain):
    """``[(rows, LensDomain)]``: which rows of the (n, 8) coefficients go with which lens domain.

    With ``domain`` given, every row uses it (Monte Carlo: perturbed lenses, the nominal
    lens's domain).  Else one domain per distinct coefficient row; rows with non-finite
    coefficients belong to none (no answer).
    """
    n = kf.shape[0]
    if domain is not None:
        return [(slice(None), domain)]
    if n == 0:
        return []
    if np.all(kf == kf[0]):
        return [(slice(None), lens_domain(kf[0]))] if np.isfinite(kf[0]).all() else []
    finite = np.isfinite(kf).all(-1)
    uniq, inv = np.unique(kf[finite], axis=0, return_inverse=True)
    rows = np.flatnonzero(finite)
    return [(rows[inv.ravel() == j], lens_domain(uniq[j])) for j in range(uniq.shape[0])]


_UNDISTORT_MANY_PY = python_twin(core.undistort_many)
#: at most this many points go through the pure-Python twin of the undistortion while its compiled kernel is not
#: cached (~60 us each; more are faster to compile for: ~14 s)
PY_MAX_POINTS = 2000


def _undistort_many(packed, ks, xs, out, ok, minv) -> None:
    """:func:`footprint_uq.fast.core.undistort_many`; for a few points, while a command line's kernels are still
    compiling (:func:`footprint_uq._notices.before_kernels`, group "lens"), its pure-Python twin instead."""
    if xs.shape[0] <= PY_MAX_POINTS and not before_kernels("lens"):
        try:
            return _UNDISTORT_MANY_PY(packed, ks, xs, out, ok, minv)
        except TWIN_ERRORS:  # where the compiled kernel gives inf or NaN, CPython raises: the kernel decides
            pass
    core.undistort_many(packed, ks, xs, out, ok, minv)


def _solve(xf: np.ndarray, kf: np.ndarray, domain):
    """The scalar core (:func:`footprint_uq.fast.core.undistort_point`) over flat arrays."""
    n = xf.shape[0]
    out = np.full((n, 2), np.nan)
    ok = np.zeros(n, dtype=bool)
    minv = np.full((n, 4), np.nan)
    for rows, dom in _groups(kf, domain):
        xs = np.ascontiguousarray(xf[rows])
        ks = np.ascontiguousarray(kf[rows])
        o, c, m = np.empty_like(xs), np.empty(xs.shape[0], dtype=bool), np.empty((xs.shape[0], 4))
        _undistort_many(dom.packed, ks, xs, o, c, m)
        out[rows], ok[rows], minv[rows] = o, c, m
    return out, ok, minv


def in_principal_region(xy_n, dist) -> np.ndarray:
    """True where undistorted normalised points lie in the lens model's principal region.

    The region connected to the optical axis where the distortion map is locally
    invertible and does not fold over (:mod:`footprint_uq.cameras.lens_domain`):
    :func:`undistort` returns only solutions in it, and projections of points
    outside it are flagged.

    Parameters
    ----------
    xy_n : array_like, shape (..., 2)
    dist : array_like, shape (..., 8)

    Returns
    -------
    ndarray of bool, shape (...)
    """
    x = np.asarray(xy_n, dtype=np.float64)
    k = np.asarray(dist, dtype=np.float64)
    shape = np.broadcast_shapes(x.shape[:-1], k.shape[:-1])
    xf = np.ascontiguousarray(np.broadcast_to(x, shape + (2,)).reshape(-1, 2))
    kf = np.ascontiguousarray(np.broadcast_to(k, shape + (8,)).reshape(-1, 8))
    ok = np.zeros(xf.shape[0], dtype=bool)
    for rows, dom in _groups(kf, None):
        ok[rows] = dom.contains_undistorted(xf[rows])
    return ok.reshape(shape)


def undistort(xy_d, dist, *, domain=None, get_gradients=False):
    """Invert :func:`distort`: the undistorted normalised point of each distorted one.

    Every point goes through the scalar core
    (:func:`footprint_uq.fast.core.undistort_point`), the one definition shared by all
    paths: a point outside the lens's valid domain (:mod:`footprint_uq.cameras.lens_domain`)
    has no answer; inside it, damped Newton from ``x_d``, retried by continuation from the
    optical axis, converges to the principal root (residual <= 1e-14 max(1, |x_d|),
    polished by one more step).

    Parameters
    ----------
    xy_d : array_like, shape (..., 2)
        Distorted normalised coordinates.
    dist : array_like, shape (..., 8)
    domain : LensDomain, optional
        The valid domain to use for every point.  Default: the domain of each point's
        own coefficients (cached per coefficient set).  Monte Carlo over perturbed lenses
        passes the nominal lens's domain.
    get_gradients : bool
        Also return ``dxyn_dxyd`` (..., 2, 2) and ``dxyn_ddist`` (..., 2, 8).

    Returns
    -------
    xy_n : ndarray, shape (..., 2)
        NaN where there is no answer.
    converged : ndarray of bool, shape (...)
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    k = np.asarray(dist, dtype=np.float64)
    shape = np.broadcast_shapes(xy_d.shape[:-1], k.shape[:-1])
    xy_d = np.broadcast_to(xy_d, shape + (2,))
    k = np.broadcast_to(k, shape + (8,))
    if not np.any(k):
        x = xy_d.copy()
        conv = np.isfinite(x).all(-1)
        if not get_gradients:
            return x, conv
        _, J, Jk = distort(x, k, get_gradients=True)
        return x, conv, np.broadcast_to(np.eye(2), shape + (2, 2)).copy(), -Jk
    xf = np.ascontiguousarray(xy_d.reshape(-1, 2))
    kf = np.ascontiguousarray(k.reshape(-1, 8))
    out, ok, minv = _solve(xf, kf, domain)
    x = out.reshape(shape + (2,))
    conv = ok.reshape(shape)
    if not get_gradients:
        return x, conv
    Jinv = minv.reshape(shape + (2, 2))
    with np.errstate(all="ignore"):
        _, _, Jk = distort(x, k, get_gradients=True)
    return x, conv, Jinv, -(Jinv @ Jk)
