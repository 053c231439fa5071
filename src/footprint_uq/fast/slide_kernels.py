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
    t = 1.0 if j >= 4 else 0.0
    return q0 + sl * ol0 + sw * ow0 + t * h0, q1 + sl * ol1 + sw * ow1 + t * h1, q2 + sl * ol2 + sw * ow2 + t * h2


@nb.njit(**_INL)
def _render(prm, R, dom, has_dist, k, cx, cy, L, W, H, cs, sn, d0, d1, d2):
    """The bottom-centre pixel ``((u_min + u_max) / 2, v_max)`` (px) of the box around the eight projected
    corners of the cuboid centred at (cx, cy) (m, frame W; its base on the ground plane at the centre), its rate
    (px/s) when every corner moves at camera-frame (d0, d1, d2) m/s (the extreme corners held, the first on a
    tie), and whether every corner projects (in front, finite, inside the lens's domain)."""
    nan = math.nan
    zg = prm[P.GDZ] + prm[P.GSX] * (cx - prm[P.XM]) + prm[P.GSY] * (cy - prm[P.YM])
    r0, r1, r2 = cx - prm[P.XM], cy - prm[P.YM], zg - prm[P.HM]
    lx, ly, wx, wy = 0.5 * L * cs, 0.5 * L * sn, -0.5 * W * sn, 0.5 * W * cs
    o = (R[0, 0] * r0 + R[1, 0] * r1 + R[2, 0] * r2, R[0, 1] * r0 + R[1, 1] * r1 + R[2, 1] * r2,
         R[0, 2] * r0 + R[1, 2] * r1 + R[2, 2] * r2,
         R[0, 0] * lx + R[1, 0] * ly, R[0, 1] * lx + R[1, 1] * ly, R[0, 2] * lx + R[1, 2] * ly,
         R[0, 0] * wx + R[1, 0] * wy, R[0, 1] * wx + R[1, 1] * wy, R[0, 2] * wx + R[1, 2] * wy,
         H * R[2, 0], H * R[2, 1], H * R[2, 2])
    fx, fy, sk, pcx, pcy = prm[P.FX], prm[P.FY], prm[P.SKEW], prm[P.CX], prm[P.CY]
    umin, umax, vmax = math.inf, -math.inf, -math.inf
    imin, imax, iv = 0, 0, 0
    ok = True
    for j in range(8):
        p0, p1, p2 = _corner(o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8], o[9], o[10], o[11], j)
        iz = 1.0 / p2
        xd, yd = p0 * iz, p1 * iz
        ok = ok and p2 > 0.0 and math.isfinite(xd) and math.isfinite(yd)
        if has_dist:
            ok = ok and core.in_domain_undistorted(dom, xd, yd)
            xd, yd = core.distort_point(xd, yd, k)
        u = fx * xd + sk * yd + pcx
        v = fy * yd + pcy
        if u < umin:
            umin, imin = u, j
        if u > umax:
            umax, imax = u, j
        if v > vmax:
            vmax, iv = v, j
    if not ok:
        return nan, nan, nan, nan, False
    du = 0.0
    for e in range(3):
        p0, p1, p2 = _corner(o[0], o[1], o[2], o[3], o[4], o[5], o[6], o[7], o[8], o[9], o[10], o[11],
                             imin if e == 0 else (imax if e == 1 else iv))
        iz = 1.0 / p2
        r = _pixel_rate(prm, k, has_dist, p0 * iz, p1 * iz, iz, d0, d1, d2)
        if e < 2:
            du += 0.5 * r[0]
        else:
            return 0.5 * (umin + umax), vmax, du, r[1], True
    return nan, nan, nan, nan, False


@nb.njit(**_INL)
def _ground(prm, R, dom, has_dist, k, u, v, du, dv):
    """The ground point (x, y) (m, frame W) of pixel (u, v), its rate (m/s) for a pixel moving at (du, dv) px/s,
    and whether it has one (the ray meets the ground plane in front of the camera; a distorting lens inverts
    there)."""
    nan = math.nan
    if not (math.isfinite(u) and math.isfinite(v)):
        return nan, nan, nan, nan, False
    yd = (v - prm[P.CY]) / prm[P.FY]
    xd = (u - prm[P.CX] - prm[P.SKEW] * yd) / prm[P.FX]
    dyd = dv / prm[P.FY]
    dxd = (du - prm[P.SKEW] * dyd) / prm[P.FX]
    if has_dist:
        ok, x, y, m00, m01, m10, m11 = core.undistort_point(dom, k, xd, yd, xd, yd)
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
    lam = num / den
    if not (den < 0.0 and num < 0.0 and math.isfinite(lam)):
        return nan, nan, nan, nan, False
    dlam = -lam * (e2 - prm[P.GSX] * e0 - prm[P.GSY] * e1) / den
    return prm[P.XM] + lam * r0, prm[P.YM] + lam * r1, dlam * r0 + lam * e0, dlam * r1 + lam * e1, True


@nb.njit(**_INL)
def _contact(prm, R, dom, has_dist, k, cx, cy, L, W, H, cs, sn, d0, d1, d2):
    """The back-projected bottom-centre contact (x, y) (m) of the box centred at (cx, cy), its rate (m/s) when the
    box moves at camera-frame (d0, d1, d2) m/s, and whether it exists."""
    u, v, du, dv, ok = _render(prm, R, dom, has_dist, k, cx, cy, L, W, H, cs, sn, d0, d1, d2)
    if not ok:
        return math.nan, math.nan, math.nan, math.nan, False
    return _ground(prm, R, dom, has_dist, k, u, v, du, dv)


@nb.njit(**_INL)
def _size(size_mean, size_sigma, nodes, i, q, a):
    """Size ``a`` of object ``i``'s node ``q``: ``mean + node * sigma`` clipped below at :data:`MIN_SIZE_M` (NaN
    stays NaN; scalars only: a view of a row would cost a reference count per node)."""
    s = size_mean[i, a] + nodes[q, a] * size_sigma[i, a]
    return MIN_SIZE_M if s < MIN_SIZE_M else s


@nb.njit(**_INL)
def _moments(prm, R, dom, has_dist, xy, v, size_mean, size_sigma, nodes, mean_out, second_out):
    """:func:`slide_moments`' loop (``has_dist`` a constant in each compiled entry)."""
    k = prm[5:13]
    for i in range(xy.shape[0]):
        vx, vy = v[i, 0], v[i, 1]
        yaw = math.atan2(vy, vx)
        cs, sn = math.cos(yaw), math.sin(yaw)
        vz = prm[P.GSX] * vx + prm[P.GSY] * vy
        d0 = R[0, 0] * vx + R[1, 0] * vy + R[2, 0] * vz     # the box's camera-frame velocity
        d1 = R[0, 1] * vx + R[1, 1] * vy + R[2, 1] * vz
        d2 = R[0, 2] * vx + R[1, 2] * vy + R[2, 2] * vz
        g0x, g0y = _contact(prm, R, dom, has_dist, k, xy[i, 0], xy[i, 1], size_mean[i, 0], size_mean[i, 1],
                            size_mean[i, 2], cs, sn, d0, d1, d2)[:2]
        cx, cy = 2.0 * xy[i, 0] - g0x, 2.0 * xy[i, 1] - g0y     # the centre whose contact is xy (one step)
        cnt, s0, s1, m00, m01, m11 = 0, 0.0, 0.0, 0.0, 0.0, 0.0
        for q in range(nodes.shape[0]):
            L = _size(size_mean, size_sigma, nodes, i, q, 0)
            W = _size(size_mean, size_sigma, nodes, i, q, 1)
            H = _size(size_mean, size_sigma, nodes, i, q, 2)
            _, _, dgx, dgy, ok = _contact(prm, R, dom, has_dist, k, cx, cy, L, W, H, cs, sn, d0, d1, d2)
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
