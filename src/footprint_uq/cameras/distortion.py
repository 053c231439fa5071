"""OpenCV lens distortion (radial k1..k6, tangential p1, p2) with Jacobians.

Normalised image coordinates ``xy_n = (X/Z, Y/Z)`` of the OpenCV camera frame are
distorted as in OpenCV (``cv2.projectPoints``)::

    r2 = x^2 + y^2
    radial = (1 + k1 r2 + k2 r2^2 + k3 r2^3) / (1 + k4 r2 + k5 r2^2 + k6 r2^3)
    x_d = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    y_d = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

Coefficients travel as ``(..., 8)`` arrays in OpenCV order (k1, k2, p1, p2, k3, k4, k5, k6).
Undistortion solves ``distort(x) = x_d`` by Newton's method; its Jacobians follow
from the implicit-function theorem: ``dx/dx_d = (ddistort/dx)^-1`` and
``dx/dk = -(ddistort/dx)^-1 ddistort/dk``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["distort", "undistort"]


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
    k1, k2, p1, p2, k3, k4, k5, k6 = (k[..., i] for i in range(8))
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = num / den
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    out = np.stack([xd, yd], axis=-1)
    if not get_gradients:
        return out
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)  # d num / d r2
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (dnum * den - num * dden) / (den * den)  # d rad / d r2
    # d r2 / dx = 2x
    dxd_dx = rad + x * drad * 2 * x + 2 * p1 * y + p2 * 6 * x
    dxd_dy = x * drad * 2 * y + 2 * p1 * x + p2 * 2 * y
    dyd_dx = y * drad * 2 * x + p1 * 2 * x + 2 * p2 * y
    dyd_dy = rad + y * drad * 2 * y + p1 * 6 * y + 2 * p2 * x
    J = np.stack([np.stack([dxd_dx, dxd_dy], -1), np.stack([dyd_dx, dyd_dy], -1)], -2)
    r4, r6 = r2 * r2, r2 * r2 * r2
    zero = np.zeros_like(rad)
    # d rad / d k_i
    dr = [r2 / den, r4 / den, zero, zero, r6 / den,
          -num * r2 / den**2, -num * r4 / den**2, -num * r6 / den**2]
    dxk = [x * d for d in dr]
    dyk = [y * d for d in dr]
    dxk[2], dyk[2] = 2.0 * x * y + zero, r2 + 2.0 * y * y
    dxk[3], dyk[3] = r2 + 2.0 * x * x, 2.0 * x * y + zero
    Jk = np.stack([np.stack(dxk, -1), np.stack(dyk, -1)], -2)
    return out, J, Jk


def _solve2(J, b):
    """Solve ``J x = b`` for batches of 2x2 systems; returns (x, det)."""
    a, bb, c, d = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
    det = a * d - bb * c
    x0 = (d * b[..., 0] - bb * b[..., 1]) / det
    x1 = (-c * b[..., 0] + a * b[..., 1]) / det
    return np.stack([x0, x1], -1), det


def _inv2(J):
    a, b, c, d = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
    det = a * d - b * c
    return np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2) / det[..., None, None]


def undistort(xy_d, dist, *, tol=1e-14, max_iter=50, get_gradients=False):
    """Invert :func:`distort` by Newton's method.

    Parameters
    ----------
    xy_d : array_like, shape (..., 2)
        Distorted normalised coordinates.
    dist : array_like, shape (..., 8)
    tol : float
        Convergence tolerance on the residual, in normalised units.  The default
        1e-14 is about 1e-11 px for a 1000 px focal length, below the 1e-10 px
        the camera models promise.
    get_gradients : bool
        Also return ``dxyn_dxyd`` (..., 2, 2) and ``dxyn_ddist`` (..., 2, 8).

    Returns
    -------
    xy_n : ndarray, shape (..., 2)
        NaN where the iteration did not converge or the distortion map is
        singular (outside the region where the lens model is invertible).
    converged : ndarray of bool, shape (...)
    """
    xy_d = np.asarray(xy_d, dtype=np.float64)
    k = np.asarray(dist, dtype=np.float64)
    shape = np.broadcast_shapes(xy_d.shape[:-1], k.shape[:-1])
    xy_d = np.broadcast_to(xy_d, shape + (2,))
    k = np.broadcast_to(k, shape + (8,))
    x = xy_d.copy()
    if not np.any(k):
        conv = np.isfinite(x).all(-1)
        if not get_gradients:
            return x, conv
        _, J, Jk = distort(x, k, get_gradients=True)
        return x, conv, np.broadcast_to(np.eye(2), shape + (2, 2)).copy(), -Jk
    conv = np.zeros(shape, dtype=bool)
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            f, J = distort(x, k, get_gradients=True)[:2]
            res = f - xy_d
            conv = np.abs(res).max(axis=-1) <= tol * np.maximum(1.0, np.abs(xy_d).max(axis=-1))
            if conv.all():
                break
            step, det = _solve2(J, res)
            x = np.where(conv[..., None], x, x - step)
        f, J, Jk = distort(x, k, get_gradients=True)
        res = f - xy_d
        det = J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0]
        conv = (np.abs(res).max(axis=-1) <= tol * np.maximum(1.0, np.abs(xy_d).max(axis=-1))) & (det > 0)
    x = np.where(conv[..., None], x, np.nan)
    if not get_gradients:
        return x, conv
    with np.errstate(all="ignore"):
        Jinv = _inv2(J)
    return x, conv, Jinv, -(Jinv @ Jk)
