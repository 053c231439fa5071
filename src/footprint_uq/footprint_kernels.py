"""Fused numba kernels for :class:`footprint_uq.footprints.FrameProcessor`.

One call processes a frame: per object, its K corners are back-projected with
their Jacobians (the math of :mod:`footprint_uq.cameras.general`, ported to scalar
code: pinhole, OpenCV distortion with Newton undistortion and implicit-function
Jacobians, rotation derivatives, perturbed-ground intersection), the corner and
centre covariances are formed with only the non-zero entries of the 22x22
parameter covariance, the centroid Jacobian is applied, the largest point picked
and the V2X integer fields computed.  The numpy reference is
:func:`footprint_uq.footprints.footprints_from_corners`; the tests hold the two to
1e-9 relative.

Camera constants travel in one float64 vector ``cam`` (layout ``_C_*`` below) and
the rotation derivatives in ``dR`` (3 angles, 3, 3), both prepared once per
camera by the processor.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# cam vector layout
_C_FX, _C_FY, _C_CX, _C_CY, _C_SK = 0, 1, 2, 3, 4
_C_DIST = 5  # 8 coefficients k1 k2 p1 p2 k3 k4 k5 k6
_C_X, _C_Y, _C_H = 13, 14, 15
_C_GDZ, _C_GSX, _C_GSY = 16, 17, 18
_C_R = 19  # 9 entries, row major, OpenCV camera -> world
_C_HASDIST = 28
_C_W, _C_HIMG = 29, 30
_C_GROUNDZ = 31
_C_LEN = 32

# status codes (footprint_uq.status) and the centre code DEGENERATE (footprints)
_OK, _ABOVE, _NOTFIN, _UNDIST, _OUTSIDE, _BEHIND = 0, 1, 2, 3, 4, 5
_DEGENERATE = 20

_Z95 = 1.96
_K95_2D = math.sqrt(-2.0 * math.log(0.05))
_GUARD = 1e-9
_ORIENT_UNIT = 360.0 / 65535.0
_PC_LEVELS = np.array([500.0, 200.0, 100.0, 50.0, 20.0, 10.0, 5.0, 2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.02, 0.01])


def camera_constants(camera) -> tuple[np.ndarray, np.ndarray]:
    """``(cam, dR)`` for the kernels from a :class:`~footprint_uq.cameras.base.Camera`."""
    from .cameras.rotation import R_W_C, dR_W_C
    from . import params as P

    p = np.asarray(camera.params, dtype=np.float64)
    cam = np.zeros(_C_LEN)
    cam[0:5] = p[0:5]
    cam[_C_DIST:_C_DIST + 8] = p[P.DIST_SLICE]
    cam[_C_X], cam[_C_Y], cam[_C_H] = p[P.XM], p[P.YM], p[P.HM]
    cam[_C_GDZ], cam[_C_GSX], cam[_C_GSY] = p[P.GDZ], p[P.GSX], p[P.GSY]
    cam[_C_R:_C_R + 9] = R_W_C(p[P.PAN], p[P.TILT], p[P.ROLL]).ravel()
    cam[_C_HASDIST] = 1.0 if np.any(p[P.DIST_SLICE] != 0) else 0.0
    cam[_C_W], cam[_C_HIMG] = camera.image_size_px
    cam[_C_GROUNDZ] = camera.ground_z_m
    dR = np.ascontiguousarray(dR_W_C(p[P.PAN], p[P.TILT], p[P.ROLL]))
    return cam, dR


@njit(cache=True)
def _distort(x, y, cam, J, Jk, want_k):
    """Distorted (xd, yd); fills J (2, 2) and, if want_k, Jk (2, 8)."""
    k1, k2, p1, p2 = cam[_C_DIST], cam[_C_DIST + 1], cam[_C_DIST + 2], cam[_C_DIST + 3]
    k3, k4, k5, k6 = cam[_C_DIST + 4], cam[_C_DIST + 5], cam[_C_DIST + 6], cam[_C_DIST + 7]
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    rad = num / den
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (dnum * den - num * dden) / (den * den)
    J[0, 0] = rad + x * drad * 2 * x + 2 * p1 * y + p2 * 6 * x
    J[0, 1] = x * drad * 2 * y + 2 * p1 * x + p2 * 2 * y
    J[1, 0] = y * drad * 2 * x + p1 * 2 * x + 2 * p2 * y
    J[1, 1] = rad + y * drad * 2 * y + p1 * 6 * y + 2 * p2 * x
    if want_k:
        r4 = r2 * r2
        r6 = r4 * r2
        d2 = den * den
        dr0, dr1, dr4 = r2 / den, r4 / den, r6 / den
        dr5, dr6, dr7 = -num * r2 / d2, -num * r4 / d2, -num * r6 / d2
        Jk[0, 0], Jk[1, 0] = x * dr0, y * dr0
        Jk[0, 1], Jk[1, 1] = x * dr1, y * dr1
        Jk[0, 2], Jk[1, 2] = 2.0 * x * y, r2 + 2.0 * y * y
        Jk[0, 3], Jk[1, 3] = r2 + 2.0 * x * x, 2.0 * x * y
        Jk[0, 4], Jk[1, 4] = x * dr4, y * dr4
        Jk[0, 5], Jk[1, 5] = x * dr5, y * dr5
        Jk[0, 6], Jk[1, 6] = x * dr6, y * dr6
        Jk[0, 7], Jk[1, 7] = x * dr7, y * dr7
    return xd, yd


@njit(cache=True)
def _backproject(u, v, cam, dR, xy, Jp, Juv, Jd, Jk):
    """Back-project one pixel: fills xy (2,), Jp (2, 22), Juv (2, 2); returns the status code.

    Jd (2, 2) and Jk (2, 8) are scratch.  Mirrors general.backproject(get_gradients=True).
    """
    fx, fy, cx, cy, sk = cam[0], cam[1], cam[2], cam[3], cam[4]
    finite = math.isfinite(u) and math.isfinite(v)
    yd = (v - cy) / fy
    xd = (u - cx - sk * yd) / fx
    # dxd/duv and dxd/dk (fx, fy, cx, cy, skew)
    dxd_du, dxd_dv, dyd_dv = 1.0 / fx, -sk / fy / fx, 1.0 / fy
    dy_dfy = -yd / fy
    kx0, kx1, kx2, kx3, kx4 = -xd / fx, -sk / fx * dy_dfy, -1.0 / fx, sk / fy / fx, -yd / fx
    ky1, ky3 = dy_dfy, -1.0 / fy
    # undistort
    conv = True
    xn, yn = xd, yd
    if cam[_C_HASDIST] != 0.0:
        tol = 1e-14 * max(1.0, max(abs(xd), abs(yd)))
        for _ in range(50):
            fxd, fyd = _distort(xn, yn, cam, Jd, Jk, False)
            r0, r1 = fxd - xd, fyd - yd
            if max(abs(r0), abs(r1)) <= tol:
                break
            det = Jd[0, 0] * Jd[1, 1] - Jd[0, 1] * Jd[1, 0]
            s0 = (Jd[1, 1] * r0 - Jd[0, 1] * r1) / det
            s1 = (-Jd[1, 0] * r0 + Jd[0, 0] * r1) / det
            xn, yn = xn - s0, yn - s1
        fxd, fyd = _distort(xn, yn, cam, Jd, Jk, True)
        r0, r1 = fxd - xd, fyd - yd
        det = Jd[0, 0] * Jd[1, 1] - Jd[0, 1] * Jd[1, 0]
        conv = (max(abs(r0), abs(r1)) <= tol) and det > 0
        # inverse of Jd
        i00, i01, i10, i11 = Jd[1, 1] / det, -Jd[0, 1] / det, -Jd[1, 0] / det, Jd[0, 0] / det
    else:
        conv = math.isfinite(xd) and math.isfinite(yd)
        _distort(xn, yn, cam, Jd, Jk, True)
        i00, i01, i10, i11 = 1.0, 0.0, 0.0, 1.0
    # ray in the world
    R = cam[_C_R:_C_R + 9]
    dx = R[0] * xn + R[1] * yn + R[2]
    dy = R[3] * xn + R[4] * yn + R[5]
    dz = R[6] * xn + R[7] * yn + R[8]
    gdz, gx, gy = cam[_C_GDZ], cam[_C_GSX], cam[_C_GSY]
    Nn = gdz - cam[_C_H]
    Dn = dz - gx * dx - gy * dy
    lam = Nn / Dn if Dn != 0.0 else math.nan
    vg = (Dn < 0.0) and (Nn < 0.0) and math.isfinite(lam)
    reason = _OK
    if not vg:
        reason = _ABOVE
    if not conv:
        reason = _UNDIST
    if not finite:
        reason = _NOTFIN
    if reason != _OK:
        xy[0] = math.nan
        xy[1] = math.nan
        for r in range(2):
            Juv[r, 0] = math.nan
            Juv[r, 1] = math.nan
            for c in range(22):
                Jp[r, c] = math.nan
        return reason
    xy[0] = cam[_C_X] + lam * dx
    xy[1] = cam[_C_Y] + lam * dy
    inv = 1.0 / Dn
    # dxy/dray (2, 3): lam I + d_xy dlam/dray, dlam/dray = (-lam/Dn) (-gx, -gy, 1)
    f = -lam * inv
    l0, l1, l2 = -gx * f, -gy * f, f
    a00, a01, a02 = lam + dx * l0, dx * l1, dx * l2
    a10, a11, a12 = dy * l0, lam + dy * l1, dy * l2
    # dxy/dxn = dxy/dray @ R[:, :2]
    b00 = a00 * R[0] + a01 * R[3] + a02 * R[6]
    b01 = a00 * R[1] + a01 * R[4] + a02 * R[7]
    b10 = a10 * R[0] + a11 * R[3] + a12 * R[6]
    b11 = a10 * R[1] + a11 * R[4] + a12 * R[7]
    # dxy/dxd = dxy/dxn @ dxn/dxd
    c00 = b00 * i00 + b01 * i10
    c01 = b00 * i01 + b01 * i11
    c10 = b10 * i00 + b11 * i10
    c11 = b10 * i01 + b11 * i11
    # intrinsics
    Jp[0, 0], Jp[1, 0] = c00 * kx0, c10 * kx0
    Jp[0, 1], Jp[1, 1] = c00 * kx1 + c01 * ky1, c10 * kx1 + c11 * ky1
    Jp[0, 2], Jp[1, 2] = c00 * kx2, c10 * kx2
    Jp[0, 3], Jp[1, 3] = c00 * kx3 + c01 * ky3, c10 * kx3 + c11 * ky3
    Jp[0, 4], Jp[1, 4] = c00 * kx4, c10 * kx4
    # distortion: dxy/dxn @ (-Jd^-1 Jk)
    for k in range(8):
        e0 = -(i00 * Jk[0, k] + i01 * Jk[1, k])
        e1 = -(i10 * Jk[0, k] + i11 * Jk[1, k])
        Jp[0, 5 + k] = b00 * e0 + b01 * e1
        Jp[1, 5 + k] = b10 * e0 + b11 * e1
    # camera position
    Jp[0, 13], Jp[0, 14], Jp[0, 15] = 1.0, 0.0, -dx * inv
    Jp[1, 13], Jp[1, 14], Jp[1, 15] = 0.0, 1.0, -dy * inv
    # angles: dxy/dray @ (dR_k @ ray_c)
    for k in range(3):
        q0 = dR[k, 0, 0] * xn + dR[k, 0, 1] * yn + dR[k, 0, 2]
        q1 = dR[k, 1, 0] * xn + dR[k, 1, 1] * yn + dR[k, 1, 2]
        q2 = dR[k, 2, 0] * xn + dR[k, 2, 1] * yn + dR[k, 2, 2]
        Jp[0, 16 + k] = a00 * q0 + a01 * q1 + a02 * q2
        Jp[1, 16 + k] = a10 * q0 + a11 * q1 + a12 * q2
    # ground: d_xy dlam/dg, dlam/dg = (1/Dn, lam dx/Dn, lam dy/Dn)
    g0, g1, g2 = inv, lam * dx * inv, lam * dy * inv
    Jp[0, 19], Jp[0, 20], Jp[0, 21] = dx * g0, dx * g1, dx * g2
    Jp[1, 19], Jp[1, 20], Jp[1, 21] = dy * g0, dy * g1, dy * g2
    # dxy/duv = dxy/dxd @ dxd/duv
    Juv[0, 0] = c00 * dxd_du
    Juv[0, 1] = c00 * dxd_dv + c01 * dyd_dv
    Juv[1, 0] = c10 * dxd_du
    Juv[1, 1] = c10 * dxd_dv + c11 * dyd_dv
    return _OK


@njit(cache=True)
def _project(X, Y, Z, cam, uv):
    """World point (Z relative to the nominal ground) -> pixel; returns the status code (general.project)."""
    R = cam[_C_R:_C_R + 9]
    rx, ry, rz = X - cam[_C_X], Y - cam[_C_Y], Z - cam[_C_H]
    pcx = R[0] * rx + R[3] * ry + R[6] * rz
    pcy = R[1] * rx + R[4] * ry + R[7] * rz
    pcz = R[2] * rx + R[5] * ry + R[8] * rz
    finite = math.isfinite(X) and math.isfinite(Y) and math.isfinite(Z)
    if not finite:
        uv[0] = math.nan
        uv[1] = math.nan
        return _NOTFIN
    if not pcz > 0.0:
        uv[0] = math.nan
        uv[1] = math.nan
        return _BEHIND
    x, y = pcx / pcz, pcy / pcz
    k1, k2, p1, p2 = cam[_C_DIST], cam[_C_DIST + 1], cam[_C_DIST + 2], cam[_C_DIST + 3]
    k3, k4, k5, k6 = cam[_C_DIST + 4], cam[_C_DIST + 5], cam[_C_DIST + 6], cam[_C_DIST + 7]
    r2 = x * x + y * y
    rad = (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) / (1.0 + r2 * (k4 + r2 * (k5 + r2 * k6)))
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    uv[0] = cam[_C_FX] * xd + cam[_C_SK] * yd + cam[_C_CX]
    uv[1] = cam[_C_FY] * yd + cam[_C_CY]
    return _OK


@njit(cache=True)
def _sandwich2(Ja, Jb, si, sj, sv):
    """``Ja S Jb^T`` for one row each (22,) with the sparse S entries."""
    s = 0.0
    for e in range(si.shape[0]):
        s += Ja[si[e]] * sv[e] * Jb[sj[e]]
    return s


@njit(cache=True)
def _v2x(c00, c01, c11, ch, sh, out):
    """CPM and J2735 integer fields of one 2x2 covariance (mirror of footprint_uq.v2x)."""
    if not (math.isfinite(c00) and math.isfinite(c01) and math.isfinite(c11)):
        out[0], out[1], out[2] = 4096, 4096, 101
        out[3], out[4], out[5], out[6] = 255, 255, 65535, 0
        return
    if sh != 0.0 or ch != 1.0:  # R C R^T with R = [[ch, sh], [-sh, ch]]
        a00 = ch * c00 + sh * c01
        a01 = ch * c01 + sh * c11
        a10 = -sh * c00 + ch * c01
        a11 = -sh * c01 + ch * c11
        e00 = a00 * ch + a01 * sh
        e01 = -a00 * sh + a01 * ch
        e10 = a10 * ch + a11 * sh
        e11 = -a10 * sh + a11 * ch
        c00, c01, c11 = e00, 0.5 * (e01 + e10), e11
    for i in range(2):
        var = c00 if i == 0 else c11
        conf = _Z95 * math.sqrt(max(var, 0.0))
        if conf > 40.94:
            out[i] = 4095
        else:
            n = math.ceil(conf / 0.01 * (1.0 - _GUARD))
            out[i] = min(max(n, 1), 4094)
    if c00 > 0.0 and c11 > 0.0:
        rho = c01 / math.sqrt(c00 * c11)
        out[2] = int(min(max(np.rint(rho * 100.0), -100.0), 100.0))
    else:
        out[2] = 101
    mean = 0.5 * (c00 + c11)
    rad = math.hypot(0.5 * (c00 - c11), c01)
    a = math.sqrt(mean + rad)
    b = math.sqrt(max(mean - rad, 0.0))
    for i in range(2):
        s = a if i == 0 else b
        if s >= 12.70:
            out[3 + i] = 254
        else:
            n = math.ceil(s / 0.05 * (1.0 - _GUARD))
            out[3 + i] = min(max(n, 0), 254)
    ang = 0.5 * math.degrees(math.atan2(2.0 * c01, c00 - c11))
    bearing = 90.0 - ang
    bearing = bearing - 180.0 * math.floor(bearing / 180.0)
    if bearing >= 180.0:
        bearing -= 180.0
    out[5] = int(np.rint(bearing / _ORIENT_UNIT))
    r95 = _K95_2D * a
    cnt = 0
    for lev in _PC_LEVELS:
        if lev >= r95 * (1.0 - _GUARD):
            cnt += 1
    out[6] = cnt


@njit(cache=True)
def process_corners(uv, extra_reason, cam, dR, si, sj, sv, spx, det, det_mode, allow_outside, ch, sh,
                    want_joint):
    """The fused per-frame kernel on corners in pixels ``uv`` (N, K, 2).

    extra_reason : (N, K) int8 codes overriding OK (3D projection), or shape (0, 0)
    si, sj, sv : sparse parameter covariance (non-zero entries)
    spx : (2, 2) budget pixel covariance;  det : 4-D detector covariance with det_mode
        0 none (any 4-D array), 1 (N, 1, 2, 2) per detection, 2 (N, K, 2, 2) per corner,
        3 (N, 1, 2K, 2K) full
    ch, sh : cos, sin of the heading offset (V2X fields)
    """
    N, K = uv.shape[0], uv.shape[1]
    nan = math.nan
    xy = np.empty((N, K, 2))
    ccov = np.empty((N, K, 2, 2))
    joint = np.empty((N if want_joint else 0, 2 * K, 2 * K))
    reason = np.empty((N, K), dtype=np.int8)
    usable = np.empty((N, K), dtype=np.bool_)
    largest_index = np.empty(N, dtype=np.int64)
    largest_semi = np.empty(N)
    largest_xy = np.empty((N, 2))
    largest_cov = np.empty((N, 2, 2))
    centre = np.empty((N, 2))
    centre_cov = np.empty((N, 2, 2))
    centre_reason = np.empty(N, dtype=np.int32)
    centre_bad = np.empty(N, dtype=np.int64)
    area_out = np.empty(N)
    v2x = np.empty((N, 7), dtype=np.int32)
    # scratch
    Jp = np.empty((K, 2, 22))
    Juv = np.empty((K, 2, 2))
    Pk = np.empty((K, 2, 2))  # per-corner pixel covariance (diagonal blocks)
    Jd = np.empty((2, 2))
    Jk = np.empty((2, 8))
    G = np.empty((2, 2 * K))
    Jc = np.empty((2, 22))
    H = np.empty((K, 2, 2))
    q = np.empty((K, 2))
    tmp = np.empty(2)
    W, Himg = cam[_C_W], cam[_C_HIMG]
    has_extra = extra_reason.shape[0] == N and N > 0
    for n in range(N):
        any_usable = False
        all_usable = True
        first_bad = -1
        best = -1
        best_semi = -1.0
        for k in range(K):
            u, v = uv[n, k, 0], uv[n, k, 1]
            r = _backproject(u, v, cam, dR, tmp, Jp[k], Juv[k], Jd, Jk)
            if r == _OK and not (u >= -0.5 and u <= W - 0.5 and v >= -0.5 and v <= Himg - 0.5):
                r = _OUTSIDE
            if has_extra and extra_reason[n, k] != _OK:
                r = extra_reason[n, k]
            computed = r == _OK or r == _OUTSIDE
            us = r == _OK or (r == _OUTSIDE and allow_outside)
            reason[n, k] = r
            usable[n, k] = us
            # per-corner pixel covariance
            for i in range(2):
                for j in range(2):
                    p = spx[i, j]
                    if det_mode == 1:
                        p += det[n, 0, i, j]
                    elif det_mode == 2:
                        p += det[n, k, i, j]
                    elif det_mode == 3:
                        p += det[n, 0, 2 * k + i, 2 * k + j]
                    Pk[k, i, j] = p
            if computed:
                xy[n, k, 0], xy[n, k, 1] = tmp[0], tmp[1]
                J0, J1 = Jp[k, 0], Jp[k, 1]
                c00 = _sandwich2(J0, J0, si, sj, sv)
                c01 = _sandwich2(J0, J1, si, sj, sv)
                c10 = _sandwich2(J1, J0, si, sj, sv)
                c11 = _sandwich2(J1, J1, si, sj, sv)
                A = Juv[k]
                for i in range(2):
                    for j in range(2):
                        s = 0.0
                        for a in range(2):
                            for b in range(2):
                                s += A[i, a] * Pk[k, a, b] * A[j, b]
                        if i == 0 and j == 0:
                            c00 += s
                        elif i == 0:
                            c01 += s
                        elif j == 0:
                            c10 += s
                        else:
                            c11 += s
                ccov[n, k, 0, 0], ccov[n, k, 0, 1], ccov[n, k, 1, 0], ccov[n, k, 1, 1] = c00, c01, c10, c11
                semi = math.sqrt(0.5 * (c00 + c11) + math.hypot(0.5 * (c00 - c11), c01))
                if us and semi > best_semi:
                    best_semi = semi
                    best = k
            else:
                xy[n, k, 0], xy[n, k, 1] = nan, nan
                for i in range(2):
                    for j in range(2):
                        ccov[n, k, i, j] = nan
            if us:
                any_usable = True
            elif all_usable:
                all_usable = False
                first_bad = k
        # joint covariance (optional)
        if want_joint:
            for k in range(K):
                ck = reason[n, k] == _OK or reason[n, k] == _OUTSIDE
                for l in range(k, K):
                    cl = reason[n, l] == _OK or reason[n, l] == _OUTSIDE
                    for i in range(2):
                        for j in range(2):
                            if not (ck and cl):
                                val = nan
                            elif k == l:
                                val = ccov[n, k, i, j]
                            else:
                                val = _sandwich2(Jp[k, i], Jp[l, j], si, sj, sv)
                                if det_mode == 3:
                                    s = 0.0
                                    for a in range(2):
                                        for b in range(2):
                                            s += Juv[k, i, a] * det[n, 0, 2 * k + a, 2 * l + b] * Juv[l, j, b]
                                    val += s
                            joint[n, 2 * k + i, 2 * l + j] = val
                            joint[n, 2 * l + j, 2 * k + i] = val
        # largest point
        largest_index[n] = best
        if best >= 0:
            largest_semi[n] = best_semi
            largest_xy[n, 0], largest_xy[n, 1] = xy[n, best, 0], xy[n, best, 1]
            for i in range(2):
                for j in range(2):
                    largest_cov[n, i, j] = ccov[n, best, i, j]
        else:
            largest_semi[n] = nan
            largest_xy[n, 0], largest_xy[n, 1] = nan, nan
            for i in range(2):
                for j in range(2):
                    largest_cov[n, i, j] = nan
        # centre
        code = _OK
        bad = -1
        area = nan
        cx_, cy_ = nan, nan
        if not all_usable:
            code = reason[n, first_bad]
            bad = first_bad
        else:
            if K < 3:
                area = 0.0
                cx_, cy_ = 0.0, 0.0
                for k in range(K):
                    cx_ += xy[n, k, 0]
                    cy_ += xy[n, k, 1]
                cx_ /= K
                cy_ /= K
                for k in range(K):
                    G[0, 2 * k], G[0, 2 * k + 1] = 1.0 / K, 0.0
                    G[1, 2 * k], G[1, 2 * k + 1] = 0.0, 1.0 / K
            else:
                mx, my = 0.0, 0.0
                for k in range(K):
                    mx += xy[n, k, 0]
                    my += xy[n, k, 1]
                mx /= K
                my /= K
                ss = 0.0
                for k in range(K):
                    q[k, 0] = xy[n, k, 0] - mx
                    q[k, 1] = xy[n, k, 1] - my
                    ss += q[k, 0] * q[k, 0] + q[k, 1] * q[k, 1]
                A2, Sx, Sy = 0.0, 0.0, 0.0
                for k in range(K):
                    kn = (k + 1) % K
                    c = q[k, 0] * q[kn, 1] - q[kn, 0] * q[k, 1]
                    A2 += c
                    Sx += (q[k, 0] + q[kn, 0]) * c
                    Sy += (q[k, 1] + q[kn, 1]) * c
                area = 0.5 * A2
                if not (abs(area) > 1e-12 * max(ss, 1e-300)):
                    code = _DEGENERATE
                else:
                    inv6A = 1.0 / (6.0 * area)
                    Cxl, Cyl = Sx * inv6A, Sy * inv6A
                    cx_, cy_ = Cxl + mx, Cyl + my
                    for k in range(K):
                        kn = (k + 1) % K
                        kp = (k - 1 + K) % K
                        x, y = q[k, 0], q[k, 1]
                        xn_, yn_ = q[kn, 0], q[kn, 1]
                        xp, yp = q[kp, 0], q[kp, 1]
                        c = x * yn_ - xn_ * y
                        cp = xp * y - x * yp
                        dA_dx = 0.5 * (yn_ - yp)
                        dA_dy = 0.5 * (xp - xn_)
                        dSx_dx = c + cp + (x + xn_) * yn_ - (xp + x) * yp
                        dSx_dy = -(x + xn_) * xn_ + (xp + x) * xp
                        dSy_dx = (y + yn_) * yn_ - (yp + y) * yp
                        dSy_dy = c + cp - (y + yn_) * xn_ + (yp + y) * xp
                        G[0, 2 * k] = (dSx_dx - 6.0 * Cxl * dA_dx) * inv6A
                        G[0, 2 * k + 1] = (dSx_dy - 6.0 * Cxl * dA_dy) * inv6A
                        G[1, 2 * k] = (dSy_dx - 6.0 * Cyl * dA_dx) * inv6A
                        G[1, 2 * k + 1] = (dSy_dy - 6.0 * Cyl * dA_dy) * inv6A
        centre_reason[n] = code
        centre_bad[n] = bad
        area_out[n] = area if all_usable else nan
        if code == _OK:
            centre[n, 0], centre[n, 1] = cx_, cy_
            # parameter part: Jc = sum_k G_k Jp_k
            for r in range(2):
                for c in range(22):
                    s = 0.0
                    for k in range(K):
                        s += G[r, 2 * k] * Jp[k, 0, c] + G[r, 2 * k + 1] * Jp[k, 1, c]
                    Jc[r, c] = s
            e00 = _sandwich2(Jc[0], Jc[0], si, sj, sv)
            e01 = _sandwich2(Jc[0], Jc[1], si, sj, sv)
            e11 = _sandwich2(Jc[1], Jc[1], si, sj, sv)
            # pixel part: H_k = G_k Juv_k, sum_k,l H_k P_kl H_l^T
            for k in range(K):
                for i in range(2):
                    for j in range(2):
                        H[k, i, j] = G[i, 2 * k] * Juv[k, 0, j] + G[i, 2 * k + 1] * Juv[k, 1, j]
            for k in range(K):
                for l in range(K):
                    if k != l and det_mode != 3:
                        continue
                    for a in range(2):
                        for b in range(2):
                            p = Pk[k, a, b] if k == l else det[n, 0, 2 * k + a, 2 * l + b]
                            if p == 0.0:
                                continue
                            e00 += H[k, 0, a] * p * H[l, 0, b]
                            e01 += H[k, 0, a] * p * H[l, 1, b]
                            e11 += H[k, 1, a] * p * H[l, 1, b]
            centre_cov[n, 0, 0], centre_cov[n, 0, 1] = e00, e01
            centre_cov[n, 1, 0], centre_cov[n, 1, 1] = e01, e11
            _v2x(e00, e01, e11, ch, sh, v2x[n])
        else:
            centre[n, 0], centre[n, 1] = nan, nan
            for i in range(2):
                for j in range(2):
                    centre_cov[n, i, j] = nan
            _v2x(nan, nan, nan, ch, sh, v2x[n])
            if code == _DEGENERATE:
                centre_bad[n] = -1
    return (xy, ccov, joint, reason, usable, largest_index, largest_semi, largest_xy, largest_cov,
            centre, centre_cov, centre_reason, centre_bad, area_out, v2x)


@njit(cache=True)
def boxes3d_to_pixels(boxes, cam, yaw_deg, bottom_on_ground):
    """Bottom corners of 3D boxes (N, 7) projected to pixels (N, 4, 2), their codes (N, 4),
    and the first row with a negative size (-1 if none)."""
    N = boxes.shape[0]
    bad = -1
    uv = np.empty((N, 4, 2))
    code = np.empty((N, 4), dtype=np.int8)
    sl = (-1.0, 1.0, 1.0, -1.0)
    sw = (-1.0, -1.0, 1.0, 1.0)
    g0 = cam[_C_GROUNDZ]
    for n in range(N):
        x0, y0, z0 = boxes[n, 0], boxes[n, 1], boxes[n, 2]
        if bad < 0 and (boxes[n, 3] < 0.0 or boxes[n, 4] < 0.0 or boxes[n, 5] < 0.0):
            bad = n
        hl, hw, hh = 0.5 * boxes[n, 3], 0.5 * boxes[n, 4], 0.5 * boxes[n, 5]
        yaw = boxes[n, 6] * (math.pi / 180.0) if yaw_deg else boxes[n, 6]
        c, s = math.cos(yaw), math.sin(yaw)
        zb = 0.0 if bottom_on_ground else (z0 - hh) - g0
        for k in range(4):
            dl, dw = sl[k] * hl, sw[k] * hw
            X = x0 + c * dl - s * dw
            Y = y0 + s * dl + c * dw
            Z = zb if math.isfinite(X) and math.isfinite(Y) else math.nan
            code[n, k] = _project(X, Y, Z, cam, uv[n, k])
    return uv, code, bad
