"""The contact model's node solver, compiled: rendered boxes of cuboids and their inverse.

:func:`solve_nodes` is the compiled form of the numpy reference
``footprint_uq.products.contact._solve_nodes_reference`` (same schedule of Newton and chord steps, same
acceptance test, same outputs, to rounding): for every object ``i`` and quadrature node ``k`` (a yaw and a
size) it finds the footprint centre whose rendered box -- the bounding box of the cuboid's eight
projected corners -- has the detected bottom-centre pixel, then the derivatives of that centre and of the
rendered box width with respect to the 22 camera parameters and the bottom-centre pixel
(implicit-function theorem).  Only the three corners that carry the box's left, right and bottom edge are
differentiated (the numpy reference differentiates all eight and selects).

The camera travels as ``prm`` (22,), ``R`` = ``R_W_C`` (3, 3), ``dR`` = its derivatives (3, 3, 3) with
respect to pan, tilt, roll, the packed lens domain ``dom`` and ``has_dist`` (the lens domain is checked
only for a distorting lens, as in :func:`footprint_uq.cameras.general.project`).
"""

from __future__ import annotations

import contextlib
import math

import numba as nb
import numpy as np

from .. import params as P
from . import core

__all__ = ["solve_nodes", "posterior", "threads_for", "CONV_TOL_PX", "STOP_M", "PARALLEL_MIN_NODES"]

_INL = dict(inline="always", cache=True, error_model="numpy", fastmath={"contract"})
_JIT = dict(cache=True, error_model="numpy", fastmath={"contract"}, parallel=True)

#: yaw/size nodes of one call below which the kernels run on one thread (:func:`threads_for`; measured on the
#: loaded 2-core machine, bench/bench_contact.py: 100 objects x 216 nodes took 46 ms on two threads, ~20 ms on one)
PARALLEL_MIN_NODES = 100_000
#: a node is converged when its rendered bottom-centre pixel is within this of the detected one (px)
CONV_TOL_PX = 1e-4
#: a node stops iterating after a step shorter than this (m) in both coordinates: the remaining steps of the
#: reference's fixed count would move its centre by less still (relative ~1e-11 of its position)
STOP_M = 1e-9
_SL = (-1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0, -1.0)   # corner signs along the length
_SW = (-1.0, -1.0, 1.0, 1.0, -1.0, -1.0, 1.0, 1.0)   # ... along the width


@nb.njit(**_INL)
def _corner(prm, cx, cy, L, W, H, cs, sn, j):
    """World corner ``j`` (x, y, z; z from the nominal ground plane) of the box centred at (cx, cy)."""
    dl, dw = 0.5 * L * _SL[j], 0.5 * W * _SW[j]
    x = cx + (cs * dl - sn * dw)
    y = cy + (sn * dl + cs * dw)
    zg = prm[P.GDZ] + prm[P.GSX] * (cx - prm[P.XM]) + prm[P.GSY] * (cy - prm[P.YM])
    return x, y, zg + (H if j >= 4 else 0.0)


@nb.njit(**_INL)
def _cam(prm, R, x, y, z):
    """Camera-frame point ``R^T (X - C)`` and the relative world point."""
    r0, r1, r2 = x - prm[P.XM], y - prm[P.YM], z - prm[P.HM]
    p0 = R[0, 0] * r0 + R[1, 0] * r1 + R[2, 0] * r2
    p1 = R[0, 1] * r0 + R[1, 1] * r1 + R[2, 1] * r2
    p2 = R[0, 2] * r0 + R[1, 2] * r1 + R[2, 2] * r2
    return p0, p1, p2, r0, r1, r2


@nb.njit(**_INL)
def _pix(prm, dom, has_dist, p0, p1, p2):
    """Pixel of a camera-frame point and whether it projects (in front, finite, inside the lens's domain)."""
    if not p2 > 0.0:
        return math.nan, math.nan, False
    xn, yn = p0 / p2, p1 / p2
    if not (math.isfinite(xn) and math.isfinite(yn)):
        return math.nan, math.nan, False
    if has_dist:
        if not core.in_domain_undistorted(dom, xn, yn):
            return math.nan, math.nan, False
        xd, yd = core.distort_point(xn, yn, prm[5:13])
    else:
        xd, yd = xn, yn
    return prm[P.FX] * xd + prm[P.SKEW] * yd + prm[P.CX], prm[P.FY] * yd + prm[P.CY], True


@nb.njit(**_INL)
def _offsets(R, L, W, H, cs, sn):
    """The box's half length, half width and height vectors in the camera frame (9 scalars): a corner is
    ``R^T (c - C) + s_l o_l + s_w o_w + top o_h`` (the rotation of :func:`_corner`, distributed)."""
    lx, ly, wx, wy = 0.5 * L * cs, 0.5 * L * sn, -0.5 * W * sn, 0.5 * W * cs
    return (R[0, 0] * lx + R[1, 0] * ly, R[0, 1] * lx + R[1, 1] * ly, R[0, 2] * lx + R[1, 2] * ly,
            R[0, 0] * wx + R[1, 0] * wy, R[0, 1] * wx + R[1, 1] * wy, R[0, 2] * wx + R[1, 2] * wy,
            R[2, 0] * H, R[2, 1] * H, R[2, 2] * H)


@nb.njit(**_INL)
def _edges(prm, R, dom, has_dist, cx, cy, o):
    """``u_min, u_max, v_max`` of the rendered box, the corners that carry them, and whether all eight
    corners project (first index on ties, like ``numpy.argmin``); ``o``: :func:`_offsets`."""
    zg = prm[P.GDZ] + prm[P.GSX] * (cx - prm[P.XM]) + prm[P.GSY] * (cy - prm[P.YM])
    q0, q1, q2 = _cam(prm, R, cx, cy, zg)[:3]
    umin, umax, vmax = math.inf, -math.inf, -math.inf
    imin, imax, iv = 0, 0, 0
    ok = True
    for j in range(8):
        sl, sw, t = _SL[j], _SW[j], 1.0 if j >= 4 else 0.0
        u, v, good = _pix(prm, dom, has_dist, q0 + sl * o[0] + sw * o[3] + t * o[6],
                          q1 + sl * o[1] + sw * o[4] + t * o[7], q2 + sl * o[2] + sw * o[5] + t * o[8])
        ok = ok and good
        if u < umin:
            umin, imin = u, j
        if u > umax:
            umax, imax = u, j
        if v > vmax:
            vmax, iv = v, j
    return umin, umax, vmax, imin, imax, iv, ok


@nb.njit(**_INL)
def _grad(prm, R, dR, cx, cy, x, y, z, out):
    """d(u, v)/d(c_x, c_y) in ``out[:, 22:24]`` and d(u, v)/d(params) in ``out[:, :22]`` of a corner that
    moves with the footprint centre (its z on the ground plane), as ``general.project`` and the reference."""
    p0, p1, p2, r0, r1, r2 = _cam(prm, R, x, y, z)
    iz = 1.0 / p2
    xn, yn = p0 * iz, p1 * iz
    k = prm[5:13]
    xd, yd, j00, j01, j10, j11, rad, den = core.distort_jac(xn, yn, k)
    fx, fy, sk = prm[P.FX], prm[P.FY], prm[P.SKEW]
    a00, a01, a10, a11 = fx * j00 + sk * j10, fx * j01 + sk * j11, fy * j10, fy * j11   # duv/dxn
    q00, q01, q02 = a00 * iz, a01 * iz, -(a00 * xn + a01 * yn) * iz   # duv/d(camera-frame point)
    q10, q11, q12 = a10 * iz, a11 * iz, -(a10 * xn + a11 * yn) * iz
    out[:, :] = 0.0
    out[0, P.FX], out[0, P.CX], out[0, P.SKEW] = xd, 1.0, yd
    out[1, P.FY], out[1, P.CY] = yd, 1.0
    r2n, num = xn * xn + yn * yn, rad * den
    r4, r6 = r2n * r2n, r2n * r2n * r2n
    dr = (r2n / den, r4 / den, 0.0, 0.0, r6 / den, -num * r2n / den**2, -num * r4 / den**2, -num * r6 / den**2)
    for i in range(8):
        dxk, dyk = xn * dr[i], yn * dr[i]
        if i == 2:
            dxk, dyk = 2.0 * xn * yn, r2n + 2.0 * yn * yn
        elif i == 3:
            dxk, dyk = r2n + 2.0 * xn * xn, 2.0 * xn * yn
        out[0, 5 + i] = fx * dxk + sk * dyk
        out[1, 5 + i] = fy * dyk
    gsx, gsy = prm[P.GSX], prm[P.GSY]
    for a in range(2):
        e0, e1, e2 = (q00, q01, q02) if a == 0 else (q10, q11, q12)
        d0 = e0 * R[0, 0] + e1 * R[0, 1] + e2 * R[0, 2]   # duv/dxyz
        d1 = e0 * R[1, 0] + e1 * R[1, 1] + e2 * R[1, 2]
        d2 = e0 * R[2, 0] + e1 * R[2, 1] + e2 * R[2, 2]
        out[a, 22], out[a, 23] = d0 + d2 * gsx, d1 + d2 * gsy
        out[a, P.XM], out[a, P.YM], out[a, P.HM] = -d0 - d2 * gsx, -d1 - d2 * gsy, -d2
        out[a, P.GDZ] = d2
        out[a, P.GSX], out[a, P.GSY] = d2 * (cx - prm[P.XM]), d2 * (cy - prm[P.YM])
        for g in range(3):
            out[a, P.PAN + g] = (e0 * (dR[g, 0, 0] * r0 + dR[g, 1, 0] * r1 + dR[g, 2, 0] * r2)
                                 + e1 * (dR[g, 0, 1] * r0 + dR[g, 1, 1] * r1 + dR[g, 2, 1] * r2)
                                 + e2 * (dR[g, 0, 2] * r0 + dR[g, 1, 2] * r1 + dR[g, 2, 2] * r2))


@nb.njit(**_INL)
def _dc(prm, R, cx, cy, L, W, H, cs, sn, j, a):
    """Row ``a`` (0: u, 1: v) of d(u, v)/d(c_x, c_y) of corner ``j`` (the Newton steps' part of :func:`_grad`)."""
    x, y, z = _corner(prm, cx, cy, L, W, H, cs, sn, j)
    p0, p1, p2 = _cam(prm, R, x, y, z)[:3]
    iz = 1.0 / p2
    xn, yn = p0 * iz, p1 * iz
    j00, j01, j10, j11 = core.distort_jac(xn, yn, prm[5:13])[2:6]
    if a == 0:
        b0, b1 = prm[P.FX] * j00 + prm[P.SKEW] * j10, prm[P.FX] * j01 + prm[P.SKEW] * j11
    else:
        b0, b1 = prm[P.FY] * j10, prm[P.FY] * j11
    e0, e1, e2 = b0 * iz, b1 * iz, -(b0 * xn + b1 * yn) * iz
    d0 = e0 * R[0, 0] + e1 * R[0, 1] + e2 * R[0, 2]
    d1 = e0 * R[1, 0] + e1 * R[1, 1] + e2 * R[1, 2]
    d2 = e0 * R[2, 0] + e1 * R[2, 1] + e2 * R[2, 2]
    return d0 + d2 * prm[P.GSX], d1 + d2 * prm[P.GSY]


@nb.njit(**_INL)
def _grads(prm, R, dR, cx, cy, L, W, H, cs, sn, imin, imax, iv, g):
    """:func:`_grad` of the corners carrying u_min, u_max and v_max into ``g[0]``, ``g[1]``, ``g[2]``."""
    for q in range(3):
        jj = imin if q == 0 else (imax if q == 1 else iv)
        x, y, z = _corner(prm, cx, cy, L, W, H, cs, sn, jj)
        _grad(prm, R, dR, cx, cy, x, y, z, g[q])


@nb.njit(**_INL)
def _newton(prm, R, dR, dom, has_dist, bu, bv, cx, cy, L, W, H, cs, sn, n_steps, g):
    """Newton's method for one node, the Jacobian refreshed every third step (chord steps in between),
    as the reference; ``g`` (3, 2, 24) is scratch.  Returns the centre."""
    j00, j01, j10, j11 = 1.0, 0.0, 0.0, 1.0
    o = _offsets(R, L, W, H, cs, sn)
    for it in range(n_steps):
        umin, umax, vmax, imin, imax, iv, ok = _edges(prm, R, dom, has_dist, cx, cy, o)
        if it % 3 == 0:
            j00, j01, j10, j11 = 1.0, 0.0, 0.0, 1.0
            if ok:
                a00, a01 = _dc(prm, R, cx, cy, L, W, H, cs, sn, imin, 0)
                b00, b01 = _dc(prm, R, cx, cy, L, W, H, cs, sn, imax, 0)
                a00, a01 = 0.5 * (a00 + b00), 0.5 * (a01 + b01)
                a10, a11 = _dc(prm, R, cx, cy, L, W, H, cs, sn, iv, 1)
                if math.isfinite(a00) and math.isfinite(a01) and math.isfinite(a10) and math.isfinite(a11):
                    j00, j01, j10, j11 = a00, a01, a10, a11
        if not ok:
            continue
        r0, r1 = 0.5 * (umin + umax) - bu, vmax - bv
        det = j00 * j11 - j01 * j10
        s0, s1 = (j11 * r0 - j01 * r1) / det, (j00 * r1 - j10 * r0) / det
        if math.isfinite(s0) and math.isfinite(s1):
            cx, cy = cx - s0, cy - s1
            if abs(s0) < STOP_M and abs(s1) < STOP_M:
                break  # the convergence mask: the remaining steps would move the centre by less still
    return cx, cy


@nb.njit(**_INL)
def _node_out(prm, R, dR, dom, has_dist, bu, bv, cx, cy, L, W, H, cs, sn, g, dc, dw):
    """The converged node: its derivatives ``dc`` (2, 24) (params, then the bottom-centre pixel) and the
    box width's ``dw`` (24,); returns (width, converged, all corners project)."""
    o = _offsets(R, L, W, H, cs, sn)
    umin, umax, vmax, imin, imax, iv, ok = _edges(prm, R, dom, has_dist, cx, cy, o)
    if not ok:
        dc[:, :] = math.nan
        dw[:] = math.nan
        return math.nan, False, False
    _grads(prm, R, dR, cx, cy, L, W, H, cs, sn, imin, imax, iv, g)
    a00, a01 = 0.5 * (g[0, 0, 22] + g[1, 0, 22]), 0.5 * (g[0, 0, 23] + g[1, 0, 23])
    a10, a11 = g[2, 1, 22], g[2, 1, 23]
    det = a00 * a11 - a01 * a10
    good = math.isfinite(det) and abs(det) > 0.0
    if not good:
        a00, a01, a10, a11, det = 1.0, 0.0, 0.0, 1.0, 1.0
    i00, i01, i10, i11 = a11 / det, -a01 / det, -a10 / det, a00 / det
    conv = good and max(abs(0.5 * (umin + umax) - bu), abs(vmax - bv)) < CONV_TOL_PX
    for m in range(22):
        f0 = 0.5 * (g[0, 0, m] + g[1, 0, m])
        f1 = g[2, 1, m]
        dc[0, m] = -(i00 * f0 + i01 * f1)
        dc[1, m] = -(i10 * f0 + i11 * f1)
    dc[0, 22], dc[0, 23], dc[1, 22], dc[1, 23] = i00, i01, i10, i11
    e0, e1 = g[1, 0, 22] - g[0, 0, 22], g[1, 0, 23] - g[0, 0, 23]    # d(width)/dc
    for m in range(24):
        dw[m] = (g[1, 0, m] - g[0, 0, m] if m < 22 else 0.0) + e0 * dc[0, m] + e1 * dc[1, m]
    return umax - umin, conv, True


@nb.njit(**_JIT)
def solve_nodes(prm, R, dR, dom, has_dist, b_px, c_start, sizes, yaw, n_steps, c, dc, w, dw, conv, ok):
    """Every node of every object, objects in parallel.

    Parameters
    ----------
    prm (22,), R (3, 3), dR (3, 3, 3), dom (packed lens domain), has_dist (bool): the camera
    b_px : (n, 2) detected bottom-centre pixels
    c_start : (n, K, 2) Newton's start per node (world, metres)
    sizes : (n, K, 3) length, width, height (m); yaw : (n, K) radians
    n_steps : Newton / chord steps before the final evaluation

    Outputs (filled): ``c`` (n, K, 2), ``dc`` (n, K, 2, 24), ``w`` (n, K) rendered box width (px),
    ``dw`` (n, K, 24), ``conv`` and ``ok`` (n, K) bool (converged; every corner projects).
    """
    n, K = yaw.shape
    for i in nb.prange(n):
        g = np.empty((3, 2, 24))
        bu, bv = b_px[i, 0], b_px[i, 1]
        for k in range(K):
            L, W, H = sizes[i, k, 0], sizes[i, k, 1], sizes[i, k, 2]
            cs, sn = math.cos(yaw[i, k]), math.sin(yaw[i, k])
            cx, cy = _newton(prm, R, dR, dom, has_dist, bu, bv, c_start[i, k, 0], c_start[i, k, 1],
                             L, W, H, cs, sn, n_steps, g)
            c[i, k, 0], c[i, k, 1] = cx, cy
            w[i, k], conv[i, k], ok[i, k] = _node_out(prm, R, dR, dom, has_dist, bu, bv, cx, cy, L, W, H, cs, sn,
                                                      g, dc[i, k], dw[i, k])


@nb.njit(**_INL)
def _yaw_node(c, dc, z, dz, w_obs, r_w, mu, dmu, Pj, dlogL):
    """One yaw node's 6 size points conditioned on the observed width (a Kalman update), forward-mode
    derivatives through it; fills ``mu`` (2,), ``dmu`` (2, M), ``Pj`` (2, 2), ``dlogL`` (M,) and returns
    ``(innovation, Czz, -0.5 innov^2 / Czz - 0.5 log Czz)`` (the reference's ``_posterior``, one node)."""
    M = dz.shape[1]
    cb0, cb1, zb = 0.0, 0.0, 0.0
    for s in range(6):
        cb0 += c[s, 0]
        cb1 += c[s, 1]
        zb += z[s]
    cb0, cb1, zb = cb0 / 6, cb1 / 6, zb / 6
    ccz0, ccz1, czz, c00, c01, c11 = 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    for s in range(6):
        e0, e1, ez = c[s, 0] - cb0, c[s, 1] - cb1, z[s] - zb
        ccz0 += e0 * ez
        ccz1 += e1 * ez
        czz += ez * ez
        c00 += e0 * e0
        c01 += e0 * e1
        c11 += e1 * e1
    ccz0, ccz1, czz = ccz0 / 6, ccz1 / 6, czz / 6 + r_w
    g0, g1 = ccz0 / czz, ccz1 / czz
    innov = w_obs - zb
    mu[0], mu[1] = cb0 + g0 * innov, cb1 + g1 * innov
    Pj[0, 0], Pj[0, 1] = c00 / 6 - g0 * ccz0, c01 / 6 - g0 * ccz1
    Pj[1, 0], Pj[1, 1] = c01 / 6 - g1 * ccz0, c11 / 6 - g1 * ccz1
    ez6 = np.empty(6)
    for s in range(6):
        ez6[s] = z[s] - zb
    for m in range(M):
        dcb0, dcb1, dzb = 0.0, 0.0, 0.0
        for s in range(6):
            dcb0 += dc[s, 0, m]
            dcb1 += dc[s, 1, m]
            dzb += dz[s, m]
        dcb0, dcb1, dzb = dcb0 / 6, dcb1 / 6, dzb / 6
        dccz0, dccz1, dczz = 0.0, 0.0, 0.0
        for s in range(6):
            dez = dz[s, m] - dzb
            dccz0 += (dc[s, 0, m] - dcb0) * ez6[s] + (c[s, 0] - cb0) * dez
            dccz1 += (dc[s, 1, m] - dcb1) * ez6[s] + (c[s, 1] - cb1) * dez
            dczz += ez6[s] * dez
        dccz0, dccz1, dczz = dccz0 / 6, dccz1 / 6, 2 * dczz / 6
        dmu[0, m] = dcb0 + (dccz0 - g0 * dczz) / czz * innov - g0 * dzb
        dmu[1, m] = dcb1 + (dccz1 - g1 * dczz) / czz * innov - g1 * dzb
        dlogL[m] = (innov / czz) * dzb + (0.5 * innov**2 / czz**2 - 0.5 / czz) * dczz
    return -0.5 * innov**2 / czz - 0.5 * math.log(czz)


@nb.njit(**_JIT)
def posterior(c, dc, w, dw, ny, w_obs, r_w, log_prior, x, dx, cov):
    """The mixture over yaw nodes of the width-conditioned size points, objects in parallel.

    ``c`` (n, ny * 6, 2), ``dc`` (n, ny * 6, 2, M), ``w`` (n, ny * 6), ``dw`` (n, ny * 6, M) (yaw-major
    nodes, :func:`solve_nodes`), ``w_obs`` and ``r_w`` (n,) the observed width and its variance (px, px^2),
    ``log_prior`` (ny,); fills the centre ``x`` (n, 2), its derivatives ``dx`` (n, 2, M) and the contact
    covariance ``cov`` (n, 2, 2).
    """
    n, M = c.shape[0], dw.shape[2]
    for i in nb.prange(n):
        mu, dmu, Pj = np.empty((ny, 2)), np.empty((ny, 2, M)), np.empty((ny, 2, 2))
        logL, dlogL, pi = np.empty(ny), np.empty((ny, M)), np.empty(ny)
        for j in range(ny):
            sl = slice(6 * j, 6 * j + 6)
            logL[j] = _yaw_node(c[i, sl], dc[i, sl], w[i, sl], dw[i, sl], w_obs[i], r_w[i], mu[j], dmu[j], Pj[j],
                                dlogL[j]) + log_prior[j]
        top = logL.max()
        tot = 0.0
        for j in range(ny):
            pi[j] = math.exp(logL[j] - top)
            tot += pi[j]
        pi /= tot
        x0, x1 = 0.0, 0.0
        for j in range(ny):
            x0 += pi[j] * mu[j, 0]
            x1 += pi[j] * mu[j, 1]
        x[i, 0], x[i, 1] = x0, x1
        for m in range(M):
            mbar = 0.0
            for j in range(ny):
                mbar += pi[j] * dlogL[j, m]
            s0, s1 = 0.0, 0.0
            for j in range(ny):
                dpi = pi[j] * (dlogL[j, m] - mbar)
                s0 += dpi * mu[j, 0] + pi[j] * dmu[j, 0, m]
                s1 += dpi * mu[j, 1] + pi[j] * dmu[j, 1, m]
            dx[i, 0, m], dx[i, 1, m] = s0, s1
        v00, v01, v11 = 0.0, 0.0, 0.0
        for j in range(ny):
            d0, d1 = mu[j, 0] - x0, mu[j, 1] - x1
            v00 += pi[j] * (Pj[j, 0, 0] + d0 * d0)
            v01 += pi[j] * (Pj[j, 0, 1] + d0 * d1)
            v11 += pi[j] * (Pj[j, 1, 1] + d1 * d1)
        cov[i, 0, 0], cov[i, 0, 1], cov[i, 1, 0], cov[i, 1, 1] = v00, v01, v01, v11


@contextlib.contextmanager
def threads_for(nodes: int):
    """One numba thread (this thread's setting, restored after) below :data:`PARALLEL_MIN_NODES` nodes: a
    parallel launch waits for a second core, ~20 ms on a loaded machine, more than a small frame costs."""
    before = nb.get_num_threads()
    if nodes >= PARALLEL_MIN_NODES or before == 1:
        yield
        return
    nb.set_num_threads(1)
    try:
        yield
    finally:
        nb.set_num_threads(before)
