"""The slide term of tracked 2-D box contacts, compiled (``footprint_uq.tracking.contact_slide``).

:func:`slide_moments` is the compiled form of the numpy reference
``footprint_uq.tracking.contact_slide.slide_moments_reference`` (same steps, the same numbers to rounding): per
tracked contact, the footprint centre ``c`` by one fixed-point step from the contact (the box of the class's
mean size rendered there, its bottom-centre pixel back-projected), then for each unscented size node the slide
in closed form, ``u = (dg/dc) v - v``: the box rendered once at ``c`` (the bounding box of its eight projected
corners), the bottom-centre pixel's derivative along the path from the corners that carry ``u_min``, ``u_max``
and ``v_max`` (every corner moves by the same camera-frame vector ``R^T (v_x, v_y, s_x v_x + s_y v_y)`` per
second: the box and its ground plane height), and the back-projection's derivative at that pixel; last the mean
and second moment of ``u`` over the nodes that render.

The camera travels as ``prm`` (22,), ``R`` = ``R_W_C`` (3, 3), the packed lens domain ``dom`` and ``has_dist``
(the lens domain is checked, and the lens inverted, only for a distorting lens, as in
:func:`footprint_uq.cameras.general.project` / ``backproject``).
"""

from __future__ import annotations

import math

import numba as nb

from .. import params as P
from . import core

__all__ = ["slide_moments", "MOMENTS_KERNELS", "MIN_SIZE_M"]

_INL = dict(inline="always", cache=True, error_model="numpy", fastmath={"contract"})
_JIT = dict(cache=True, error_model="numpy", fastmath={"contract"})

#: a size node's length, width or height is clipped below at this (m), as the numpy reference
MIN_SIZE_M = 0.02


@nb.njit(**_INL)
def _pixel_rate(prm, k, has_dist, xn, yn, iz, d0, d1, d2):
    """d(u, v)/dt (px/s) of a corner at normalised (xn, yn), ``iz`` = 1 / its depth, moving at camera-frame
    (d0, d1, d2) m/s."""
    ex, ey = (d0 - xn * d2) * iz, (d1 - yn * d2) * iz
    if has_dist:
        j00, j01, j10, j11 = core.distort_jac(xn, yn, k)[2:6]
        ex, ey = j00 * ex + j01 * ey, j10 * ex + j11 * ey
    return prm[P.FX] * ex + prm[P.SKEW] * ey, prm[P.FY] * ey


@nb.njit(**_INL)
def _corner(q0, q1, q2, ol0, ol1, ol2, ow0, ow1, ow2, h0, h1, h2, j):
    """Camera-frame corner ``j`` (0-3 the base, 4-7 the top; signs along the length -++- and width --++)."""
    jj = j & 3
    sl = 1.0 if (jj == 1 or jj == 2) else -1.0
    sw = 1.0 if jj >= 2 else -1.0
    if j >= 4:
        return q0 + sl * ol0 + sw * ow0 + h0, q1 + sl * ol1 + sw * ow1 + h1, q2 + sl * ol2 + sw * ow2 + h2
    return q0 + sl * ol0 + sw * ow0, q1 + sl * ol1 + sw * ow1, q2 + sl * ol2 + sw * ow2


@nb.njit(**_INL)
def _heading(vx, vy):
    """``(cos, sin)`` of the course of the velocity (vx, vy) m/s as ``v / |v|`` (no angle): ``(1, 0)`` standing
    (the course ``atan2(0, 0) = 0``), NaN for a NaN velocity."""
    s = math.hypot(vx, vy)
    if s == 0.0:
        return 1.0, 0.0
    return vx / s, vy / s


@nb.njit(**_INL)
def _offset(prm, R, x, y):
    """The camera-frame vector (m) from the camera to the ground point at (x, y) (m, frame W), ``R^T (x - X_m,
    y - Y_m, z_ground(x, y) - h_m)``."""
    r0, r1 = x - prm[P.XM], y - prm[P.YM]
    r2 = prm[P.GDZ] + prm[P.GSX] * r0 + prm[P.GSY] * r1 - prm[P.HM]
    return (R[0, 0] * r0 + R[1, 0] * r1 + R[2, 0] * r2, R[0, 1] * r0 + R[1, 1] * r1 + R[2, 1] * r2,
            R[0, 2] * r0 + R[1, 2] * r1 + R[2, 2] * r2)


@nb.njit(**_INL)
def _render(prm, dom, has_dist, k, q, ol, ow, oh, d0, d1, d2):
    """The bottom-centre pixel ``((u_min + u_max) / 2, v_max)`` (px) of the box around the eight projected
    corners ``q +- ol +- ow (+ oh)`` (camera frame, m: ``q`` the base's centre, ``ol``, ``ow`` the half-length and
    half-width vectors, ``oh`` the height), its rate (px/s) when every corner moves at camera-frame (d0, d1, d2)
    m/s (the extreme corners held, the first on a tie), whether every corner projects (in front, finite, inside
    the lens's domain), and the undistorted normalised point ``(x, y)`` of the bottom-centre pixel's corners
    (a start for the lens's inversion)."""
    nan = math.nan
    fx, fy, sk, pcx, pcy = prm[P.FX], prm[P.FY], prm[P.SKEW], prm[P.CX], prm[P.CY]
    umin, umax, vmax = math.inf, -math.inf, -math.inf
    xa, ya, za, xb, yb, zb, xc, yc, zc = nan, nan, nan, nan, nan, nan, nan, nan, nan
    ok = True
    for j in range(8):   # (unrolled: the corner's signs are constants)
        p0, p1, p2 = _corner(q[0], q[1], q[2], ol[0], ol[1], ol[2], ow[0], ow[1], ow[2], oh[0], oh[1], oh[2], j)
        iz = 1.0 / p2
        xn, yn = p0 * iz, p1 * iz
        ok = ok & (p2 > 0.0) & math.isfinite(xn) & math.isfinite(yn)
        xd, yd = xn, yn
        if has_dist:
            ok = ok & core.in_domain_undistorted(dom, xn, yn)
            xd, yd = core.distort_point(xn, yn, k)
        u = fx * xd + sk * yd + pcx
        v = fy * yd + pcy
        if u < umin:
            umin, xa, ya, za = u, xn, yn, iz
        if u > umax:
            umax, xb, yb, zb = u, xn, yn, iz
        if v > vmax:
            vmax, xc, yc, zc = v, xn, yn, iz
    if not ok:
        return nan, nan, nan, nan, False, nan, nan
    ra = _pixel_rate(prm, k, has_dist, xa, ya, za, d0, d1, d2)
    rb = _pixel_rate(prm, k, has_dist, xb, yb, zb, d0, d1, d2)
    rc = _pixel_rate(prm, k, has_dist, xc, yc, zc, d0, d1, d2)
    return 0.5 * (umin + umax), vmax, 0.5 * ra[0] + 0.5 * rb[0], rc[1], True, 0.5 * (xa + xb), yc


@nb.njit(**_INL)
def _ground(prm, R, dom, has_dist, k, ifx, ify, u, v, du, dv, x0, y0):
    """The ground point (x, y) (m, frame W) of pixel (u, v), its rate (m/s) for a pixel moving at (du, dv) px/s,
    and whether it has one (the ray meets the ground plane in front of the camera; a distorting lens inverts
    there, its Newton steps started from the undistorted normalised point (x0, y0) when that is in the lens's
    domain: the same root to rounding from any start, ``core.undistort_point``); ``ifx``, ``ify``: ``1 / f_x``,
    ``1 / f_y`` (1/px, computed once per call: a division per node less)."""
    nan = math.nan
    if not (math.isfinite(u) and math.isfinite(v)):
        return nan, nan, nan, nan, False
    yd = (v - prm[P.CY]) * ify
    xd = (u - prm[P.CX] - prm[P.SKEW] * yd) * ifx
    dyd = dv * ify
    dxd = (du - prm[P.SKEW] * dyd) * ifx
    if has_dist:
        ok, x, y, m00, m01, m10, m11 = core.undistort_point(dom, k, xd, yd, x0, y0)
        if not ok:
            return nan, nan, nan, nan, False
        dx, dy = m00 * dxd + m01 * dyd, m10 * dxd + m11 * dyd
    else:
        x, y, dx, dy = xd, yd, dxd, dyd
    r0 = R[0, 0] * x + R[0, 1] * y + R[0, 2]
    r1 = R[1, 0] * x + R[1, 1] * y + R[1, 2]
    r2 = R[2, 0] * x + R[2, 1] * y + R[2, 2]
    e0, e1, e2 = R[0, 0] * dx + R[0, 1] * dy, R[1, 0] * dx + R[1, 1] * dy, R[2, 0] * dx + R[2, 1] * dy
    num = prm[P.GDZ] - prm[P.HM]
    den = r2 - prm[P.GSX] * r0 - prm[P.GSY] * r1
    iden = 1.0 / den
    lam = num * iden
    if not (den < 0.0 and num < 0.0 and math.isfinite(lam)):
        return nan, nan, nan, nan, False
    dlam = -lam * (e2 - prm[P.GSX] * e0 - prm[P.GSY] * e1) * iden
    return prm[P.XM] + lam * r0, prm[P.YM] + lam * r1, dlam * r0 + lam * e0, dlam * r1 + lam * e1, True


@nb.njit(**_INL)
def _contact(prm, R, dom, has_dist, k, ifx, ify, q, ol, ow, oh, d0, d1, d2):
    """The back-projected bottom-centre contact (x, y) (m) of the box ``q +- ol +- ow (+ oh)`` (:func:`_render`),
    its rate (m/s) when the box moves at camera-frame (d0, d1, d2) m/s, and whether it exists."""
    u, v, du, dv, ok, x0, y0 = _render(prm, dom, has_dist, k, q, ol, ow, oh, d0, d1, d2)
    if not ok:
        return math.nan, math.nan, math.nan, math.nan, False
    return _ground(prm, R, dom, has_dist, k, ifx, ify, u, v, du, dv, x0, y0)


@nb.njit(**_INL)
def _size(size_mean, size_sigma, nodes, i, q, a):
    """Size ``a`` of object ``i``'s node ``q``: ``mean + node * sigma`` clipped below at :data:`MIN_SIZE_M` (NaN
    stays NaN; scalars only: a view of a row would cost a reference count per node)."""
    s = size_mean[i, a] + nodes[q, a] * size_sigma[i, a]
    return MIN_SIZE_M if s < MIN_SIZE_M else s


@nb.njit(**_INL)
def _moments(prm, R, dom, has_dist, xy, v, size_mean, size_sigma, nodes, mean_out, second_out):
    """:func:`slide_moments`' loop (``has_dist`` a constant in each compiled entry).  Per object the course's
    camera-frame half-length and half-width unit vectors ``a``, ``b`` and the height's ``R^T e_z`` are computed
    once: a node's box is ``q +- L a +- W b (+ H e)``."""
    k = prm[5:13]
    e = (R[2, 0], R[2, 1], R[2, 2])
    ifx, ify = 1.0 / prm[P.FX], 1.0 / prm[P.FY]
    for i in range(xy.shape[0]):
        vx, vy = v[i, 0], v[i, 1]
        cs, sn = _heading(vx, vy)
        vz = prm[P.GSX] * vx + prm[P.GSY] * vy
        d0 = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz     # the box's camera-frame velocity
        d1 = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
        d2 = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
        a = (0.5 * (R[0, 0] * cs + R[1, 0] * sn), 0.5 * (R[0, 1] * cs + R[1, 1] * sn),
             0.5 * (R[0, 2] * cs + R[1, 2] * sn))
        b = (0.5 * (R[1, 0] * cs - R[0, 0] * sn), 0.5 * (R[1, 1] * cs - R[0, 1] * sn),
             0.5 * (R[1, 2] * cs - R[0, 2] * sn))
        L, W, H = size_mean[i, 0], size_mean[i, 1], size_mean[i, 2]
        g0x, g0y = _contact(prm, R, dom, has_dist, k, ifx, ify, _offset(prm, R, xy[i, 0], xy[i, 1]),
                            (L * a[0], L * a[1], L * a[2]), (W * b[0], W * b[1], W * b[2]),
                            (H * e[0], H * e[1], H * e[2]), d0, d1, d2)[:2]
        # the centre whose contact is xy (one step), its camera-frame vector
        q = _offset(prm, R, 2.0 * xy[i, 0] - g0x, 2.0 * xy[i, 1] - g0y)
        cnt, s0, s1, m00, m01, m11 = 0, 0.0, 0.0, 0.0, 0.0, 0.0
        for n in range(nodes.shape[0]):
            L = _size(size_mean, size_sigma, nodes, i, n, 0)
            W = _size(size_mean, size_sigma, nodes, i, n, 1)
            H = _size(size_mean, size_sigma, nodes, i, n, 2)
            _, _, dgx, dgy, ok = _contact(prm, R, dom, has_dist, k, ifx, ify, q, (L * a[0], L * a[1], L * a[2]),
                                          (W * b[0], W * b[1], W * b[2]), (H * e[0], H * e[1], H * e[2]),
                                          d0, d1, d2)
            ux, uy = dgx - vx, dgy - vy
            if ok and math.isfinite(ux) and math.isfinite(uy):
                cnt += 1
                s0, s1 = s0 + ux, s1 + uy
                m00, m01, m11 = m00 + ux * ux, m01 + ux * uy, m11 + uy * uy
        w = 1.0 / cnt if cnt else math.nan     # (NaN where no node renders)
        mean_out[i, 0], mean_out[i, 1] = s0 * w, s1 * w
        second_out[i, 0, 0], second_out[i, 1, 1] = m00 * w, m11 * w
        second_out[i, 0, 1] = second_out[i, 1, 0] = m01 * w


@nb.njit(**_JIT)
def _moments_pinhole(prm, R, dom, xy, v, size_mean, size_sigma, nodes, mean_out, second_out):
    """:func:`_moments` of a lens without distortion (the lens code compiled out: 0.6 x the time)."""
    _moments(prm, R, dom, False, xy, v, size_mean, size_sigma, nodes, mean_out, second_out)


@nb.njit(**_JIT)
def _moments_lens(prm, R, dom, xy, v, size_mean, size_sigma, nodes, mean_out, second_out):
    """:func:`_moments` of a distorting lens."""
    _moments(prm, R, dom, True, xy, v, size_mean, size_sigma, nodes, mean_out, second_out)


#: the compiled entries of :func:`slide_moments` by ``has_dist``, each called with its arguments less ``has_dist``:
#: a caller on a per-frame path looks its camera's entry up once and calls it itself (no Python frame of this
#: layer per frame, ``tracking/contact_slide.py``; ``bench/frame_walk.py`` counts them)
MOMENTS_KERNELS = {False: _moments_pinhole, True: _moments_lens}


def slide_moments(prm, R, dom, has_dist, xy, v, size_mean, size_sigma, nodes, mean_out, second_out) -> None:
    """The slide's mean and second moment over the size nodes of every tracked contact.

    Parameters
    ----------
    prm (22,), R (3, 3), dom (packed lens domain), has_dist (bool): the camera
    xy : (n, 2)            tracked contacts, frame W, m
    v : (n, 2)             their velocities, m/s (the yaw: their course)
    size_mean, size_sigma : (n, 3)   the class's size prior (length, width, height), m
    nodes : (K, 3)         the size nodes in sigmas (``contact_slide.SIZE_NODES``), weight 1/K each

    Outputs (filled): ``mean_out`` (n, 2) m/s and ``second_out`` (n, 2, 2) m^2/s^2; NaN where no node renders.
    """
    MOMENTS_KERNELS[bool(has_dist)](prm, R, dom, xy, v, size_mean, size_sigma, nodes, mean_out, second_out)
