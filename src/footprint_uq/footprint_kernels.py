"""Fused numba kernels for :class:`footprint_uq.footprints.FrameProcessor`.

One call processes a frame.  The corners of up to 32 objects at a time are laid
out structure-of-arrays (corner index last) and go through three straight-line
stages that the compiler vectorises:

1. :func:`_stage_undistort` -- pixel -> normalised coordinates, OpenCV undistortion
   (Newton, all corners of the chunk together, each stopping when converged, as
   :func:`footprint_uq.cameras.distortion.undistort`) and its implicit-function Jacobians;
2. :func:`_stage_ground` -- ray in the world, perturbed-ground intersection and the full
   d(x, y)/d(params) (2 x 22) and d(x, y)/d(u, v) Jacobians (the math of
   :func:`footprint_uq.cameras.general.backproject`, ported to scalar code);
3. :func:`_stage_whiten` -- ``J L`` with the sparse factor ``L L^T`` of the 22x22 parameter
   covariance (:func:`psd_factor`: only its non-zero entries are touched) and the
   parameter part of each corner's covariance.

Then, per object: status flags (outside image, 3D projection), per-point pixel noise
(budget + detector), the optional joint (2K x 2K) covariance, the largest point,
the centroid and its closed-form Jacobian, the centre covariance and the V2X integer
fields.  The numpy reference is :func:`footprint_uq.footprints.footprints_from_corners`;
the tests hold the two to 1e-9 relative.

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
_C_IFX, _C_IFY = 32, 33  # 1 / fx, 1 / fy
_C_LEN = 34

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
    from . import params as P
    from .cameras.rotation import R_W_C, dR_W_C

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
    cam[_C_IFX], cam[_C_IFY] = 1.0 / p[0], 1.0 / p[1]
    dR = np.ascontiguousarray(dR_W_C(p[P.PAN], p[P.TILT], p[P.ROLL]))
    return cam, dR


def psd_factor(S: np.ndarray, *, rtol: float = 1e-14):
    """Sparse factor of a PSD covariance: ``S = L L^T`` by diagonal-pivoted Cholesky.

    Returns ``(rows, cols, vals, r)``: the non-zero entries of ``L`` (n x r) with r the
    numerical rank.  Pivoting stops when the largest remaining diagonal is below
    ``rtol * max(diag S)``; a diagonal S gives a diagonal L and fully correlated
    parameters (one focal error moving fx and fy) share one column.
    """
    A = np.array(S, dtype=np.float64, copy=True)
    n = A.shape[0]
    L = np.zeros((n, n))
    tol = rtol * max(float(np.max(np.diag(A), initial=0.0)), 0.0)
    r = 0
    while r < n:
        d = np.diag(A)
        p = int(np.argmax(d))
        if not d[p] > tol:
            break
        col = A[:, p] / np.sqrt(d[p])
        L[:, r] = col
        A = A - np.outer(col, col)
        A[p, :] = 0.0
        A[:, p] = 0.0
        r += 1
    rows, cols = np.nonzero(L[:, :r])
    return rows.astype(np.int64), cols.astype(np.int64), np.ascontiguousarray(L[rows, cols]), r


@njit(cache=True, error_model="numpy", nogil=True)
def _distort(x, y, cam, J, Jk, want_k):
    """Distorted (xd, yd); fills J (2, 2) and, if want_k, Jk (2, 8)."""
    k1, k2, p1, p2 = cam[_C_DIST], cam[_C_DIST + 1], cam[_C_DIST + 2], cam[_C_DIST + 3]
    k3, k4, k5, k6 = cam[_C_DIST + 4], cam[_C_DIST + 5], cam[_C_DIST + 6], cam[_C_DIST + 7]
    r2 = x * x + y * y
    num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
    iden = 1.0 / den
    rad = num * iden
    xd = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
    yd = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
    dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
    dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
    drad = (dnum * den - num * dden) * (iden * iden)
    J[0, 0] = rad + x * drad * 2 * x + 2 * p1 * y + p2 * 6 * x
    J[0, 1] = x * drad * 2 * y + 2 * p1 * x + p2 * 2 * y
    J[1, 0] = y * drad * 2 * x + p1 * 2 * x + 2 * p2 * y
    J[1, 1] = rad + y * drad * 2 * y + p1 * 6 * y + 2 * p2 * x
    if want_k:
        r4 = r2 * r2
        r6 = r4 * r2
        nd2 = -num * iden * iden
        dr0, dr1, dr4 = r2 * iden, r4 * iden, r6 * iden
        dr5, dr6, dr7 = nd2 * r2, nd2 * r4, nd2 * r6
        Jk[0, 0], Jk[1, 0] = x * dr0, y * dr0
        Jk[0, 1], Jk[1, 1] = x * dr1, y * dr1
        Jk[0, 2], Jk[1, 2] = 2.0 * x * y, r2 + 2.0 * y * y
        Jk[0, 3], Jk[1, 3] = r2 + 2.0 * x * x, 2.0 * x * y
        Jk[0, 4], Jk[1, 4] = x * dr4, y * dr4
        Jk[0, 5], Jk[1, 5] = x * dr5, y * dr5
        Jk[0, 6], Jk[1, 6] = x * dr6, y * dr6
        Jk[0, 7], Jk[1, 7] = x * dr7, y * dr7
    return xd, yd


@njit(cache=True, error_model="numpy", nogil=True)
def _stage_undistort(U, V, m, cam, XD, YD, XN, YN, CONV, INV, JK, Jd, Jk, need):
    """Pixels -> distorted (XD, YD) and undistorted (XN, YN) normalised coordinates.

    Also fills CONV (1.0 where undistortion converged), INV (rows i00, i01, i10, i11 of
    d(undistorted)/d(distorted)) and JK (rows 0..7: d x_d / d k, rows 8..15: d y_d / d k).
    Without distortion the loops are straight-line and vectorise; with it each corner
    runs the Newton iteration of :func:`footprint_uq.cameras.distortion.undistort`.
    ``need`` as in :func:`_stage_ground`: without distortion, JK rows nobody reads are skipped.
    """
    cx, cy, sk = cam[_C_CX], cam[_C_CY], cam[_C_SK]
    ifx, ify = cam[_C_IFX], cam[_C_IFY]
    for j in range(m):
        yd = (V[j] - cy) * ify
        XD[j] = (U[j] - cx - sk * yd) * ifx
        YD[j] = yd
    if cam[_C_HASDIST] == 0.0:
        for j in range(m):
            x, y = XD[j], YD[j]
            XN[j], YN[j] = x, y
            CONV[j] = 1.0 if (math.isfinite(x) & math.isfinite(y)) else 0.0
            INV[0, j], INV[1, j], INV[2, j], INV[3, j] = 1.0, 0.0, 0.0, 1.0
        if need[5]:
            for j in range(m):
                x, y = XD[j], YD[j]
                r2 = x * x + y * y
                r4 = r2 * r2
                r6 = r4 * r2
                JK[0, j], JK[8, j] = x * r2, y * r2
                JK[1, j], JK[9, j] = x * r4, y * r4
                JK[2, j], JK[10, j] = 2.0 * x * y, r2 + 2.0 * y * y
                JK[3, j], JK[11, j] = r2 + 2.0 * x * x, 2.0 * x * y
                JK[4, j], JK[12, j] = x * r6, y * r6
        if need[10]:
            for j in range(m):
                x, y = XD[j], YD[j]
                r2 = x * x + y * y
                r4 = r2 * r2
                r6 = r4 * r2
                JK[5, j], JK[13, j] = -x * r2, -y * r2
                JK[6, j], JK[14, j] = -x * r4, -y * r4
                JK[7, j], JK[15, j] = -x * r6, -y * r6
        return
    # Newton on all corners at once; a corner stops moving once converged (as the reference)
    k1, k2, p1, p2 = cam[_C_DIST], cam[_C_DIST + 1], cam[_C_DIST + 2], cam[_C_DIST + 3]
    k3, k4, k5, k6 = cam[_C_DIST + 4], cam[_C_DIST + 5], cam[_C_DIST + 6], cam[_C_DIST + 7]
    for j in range(m):
        XN[j], YN[j] = XD[j], YD[j]
        CONV[j] = 0.0
    for _ in range(50):
        n_active = 0
        for j in range(m):
            x, y, xd, yd = XN[j], YN[j], XD[j], YD[j]
            tol = 1e-14 * max(1.0, max(abs(xd), abs(yd)))
            r2 = x * x + y * y
            num = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
            den = 1.0 + r2 * (k4 + r2 * (k5 + r2 * k6))
            iden = 1.0 / den
            rad = num * iden
            r0 = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
            r1 = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
            dnum = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
            dden = k4 + r2 * (2.0 * k5 + 3.0 * k6 * r2)
            drad = (dnum * den - num * dden) * (iden * iden)
            j00 = rad + x * drad * 2 * x + 2 * p1 * y + p2 * 6 * x
            j01 = x * drad * 2 * y + 2 * p1 * x + p2 * 2 * y
            j10 = y * drad * 2 * x + p1 * 2 * x + 2 * p2 * y
            j11 = rad + y * drad * 2 * y + p1 * 6 * y + 2 * p2 * x
            # converged -- or hopeless (NaN): it stays as it is and fails the final check
            done = (max(abs(r0), abs(r1)) <= tol) | (not math.isfinite(r0 + r1))
            idet = 1.0 / (j00 * j11 - j01 * j10)
            s0 = (j11 * r0 - j01 * r1) * idet
            s1 = (-j10 * r0 + j00 * r1) * idet
            XN[j] = x if done else x - s0
            YN[j] = y if done else y - s1
            n_active += 0 if done else 1
        if n_active == 0:
            break
    for j in range(m):
        xn, yn, xd, yd = XN[j], YN[j], XD[j], YD[j]
        tol = 1e-14 * max(1.0, max(abs(xd), abs(yd)))
        fxd, fyd = _distort(xn, yn, cam, Jd, Jk, True)
        r0, r1 = fxd - xd, fyd - yd
        det = Jd[0, 0] * Jd[1, 1] - Jd[0, 1] * Jd[1, 0]
        CONV[j] = 1.0 if ((max(abs(r0), abs(r1)) <= tol) and det > 0) else 0.0
        idet = 1.0 / det
        INV[0, j], INV[1, j] = Jd[1, 1] * idet, -Jd[0, 1] * idet
        INV[2, j], INV[3, j] = -Jd[1, 0] * idet, Jd[0, 0] * idet
        for kk in range(8):
            JK[kk, j] = Jk[0, kk]
            JK[8 + kk, j] = Jk[1, kk]


@njit(cache=True, error_model="numpy", nogil=True)
def _stage_ground(U, V, m, cam, dR, XD, YD, XN, YN, CONV, INV, JK, X, Y, CODE, JP, JUV, need):
    """Ray / ground intersection and all Jacobians, straight-line over the corners (vectorises).

    Mirrors :func:`footprint_uq.cameras.general.backproject` with gradients: X, Y the ground
    point, CODE the status, JP (44, m) = d(x, y)/d(params) (row ``i * 22 + param``),
    JUV (4, m) = d(x, y)/d(u, v) (rows 00, 01, 10, 11).  Invalid corners carry NaN or
    meaningless numbers here; the caller masks them by CODE.  ``need`` (22,) bool: the
    parameters with non-zero variance; JP rows of the others are left unwritten (never read).
    """
    need_sk, need_k, need_k456, need_roll = need[4], need[5], need[10], need[18]
    need_g = need[19] or need[20] or need[21]
    dR0, dR1, dR2 = dR[0], dR[1], dR[2]
    p00, p01, p02, p10, p11, p12, p20, p21, p22 = (dR0[0, 0], dR0[0, 1], dR0[0, 2], dR0[1, 0], dR0[1, 1], dR0[1, 2],
                                                   dR0[2, 0], dR0[2, 1], dR0[2, 2])
    t00, t01, t02, t10, t11, t12, t20, t21, t22 = (dR1[0, 0], dR1[0, 1], dR1[0, 2], dR1[1, 0], dR1[1, 1], dR1[1, 2],
                                                   dR1[2, 0], dR1[2, 1], dR1[2, 2])
    o00, o01, o02, o10, o11, o12, o20, o21, o22 = (dR2[0, 0], dR2[0, 1], dR2[0, 2], dR2[1, 0], dR2[1, 1], dR2[1, 2],
                                                   dR2[2, 0], dR2[2, 1], dR2[2, 2])
    sk, ifx, ify = cam[_C_SK], cam[_C_IFX], cam[_C_IFY]
    skf = sk * ify * ifx
    R0, R1, R2, R3, R4, R5, R6, R7, R8 = (cam[_C_R], cam[_C_R + 1], cam[_C_R + 2], cam[_C_R + 3], cam[_C_R + 4],
                                          cam[_C_R + 5], cam[_C_R + 6], cam[_C_R + 7], cam[_C_R + 8])
    gdz, gx, gy = cam[_C_GDZ], cam[_C_GSX], cam[_C_GSY]
    Nn = gdz - cam[_C_H]
    X0, Y0 = cam[_C_X], cam[_C_Y]
    for j in range(m):
        u, v = U[j], V[j]
        xd, yd, xn, yn = XD[j], YD[j], XN[j], YN[j]
        i00, i01, i10, i11 = INV[0, j], INV[1, j], INV[2, j], INV[3, j]
        finite = math.isfinite(u) & math.isfinite(v)
        dx = R0 * xn + R1 * yn + R2
        dy = R3 * xn + R4 * yn + R5
        dz = R6 * xn + R7 * yn + R8
        Dn = dz - gx * dx - gy * dy
        inv = 1.0 / Dn
        lam = Nn * inv
        vg = (Dn < 0.0) & (Nn < 0.0) & math.isfinite(lam)
        rc = _OK if vg else _ABOVE
        rc = _UNDIST if CONV[j] == 0.0 else rc
        rc = rc if finite else _NOTFIN
        CODE[j] = rc
        X[j] = X0 + lam * dx
        Y[j] = Y0 + lam * dy
        # dxy/dray (2, 3) = lam I + d_xy dlam/dray, dlam/dray = (-lam/Dn) (-gx, -gy, 1)
        f = -lam * inv
        l0, l1, l2 = -gx * f, -gy * f, f
        a00, a01, a02 = lam + dx * l0, dx * l1, dx * l2
        a10, a11, a12 = dy * l0, lam + dy * l1, dy * l2
        # dxy/dxn = dxy/dray @ R[:, :2];  dxy/dxd = dxy/dxn @ dxn/dxd
        b00 = a00 * R0 + a01 * R3 + a02 * R6
        b01 = a00 * R1 + a01 * R4 + a02 * R7
        b10 = a10 * R0 + a11 * R3 + a12 * R6
        b11 = a10 * R1 + a11 * R4 + a12 * R7
        c00 = b00 * i00 + b01 * i10
        c01 = b00 * i01 + b01 * i11
        c10 = b10 * i00 + b11 * i10
        c11 = b10 * i01 + b11 * i11
        # intrinsics: dxd/dk (fx, fy, cx, cy, skew), see pinhole.pixel_to_normalised
        dy_dfy = -yd * ify
        kx0, kx1, kx2, kx3, kx4 = -xd * ifx, -sk * ifx * dy_dfy, -ifx, skf, -yd * ifx
        ky1, ky3 = dy_dfy, -ify
        JP[0, j], JP[22, j] = c00 * kx0, c10 * kx0
        JP[1, j], JP[23, j] = c00 * kx1 + c01 * ky1, c10 * kx1 + c11 * ky1
        JP[2, j], JP[24, j] = c00 * kx2, c10 * kx2
        JP[3, j], JP[25, j] = c00 * kx3 + c01 * ky3, c10 * kx3 + c11 * ky3
        if need_sk:
            JP[4, j], JP[26, j] = c00 * kx4, c10 * kx4
        # distortion: dxy/dxn @ (-(dxd/dxn)^-1 dxd/dk)  (k1 k2 p1 p2 k3, then k4 k5 k6)
        if need_k:
            for kk in range(8 if need_k456 else 5):
                jx, jy = JK[kk, j], JK[8 + kk, j]
                e0 = -(i00 * jx + i01 * jy)
                e1 = -(i10 * jx + i11 * jy)
                JP[5 + kk, j] = b00 * e0 + b01 * e1
                JP[27 + kk, j] = b10 * e0 + b11 * e1
        # camera position
        JP[13, j], JP[14, j], JP[15, j] = 1.0, 0.0, -dx * inv
        JP[35, j], JP[36, j], JP[37, j] = 0.0, 1.0, -dy * inv
        # angles: dxy/dray @ (dR_k @ ray_c)
        q0 = p00 * xn + p01 * yn + p02
        q1 = p10 * xn + p11 * yn + p12
        q2 = p20 * xn + p21 * yn + p22
        JP[16, j] = a00 * q0 + a01 * q1 + a02 * q2
        JP[38, j] = a10 * q0 + a11 * q1 + a12 * q2
        q0 = t00 * xn + t01 * yn + t02
        q1 = t10 * xn + t11 * yn + t12
        q2 = t20 * xn + t21 * yn + t22
        JP[17, j] = a00 * q0 + a01 * q1 + a02 * q2
        JP[39, j] = a10 * q0 + a11 * q1 + a12 * q2
        if need_roll:
            q0 = o00 * xn + o01 * yn + o02
            q1 = o10 * xn + o11 * yn + o12
            q2 = o20 * xn + o21 * yn + o22
            JP[18, j] = a00 * q0 + a01 * q1 + a02 * q2
            JP[40, j] = a10 * q0 + a11 * q1 + a12 * q2
        # ground: d_xy dlam/dg, dlam/dg = (1/Dn, lam dx/Dn, lam dy/Dn)
        if need_g:
            g1, g2 = lam * dx * inv, lam * dy * inv
            JP[19, j], JP[20, j], JP[21, j] = dx * inv, dx * g1, dx * g2
            JP[41, j], JP[42, j], JP[43, j] = dy * inv, dy * g1, dy * g2
        # dxy/duv = dxy/dxd @ dxd/duv
        JUV[0, j] = c00 * ifx
        JUV[1, j] = -c00 * skf + c01 * ify
        JUV[2, j] = c10 * ifx
        JUV[3, j] = -c10 * skf + c11 * ify


@njit(cache=True, error_model="numpy", nogil=True)
def _project(X, Y, Z, cam, uv):
    """World point (Z relative to the nominal ground) -> pixel; returns the status code (general.project)."""
    rx, ry, rz = X - cam[_C_X], Y - cam[_C_Y], Z - cam[_C_H]
    pcx = cam[_C_R + 0] * rx + cam[_C_R + 3] * ry + cam[_C_R + 6] * rz
    pcy = cam[_C_R + 1] * rx + cam[_C_R + 4] * ry + cam[_C_R + 7] * rz
    pcz = cam[_C_R + 2] * rx + cam[_C_R + 5] * ry + cam[_C_R + 8] * rz
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


@njit(cache=True, error_model="numpy", nogil=True)
def _stage_whiten(m, JP, Lr, Lc, Lv, r, AW, C3):
    """AW (2r, m) = rows of J L (row ``2 c + i``); C3 (3, m) = the parameter part of each corner's
    covariance (c00, c01, c11) = (J L)(J L)^T."""
    for c in range(2 * r):
        for j in range(m):
            AW[c, j] = 0.0
    for e in range(Lr.shape[0]):
        c, p, val = Lc[e], Lr[e], Lv[e]
        for j in range(m):
            AW[2 * c, j] += JP[p, j] * val
            AW[2 * c + 1, j] += JP[22 + p, j] * val
    for j in range(m):
        C3[0, j], C3[1, j], C3[2, j] = 0.0, 0.0, 0.0
    for c in range(r):
        for j in range(m):
            a0, a1 = AW[2 * c, j], AW[2 * c + 1, j]
            C3[0, j] += a0 * a0
            C3[1, j] += a0 * a1
            C3[2, j] += a1 * a1


@njit(cache=True, error_model="numpy", nogil=True)
def _v2x(c00, c01, c11, ch, sh, out, n):
    """CPM and J2735 integer fields of one 2x2 covariance (mirror of footprint_uq.v2x)."""
    if not (math.isfinite(c00) and math.isfinite(c01) and math.isfinite(c11)):
        out[n, 0], out[n, 1], out[n, 2] = 4096, 4096, 101
        out[n, 3], out[n, 4], out[n, 5], out[n, 6] = 255, 255, 65535, 0
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
            out[n, i] = 4095
        else:
            m = math.ceil(conf / 0.01 * (1.0 - _GUARD))
            out[n, i] = min(max(m, 1), 4094)
    if c00 > 0.0 and c11 > 0.0:
        rho = c01 / math.sqrt(c00 * c11)
        out[n, 2] = int(min(max(np.rint(rho * 100.0), -100.0), 100.0))
    else:
        out[n, 2] = 101
    mean = 0.5 * (c00 + c11)
    rad = math.sqrt(0.25 * (c00 - c11) * (c00 - c11) + c01 * c01)
    a = math.sqrt(mean + rad)
    b = math.sqrt(max(mean - rad, 0.0))
    for i in range(2):
        s = a if i == 0 else b
        if s >= 12.70:
            out[n, 3 + i] = 254
        else:
            m = math.ceil(s / 0.05 * (1.0 - _GUARD))
            out[n, 3 + i] = min(max(m, 0), 254)
    ang = 0.5 * math.degrees(math.atan2(2.0 * c01, c00 - c11))
    bearing = 90.0 - ang
    bearing = bearing - 180.0 * math.floor(bearing / 180.0)
    if bearing >= 180.0:
        bearing -= 180.0
    if a * a - b * b <= 1e-9 * (a * a + b * b):  # circular: any orientation is right; report north
        bearing = 0.0
    out[n, 5] = int(np.rint(bearing / _ORIENT_UNIT))
    r95 = _K95_2D * a
    cnt = 0
    for lev in _PC_LEVELS:
        if lev >= r95 * (1.0 - _GUARD):
            cnt += 1
    out[n, 6] = cnt


@njit(cache=True, error_model="numpy", nogil=True)
def process_corners(uv, extra_reason, cam, dR, Lr, Lc, Lv, r, spx, det, det_mode, allow_outside, ch, sh,
                    want_joint):
    """The fused per-frame kernel on corners in pixels ``uv`` (N, K, 2).

    extra_reason : (N, K) int8 codes overriding OK (3D projection), or shape (0, 0)
    Lr, Lc, Lv, r : sparse factor of the parameter covariance (:func:`psd_factor`)
    spx : (2, 2) budget pixel covariance;  det : 4-D detector covariance with det_mode
        0 none (any 4-D array), 1 (N, 1, 2, 2) per detection, 2 (N, K, 2, 2) per corner,
        3 (N, 1, 2K, 2K) full
    ch, sh : cos, sin of the heading offset (V2X fields)
    """
    N, K = uv.shape[0], uv.shape[1]
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
    # scratch: corners of CH objects at a time, structure of arrays (corner index last)
    CH = 32
    M = CH * K
    U, V = np.empty(M), np.empty(M)
    XD, YD, XN, YN, CONV = np.empty(M), np.empty(M), np.empty(M), np.empty(M), np.empty(M)
    INV, JK = np.empty((4, M)), np.empty((16, M))
    X, Y, CODE = np.empty(M), np.empty(M), np.empty(M, dtype=np.int64)
    JP, JUV = np.empty((44, M)), np.empty((4, M))
    AW, C3 = np.empty((2 * max(r, 1), M)), np.empty((3, M))
    Jd, Jk = np.empty((2, 2)), np.empty((2, 8))
    Pk = np.empty((K, 2, 2))  # per-corner pixel covariance (diagonal blocks)
    G = np.empty((2, 2 * K))
    H = np.empty((K, 2, 2))
    q = np.empty((K, 2))
    W, Himg = cam[_C_W], cam[_C_HIMG]
    nan = math.nan
    has_extra = extra_reason.shape[0] == N and N > 0
    uvf = uv.reshape(N * K, 2)
    # parameters with a non-zero row in the factor; flags for groups of them: if any of k1..k6 is
    # needed, need[5] (k1..k3, p1, p2) stands for the group, need[10] for k4..k6
    need = np.zeros(22, dtype=np.bool_)
    for e in range(Lr.shape[0]):
        need[Lr[e]] = True
    kd = False
    for e in range(5, 13):
        kd = kd or need[e]
    need[5] = kd
    need[10] = need[10] or need[11] or need[12]
    for n0 in range(0, N, CH):
        n1 = min(N, n0 + CH)
        m = (n1 - n0) * K
        for j in range(m):
            U[j] = uvf[n0 * K + j, 0]
            V[j] = uvf[n0 * K + j, 1]
        _stage_undistort(U, V, m, cam, XD, YD, XN, YN, CONV, INV, JK, Jd, Jk, need)
        _stage_ground(U, V, m, cam, dR, XD, YD, XN, YN, CONV, INV, JK, X, Y, CODE, JP, JUV, need)
        _stage_whiten(m, JP, Lr, Lc, Lv, r, AW, C3)
        for n in range(n0, n1):
            # ---- per object: flags, corner covariances, joint, largest point, centroid, V2X ----
            j0 = (n - n0) * K  # corner k of object n is column j0 + k of the stage arrays
            nan = math.nan
            all_usable = True
            first_bad = -1
            best = -1
            best_semi = -1.0
            for k in range(K):
                jk = j0 + k
                u, v = U[jk], V[jk]
                rc = CODE[jk]
                if rc == _OK and not (u >= -0.5 and u <= W - 0.5 and v >= -0.5 and v <= Himg - 0.5):
                    rc = _OUTSIDE
                if has_extra and extra_reason[n, k] != _OK:
                    rc = extra_reason[n, k]
                computed = rc == _OK or rc == _OUTSIDE
                us = rc == _OK or (rc == _OUTSIDE and allow_outside)
                reason[n, k] = rc
                usable[n, k] = us
                # per-corner pixel covariance
                p00, p01, p10, p11 = spx[0, 0], spx[0, 1], spx[1, 0], spx[1, 1]
                if det_mode == 1:
                    p00 += det[n, 0, 0, 0]
                    p01 += det[n, 0, 0, 1]
                    p10 += det[n, 0, 1, 0]
                    p11 += det[n, 0, 1, 1]
                elif det_mode == 2:
                    p00 += det[n, k, 0, 0]
                    p01 += det[n, k, 0, 1]
                    p10 += det[n, k, 1, 0]
                    p11 += det[n, k, 1, 1]
                elif det_mode == 3:
                    p00 += det[n, 0, 2 * k, 2 * k]
                    p01 += det[n, 0, 2 * k, 2 * k + 1]
                    p10 += det[n, 0, 2 * k + 1, 2 * k]
                    p11 += det[n, 0, 2 * k + 1, 2 * k + 1]
                Pk[k, 0, 0], Pk[k, 0, 1], Pk[k, 1, 0], Pk[k, 1, 1] = p00, p01, p10, p11
                if computed:
                    xy[n, k, 0], xy[n, k, 1] = X[jk], Y[jk]
                    j00, j01, j10, j11 = JUV[0, jk], JUV[1, jk], JUV[2, jk], JUV[3, jk]
                    m00, m01 = j00 * p00 + j01 * p10, j00 * p01 + j01 * p11
                    m10, m11 = j10 * p00 + j11 * p10, j10 * p01 + j11 * p11
                    c00 = C3[0, jk] + m00 * j00 + m01 * j01
                    c01 = C3[1, jk] + m00 * j10 + m01 * j11
                    c10 = c01
                    c11 = C3[2, jk] + m10 * j10 + m11 * j11
                    ccov[n, k, 0, 0], ccov[n, k, 0, 1], ccov[n, k, 1, 0], ccov[n, k, 1, 1] = c00, c01, c10, c11
                    semi = math.sqrt(0.5 * (c00 + c11) + math.sqrt(0.25 * (c00 - c11) * (c00 - c11) + c01 * c01))
                    if us and semi > best_semi:
                        best_semi = semi
                        best = k
                else:
                    xy[n, k, 0], xy[n, k, 1] = nan, nan
                    for i in range(2):
                        for j in range(2):
                            ccov[n, k, i, j] = nan
                if not us and all_usable:
                    all_usable = False
                    first_bad = k
            # joint covariance (optional): diagonal blocks = corner covariances, off-diagonal
            # blocks = shared parameter part (+ detector cross terms in the full form)
            if want_joint:
                for k in range(K):
                    ck = reason[n, k] == _OK or reason[n, k] == _OUTSIDE
                    for l in range(k, K):
                        cl = reason[n, l] == _OK or reason[n, l] == _OUTSIDE
                        if not (ck and cl):
                            v00, v01, v10, v11 = nan, nan, nan, nan
                        elif k == l:
                            v00, v01 = ccov[n, k, 0, 0], ccov[n, k, 0, 1]
                            v10, v11 = ccov[n, k, 1, 0], ccov[n, k, 1, 1]
                        else:
                            v00, v01, v10, v11 = 0.0, 0.0, 0.0, 0.0
                            for c in range(r):
                                a0k, a1k = AW[2 * c, j0 + k], AW[2 * c + 1, j0 + k]
                                a0l, a1l = AW[2 * c, j0 + l], AW[2 * c + 1, j0 + l]
                                v00 += a0k * a0l
                                v01 += a0k * a1l
                                v10 += a1k * a0l
                                v11 += a1k * a1l
                            if det_mode == 3:
                                for a in range(2):
                                    for b in range(2):
                                        p = det[n, 0, 2 * k + a, 2 * l + b]
                                        v00 += JUV[a, j0 + k] * p * JUV[b, j0 + l]
                                        v01 += JUV[a, j0 + k] * p * JUV[2 + b, j0 + l]
                                        v10 += JUV[2 + a, j0 + k] * p * JUV[b, j0 + l]
                                        v11 += JUV[2 + a, j0 + k] * p * JUV[2 + b, j0 + l]
                        joint[n, 2 * k, 2 * l], joint[n, 2 * k, 2 * l + 1] = v00, v01
                        joint[n, 2 * k + 1, 2 * l], joint[n, 2 * k + 1, 2 * l + 1] = v10, v11
                        joint[n, 2 * l, 2 * k], joint[n, 2 * l + 1, 2 * k] = v00, v01
                        joint[n, 2 * l, 2 * k + 1], joint[n, 2 * l + 1, 2 * k + 1] = v10, v11
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
                        kn = k + 1 if k + 1 < K else 0  # (k + 1) % K without an integer division
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
                            kn = k + 1 if k + 1 < K else 0  # (k + 1) % K without an integer division
                            kp = k - 1 if k > 0 else K - 1
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
                # parameter part: B = sum_k G_k (J_k L), cov = B B^T
                e00, e01, e11 = 0.0, 0.0, 0.0
                for c in range(r):
                    b0, b1 = 0.0, 0.0
                    for k in range(K):
                        a0, a1 = AW[2 * c, j0 + k], AW[2 * c + 1, j0 + k]
                        b0 += G[0, 2 * k] * a0 + G[0, 2 * k + 1] * a1
                        b1 += G[1, 2 * k] * a0 + G[1, 2 * k + 1] * a1
                    e00 += b0 * b0
                    e01 += b0 * b1
                    e11 += b1 * b1
                # pixel part: H_k = G_k Juv_k, sum_k,l H_k P_kl H_l^T
                for k in range(K):
                    for i in range(2):
                        for j in range(2):
                            H[k, i, j] = G[i, 2 * k] * JUV[j, j0 + k] + G[i, 2 * k + 1] * JUV[2 + j, j0 + k]
                for k in range(K):
                    h00, h01, h10, h11 = H[k, 0, 0], H[k, 0, 1], H[k, 1, 0], H[k, 1, 1]
                    p00, p01, p10, p11 = Pk[k, 0, 0], Pk[k, 0, 1], Pk[k, 1, 0], Pk[k, 1, 1]
                    m00, m01 = h00 * p00 + h01 * p10, h00 * p01 + h01 * p11
                    m10, m11 = h10 * p00 + h11 * p10, h10 * p01 + h11 * p11
                    e00 += m00 * h00 + m01 * h01
                    e01 += m00 * h10 + m01 * h11
                    e11 += m10 * h10 + m11 * h11
                    if det_mode == 3:  # detector cross terms between corners
                        for l in range(K):
                            if l == k:
                                continue
                            for a in range(2):
                                for b in range(2):
                                    p = det[n, 0, 2 * k + a, 2 * l + b]
                                    e00 += H[k, 0, a] * p * H[l, 0, b]
                                    e01 += H[k, 0, a] * p * H[l, 1, b]
                                    e11 += H[k, 1, a] * p * H[l, 1, b]
                centre_cov[n, 0, 0], centre_cov[n, 0, 1] = e00, e01
                centre_cov[n, 1, 0], centre_cov[n, 1, 1] = e01, e11
                _v2x(e00, e01, e11, ch, sh, v2x, n)
            else:
                centre[n, 0], centre[n, 1] = nan, nan
                for i in range(2):
                    for j in range(2):
                        centre_cov[n, i, j] = nan
                _v2x(nan, nan, nan, ch, sh, v2x, n)
                if code == _DEGENERATE:
                    centre_bad[n] = -1
    return (xy, ccov, joint, reason, usable, largest_index, largest_semi, largest_xy, largest_cov,
            centre, centre_cov, centre_reason, centre_bad, area_out, v2x)


@njit(cache=True, error_model="numpy", nogil=True)
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


@njit(cache=True, error_model="numpy", nogil=True)
def process_boxes3d(boxes, yaw_deg, bottom_on_ground, cam, dR, Lr, Lc, Lv, r, spx, det, det_mode, allow_outside,
                    ch, sh, want_joint):
    """:func:`boxes3d_to_pixels` then :func:`process_corners` in one dispatch; returns (bad_row, uv, results)."""
    uv, code, bad = boxes3d_to_pixels(boxes, cam, yaw_deg, bottom_on_ground)
    res = process_corners(uv, code, cam, dR, Lr, Lc, Lv, r, spx, det, det_mode, allow_outside, ch, sh, want_joint)
    return bad, uv, res
