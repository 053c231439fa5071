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


def _solve2(J, b):
    """Solve ``J x = b`` for batches of 2x2 systems; returns (x, det)."""
    a, bb, c, d = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
    det = a * d - bb * c
    x0 = (d * b[..., 0] - bb * b[..., 1]) / det
    x1 = (-c * b[..., 0] + a * b[..., 1]) / det
    return np.stack([x0, x1], -1), det


def _branch_ok(x, k, n_steps=16):
    """True where ``x`` lies in the lens model's principal (invertible) region.

    The region is the one connected to the optical axis in which the distortion
    map is locally invertible and does not fold the image over: along the segment
    from 0 to ``x`` the Jacobian determinant and the radial factor stay positive
    (checked at ``n_steps`` points).  A Newton solution outside it solves
    ``distort(x) = x_d`` on another branch of the polynomial (e.g. a point on the
    opposite side of the image) and must not be used.
    """
    ok = np.ones(np.broadcast_shapes(x.shape[:-1], k.shape[:-1]), dtype=bool)
    for t in np.arange(1, n_steps + 1) / n_steps:
        _, _, rad, den, a, b, c, d = _fj(t * x[..., 0], t * x[..., 1], k)
        ok &= (a * d - b * c > 0) & (rad > 0) & (den > 0)
    return ok


def in_principal_region(xy_n, dist, *, n_steps: int = 16) -> np.ndarray:
    """True where undistorted normalised points lie in the lens model's principal region.

    The region connected to the optical axis where the distortion map is locally
    invertible and does not fold over: along the segment from 0 to ``xy_n`` the
    Jacobian determinant, the radial factor and its denominator stay positive
    (checked at ``n_steps`` evenly spaced points, the last one ``xy_n`` itself).
    :func:`undistort` accepts only solutions in this region, and projections of
    points outside it are flagged.

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
    with np.errstate(all="ignore"):
        return _branch_ok(x, k, n_steps)


def _inv2(J):
    a, b, c, d = J[..., 0, 0], J[..., 0, 1], J[..., 1, 0], J[..., 1, 1]
    det = a * d - b * c
    return np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2) / det[..., None, None]


_N_CONTINUATION = 16


def _accept(x, xy_d, k, tol):
    """Converged: residual within ``tol``, Jacobian non-singular, principal branch."""
    xd, yd, _, _, a, b, c, d = _fj(x[..., 0], x[..., 1], k)
    err = np.maximum(np.abs(xd - xy_d[..., 0]), np.abs(yd - xy_d[..., 1]))
    ok = (err <= tol * np.maximum(1.0, np.abs(xy_d).max(axis=-1))) & (a * d - b * c > 0)
    return ok & _branch_ok(x, k)


def _newton(xy_d, k, tol, max_iter, x0=None):
    """Damped Newton iteration for ``distort(x, k) = xy_d`` on an active set of points.

    Starts from ``x0`` (default ``xy_d``); a step is halved (up to 12 times) until it lowers the
    residual, which keeps the iteration from jumping over the fold of the lens
    model onto another branch.  Returns the last iterate (convergence is judged
    by the caller).
    """
    shape = xy_d.shape[:-1]
    k = np.broadcast_to(k, shape + (8,))
    shared = k.ndim == 1 or all(st == 0 for st in k.strides[:-1])
    kf = k[(0,) * (k.ndim - 1)][None, :] if shared else k.reshape(-1, 8)
    tx, ty = xy_d[..., 0].ravel(), xy_d[..., 1].ravel()
    x0 = xy_d if x0 is None else np.broadcast_to(np.asarray(x0, dtype=np.float64), shape + (2,))
    x, y = x0[..., 0].ravel().copy(), x0[..., 1].ravel().copy()
    lim = tol * np.maximum(1.0, np.maximum(np.abs(tx), np.abs(ty)))
    ok = np.isfinite(tx) & np.isfinite(ty) & np.isfinite(x) & np.isfinite(y)
    ok &= np.isfinite(kf).all(-1) if not shared else bool(np.isfinite(kf).all())
    active = np.flatnonzero(ok)
    with np.errstate(all="ignore"):
        for _ in range(max_iter):
            if active.size == 0:
                break
            ka = kf if shared else kf[active]
            xa, ya, ta, ua = x[active], y[active], tx[active], ty[active]
            fx, fy, _, _, a, b, c, d = _fj(xa, ya, ka)
            rx, ry = fx - ta, fy - ua
            keep = np.maximum(np.abs(rx), np.abs(ry)) > lim[active]
            if not keep.all():
                active, xa, ya, ta, ua, rx, ry = (v[keep] for v in (active, xa, ya, ta, ua, rx, ry))
                a, b, c, d = a[keep], b[keep], c[keep], d[keep]
                ka = kf if shared else kf[active]
            if active.size == 0:
                break
            det = a * d - b * c
            sx, sy = (d * rx - b * ry) / det, (a * ry - c * rx) / det
            r0 = rx * rx + ry * ry
            lam = np.ones(active.size)
            for _ in range(12):
                xn, yn = xa - lam * sx, ya - lam * sy
                fx, fy = _fj(xn, yn, ka, jac=False)[:2]
                better = (fx - ta) ** 2 + (fy - ua) ** 2 < r0
                if better.all():
                    break
                lam = np.where(better, lam, 0.5 * lam)
            x[active], y[active] = xn, yn
            active = active[np.isfinite(xn) & np.isfinite(yn)]
    x = np.stack([x, y], -1)
    return x.reshape(shape + (2,))


def undistort(xy_d, dist, *, tol=1e-14, max_iter=50, get_gradients=False):
    """Invert :func:`distort` by (damped) Newton's method.

    The solution is accepted only in the lens model's principal region (see
    :func:`_branch_ok`): past the fold of the radial polynomial another root of
    ``distort(x) = x_d`` may exist (e.g. on the opposite side of the image), and
    returning it would send the ray in a wrong direction.  Where Newton from
    ``x_d`` fails, the solution is followed by continuation from the optical axis.

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
    if not np.any(k):
        x = xy_d.copy()
        conv = np.isfinite(x).all(-1)
        if not get_gradients:
            return x, conv
        _, J, Jk = distort(x, k, get_gradients=True)
        return x, conv, np.broadcast_to(np.eye(2), shape + (2, 2)).copy(), -Jk
    x = _newton(xy_d, k, tol, max_iter)
    with np.errstate(all="ignore"):
        conv = np.array(_accept(x, xy_d, k, tol), dtype=bool)  # writable, also for a single point
        retry = ~conv & np.isfinite(xy_d).all(-1) & np.isfinite(k).all(-1)
        if np.any(retry):
            # Newton from x_d may land on another branch of the polynomial (past the fold)
            # or stall; follow the solution of distort(x) = t x_d from the optical axis (t = 0)
            # to t = 1 instead, which stays on the principal branch while there is one.
            td, kr = xy_d[retry], k[retry]
            xr = np.zeros_like(td)
            for t in np.arange(1, _N_CONTINUATION + 1) / _N_CONTINUATION:
                xr = _newton(t * td, kr, tol, 8, x0=xr)
            xr = _newton(td, kr, tol, max_iter, x0=xr)
            x = x.copy()
            x[retry] = xr
            conv[retry] = _accept(xr, td, kr, tol)
    x = np.where(conv[..., None], x, np.nan)
    if not get_gradients:
        return x, conv
    with np.errstate(all="ignore"):
        _, J, Jk = distort(x, k, get_gradients=True)
        Jinv = _inv2(J)
    return x, conv, Jinv, -(Jinv @ Jk)
