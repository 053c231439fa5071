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

Two entries, by lens (:data:`MOMENTS_KERNELS`), both *columnar*: per block of 64 objects, each step -- the inputs
copied in, the course and the mean box, one render (the eight corners written out, the bounding box's extreme
corners kept by selects, their pixel rates), the centre's fixed-point step, per node the box, one render and the
moments' update -- is one pass over the block's objects on contiguous columns of a scratch array, branch-free
(flags as 1.0 / 0.0, NaN where nothing renders carried as object by object), with the camera's constants as
scalars: LLVM vectorises each pass (8 objects per AVX-512 instruction; ``tests/test_contact_slide.py`` checks that
the render's pass uses vector instructions).  A pinhole (``_moments_pinhole``, the common camera): ~5 us per 100
objects.  A distorting lens (``_moments_lens``; object by object until 2026-11-29, ~130 us per 100 objects): the
render's pass distorts the corners (OpenCV's model, a division each) and takes the lens's valid domain as its
outer radius, flagging the objects with a corner in the ring between the domain's inner and outer radii, where
its table decides -- those few are rendered again object by object (:func:`_render`, exact); the bottom-centre
pixels are undistorted together on the block's columns by ``core.undistort_vec`` (Newton steps for all of them at
once, started from the render's undistorted corners; a point it leaves goes to ``core.undistort_point``: the same
validity, the root to the solver's tolerance).  Same steps, same operations in the same order as the numpy
reference, so the same numbers to rounding (the course as ``v / |v|`` with ``v`` scaled by its larger component,
branch-free: ``hypot`` is a library call that would keep the pass scalar).

:data:`ADDED_KERNELS` (``ContactSlide.apply``'s one call per frame): the same moments, the second added to the
tracker's velocity covariance in the same call (:func:`slide_added`).

The camera travels as ``prm`` (22,), ``R`` = ``R_W_C`` (3, 3), the packed lens domain ``dom`` and ``has_dist``
(the lens domain is checked, and the lens inverted, only for a distorting lens, as in
:func:`footprint_uq.cameras.general.project` / ``backproject``).  :func:`_render` (one object, either lens) is the
object-by-object render the lens's flagged objects take and the tests hold the columnar passes to.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from .. import params as P
from . import core

__all__ = ["slide_moments", "slide_added", "MOMENTS_KERNELS", "ADDED_KERNELS", "MIN_SIZE_M"]

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
    (the course ``atan2(0, 0) = 0``), NaN for a NaN velocity.  Branch-free and without ``hypot`` (a library
    call, which would keep the object loop scalar): ``v`` is scaled by its larger component first (no overflow
    or underflow of ``|v|``)."""
    ax, ay = abs(vx), abs(vy)
    m = ax if ax > ay else ay          # (NaN when vy is; vx NaN: NaN below)
    t, w = vx / m, vy / m
    s = math.sqrt(t * t + w * w)
    standing = m == 0.0
    return 1.0 if standing else t / s, 0.0 if standing else w / s


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


# -- the pinhole entry, columnar (module doc): per block of objects, each step a pass over the block's objects on
# contiguous columns of one scratch array, branch-free, the loop over the objects innermost: LLVM vectorises it

#: objects per block: the scratch (_NCOL columns of _BLOCK float64, 21 kB) stays in the L1 cache
_BLOCK = 64
#: a block's passes run over a whole number of vectors of this many objects (8 float64 in AVX-512; the lanes past
#: the block's last object repeat its first, their results are not stored): no scalar remainder loop
_LANES = 8
# The scratch's columns: column k of the block is S[k * _BLOCK : (k + 1) * _BLOCK].  Constant offsets, so LLVM
# sees that the columns do not overlap and needs no run-time check of the pointers.
_X, _Y, _VX, _VY, _SM0, _SM1, _SM2, _SG0, _SG1, _SG2 = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9   # the inputs (copied)
_D0, _D1, _D2, _A0, _A1, _A2, _B0, _B1, _B2 = 10, 11, 12, 13, 14, 15, 16, 17, 18      # velocity, course (camera)
_Q0, _Q1, _Q2, _OL0, _OL1, _OL2, _OW0, _OW1, _OW2, _OH0, _OH1, _OH2 = 19, 20, 21, 22, 23, 24, 25, 26, 27, 28, 29, 30
_U, _V, _DU, _DV, _OK = 31, 32, 33, 34, 35                                              # a render's result
_N, _S0, _S1, _M00, _M01, _M11 = 36, 37, 38, 39, 40, 41                                 # the running moments
_NCOL = 42


@nb.njit(**_INL)
def _camera_scalars(prm, R):
    """The pinhole camera as a tuple of 22 scalars: ``fx, fy, skew, cx, cy`` (px), ``1/fx, 1/fy`` (1/px),
    ``X_m, Y_m, ground dz, slope x, slope y, h_m`` and ``R_W_C`` row by row (loaded once per call: an array
    read in a loop could alias the outputs, and LLVM would reload it)."""
    return (prm[P.FX], prm[P.FY], prm[P.SKEW], prm[P.CX], prm[P.CY], 1.0 / prm[P.FX], 1.0 / prm[P.FY],
            prm[P.XM], prm[P.YM], prm[P.GDZ], prm[P.GSX], prm[P.GSY], prm[P.HM],
            R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2], R[2, 0], R[2, 1], R[2, 2])


@nb.njit(**_INL)
def _offset_c(cam, x, y):
    """:func:`_offset` with the camera's scalars (:func:`_camera_scalars`)."""
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = cam[13:22]
    r0, r1 = x - cam[7], y - cam[8]
    r2 = cam[9] + cam[10] * r0 + cam[11] * r1 - cam[12]
    return (r00 * r0 + r10 * r1 + r20 * r2, r01 * r0 + r11 * r1 + r21 * r2, r02 * r0 + r12 * r1 + r22 * r2)


@nb.njit(**_INL)
def _ground_c(cam, u, v, du, dv):
    """:func:`_ground` of a pinhole, branch-free: ``(x, y, dx, dy, ok)`` (m, m/s)."""
    sk, ifx, ify, gsx, gsy = cam[2], cam[5], cam[6], cam[10], cam[11]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = cam[13:22]
    yd = (v - cam[4]) * ify
    xd = (u - cam[3] - sk * yd) * ifx
    dyd = dv * ify
    dxd = (du - sk * dyd) * ifx
    r0 = r00 * xd + r01 * yd + r02
    r1 = r10 * xd + r11 * yd + r12
    r2 = r20 * xd + r21 * yd + r22
    e0, e1, e2 = r00 * dxd + r01 * dyd, r10 * dxd + r11 * dyd, r20 * dxd + r21 * dyd
    num = cam[9] - cam[12]
    den = r2 - gsx * r0 - gsy * r1
    iden = 1.0 / den
    lam = num * iden
    ok = math.isfinite(u) & math.isfinite(v) & (den < 0.0) & (num < 0.0) & math.isfinite(lam)
    dlam = -lam * (e2 - gsx * e0 - gsy * e1) * iden
    return cam[7] + lam * r0, cam[8] + lam * r1, dlam * r0 + lam * e0, dlam * r1 + lam * e1, ok


@nb.njit(**_INL)
def _keep_corner(st, cam, p0, p1, p2):
    """Corner (p0, p1, p2) (camera frame, m) into the running bounding box ``st`` = ``(u_min, x, y, 1/z of its
    corner, u_max, ..., v_max, ..., every corner projects)`` (selects: the first corner kept on a tie, as
    :func:`_render`)."""
    iz = 1.0 / p2
    xn, yn = p0 * iz, p1 * iz
    ok = st[12] & (p2 > 0.0) & math.isfinite(xn) & math.isfinite(yn)
    u = cam[0] * xn + cam[2] * yn + cam[3]
    v = cam[1] * yn + cam[4]
    lo, hi, lw = u < st[0], u > st[4], v > st[8]
    return (u if lo else st[0], xn if lo else st[1], yn if lo else st[2], iz if lo else st[3],
            u if hi else st[4], xn if hi else st[5], yn if hi else st[6], iz if hi else st[7],
            v if lw else st[8], xn if lw else st[9], yn if lw else st[10], iz if lw else st[11], ok)


@nb.njit(**_INL)
def _corner_c(st, cam, S, j, c):
    """Corner ``c`` (:func:`_corner`'s order and signs) of object ``j``'s box (columns _Q, _OL, _OW, _OH) into
    ``st`` (:func:`_keep_corner`)."""
    B = _BLOCK
    p0, p1, p2 = _corner(S[_Q0 * B + j], S[_Q1 * B + j], S[_Q2 * B + j], S[_OL0 * B + j], S[_OL1 * B + j],
                         S[_OL2 * B + j], S[_OW0 * B + j], S[_OW1 * B + j], S[_OW2 * B + j], S[_OH0 * B + j],
                         S[_OH1 * B + j], S[_OH2 * B + j], c)
    return _keep_corner(st, cam, p0, p1, p2)


@nb.njit(**_JIT)
def _render_block(S, cam, n_obj):
    """:func:`_render` of the block's first ``n_obj`` boxes (columns _Q, _OL, _OW, _OH; velocity _D): the
    bottom-centre pixel and its rate into _U, _V, _DU, _DV, whether every corner projects into _OK (1.0 / 0.0).
    One pass over the objects, the eight corners written out (no loop inside it: LLVM vectorises it)."""
    B, nan, inf = _BLOCK, math.nan, math.inf
    fx, fy, sk = cam[0], cam[1], cam[2]
    for j in range(n_obj):
        st = (inf, nan, nan, nan, -inf, nan, nan, nan, -inf, nan, nan, nan, True)
        st = _corner_c(st, cam, S, j, 0)
        st = _corner_c(st, cam, S, j, 1)
        st = _corner_c(st, cam, S, j, 2)
        st = _corner_c(st, cam, S, j, 3)
        st = _corner_c(st, cam, S, j, 4)
        st = _corner_c(st, cam, S, j, 5)
        st = _corner_c(st, cam, S, j, 6)
        st = _corner_c(st, cam, S, j, 7)
        d0, d1, d2 = S[_D0 * B + j], S[_D1 * B + j], S[_D2 * B + j]
        exa, eya = (d0 - st[1] * d2) * st[3], (d1 - st[2] * d2) * st[3]
        exb, eyb = (d0 - st[5] * d2) * st[7], (d1 - st[6] * d2) * st[7]
        eyc = (d1 - st[10] * d2) * st[11]
        S[_U * B + j], S[_V * B + j] = 0.5 * (st[0] + st[4]), st[8]
        S[_DU * B + j] = 0.5 * (fx * exa + sk * eya) + 0.5 * (fx * exb + sk * eyb)
        S[_DV * B + j], S[_OK * B + j] = fy * eyc, 1.0 if st[12] else 0.0


@nb.njit(**_INL)
def _box_columns(S, cam, j, L, W, H):
    """The half-length, half-width and height vectors (camera frame, m) of object ``j``'s box of size (L, W, H)
    m into _OL, _OW, _OH (its course's unit vectors _A, _B and the vertical ``R^T e_z`` scaled)."""
    B = _BLOCK
    S[_OL0 * B + j], S[_OL1 * B + j], S[_OL2 * B + j] = L * S[_A0 * B + j], L * S[_A1 * B + j], L * S[_A2 * B + j]
    S[_OW0 * B + j], S[_OW1 * B + j], S[_OW2 * B + j] = W * S[_B0 * B + j], W * S[_B1 * B + j], W * S[_B2 * B + j]
    S[_OH0 * B + j], S[_OH1 * B + j], S[_OH2 * B + j] = H * cam[19], H * cam[20], H * cam[21]


@nb.njit(**_JIT)
def _block_load(S, xy, v, size_mean, size_sigma, i0, n_obj, n_pass):
    """Objects ``i0 .. i0 + n_obj`` of the call into the block's columns _X, _Y, _VX, _VY, _SM, _SG (a copy: the
    passes after it read the scratch only, contiguous and known not to overlap what they write), and object
    ``i0`` again up to ``n_pass`` (a whole number of vectors: the passes have no scalar remainder; those lanes'
    results are not stored)."""
    B = _BLOCK
    for j in range(n_pass):
        i = i0 + j if j < n_obj else i0
        S[_X * B + j], S[_Y * B + j], S[_VX * B + j], S[_VY * B + j] = xy[i, 0], xy[i, 1], v[i, 0], v[i, 1]
        S[_SM0 * B + j], S[_SM1 * B + j], S[_SM2 * B + j] = size_mean[i, 0], size_mean[i, 1], size_mean[i, 2]
        S[_SG0 * B + j], S[_SG1 * B + j], S[_SG2 * B + j] = size_sigma[i, 0], size_sigma[i, 1], size_sigma[i, 2]


@nb.njit(**_JIT)
def _block_start(S, cam, n_obj):
    """The block's velocity in the camera frame (_D), the course's half-length and half-width unit vectors (_A,
    _B), the mean box (_OL, _OW, _OH) and the camera-frame vector to the contact (_Q); the running moments
    zeroed."""
    B = _BLOCK
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = cam[13:22]
    for j in range(n_obj):
        x, y, vx, vy = S[_X * B + j], S[_Y * B + j], S[_VX * B + j], S[_VY * B + j]
        cs, sn = _heading(vx, vy)
        vz = cam[10] * vx + cam[11] * vy
        S[_D0 * B + j] = r00 * vx + r10 * vy + r20 * vz
        S[_D1 * B + j] = r01 * vx + r11 * vy + r21 * vz
        S[_D2 * B + j] = r02 * vx + r12 * vy + r22 * vz
        S[_A0 * B + j], S[_A1 * B + j] = 0.5 * (r00 * cs + r10 * sn), 0.5 * (r01 * cs + r11 * sn)
        S[_A2 * B + j] = 0.5 * (r02 * cs + r12 * sn)
        S[_B0 * B + j], S[_B1 * B + j] = 0.5 * (r10 * cs - r00 * sn), 0.5 * (r11 * cs - r01 * sn)
        S[_B2 * B + j] = 0.5 * (r12 * cs - r02 * sn)
        _box_columns(S, cam, j, S[_SM0 * B + j], S[_SM1 * B + j], S[_SM2 * B + j])
        S[_Q0 * B + j], S[_Q1 * B + j], S[_Q2 * B + j] = _offset_c(cam, x, y)
        S[_N * B + j] = S[_S0 * B + j] = S[_S1 * B + j] = 0.0
        S[_M00 * B + j] = S[_M01 * B + j] = S[_M11 * B + j] = 0.0


@nb.njit(**_JIT)
def _block_centre(S, cam, n_obj):
    """The centre whose contact is the tracked one (one fixed-point step from the mean box's rendered contact,
    NaN where it does not render): its camera-frame vector into _Q."""
    B = _BLOCK
    for j in range(n_obj):
        gx, gy, _, _, ok = _ground_c(cam, S[_U * B + j], S[_V * B + j], 0.0, 0.0)
        ok = ok & (S[_OK * B + j] != 0.0)
        gx, gy = gx if ok else math.nan, gy if ok else math.nan
        S[_Q0 * B + j], S[_Q1 * B + j], S[_Q2 * B + j] = _offset_c(cam, 2.0 * S[_X * B + j] - gx,
                                                                   2.0 * S[_Y * B + j] - gy)


@nb.njit(**_JIT)
def _block_node(S, cam, n0, n1, n2, n_obj):
    """One size node ``mean + (n0, n1, n2) * sigma`` (clipped below at :data:`MIN_SIZE_M`) of the block: its box
    rendered at the centre, the slide ``u`` where it renders added to the running moments (selects)."""
    B = _BLOCK
    _block_boxes(S, cam, n0, n1, n2, n_obj)
    _render_block(S, cam, n_obj)
    for j in range(n_obj):
        _, _, dgx, dgy, ok = _ground_c(cam, S[_U * B + j], S[_V * B + j], S[_DU * B + j], S[_DV * B + j])
        ux, uy = dgx - S[_VX * B + j], dgy - S[_VY * B + j]
        good = ok & (S[_OK * B + j] != 0.0) & math.isfinite(ux) & math.isfinite(uy)
        ux, uy = ux if good else 0.0, uy if good else 0.0
        S[_N * B + j] += 1.0 if good else 0.0
        S[_S0 * B + j] += ux
        S[_S1 * B + j] += uy
        S[_M00 * B + j] += ux * ux
        S[_M01 * B + j] += ux * uy
        S[_M11 * B + j] += uy * uy


@nb.njit(**_JIT)
def _block_boxes(S, cam, n0, n1, n2, n_obj):
    """The block's boxes of the size node ``mean + (n0, n1, n2) * sigma`` (clipped below at :data:`MIN_SIZE_M`)
    into _OL, _OW, _OH."""
    B = _BLOCK
    for j in range(n_obj):
        _box_columns(S, cam, j, _clip(S[_SM0 * B + j] + n0 * S[_SG0 * B + j]),
                     _clip(S[_SM1 * B + j] + n1 * S[_SG1 * B + j]), _clip(S[_SM2 * B + j] + n2 * S[_SG2 * B + j]))


@nb.njit(**_INL)
def _clip(s):
    """A node's size clipped below at :data:`MIN_SIZE_M` (NaN stays NaN), as :func:`_size`."""
    return MIN_SIZE_M if s < MIN_SIZE_M else s


@nb.njit(**_INL)
def _pinhole_block(S, cam, xy, v, size_mean, size_sigma, nodes, i0, n_obj):
    """The running moments (_N, _S, _M) of objects ``i0 .. i0 + n_obj`` (a block) of a pinhole: the mean box's
    render and the centre, then per node a render and the moments' update, each step a vectorised pass."""
    n_pass = (n_obj + _LANES - 1) // _LANES * _LANES
    _block_load(S, xy, v, size_mean, size_sigma, i0, n_obj, n_pass)
    _block_start(S, cam, n_pass)
    _render_block(S, cam, n_pass)
    _block_centre(S, cam, n_pass)
    for n in range(nodes.shape[0]):
        _block_node(S, cam, nodes[n, 0], nodes[n, 1], nodes[n, 2], n_pass)


@nb.njit(**_INL)
def _store_moments(S, i0, n_obj, mean_out, second_out):
    """The block's mean and second moment (running sums over the count, NaN where no node renders) into rows
    ``i0 ..`` of the outputs."""
    B = _BLOCK
    for j in range(n_obj):
        k = S[_N * B + j]
        w = 1.0 / k if k > 0.0 else math.nan     # (NaN where no node renders)
        mean_out[i0 + j, 0], mean_out[i0 + j, 1] = S[_S0 * B + j] * w, S[_S1 * B + j] * w
        second_out[i0 + j, 0, 0], second_out[i0 + j, 1, 1] = S[_M00 * B + j] * w, S[_M11 * B + j] * w
        second_out[i0 + j, 0, 1] = second_out[i0 + j, 1, 0] = S[_M01 * B + j] * w


@nb.njit(**_INL)
def _store_added(S, xy, v, i0, n_obj, cov_v, cov_out):
    """Rows ``i0 ..`` of ``cov_out = cov_v + E[u u^T]`` for the block's objects (the second moment as
    :func:`_store_moments` forms it, added element by element): NaN where no node renders, except that a term
    without a finite position and velocity is zero (the row's own ``cov_v`` then, plus 0.0)."""
    B = _BLOCK
    for j in range(n_obj):
        i = i0 + j
        k = S[_N * B + j]
        w = 1.0 / k if k > 0.0 else math.nan
        t00, t01, t11 = S[_M00 * B + j] * w, S[_M01 * B + j] * w, S[_M11 * B + j] * w
        if k == 0.0 and not (math.isfinite(xy[i, 0]) and math.isfinite(xy[i, 1]) and math.isfinite(v[i, 0])
                             and math.isfinite(v[i, 1])):
            t00, t01, t11 = 0.0, 0.0, 0.0
        cov_out[i, 0, 0], cov_out[i, 0, 1] = cov_v[i, 0, 0] + t00, cov_v[i, 0, 1] + t01
        cov_out[i, 1, 0], cov_out[i, 1, 1] = cov_v[i, 1, 0] + t01, cov_v[i, 1, 1] + t11


@nb.njit(**_JIT)
def _moments_pinhole(prm, R, dom, xy, v, size_mean, size_sigma, nodes, mean_out, second_out):
    """:func:`_moments` of a lens without distortion, columnar (module doc): per block of objects
    :func:`_pinhole_block` (any number of nodes; ``dom`` unused, as in :func:`_moments` without distortion)."""
    cam = _camera_scalars(prm, R)
    S = np.empty(_NCOL * _BLOCK)
    for i0 in range(0, xy.shape[0], _BLOCK):
        n_obj = min(_BLOCK, xy.shape[0] - i0)
        _pinhole_block(S, cam, xy, v, size_mean, size_sigma, nodes, i0, n_obj)
        _store_moments(S, i0, n_obj, mean_out, second_out)


@nb.njit(**_JIT)
def _added_pinhole(prm, R, dom, xy, v, size_mean, size_sigma, nodes, cov_v, cov_out):
    """:func:`_moments_pinhole`'s second moment added to ``cov_v`` into ``cov_out`` (:func:`_store_added`)."""
    cam = _camera_scalars(prm, R)
    S = np.empty(_NCOL * _BLOCK)
    for i0 in range(0, xy.shape[0], _BLOCK):
        n_obj = min(_BLOCK, xy.shape[0] - i0)
        _pinhole_block(S, cam, xy, v, size_mean, size_sigma, nodes, i0, n_obj)
        _store_added(S, xy, v, i0, n_obj, cov_v, cov_out)


# -- the distorting lens's entry, columnar as the pinhole's: the same blocks and passes; the render's pass distorts
# the corners (vectorised: a division each), the undistortion of the bottom-centre pixels is core.undistort_vec on
# the block's columns (Newton steps for all of them together, the rare point it leaves to undistort_point), and
# the few objects with a corner in the ring where the lens's domain needs its table are rendered again object by
# object (_render, exact)

_X0, _Y0, _DBT = 42, 43, 44                       # the render's undistorted start, an object needing the table
_XD, _YD, _XN, _YN = 45, 46, 47, 48               # the pixel distorted and undistorted (normalised)
_J00, _J01, _J10, _J11, _IDN = 49, 50, 51, 52, 53  # d(x, y)/d(xd, yd) there, 1 / the radial denominator
_NCOL_LENS = 54


@nb.njit(**_INL)
def _keep_corner_lens(st, cam, kt, lim2, in2, p0, p1, p2):
    """:func:`_keep_corner` through the lens (``kt`` its 8 coefficients as scalars): the box's extremes taken
    on the distorted pixel, the corner's undistorted normalised point kept; the lens's domain as the square
    radius below ``lim2`` (``max`` of the domain's inner and outer radii), ``st[13]`` set where a corner lies in
    the ring between them (there the domain's table decides: :func:`_render_doubts`)."""
    iz = 1.0 / p2
    xn, yn = p0 * iz, p1 * iz
    r2 = xn * xn + yn * yn
    ok = st[12] & (p2 > 0.0) & math.isfinite(xn) & math.isfinite(yn) & (r2 < lim2)
    doubt = st[13] | ((not (r2 < in2)) & (r2 < lim2))
    xd, yd = core.distort_point(xn, yn, kt)
    u = cam[0] * xd + cam[2] * yd + cam[3]
    v = cam[1] * yd + cam[4]
    lo, hi, lw = u < st[0], u > st[4], v > st[8]
    return (u if lo else st[0], xn if lo else st[1], yn if lo else st[2], iz if lo else st[3],
            u if hi else st[4], xn if hi else st[5], yn if hi else st[6], iz if hi else st[7],
            v if lw else st[8], xn if lw else st[9], yn if lw else st[10], iz if lw else st[11], ok, doubt)


@nb.njit(**_INL)
def _corner_lens(st, cam, kt, lim2, in2, S, j, c):
    """Corner ``c`` of object ``j``'s box into ``st`` (:func:`_keep_corner_lens`)."""
    B = _BLOCK
    p0, p1, p2 = _corner(S[_Q0 * B + j], S[_Q1 * B + j], S[_Q2 * B + j], S[_OL0 * B + j], S[_OL1 * B + j],
                         S[_OL2 * B + j], S[_OW0 * B + j], S[_OW1 * B + j], S[_OW2 * B + j], S[_OH0 * B + j],
                         S[_OH1 * B + j], S[_OH2 * B + j], c)
    return _keep_corner_lens(st, cam, kt, lim2, in2, p0, p1, p2)


@nb.njit(**_INL)
def _rate_lens(cam, kt, xn, yn, iz, d0, d1, d2):
    """:func:`_pixel_rate` through the lens (px/s)."""
    ex, ey = (d0 - xn * d2) * iz, (d1 - yn * d2) * iz
    j00, j01, j10, j11 = core.distort_jac(xn, yn, kt)[2:6]
    ex, ey = j00 * ex + j01 * ey, j10 * ex + j11 * ey
    return cam[0] * ex + cam[2] * ey, cam[1] * ey


@nb.njit(**_JIT)
def _render_block_lens(S, cam, kt, lim2, in2, n_obj):
    """:func:`_render_block` through the lens: also the undistorted start of the bottom-centre pixel (_X0, _Y0)
    and whether a corner needs the domain's table (_DBT, 1.0 / 0.0).  One pass, branch-free."""
    B, nan, inf = _BLOCK, math.nan, math.inf
    for j in range(n_obj):
        st = (inf, nan, nan, nan, -inf, nan, nan, nan, -inf, nan, nan, nan, True, False)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 0)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 1)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 2)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 3)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 4)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 5)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 6)
        st = _corner_lens(st, cam, kt, lim2, in2, S, j, 7)
        d0, d1, d2 = S[_D0 * B + j], S[_D1 * B + j], S[_D2 * B + j]
        ra = _rate_lens(cam, kt, st[1], st[2], st[3], d0, d1, d2)
        rb = _rate_lens(cam, kt, st[5], st[6], st[7], d0, d1, d2)
        rc = _rate_lens(cam, kt, st[9], st[10], st[11], d0, d1, d2)
        S[_U * B + j], S[_V * B + j] = 0.5 * (st[0] + st[4]), st[8]
        S[_DU * B + j], S[_DV * B + j] = 0.5 * ra[0] + 0.5 * rb[0], rc[1]
        S[_X0 * B + j], S[_Y0 * B + j] = 0.5 * (st[1] + st[5]), st[10]
        S[_OK * B + j], S[_DBT * B + j] = 1.0 if st[12] else 0.0, 1.0 if st[13] else 0.0


@nb.njit(**_JIT)
def _render_doubts(S, prm, dom, k, n_obj):
    """The objects of the block with a corner in the domain's ring (_DBT) rendered again by :func:`_render`
    (the domain's table: exact), their columns overwritten."""
    B = _BLOCK
    for j in range(n_obj):
        if S[_DBT * B + j] == 0.0:
            continue
        u, v, du, dv, ok, x0, y0 = _render(
            prm, dom, True, k, (S[_Q0 * B + j], S[_Q1 * B + j], S[_Q2 * B + j]),
            (S[_OL0 * B + j], S[_OL1 * B + j], S[_OL2 * B + j]), (S[_OW0 * B + j], S[_OW1 * B + j], S[_OW2 * B + j]),
            (S[_OH0 * B + j], S[_OH1 * B + j], S[_OH2 * B + j]), S[_D0 * B + j], S[_D1 * B + j], S[_D2 * B + j])
        S[_U * B + j], S[_V * B + j], S[_DU * B + j], S[_DV * B + j] = u, v, du, dv
        S[_X0 * B + j], S[_Y0 * B + j], S[_OK * B + j] = x0, y0, 1.0 if ok else 0.0


@nb.njit(**_JIT)
def _undistort_block(S, cam, dom, k, okb, n_obj):
    """The rendered bottom-centre pixels (_U, _V) undistorted: their distorted normalised points (_XD, _YD; NaN
    where the box does not render: not iterated), then ``core.undistort_vec`` from the render's start (_X0, _Y0)
    into _XN, _YN, its Jacobian _J and ``okb`` (whether the pixel has a ray)."""
    B = _BLOCK
    sk, ifx, ify = cam[2], cam[5], cam[6]
    for j in range(n_obj):
        good = S[_OK * B + j] != 0.0
        yd = (S[_V * B + j] - cam[4]) * ify
        xd = (S[_U * B + j] - cam[3] - sk * yd) * ifx
        S[_XD * B + j], S[_YD * B + j] = xd if good else math.nan, yd if good else math.nan
        S[_XN * B + j], S[_YN * B + j] = S[_X0 * B + j], S[_Y0 * B + j]
    core.undistort_vec(dom, k, S[_XD * B:_XD * B + n_obj], S[_YD * B:_YD * B + n_obj],
                       S[_XN * B:_XN * B + n_obj], S[_YN * B:_YN * B + n_obj], S[_J00 * B:_J00 * B + n_obj],
                       S[_J01 * B:_J01 * B + n_obj], S[_J10 * B:_J10 * B + n_obj], S[_J11 * B:_J11 * B + n_obj],
                       S[_IDN * B:_IDN * B + n_obj], okb[:n_obj])


@nb.njit(**_INL)
def _ground_lens(S, cam, okb, j):
    """:func:`_ground` of object ``j``'s undistorted pixel (_XN, _YN, its Jacobian _J, the pixel's rate _DU,
    _DV), branch-free: ``(x, y, dx, dy, ok)`` (m, m/s)."""
    B = _BLOCK
    sk, ifx, ify, gsx, gsy = cam[2], cam[5], cam[6], cam[10], cam[11]
    r00, r01, r02, r10, r11, r12, r20, r21, r22 = cam[13:22]
    dyd = S[_DV * B + j] * ify
    dxd = (S[_DU * B + j] - sk * dyd) * ifx
    x, y = S[_XN * B + j], S[_YN * B + j]
    dx = S[_J00 * B + j] * dxd + S[_J01 * B + j] * dyd
    dy = S[_J10 * B + j] * dxd + S[_J11 * B + j] * dyd
    r0 = r00 * x + r01 * y + r02
    r1 = r10 * x + r11 * y + r12
    r2 = r20 * x + r21 * y + r22
    e0, e1, e2 = r00 * dx + r01 * dy, r10 * dx + r11 * dy, r20 * dx + r21 * dy
    num = cam[9] - cam[12]
    den = r2 - gsx * r0 - gsy * r1
    iden = 1.0 / den
    lam = num * iden
    ok = okb[j] & (S[_OK * B + j] != 0.0) & (den < 0.0) & (num < 0.0) & math.isfinite(lam)
    dlam = -lam * (e2 - gsx * e0 - gsy * e1) * iden
    return cam[7] + lam * r0, cam[8] + lam * r1, dlam * r0 + lam * e0, dlam * r1 + lam * e1, ok


@nb.njit(**_JIT)
def _block_centre_lens(S, cam, okb, n_obj):
    """:func:`_block_centre` through the lens (the pixels undistorted by :func:`_undistort_block`)."""
    B = _BLOCK
    for j in range(n_obj):
        gx, gy, _, _, ok = _ground_lens(S, cam, okb, j)
        gx, gy = gx if ok else math.nan, gy if ok else math.nan
        S[_Q0 * B + j], S[_Q1 * B + j], S[_Q2 * B + j] = _offset_c(cam, 2.0 * S[_X * B + j] - gx,
                                                                   2.0 * S[_Y * B + j] - gy)


@nb.njit(**_JIT)
def _block_update_lens(S, cam, okb, n_obj):
    """:func:`_block_node`'s update of the running moments through the lens."""
    B = _BLOCK
    for j in range(n_obj):
        _, _, dgx, dgy, ok = _ground_lens(S, cam, okb, j)
        ux, uy = dgx - S[_VX * B + j], dgy - S[_VY * B + j]
        good = ok & math.isfinite(ux) & math.isfinite(uy)
        ux, uy = ux if good else 0.0, uy if good else 0.0
        S[_N * B + j] += 1.0 if good else 0.0
        S[_S0 * B + j] += ux
        S[_S1 * B + j] += uy
        S[_M00 * B + j] += ux * ux
        S[_M01 * B + j] += ux * uy
        S[_M11 * B + j] += uy * uy


@nb.njit(**_JIT)
def _lens_block(S, okb, cam, prm, dom, xy, v, size_mean, size_sigma, nodes, i0, n_obj):
    """:func:`_pinhole_block` through a distorting lens: per render the pass (:func:`_render_block_lens`), the
    objects that need the domain's table again object by object, the pixels' undistortion on the columns, then
    the centre or the moments' update."""
    k = prm[5:13]
    kt = (k[0], k[1], k[2], k[3], k[4], k[5], k[6], k[7])
    in2, lim2 = dom[core.DOM_RU_IN2], max(dom[core.DOM_RU_IN2], dom[core.DOM_RU_OUT2])
    n_pass = (n_obj + _LANES - 1) // _LANES * _LANES
    _block_load(S, xy, v, size_mean, size_sigma, i0, n_obj, n_pass)
    _block_start(S, cam, n_pass)
    _render_block_lens(S, cam, kt, lim2, in2, n_pass)
    _render_doubts(S, prm, dom, k, n_pass)
    _undistort_block(S, cam, dom, k, okb, n_pass)
    _block_centre_lens(S, cam, okb, n_pass)
    for n in range(nodes.shape[0]):
        _block_boxes(S, cam, nodes[n, 0], nodes[n, 1], nodes[n, 2], n_pass)
        _render_block_lens(S, cam, kt, lim2, in2, n_pass)
        _render_doubts(S, prm, dom, k, n_pass)
        _undistort_block(S, cam, dom, k, okb, n_pass)
        _block_update_lens(S, cam, okb, n_pass)


@nb.njit(**_JIT)
def _moments_lens(prm, R, dom, xy, v, size_mean, size_sigma, nodes, mean_out, second_out):
    """:func:`_moments` of a distorting lens, columnar (:func:`_lens_block`)."""
    cam = _camera_scalars(prm, R)
    S, okb = np.empty(_NCOL_LENS * _BLOCK), np.empty(_BLOCK, np.bool_)
    for i0 in range(0, xy.shape[0], _BLOCK):
        n_obj = min(_BLOCK, xy.shape[0] - i0)
        _lens_block(S, okb, cam, prm, dom, xy, v, size_mean, size_sigma, nodes, i0, n_obj)
        _store_moments(S, i0, n_obj, mean_out, second_out)


@nb.njit(**_JIT)
def _added_lens(prm, R, dom, xy, v, size_mean, size_sigma, nodes, cov_v, cov_out):
    """:func:`_moments_lens`' second moment added to ``cov_v`` into ``cov_out`` (:func:`_store_added`)."""
    cam = _camera_scalars(prm, R)
    S, okb = np.empty(_NCOL_LENS * _BLOCK), np.empty(_BLOCK, np.bool_)
    for i0 in range(0, xy.shape[0], _BLOCK):
        n_obj = min(_BLOCK, xy.shape[0] - i0)
        _lens_block(S, okb, cam, prm, dom, xy, v, size_mean, size_sigma, nodes, i0, n_obj)
        _store_added(S, xy, v, i0, n_obj, cov_v, cov_out)


#: the compiled entries of :func:`slide_moments` by ``has_dist``, each called with its arguments less ``has_dist``:
#: a caller on a per-frame path looks its camera's entry up once and calls it itself (no Python frame of this
#: layer per frame, ``tracking/contact_slide.py``; ``bench/frame_walk.py`` counts them)
MOMENTS_KERNELS = {False: _moments_pinhole, True: _moments_lens}
#: the same for :func:`slide_added` (``ContactSlide.apply``'s one call per frame)
ADDED_KERNELS = {False: _added_pinhole, True: _added_lens}


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


def slide_added(prm, R, dom, has_dist, xy, v, size_mean, size_sigma, nodes, cov_v, cov_out) -> None:
    """A velocity covariance with the slide term added, in one pass: ``cov_out = cov_v + E[u u^T]``.

    Parameters as :func:`slide_moments`, and ``cov_v`` (n, 2, 2) m^2/s^2, the tracker's velocity covariance.

    Output (filled): ``cov_out`` (n, 2, 2) m^2/s^2, ``cov_v`` plus :func:`slide_moments`' second moment element by
    element -- to the bit the numpy sum of the two -- where that moment is NaN (no node renders) and the row has no
    finite position or velocity, ``cov_v + 0.0`` (the term of an object without a velocity is zero; one with a
    velocity whose box does not render stays NaN: not reported with a covariance).
    """
    ADDED_KERNELS[bool(has_dist)](prm, R, dom, xy, v, size_mean, size_sigma, nodes, cov_v, cov_out)
