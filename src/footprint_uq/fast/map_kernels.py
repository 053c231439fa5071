"""Fused per-pixel kernels: ground point and 2x2 covariance of every pixel (numba).

The public entries (budget loading, input checks, the camera's constants) are
:func:`footprint_uq.products.covariance.covariance_map` and
:func:`~footprint_uq.products.covariance.covariance_points`; this module holds the kernels and the
array-level :func:`map_into` / :func:`points_into` that dispatch to them, and imports nothing above
``fast/`` (``docs/architecture.md``).

These compute exactly what :func:`footprint_uq.uncertainty.propagation.propagate` computes
(first-order ``Cov = J_p Sigma_p J_p^T + J_uv Sigma_uv J_uv^T``), without ever
materialising the ``(..., 2, 22)`` Jacobians, so that a full-HD map takes
milliseconds.  They agree with :func:`~footprint_uq.uncertainty.propagation.propagate` to
about 1e-12 relative (tests ask for 1e-9).  The only fast-math flag is
``contract`` (fused multiply-add); no reassociation, NaN/inf semantics kept.

Formulation (valid for any camera of the shared parameter vector):

* The ray of a pixel is ``d = R q`` with ``q = (x_n, y_n, 1)`` the undistorted
  normalised coordinates and ``R = R_W_C(pan, tilt, roll)``.  It meets the
  ground ``z = dz + gx (x - x0) + gy (y - y0)`` at ``xy = (x0, y0) + o`` with
  ``o = Hn w d_xy``, ``Hn = h - dz``, ``w = -1 / (g~ . d)``, ``g~ = (-gx, -gy, 1)``.
  For the pan-tilt camera this is the paper's closed form written with ``R``:
  ``(d_x, d_y, -d_z)`` is ``(nY, nX, s)`` up to a common factor, so
  ``o = h (nY, nX) / s``.
* Every camera-level parameter moves the ground point through an 8-dimensional
  *state* ``(dq_0, dq_1, x0, y0, h, dz, gx, gy)``: intrinsics, distortion and the
  three angles act on the ray only, i.e. on the normalised coordinates
  (``dq``, rotations as ``w x q`` minus its component along the ray); position,
  height and ground act directly.  With ``Q = d xy / d q = w (Hn R_xy + o (g~ R))``
  (2x2) and ``a = o / Hn``::

      d xy = Q dq + (dx0, dy0) + a (dh - ddz - o_x dgx - o_y dgy)

  so ``Cov = Q C_qq Q^T + C_pos + a a^T (rho^T C_hg rho) + cross terms``
  with ``rho = (1, -1, -o_x, -o_y)`` and ``C`` the state covariance.
* Pan-tilt / undistorted kernel: along an image row ``y_n`` is constant and every
  ``dq`` is a polynomial in ``x_n`` (degree <= 7, from k3), so ``C_qq`` is three
  polynomials in ``x_n`` (degree <= 14) whose coefficients are computed once per
  row from any (full) parameter covariance; a pixel then costs a division, three
  Horner evaluations and a 2x2 sandwich.  Pixel noise adds a constant.
* OpenCV kernel with distortion: Newton undistortion per pixel, one image row
  at a time (vectorised over the row; same tolerance, iteration limit and
  convergence test -- residual <= 1e-14 max(1, |x_d|) and det > 0 -- as
  :func:`footprint_uq.cameras.distortion.undistort`, but started from the
  previous row's solution continued to first order, which needs 2-3 iterations
  instead of 5-8; a pixel whose neighbour above did not converge starts from
  ``x_d`` as the reference does).  Then ``dq`` of each parameter
  (``M = (d distort / d x)^-1``; intrinsics ``M d x_d``, distortion
  ``-M d distort / d k``) and the state covariance from a sparse factor
  ``Sigma = L L^T`` of the budget (per connected block, scaled to a correlation
  matrix so that parameters of very different units keep their relative
  precision).  Factor columns acting on the intrinsics only (with the pixel
  noise: a polynomial in ``x_d`` per row) or on the angles only (a 3x3
  covariance of the rotation vector) are folded into the last pass; the others
  (distortion, mixed) cost one vectorised pass over the row each.

* Linearity flag (``get_nonlinearity``): the ray denominator ``Dn = g~ . d`` also depends on
  the component ``z`` of a rotation's ray change along the ray (which the ground point
  ignores), so the state gains ``z`` (per-row polynomials ``ZQ``/``ZZ``/``BZ`` in the pan-tilt
  kernel, buffer rows ``Z``/``QZ0``/``QZ1``/``ZZ`` and ``BQ[12:18]`` in the general one); the
  quadratic forms the flag needs come from the state covariance (:func:`_flag`) and the scalar
  core evaluates it (:func:`footprint_uq.fast.core.nonlinearity_point`), in the same pass.

Structure: each row of the general kernel goes through small stages (:func:`_row_undistort`,
:func:`_row_intrinsics`, :func:`_row_mixed`, :func:`_row_pixels`, :func:`_row_qc`,
:func:`_row_flag`); its buffer's rows are named in :data:`BUF_ROWS`.

Performance notes (see ``bench/``): the pixel loops are written on 1-D views of
one output row so that LLVM vectorises them (2-D indexing or a runtime-length
inner loop defeats the vectoriser).  ``fastmath={"contract"}`` (FMA only,
NaN/inf semantics kept) measured 25-45 % less CPU time than ``fastmath=False``
at the same 1e-12 agreement with the numpy reference.

Invalid pixels (ray at or above the horizon, lens model not invertible) get NaN
and ``valid = False``.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from numba.np.unsafe.ndarray import to_fixed_tuple

from .. import params as P
from .. import status
from . import core
from .buffers import thread_buffer
from .cores import free_cores

__all__ = ["map_into", "points_into", "SERIAL_BELOW", "BUF_ROWS", "MAP_KERNELS", "POINT_KERNELS"]

_JIT = dict(parallel=True, fastmath={"contract"}, cache=True, error_model="numpy")
_JIT1 = dict(fastmath={"contract"}, cache=True, error_model="numpy")


# --------------------------------------------------------------------------------------
# per-row polynomials of the undistorted kernel
# --------------------------------------------------------------------------------------
@nb.njit(**_JIT1)
def _add_ray_poly(k, lv, yn, prm, om, a, b):
    """Add ``lv * dq_k(x)`` to the polynomials ``a`` (dq_0) and ``b`` (dq_1) in ``x = x_n`` (row ``y_n``).

    Zero nominal distortion; coefficient arrays have length 8 (degree <= 7).
    """
    fx, fy, sk = prm[0], prm[1], prm[4]
    y2 = yn * yn
    if k == 0:  # fx: dx_n = -x_n / fx
        a[1] -= lv / fx
    elif k == 1:  # fy
        a[0] += lv * sk * yn / (fx * fy)
        b[0] -= lv * yn / fy
    elif k == 2:  # cx
        a[0] -= lv / fx
    elif k == 3:  # cy
        a[0] += lv * sk / (fx * fy)
        b[0] -= lv / fy
    elif k == 4:  # skew
        a[0] -= lv * yn / fx
    elif k == 5 or k == 6 or k == 9 or k == 10 or k == 11 or k == 12:
        # radial: dq = -(x, y) r2^n (k1, k2, k3), +(x, y) r2^n (k4, k5, k6); r2 = x^2 + y2
        sgn = -lv if k <= 9 else lv
        n = 1 if (k == 5 or k == 10) else (2 if (k == 6 or k == 11) else 3)
        if n == 1:
            c0, c2, c4, c6 = y2, 1.0, 0.0, 0.0
        elif n == 2:
            c0, c2, c4, c6 = y2 * y2, 2.0 * y2, 1.0, 0.0
        else:
            c0, c2, c4, c6 = y2 * y2 * y2, 3.0 * y2 * y2, 3.0 * y2, 1.0
        a[1] += sgn * c0
        a[3] += sgn * c2
        a[5] += sgn * c4
        a[7] += sgn * c6
        b[0] += sgn * yn * c0
        b[2] += sgn * yn * c2
        b[4] += sgn * yn * c4
        b[6] += sgn * yn * c6
    elif k == 7:  # p1: dq = -(2 x y, x^2 + 3 y^2)
        a[1] -= 2.0 * lv * yn
        b[0] -= 3.0 * lv * y2
        b[2] -= lv
    elif k == 8:  # p2: dq = -(3 x^2 + y^2, 2 x y)
        a[0] -= lv * y2
        a[2] -= 3.0 * lv
        b[1] -= 2.0 * lv * yn
    elif k == 16 or k == 17 or k == 18:
        # rotation generator w: dq = (w1 - w2 y - w0 x y + w1 x^2, -w0 (1 + y^2) + w2 x + w1 x y)
        i = k - 16
        w0, w1, w2 = om[i, 0], om[i, 1], om[i, 2]
        a[0] += lv * (w1 - w2 * yn)
        a[1] -= lv * w0 * yn
        a[2] += lv * w1
        b[0] -= lv * w0 * (1.0 + y2)
        b[1] += lv * (w2 + w1 * yn)


@nb.njit(**_JIT1)
def _horner14(c, x):
    """Degree-14 polynomial, Estrin's scheme (shorter dependency chains than Horner)."""
    x2 = x * x
    x4 = x2 * x2
    x8 = x4 * x4
    a0 = c[0] + c[1] * x
    a1 = c[2] + c[3] * x
    a2 = c[4] + c[5] * x
    a3 = c[6] + c[7] * x
    a4 = c[8] + c[9] * x
    a5 = c[10] + c[11] * x
    a6 = c[12] + c[13] * x
    b0 = a0 + a1 * x2
    b1 = a2 + a3 * x2
    b2 = a4 + a5 * x2
    b3 = a6 + c[14] * x2
    return (b0 + b1 * x4) + (b2 + b3 * x4) * x8


@nb.njit(inline="always", **_JIT1)
def _horner8(c, x):
    """Degree-8 polynomial ``c`` (9,) at ``x``."""
    x2 = x * x
    x4 = x2 * x2
    return ((c[0] + c[1] * x) + (c[2] + c[3] * x) * x2) + ((c[4] + c[5] * x) + (c[6] + c[7] * x) * x2) * x4 \
        + c[8] * (x4 * x4)


@nb.njit(**_JIT1)
def _horner7(c, x):
    r = c[7]
    r = r * x + c[6]
    r = r * x + c[5]
    r = r * x + c[4]
    r = r * x + c[3]
    r = r * x + c[2]
    r = r * x + c[1]
    return r * x + c[0]


@nb.njit(**_JIT1)
def _finish(q00, q01, q11, Q00, Q01, Q10, Q11, ax, ay, ox, oy, Ccc, bq, has_qc):
    """Covariance from the state covariance (see module docstring); bq (2, 6) q/constant cross terms."""
    # Q C_qq Q^T
    A00 = Q00 * q00 + Q01 * q01
    A01 = Q00 * q01 + Q01 * q11
    A10 = Q10 * q00 + Q11 * q01
    A11 = Q10 * q01 + Q11 * q11
    c00 = A00 * Q00 + A01 * Q01
    c01 = A00 * Q10 + A01 * Q11
    c11 = A10 * Q10 + A11 * Q11
    # position block
    c00 += Ccc[0, 0]
    c01 += Ccc[0, 1]
    c11 += Ccc[1, 1]
    # height / ground block: a a^T rho^T C rho, rho = (1, -1, -ox, -oy)
    r0, r1, r2, r3 = 1.0, -1.0, -ox, -oy
    t2 = Ccc[2, 2] * r0 + Ccc[2, 3] * r1 + Ccc[2, 4] * r2 + Ccc[2, 5] * r3
    t3 = Ccc[3, 2] * r0 + Ccc[3, 3] * r1 + Ccc[3, 4] * r2 + Ccc[3, 5] * r3
    t4 = Ccc[4, 2] * r0 + Ccc[4, 3] * r1 + Ccc[4, 4] * r2 + Ccc[4, 5] * r3
    t5 = Ccc[5, 2] * r0 + Ccc[5, 3] * r1 + Ccc[5, 4] * r2 + Ccc[5, 5] * r3
    s = r0 * t2 + r1 * t3 + r2 * t4 + r3 * t5
    c00 += s * ax * ax
    c01 += s * ax * ay
    c11 += s * ay * ay
    # position x (height, ground) cross: m = C_p,hg rho
    m0 = Ccc[0, 2] * r0 + Ccc[0, 3] * r1 + Ccc[0, 4] * r2 + Ccc[0, 5] * r3
    m1 = Ccc[1, 2] * r0 + Ccc[1, 3] * r1 + Ccc[1, 4] * r2 + Ccc[1, 5] * r3
    c00 += 2.0 * m0 * ax
    c01 += m0 * ay + ax * m1
    c11 += 2.0 * m1 * ay
    if has_qc:
        # ray x position: E = Q B_qp, cov += E + E^T
        E00 = Q00 * bq[0, 0] + Q01 * bq[1, 0]
        E01 = Q00 * bq[0, 1] + Q01 * bq[1, 1]
        E10 = Q10 * bq[0, 0] + Q11 * bq[1, 0]
        E11 = Q10 * bq[0, 1] + Q11 * bq[1, 1]
        c00 += 2.0 * E00
        c01 += E01 + E10
        c11 += 2.0 * E11
        # ray x (height, ground): n = Q (B_qh rho); cov += n a^T + a n^T
        g0 = bq[0, 2] * r0 + bq[0, 3] * r1 + bq[0, 4] * r2 + bq[0, 5] * r3
        g1 = bq[1, 2] * r0 + bq[1, 3] * r1 + bq[1, 4] * r2 + bq[1, 5] * r3
        n0 = Q00 * g0 + Q01 * g1
        n1 = Q10 * g0 + Q11 * g1
        c00 += 2.0 * n0 * ax
        c01 += n0 * ay + ax * n1
        c11 += 2.0 * n1 * ay
    return c00, c01, c11


@nb.njit(inline="always", **_JIT1)
def _flag(c00, c01, c11, dn, idn, lam, dxr, dyr, ox, oy, ax, ay, Q00, Q01, Q10, Q11, g0, g1, q00, q01, q11, zq0, zq1,
          zz, cc, has_qc, bq, bz):
    """Nonlinearity of one pixel (:func:`footprint_uq.fast.core.nonlinearity_point`) from its state covariance.

    State ``(q0, q1 | z | x0, y0, h, dz, gx, gy)``: ``z`` is the component of a rotation's ray
    change along the ray itself (``omega x q~`` = ``(dq, 0) + z q~``), which moves ``Dn`` but not
    the ground point.  ``J = A_J S`` with ``A_J = [Q | 0 | I2 | a (1, -1, -o_x, -o_y)]`` and
    ``g = a_g S`` with ``a_g = (g0, g1 | Dn | 0, 0, 0, 0, -d_x, -d_y)``, so ``J Sigma g = A_J C_s a_g``,
    ``g^T Sigma g = a_g . C_s a_g`` and ``J Sigma E = A_J C_s[:, (x0, y0)]``.  Pieces of ``C_s``:
    ``q00, q01, q11`` (ray, pixel noise included), ``zq0, zq1, zz`` (z rows), ``cc`` the constants'
    covariance ``Ccc`` (6, 6) as a flat tuple (row-major: a pixel loop then reads no array and
    vectorises), and with ``has_qc`` ``bq`` (2, 6) / ``bz`` (6,) the ray / constant cross terms.  ``idn = 1 / Dn``
    (``-lam / Hn``, which the caller holds: no division by ``Dn`` here).
    """
    uq0 = q00 * g0 + q01 * g1 + zq0 * dn
    uq1 = q01 * g0 + q11 * g1 + zq1 * dn
    uz = zq0 * g0 + zq1 * g1 + zz * dn
    uc0 = -(cc[4] * dxr + cc[5] * dyr)
    uc1 = -(cc[10] * dxr + cc[11] * dyr)
    uc2 = -(cc[16] * dxr + cc[17] * dyr)
    uc3 = -(cc[22] * dxr + cc[23] * dyr)
    uc4 = -(cc[28] * dxr + cc[29] * dyr)
    uc5 = -(cc[34] * dxr + cc[35] * dyr)
    h0 = cc[12] - cc[18] - ox * cc[24] - oy * cc[30]
    h1 = cc[13] - cc[19] - ox * cc[25] - oy * cc[31]
    X00 = cc[0] + ax * h0
    X01 = cc[1] + ax * h1
    X10 = cc[6] + ay * h0
    X11 = cc[7] + ay * h1
    if has_qc:
        uq0 -= bq[0, 4] * dxr + bq[0, 5] * dyr
        uq1 -= bq[1, 4] * dxr + bq[1, 5] * dyr
        uz -= bz[4] * dxr + bz[5] * dyr
        uc0 += bq[0, 0] * g0 + bq[1, 0] * g1 + bz[0] * dn
        uc1 += bq[0, 1] * g0 + bq[1, 1] * g1 + bz[1] * dn
        uc2 += bq[0, 2] * g0 + bq[1, 2] * g1 + bz[2] * dn
        uc3 += bq[0, 3] * g0 + bq[1, 3] * g1 + bz[3] * dn
        uc4 += bq[0, 4] * g0 + bq[1, 4] * g1 + bz[4] * dn
        uc5 += bq[0, 5] * g0 + bq[1, 5] * g1 + bz[5] * dn
        X00 += Q00 * bq[0, 0] + Q01 * bq[1, 0]
        X01 += Q00 * bq[0, 1] + Q01 * bq[1, 1]
        X10 += Q10 * bq[0, 0] + Q11 * bq[1, 0]
        X11 += Q10 * bq[0, 1] + Q11 * bq[1, 1]
    gamma = g0 * uq0 + g1 * uq1 + dn * uz - dxr * uc4 - dyr * uc5
    hg = uc2 - uc3 - ox * uc4 - oy * uc5
    jg0 = Q00 * uq0 + Q01 * uq1 + uc0 + ax * hg
    jg1 = Q10 * uq0 + Q11 * uq1 + uc1 + ay * hg
    return core.nonlinearity_point_idn(c00, c01, c11, idn, lam, dxr, dyr, jg0, jg1, gamma, uc0, uc1, X00, X01, X10,
                                       X11, cc[0], cc[1], cc[7])


# --------------------------------------------------------------------------------------
# kernel 1: zero nominal distortion (the paper's pan-tilt camera), per-row polynomials
# --------------------------------------------------------------------------------------
@nb.njit(**_JIT1)
def _row_polys(yn, prm, om, colptr, rowidx, vals, vc, has_qc, Cpq, P00, P01, P11, BQ, flag, ZQ, ZZ, BZ):
    """Per-row polynomial coefficients of C_qq (degree 14) and of the q/constant cross terms (degree 7).

    With ``flag`` also those of the rotations' ray-scale component ``z = w0 y_n - w1 x_n`` (see
    :func:`_flag`): ``ZQ`` (2, 9) its covariance with ``dq`` (degree 8), ``ZZ`` (3,) its variance,
    ``BZ`` (6, 2) (with ``has_qc``) its covariance with the constant state.
    """
    P00[:] = 0.0
    P01[:] = 0.0
    P11[:] = 0.0
    BQ[:] = 0.0
    if flag:
        ZQ[:] = 0.0
        ZZ[:] = 0.0
        BZ[:] = 0.0
    a = np.empty(8)
    b = np.empty(8)
    r = colptr.size - 1
    for j in range(r):
        a[:] = 0.0
        b[:] = 0.0
        z0, z1 = 0.0, 0.0
        ray = False
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            if k < 13 or (k >= 16 and k <= 18):
                _add_ray_poly(k, vals[nz], yn, prm, om, a, b)
                ray = True
            if k >= 16 and k <= 18:
                z0 += vals[nz] * om[k - 16, 0] * yn
                z1 -= vals[nz] * om[k - 16, 1]
        if not ray:
            continue
        for i in range(8):
            ai = a[i]
            bi = b[i]
            for m in range(8):
                P00[i + m] += ai * a[m]
                P01[i + m] += ai * b[m]
                P11[i + m] += bi * b[m]
        if flag:
            for i in range(8):
                ZQ[0, i] += a[i] * z0
                ZQ[0, i + 1] += a[i] * z1
                ZQ[1, i] += b[i] * z0
                ZQ[1, i + 1] += b[i] * z1
            ZZ[0] += z0 * z0
            ZZ[1] += 2.0 * z0 * z1
            ZZ[2] += z1 * z1
        if has_qc:
            for c in range(6):
                v = vc[j, c]
                if v != 0.0:
                    for i in range(8):
                        BQ[0, c, i] += a[i] * v
                        BQ[1, c, i] += b[i] * v
                    if flag:
                        BZ[c, 0] += z0 * v
                        BZ[c, 1] += z1 * v
    P00[0] += Cpq[0, 0]
    P01[0] += Cpq[0, 1]
    P11[0] += Cpq[1, 1]


_CST_NAMES = ("x0", "y0", "Hn", "g0", "g1", "HR00", "HR01", "HR10", "HR11", "R00", "R10",
              "p00", "p01", "p11", "s0", "s1", "s2", "s3", "s4", "s5",
              "m00", "m01", "m02", "m10", "m11", "m12", "iHn", "stepf", "ifx", "g2")


def _undistorted_constants(k: dict, step: int) -> np.ndarray:
    """Camera-level scalars of the undistorted kernel (order :data:`_CST_NAMES`)."""
    prm, R, C = k["params"], k["R"], k["Ccc"]
    Hn = prm[P.HM] - prm[P.GDZ]
    gx, gy = prm[P.GSX], prm[P.GSY]
    g = R[2] - gx * R[0] - gy * R[1]  # g~ . R[:, c]
    # height/ground block: rho = e + ox f + oy g with e = (1, -1, 0, 0), f = -e_gx, g = -e_gy
    Chg = C[2:6, 2:6]
    e = np.array([1.0, -1.0, 0.0, 0.0])
    f = np.array([0.0, 0.0, -1.0, 0.0])
    gg = np.array([0.0, 0.0, 0.0, -1.0])
    s = (e @ Chg @ e, 2 * e @ Chg @ f, 2 * e @ Chg @ gg, f @ Chg @ f, 2 * f @ Chg @ gg, gg @ Chg @ gg)
    m = [(C[a, 2:6] @ e, C[a, 2:6] @ f, C[a, 2:6] @ gg) for a in (0, 1)]
    vals = dict(x0=prm[P.XM], y0=prm[P.YM], Hn=Hn, g0=g[0], g1=g[1], HR00=Hn * R[0, 0], HR01=Hn * R[0, 1],
                HR10=Hn * R[1, 0], HR11=Hn * R[1, 1], R00=R[0, 0], R10=R[1, 0], p00=C[0, 0], p01=C[0, 1],
                p11=C[1, 1], s0=s[0], s1=s[1], s2=s[2], s3=s[3], s4=s[4], s5=s[5], m00=m[0][0], m01=m[0][1],
                m02=m[0][2], m10=m[1][0], m11=m[1][1], m12=m[1][2], iHn=1.0 / Hn, stepf=float(step),
                ifx=1.0 / prm[P.FX], g2=g[2])
    return np.array([vals[n] for n in _CST_NAMES], dtype=np.float64)


@nb.njit(inline="always", **_JIT1)
def _pixel_undistorted(cst, x, dx0, dy0, dn0, P00, P01, P11):
    """Ground offset and covariance of one pixel at normalised column ``x`` of a row (shared by the row kernels).

    Returns ``(ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11, dn, lam, dxr, dyr, q00, q01, q11)``
    (the last seven for the linearity flag: ray denominator, depth, ray, ray-state covariance).
    """
    g0 = cst[3]
    dxr = dx0 + x * cst[9]
    dyr = dy0 + x * cst[10]
    dn = dn0 + x * g0
    ok = dn < 0.0
    lam, ox, oy, Q00, Q01, Q10, Q11 = core.ground_of_ray(cst[2], cst[5], cst[6], cst[7], cst[8], g0, cst[4], dxr,
                                                         dyr, dn)
    q00 = _horner14(P00, x)
    q01 = _horner14(P01, x)
    q11 = _horner14(P11, x)
    # Q C_qq Q^T
    A00 = Q00 * q00 + Q01 * q01
    A01 = Q00 * q01 + Q01 * q11
    A10 = Q10 * q00 + Q11 * q01
    A11 = Q10 * q01 + Q11 * q11
    c00 = A00 * Q00 + A01 * Q01 + cst[11]
    c01 = A00 * Q10 + A01 * Q11 + cst[12]
    c11 = A10 * Q10 + A11 * Q11 + cst[13]
    # height / ground: a a^T rho^T C rho, a = o / Hn; position x (height, ground) cross
    ax = ox * cst[26]
    ay = oy * cst[26]
    sv = cst[14] + ox * (cst[15] + cst[17] * ox + cst[18] * oy) + oy * (cst[16] + cst[19] * oy)
    mx = cst[20] + cst[21] * ox + cst[22] * oy
    my = cst[23] + cst[24] * ox + cst[25] * oy
    c00 += (sv * ax + 2.0 * mx) * ax
    c01 += sv * ax * ay + mx * ay + ax * my
    c11 += (sv * ay + 2.0 * my) * ay
    return ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11, dn, lam, dxr, dyr, q00, q01, q11


@nb.njit(inline="always", **_JIT1)
def _finite(a):
    """``a`` is finite (``a - a`` is 0 for finite numbers, NaN for inf and NaN): branch-free, vectorises."""
    return (a - a) == 0.0


@nb.njit(inline="always", **_JIT1)
def _store_pixel(xr, cr, vr, iu, ok, x, y, c00, c01, c11):
    """Store one pixel; returns whether it is valid: ``ok`` (it meets the ground) and every output finite
    (the outputs are checked in the same pass: a computed pixel that is not finite is OVERFLOW, NaN)."""
    nan = np.nan
    good = ok & _finite(x) & _finite(y) & _finite(c00) & _finite(c01) & _finite(c11)
    xr[2 * iu] = x if good else nan
    xr[2 * iu + 1] = y if good else nan
    cr[4 * iu] = c00 if good else nan
    cr[4 * iu + 1] = c01 if good else nan
    cr[4 * iu + 2] = c01 if good else nan
    cr[4 * iu + 3] = c11 if good else nan
    vr[iu] = good
    return good


@nb.njit(**_JIT1)
def _row_undistorted(cst, cxs, dx0, dy0, dn0, P00, P01, P11, xr, cr, vr):
    """One image row (1-D views of the outputs, so that LLVM vectorises the pixel loop)."""
    # constants and polynomials as scalars: stores to the outputs cannot make the loop reload them (it vectorises)
    cs = to_fixed_tuple(cst, 30)
    p00, p01, p11 = to_fixed_tuple(P00, 15), to_fixed_tuple(P01, 15), to_fixed_tuple(P11, 15)
    x0, y0, stepf, ifx = cs[0], cs[1], cs[27], cs[28]
    for iu in range(vr.shape[0]):
        x = (np.float64(iu) * stepf - cxs) * ifx
        ok, ox, oy, _, _, _, _, _, _, c00, c01, c11, _, _, _, _, _, _, _ = _pixel_undistorted(cs, x, dx0, dy0, dn0,
                                                                                             p00, p01, p11)
        _store_pixel(xr, cr, vr, iu, ok, x0 + ox, y0 + oy, c00, c01, c11)


@nb.njit(**_JIT1)
def _row_undistorted_flag(cst, cxs, dx0, dy0, dn0, P00, P01, P11, ZQ, ZZ, Ccc, xr, cr, vr, nr):
    """As :func:`_row_undistorted`, with the linearity flag into ``nr`` (NaN where not valid)."""
    # every coefficient as a tuple: the pixel loop reads no array (LLVM vectorises it without alias checks)
    cs = to_fixed_tuple(cst, 30)
    p00, p01, p11 = to_fixed_tuple(P00, 15), to_fixed_tuple(P01, 15), to_fixed_tuple(P11, 15)
    zq0c, zq1c, zzc = to_fixed_tuple(ZQ[0], 9), to_fixed_tuple(ZQ[1], 9), to_fixed_tuple(ZZ, 3)
    cc = to_fixed_tuple(Ccc.ravel(), 36)
    x0, y0, g0, g1, stepf, ifx = cs[0], cs[1], cs[3], cs[4], cs[27], cs[28]
    bq = np.zeros((2, 6))
    bz = np.zeros(6)
    for iu in range(vr.shape[0]):
        x = (np.float64(iu) * stepf - cxs) * ifx
        ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11, dn, lam, dxr, dyr, q00, q01, q11 = \
            _pixel_undistorted(cs, x, dx0, dy0, dn0, p00, p01, p11)
        zq0 = _horner8(zq0c, x)
        zq1 = _horner8(zq1c, x)
        zz = zzc[0] + x * (zzc[1] + x * zzc[2])
        nl = _flag(c00, c01, c11, dn, -lam * cs[26], lam, dxr, dyr, ox, oy, ax, ay, Q00, Q01, Q10, Q11, g0, g1, q00,
                   q01, q11, zq0, zq1, zz, cc, False, bq, bz)
        good = _store_pixel(xr, cr, vr, iu, ok, x0 + ox, y0 + oy, c00, c01, c11)
        nr[iu] = nl if good else np.nan


@nb.njit(inline="always", **_JIT1)
def _qc_terms(Q00, Q01, Q10, Q11, ax, ay, ox, oy, bq):
    """Covariance terms of the ray / constant cross-covariance ``bq`` (2, 6): ``(d00, d01, d11)``."""
    E00 = Q00 * bq[0, 0] + Q01 * bq[1, 0]
    E01 = Q00 * bq[0, 1] + Q01 * bq[1, 1]
    E10 = Q10 * bq[0, 0] + Q11 * bq[1, 0]
    E11 = Q10 * bq[0, 1] + Q11 * bq[1, 1]
    rx, ry = -ox, -oy
    h0 = bq[0, 2] - bq[0, 3] + bq[0, 4] * rx + bq[0, 5] * ry
    h1 = bq[1, 2] - bq[1, 3] + bq[1, 4] * rx + bq[1, 5] * ry
    n0 = Q00 * h0 + Q01 * h1
    n1 = Q10 * h0 + Q11 * h1
    return 2.0 * E00 + 2.0 * n0 * ax, E01 + E10 + n0 * ay + ax * n1, 2.0 * E11 + 2.0 * n1 * ay


@nb.njit(**_JIT1)
def _row_undistorted_qc(cst, cxs, dx0, dy0, dn0, P00, P01, P11, BQ, ZQ, ZZ, BZ, Ccc, xr, cr, vr, nr):
    """As :func:`_row_undistorted`, with ray/position/ground cross-covariances (full budgets); the
    linearity flag into ``nr`` if it has a row's length (else not computed)."""
    cs = to_fixed_tuple(cst, 30)
    x0, y0, g0, g1, stepf, ifx = cs[0], cs[1], cs[3], cs[4], cs[27], cs[28]
    flag = nr.shape[0] == vr.shape[0]
    cc = to_fixed_tuple(Ccc.ravel(), 36)
    bq = np.zeros((2, 6))
    bz = np.zeros(6)
    for iu in range(vr.shape[0]):
        x = (np.float64(iu) * stepf - cxs) * ifx
        ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11, dn, lam, dxr, dyr, q00, q01, q11 = \
            _pixel_undistorted(cs, x, dx0, dy0, dn0, P00, P01, P11)
        for a_ in range(2):
            for c_ in range(6):
                bq[a_, c_] = _horner7(BQ[a_, c_], x)
        d00, d01, d11 = _qc_terms(Q00, Q01, Q10, Q11, ax, ay, ox, oy, bq)
        c00 += d00
        c01 += d01
        c11 += d11
        good = _store_pixel(xr, cr, vr, iu, ok, x0 + ox, y0 + oy, c00, c01, c11)
        if flag:
            for c_ in range(6):
                bz[c_] = BZ[c_, 0] + BZ[c_, 1] * x
            zq0 = _horner8(ZQ[0], x)
            zq1 = _horner8(ZQ[1], x)
            zz = ZZ[0] + x * (ZZ[1] + x * ZZ[2])
            nl = _flag(c00, c01, c11, dn, -lam * cs[26], lam, dxr, dyr, ox, oy, ax, ay, Q00, Q01, Q10, Q11, g0, g1,
                       q00, q01, q11, zq0, zq1, zz, cc, True, bq, bz)
            nr[iu] = nl if good else np.nan


@nb.njit(**_JIT)
def _map_undistorted(prm, R, om, colptr, rowidx, vals, vc, has_qc, Cpq, Ccc, cst, step, xyf, covf, validf, reasonf,
                     nlf, W, nblk):
    """Blocks of contiguous rows of the undistorted kernel in parallel (the per-row scratch allocated once per
    block: allocations in every row of a parallel loop cost both threads); ``nlf`` (H W,) receives the
    nonlinearity, ``reasonf`` (H W,) the status codes, or either has 0 rows (not wanted)."""
    Hh = validf.shape[0] // W
    flag = nlf.shape[0] == validf.shape[0]
    codes = reasonf.shape[0] == validf.shape[0]
    fy, cx, cy, sk = prm[1], prm[2], prm[3], prm[4]
    gx, gy = prm[20], prm[21]
    g1 = R[2, 1] - gx * R[0, 1] - gy * R[1, 1]
    g2 = R[2, 2] - gx * R[0, 2] - gy * R[1, 2]
    per = (Hh + nblk - 1) // nblk
    for blk in nb.prange(nblk):
        P00 = np.empty(15)
        P01 = np.empty(15)
        P11 = np.empty(15)
        BQ = np.zeros((2, 6, 8))
        ZQ = np.zeros((2, 9))
        ZZ = np.zeros(3)
        BZ = np.zeros((6, 2))
        for iv in range(blk * per, min(Hh, (blk + 1) * per)):
            yn = (iv * step - cy) / fy
            _row_polys(yn, prm, om, colptr, rowidx, vals, vc, has_qc, Cpq, P00, P01, P11, BQ, flag, ZQ, ZZ, BZ)
            xr = xyf[2 * W * iv:2 * W * (iv + 1)]
            cr = covf[4 * W * iv:4 * W * (iv + 1)]
            vr = validf[W * iv:W * (iv + 1)]
            nr = nlf[W * iv:W * (iv + 1)] if flag else nlf[0:0]
            cxs, dx0, dy0, dn0 = cx + sk * yn, R[0, 1] * yn + R[0, 2], R[1, 1] * yn + R[1, 2], g1 * yn + g2
            if has_qc:
                _row_undistorted_qc(cst, cxs, dx0, dy0, dn0, P00, P01, P11, BQ, ZQ, ZZ, BZ, Ccc, xr, cr, vr, nr)
            elif flag:
                _row_undistorted_flag(cst, cxs, dx0, dy0, dn0, P00, P01, P11, ZQ, ZZ, Ccc, xr, cr, vr, nr)
            else:
                _row_undistorted(cst, cxs, dx0, dy0, dn0, P00, P01, P11, xr, cr, vr)
            if codes:  # without distortion a pixel is fine, at / above the horizon, or computed but not finite
                _row_codes_undistorted(cxs, dn0, cst[3], cst[27], cst[28], vr, reasonf[W * iv:W * (iv + 1)])


@nb.njit(**_JIT1)
def _row_codes_undistorted(cxs, dn0, g0, stepf, ifx, vr, rr):
    """Status codes of a row of the undistorted kernel (in a loop of its own: an int8 store in the pixel loop
    stops it vectorising): OK where valid, else OVERFLOW where the ray meets the ground (``dn < 0``, as in
    :func:`_pixel_undistorted`) but an output was not finite, else ABOVE_HORIZON."""
    for iu in range(vr.shape[0]):
        dn = dn0 + (np.float64(iu) * stepf - cxs) * ifx * g0
        rr[iu] = status.OK if vr[iu] else (status.OVERFLOW if dn < 0.0 else status.ABOVE_HORIZON)


# --------------------------------------------------------------------------------------
# kernel 2: general (OpenCV with distortion), per point
# --------------------------------------------------------------------------------------
@nb.njit(**_JIT1)
def _point_general(u, v, S00, S01, S11, prm, R, om, colptr, rowidx, vals, vc, Ccc, has_qc, has_dist, dom, sq, bq, bz,
                   flag):
    """Ground point and covariance of one pixel; sq (22, 2), bq (2, 6), bz (6,) scratch arrays.

    Returns ``(code, x, y, c00, c01, c11, nl)`` with ``code`` a :mod:`footprint_uq.status` code
    (precedence as the reference: not finite, then undistortion, then horizon) and ``nl`` the
    linearity flag's ``nonlinearity`` (with ``flag``; NaN otherwise or where not OK).
    """
    fx, fy, cx, cy, sk = prm[0], prm[1], prm[2], prm[3], prm[4]
    dist = prm[5:13]
    yd = (v - cy) / fy
    xd = (u - cx - sk * yd) / fx
    xn, yn = xd, yd
    M00, M01, M10, M11 = 1.0, 0.0, 0.0, 1.0
    conv = True
    if has_dist:
        conv, xn, yn, M00, M01, M10, M11 = core.undistort_point(dom, dist, xd, yd, xd, yd)
    r2 = xn * xn + yn * yn
    num = 1.0 + r2 * (dist[0] + r2 * (dist[1] + r2 * dist[4]))
    den = 1.0 + r2 * (dist[5] + r2 * (dist[6] + r2 * dist[7]))
    x0, y0 = prm[13], prm[14]
    Hn = prm[15] - prm[19]
    gx, gy = prm[20], prm[21]
    g0 = R[2, 0] - gx * R[0, 0] - gy * R[1, 0]
    g1 = R[2, 1] - gx * R[0, 1] - gy * R[1, 1]
    g2 = R[2, 2] - gx * R[0, 2] - gy * R[1, 2]
    dxr = R[0, 0] * xn + R[0, 1] * yn + R[0, 2]
    dyr = R[1, 0] * xn + R[1, 1] * yn + R[1, 2]
    dn = g0 * xn + g1 * yn + g2
    if not conv:
        return status.UNDISTORT_FAILED, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan
    if not ((dn < 0.0) and (Hn > 0.0)):
        return status.ABOVE_HORIZON, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan
    lam, ox, oy, Q00, Q01, Q10, Q11 = core.ground_of_ray(Hn, Hn * R[0, 0], Hn * R[0, 1], Hn * R[1, 0], Hn * R[1, 1],
                                                         g0, g1, dxr, dyr, dn)
    _point_dq(xd, yd, xn, yn, num, den, M00, M01, M10, M11, prm, om, sq)
    # pixel noise: dq/duv = M A, A = [[1/fx, -sk/(fx fy)], [0, 1/fy]]
    B00 = M00 / fx
    B01 = -M00 * sk / (fx * fy) + M01 / fy
    B10 = M10 / fx
    B11 = -M10 * sk / (fx * fy) + M11 / fy
    T00 = B00 * S00 + B01 * S01
    T01 = B00 * S01 + B01 * S11
    T10 = B10 * S00 + B11 * S01
    T11 = B10 * S01 + B11 * S11
    q00, q01, q11, zq0, zq1, zz = _point_state(T00 * B00 + T01 * B01, T00 * B10 + T01 * B11,
                                               T10 * B10 + T11 * B11, xn, yn, om, colptr, rowidx, vals, vc,
                                               has_qc, sq, bq, bz)
    ax, ay = ox / Hn, oy / Hn
    c00, c01, c11 = _finish(q00, q01, q11, Q00, Q01, Q10, Q11, ax, ay, ox, oy, Ccc, bq, has_qc)
    x, y = x0 + ox, y0 + oy
    if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(c00) and np.isfinite(c01) and np.isfinite(c11)):
        return status.OVERFLOW, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan
    nl = np.nan
    if flag:
        nl = _flag(c00, c01, c11, dn, 1.0 / dn, lam, dxr, dyr, ox, oy, ax, ay, Q00, Q01, Q10, Q11, g0, g1, q00, q01,
                   q11, zq0, zq1, zz, to_fixed_tuple(Ccc.ravel(), 36), has_qc, bq, bz)
    return status.OK, x, y, c00, c01, c11, nl


@nb.njit(**_JIT1)
def _point_dq(xd, yd, xn, yn, num, den, M00, M01, M10, M11, prm, om, sq):
    """``sq[k] = d q / d param_k`` (2,) of one pixel for every ray parameter: intrinsics act on ``x_d``
    (``dq = M dx_d``), distortion ``dq = -M d distort / dk`` at ``(x_n, y_n)``, rotations ``omega x q~``
    without its component along the ray (``M`` = d(undistorted)/d(distorted); ``num``, ``den`` the
    radial factor's numerator and denominator)."""
    fx, fy, sk = prm[0], prm[1], prm[4]
    for k in range(19):
        sq[k, 0] = 0.0
        sq[k, 1] = 0.0
    for k in range(5):
        if k == 0:
            a0, a1 = -xd / fx, 0.0
        elif k == 1:
            a0, a1 = sk * yd / (fx * fy), -yd / fy
        elif k == 2:
            a0, a1 = -1.0 / fx, 0.0
        elif k == 3:
            a0, a1 = sk / (fx * fy), -1.0 / fy
        else:
            a0, a1 = -yd / fx, 0.0
        sq[k, 0] = M00 * a0 + M01 * a1
        sq[k, 1] = M10 * a0 + M11 * a1
    r2 = xn * xn + yn * yn
    r4 = r2 * r2
    r6 = r4 * r2
    id_ = 1.0 / den
    nd2 = num * id_ * id_
    drk = (r2 * id_, r4 * id_, 0.0, 0.0, r6 * id_, -r2 * nd2, -r4 * nd2, -r6 * nd2)
    for i in range(8):
        if i == 2:
            a0, a1 = 2.0 * xn * yn, r2 + 2.0 * yn * yn
        elif i == 3:
            a0, a1 = r2 + 2.0 * xn * xn, 2.0 * xn * yn
        else:
            a0, a1 = xn * drk[i], yn * drk[i]
        sq[5 + i, 0] = -(M00 * a0 + M01 * a1)
        sq[5 + i, 1] = -(M10 * a0 + M11 * a1)
    for i in range(3):
        w0, w1, w2 = om[i, 0], om[i, 1], om[i, 2]
        sq[16 + i, 0] = w1 - w2 * yn - w0 * xn * yn + w1 * xn * xn
        sq[16 + i, 1] = -w0 * (1.0 + yn * yn) + w2 * xn + w1 * xn * yn


@nb.njit(**_JIT1)
def _point_state(q00, q01, q11, xn, yn, om, colptr, rowidx, vals, vc, has_qc, sq, bq, bz):
    """The ray-state covariance of one pixel, factor column by factor column, added to the pixel noise's
    ``(q00, q01, q11)``: returns ``(q00, q01, q11, zq0, zq1, zz)`` (the ``z`` parts for :func:`_flag`) and
    fills ``bq`` (2, 6) / ``bz`` (6,), the ray / constant cross terms (with ``has_qc``)."""
    bq[:] = 0.0
    bz[:] = 0.0
    zq0, zq1, zz = 0.0, 0.0, 0.0
    for j in range(colptr.size - 1):
        v0 = 0.0
        v1 = 0.0
        z = 0.0
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            if k < 13 or (k >= 16 and k <= 18):
                v0 += vals[nz] * sq[k, 0]
                v1 += vals[nz] * sq[k, 1]
            if k >= 16 and k <= 18:
                z += vals[nz] * (om[k - 16, 0] * yn - om[k - 16, 1] * xn)
        q00 += v0 * v0
        q01 += v0 * v1
        q11 += v1 * v1
        zq0 += v0 * z
        zq1 += v1 * z
        zz += z * z
        if has_qc:
            for c in range(6):
                bq[0, c] += v0 * vc[j, c]
                bq[1, c] += v1 * vc[j, c]
                bz[c] += z * vc[j, c]
    return q00, q01, q11, zq0, zq1, zz


#: blocks of contiguous rows per thread of the map kernels (scratch allocated once per block; in the general
#: kernel also the Newton warm-starts within a block)
_ROWS_PER_BLOCK_DIV = 16

# row buffers of the general map kernel
#: (name, meaning) of the rows of ``buf`` (_NBUF, W); the offsets _XD ... are generated from this table
BUF_ROWS = (
    ("XD", "distorted normalised x"), ("XN", "undistorted normalised x"), ("YN", "undistorted normalised y"),
    ("M00", "d(undistorted)/d(distorted) 00"), ("M01", "01"), ("M10", "10"), ("M11", "11"),
    ("Q00", "ray-state covariance C_qq 00 of the mixed factor columns (_ray_cov adds the rest)"),
    ("Q01", "C_qq 01"), ("Q11", "C_qq 11"), ("V0", "one factor column's dq_0"), ("V1", "its dq_1"),
    ("CONV", "previous row's y_d where that pixel converged, else NaN"), ("IDEN", "1 / distortion denominator"),
    ("YDB", "the row's y_d, broadcast"),
    # the linearity flag (see _flag): the rotations' ray-scale component z of the mixed factor columns
    ("Z", "one factor column's z"), ("QZ0", "C_qz 0"), ("QZ1", "C_qz 1"), ("ZZ", "C_zz"),
)
_BUF = {name: i for i, (name, _) in enumerate(BUF_ROWS)}
_XD, _XN, _YN, _M00, _M01, _M10, _M11, _Q00, _Q01, _Q11, _V0, _V1, _CONV, _IDEN, _YDB = (
    _BUF[k] for k in ("XD", "XN", "YN", "M00", "M01", "M10", "M11", "Q00", "Q01", "Q11", "V0", "V1", "CONV", "IDEN",
                      "YDB"))
_Z, _QZ0, _QZ1, _ZZ = (_BUF[k] for k in ("Z", "QZ0", "QZ1", "ZZ"))
_NBUF = len(BUF_ROWS)
#: rows of the ray / constant cross terms ``BQ`` of the general kernel: dq_0 x constants (6), dq_1 x constants
#: (6), and with the flag z x constants (6)
_NBQ = 18


@nb.njit(**_JIT1)
def _acc_param(k, lv, yd, prm, om, buf, W, sq, flag):
    """Add ``lv * dq_k`` of every pixel of the row to ``buf[V0/V1]`` or, with ``sq``, add
    ``lv^2 dq_k dq_k^T`` to ``buf[Q00/Q01/Q11]`` (one vectorised loop per parameter type).
    With ``flag`` a rotation also adds its ray-scale component ``lv z_k`` to ``buf[Z]`` (not with ``sq``:
    single rotations are folded into ``Om``)."""
    if k <= 4:
        _acc_intrinsic(k, lv, yd, prm, buf, W, sq)
    elif k <= 12:
        _acc_distortion(k, lv, prm, buf, W, sq)
    elif k >= 16 and k <= 18:
        _acc_rotation(k, lv, om, buf, W, sq, flag)


@nb.njit(**_JIT1)
def _acc_intrinsic(k, lv, yd, prm, buf, W, sq):
    """Intrinsics act on x_d: ``dq = M dx_d`` with ``dx_d = (a0 + a1 x_d, b0)`` (row constants)."""
    fx, fy, sk = prm[0], prm[1], prm[4]
    if k == 0:
        a0, a1, b0 = 0.0, -lv / fx, 0.0
    elif k == 1:
        a0, a1, b0 = lv * sk * yd / (fx * fy), 0.0, -lv * yd / fy
    elif k == 2:
        a0, a1, b0 = -lv / fx, 0.0, 0.0
    elif k == 3:
        a0, a1, b0 = lv * sk / (fx * fy), 0.0, -lv / fy
    else:
        a0, a1, b0 = -lv * yd / fx, 0.0, 0.0
    xd = buf[_XD]
    M00, M01, M10, M11 = buf[_M00], buf[_M01], buf[_M10], buf[_M11]
    if sq:
        q00, q01, q11 = buf[_Q00], buf[_Q01], buf[_Q11]
        for i in range(W):
            e = a0 + a1 * xd[i]
            f0 = M00[i] * e + M01[i] * b0
            f1 = M10[i] * e + M11[i] * b0
            q00[i] += f0 * f0
            q01[i] += f0 * f1
            q11[i] += f1 * f1
    else:
        v0, v1 = buf[_V0], buf[_V1]
        for i in range(W):
            e = a0 + a1 * xd[i]
            v0[i] += M00[i] * e + M01[i] * b0
            v1[i] += M10[i] * e + M11[i] * b0


@nb.njit(**_JIT1)
def _acc_distortion(k, lv, prm, buf, W, sq):
    """Distortion coefficient ``k`` (5..12): ``dq = -M d distort / dk`` at ``(x_n, y_n)``."""
    i8 = k - 5
    d = prm[5:13]
    k1, k2, k3 = d[0], d[1], d[4]
    xn, yn = buf[_XN], buf[_YN]
    iden_ = buf[_IDEN]  # 1 / (1 + k4 r2 + k5 r2^2 + k6 r2^3) at (x_n, y_n), from the Newton pass
    M00, M01, M10, M11 = buf[_M00], buf[_M01], buf[_M10], buf[_M11]
    v0, v1 = buf[_V0], buf[_V1]
    q00, q01, q11 = buf[_Q00], buf[_Q01], buf[_Q11]
    tang = i8 == 2 or i8 == 3
    n = 1 if (i8 == 0 or i8 == 5) else (2 if (i8 == 1 or i8 == 6) else 3)
    for i in range(W):
        x = xn[i]
        y = yn[i]
        r2 = x * x + y * y
        if tang:
            if i8 == 2:
                e0 = 2.0 * x * y
                e1 = r2 + 2.0 * y * y
            else:
                e0 = r2 + 2.0 * x * x
                e1 = 2.0 * x * y
        else:
            rr = r2 if n == 1 else (r2 * r2 if n == 2 else r2 * r2 * r2)
            idn = iden_[i]
            if i8 <= 4:
                dr = rr * idn
            else:
                dr = -(1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))) * rr * (idn * idn)
            e0 = x * dr
            e1 = y * dr
        f0 = -lv * (M00[i] * e0 + M01[i] * e1)
        f1 = -lv * (M10[i] * e0 + M11[i] * e1)
        if sq:
            q00[i] += f0 * f0
            q01[i] += f0 * f1
            q11[i] += f1 * f1
        else:
            v0[i] += f0
            v1[i] += f1


@nb.njit(**_JIT1)
def _acc_rotation(k, lv, om, buf, W, sq, flag):
    """Rotation generator ``k`` (16..18): ``dq`` = ``omega x q~`` without its component along the ray;
    with ``flag`` (and not ``sq``) also that component ``z = w0 y_n - w1 x_n`` into ``buf[Z]``."""
    w0, w1, w2 = lv * om[k - 16, 0], lv * om[k - 16, 1], lv * om[k - 16, 2]
    xn, yn = buf[_XN], buf[_YN]
    if sq:
        q00, q01, q11 = buf[_Q00], buf[_Q01], buf[_Q11]
        for i in range(W):
            x = xn[i]
            y = yn[i]
            f0 = w1 - w2 * y - w0 * x * y + w1 * x * x
            f1 = -w0 * (1.0 + y * y) + w2 * x + w1 * x * y
            q00[i] += f0 * f0
            q01[i] += f0 * f1
            q11[i] += f1 * f1
    else:
        v0, v1 = buf[_V0], buf[_V1]
        for i in range(W):
            x = xn[i]
            y = yn[i]
            v0[i] += w1 - w2 * y - w0 * x * y + w1 * x * x
            v1[i] += -w0 * (1.0 + y * y) + w2 * x + w1 * x * y
        if flag:
            zr = buf[_Z]
            for i in range(W):
                zr[i] += w0 * yn[i] - w1 * xn[i]


@nb.njit(**_JIT1)
def _row_undistort(v, prm, has_dist, dom, warm, stepf, buf, ok):
    """Pixels of one row -> distorted (XD) and undistorted (XN, YN) normalised coordinates, M, IDEN, ``ok``.

    Undistortion is the scalar core's (:func:`footprint_uq.fast.core.undistort_row`: the
    lens's valid domain, Newton, the reference's acceptance test and its robust retry).  With
    ``warm``, ``buf`` holds the previous row's solution: Newton then starts from its
    first-order continuation ``x_n,prev + M_prev (x_d - x_d,prev)`` where that pixel
    converged (2-3 iterations instead of 5-8), else from ``x_d``.  Returns the row's ``y_d``.
    """
    W = ok.shape[0]
    fx, fy, cx, cy, sk = prm[0], prm[1], prm[2], prm[3], prm[4]
    yd = (v - cy) / fy
    xd, xn, yn = buf[_XD], buf[_XN], buf[_YN]
    M00, M01, M10, M11 = buf[_M00], buf[_M01], buf[_M10], buf[_M11]
    cv = buf[_CONV]
    idn_b = buf[_IDEN]
    ydb = buf[_YDB]
    ifx_ = 1.0 / fx
    if warm and has_dist:
        # cv holds the previous row's y_d where that pixel converged, NaN elsewhere
        for i in range(W):
            x = (np.float64(i) * stepf - cx - sk * yd) * ifx_
            dx = x - xd[i]
            dy = yd - cv[i]
            xd[i] = x
            good = dy == dy
            sx = xn[i] + M00[i] * dx + M01[i] * dy
            sy = yn[i] + M10[i] * dx + M11[i] * dy
            xn[i] = sx if good else x
            yn[i] = sy if good else yd
    else:
        for i in range(W):
            x = (np.float64(i) * stepf - cx - sk * yd) * ifx_
            xd[i] = x
            xn[i] = x
            yn[i] = yd
    # cv: y_d where the lens let the pixel through, NaN elsewhere (the next row's warm start; the codes)
    if has_dist:
        core.undistort_row(dom, prm[5:13], xd, yd, ydb, xn, yn, M00, M01, M10, M11, idn_b, ok)
        for i in range(W):
            cv[i] = yd if ok[i] else np.nan
    else:
        for i in range(W):
            ok[i] = True
            cv[i] = yd
            idn_b[i] = 1.0
            M00[i] = 1.0
            M01[i] = 0.0
            M10[i] = 0.0
            M11[i] = 1.0
    return yd


@nb.njit(**_JIT1)
def _row_intrinsics(yd, prm, colptr, rowidx, vals, colkind, Suv):
    """The pre-M covariance ``C_pre`` of one row: intrinsics-only factor columns and the pixel noise.

    Those columns move ``x_d`` by ``(A0 + A1 x_d, B0)`` (row constants), so with the pixel noise
    ``A Suv A^T`` their covariance is a polynomial in ``x_d``: returns its coefficients
    ``(c00_0, c00_1, c00_2, c01_0, c01_1, c11_0)``.
    """
    fx, fy, sk = prm[0], prm[1], prm[4]
    ifx, ify, skf = 1.0 / fx, 1.0 / fy, -sk / (fx * fy)
    S00, S01, S11 = Suv[0, 0], Suv[0, 1], Suv[1, 1]
    c00_0 = ifx * ifx * S00 + 2.0 * ifx * skf * S01 + skf * skf * S11
    c01_0 = ifx * ify * S01 + skf * ify * S11
    c11_0 = ify * ify * S11
    c00_1, c00_2, c01_1 = 0.0, 0.0, 0.0
    for j in range(colptr.size - 1):
        if colkind[j] != 1:
            continue
        A0, A1, B0 = 0.0, 0.0, 0.0
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            lv = vals[nz]
            if k == 0:
                A1 -= lv / fx
            elif k == 1:
                A0 += lv * sk * yd / (fx * fy)
                B0 -= lv * yd / fy
            elif k == 2:
                A0 -= lv / fx
            elif k == 3:
                A0 += lv * sk / (fx * fy)
                B0 -= lv / fy
            elif k == 4:
                A0 -= lv * yd / fx
        c00_0 += A0 * A0
        c00_1 += 2.0 * A0 * A1
        c00_2 += A1 * A1
        c01_0 += A0 * B0
        c01_1 += A1 * B0
        c11_0 += B0 * B0
    return c00_0, c00_1, c00_2, c01_0, c01_1, c11_0


@nb.njit(**_JIT1)
def _row_mixed(yd, prm, om, colptr, rowidx, vals, vc, colkind, has_qc, flag, buf, BQ):
    """The other factor columns (distortion, mixed) of one row into ``buf[Q00/Q01/Q11]`` (C_qq) and
    ``BQ`` (ray / constant cross terms); with ``flag`` also the rotations' ``z`` rows (see :func:`_flag`)."""
    W = buf.shape[1]
    q00, q01, q11, v0, v1 = buf[_Q00], buf[_Q01], buf[_Q11], buf[_V0], buf[_V1]
    zr, qz0, qz1, zz = buf[_Z], buf[_QZ0], buf[_QZ1], buf[_ZZ]
    for j in range(colptr.size - 1):
        if colkind[j] != 0:
            continue  # intrinsics-only (_row_intrinsics) and rotation-only (Om, in _row_pixels) columns
        if colptr[j + 1] - colptr[j] == 1:
            k = rowidx[colptr[j]]
            if k < 13 or (k >= 16 and k <= 18):  # a ray parameter alone: no constant part
                _acc_param(k, vals[colptr[j]], yd, prm, om, buf, W, True, False)
            continue
        v0[:] = 0.0
        v1[:] = 0.0
        ray = False
        rot = False
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            if k >= 16 and k <= 18 and flag and not rot:
                zr[:] = 0.0
                rot = True
            if k < 13 or (k >= 16 and k <= 18):
                _acc_param(k, vals[nz], yd, prm, om, buf, W, False, flag)
                ray = True
        if not ray:
            continue
        for i in range(W):
            a = v0[i]
            b = v1[i]
            q00[i] += a * a
            q01[i] += a * b
            q11[i] += b * b
        if rot:
            for i in range(W):
                z = zr[i]
                qz0[i] += v0[i] * z
                qz1[i] += v1[i] * z
                zz[i] += z * z
        if has_qc:
            for c in range(6):
                vcc = vc[j, c]
                if vcc != 0.0:
                    B0 = BQ[c]
                    B1 = BQ[6 + c]
                    for i in range(W):
                        B0[i] += v0[i] * vcc
                        B1[i] += v1[i] * vcc
                    if rot:
                        B2 = BQ[12 + c]
                        for i in range(W):
                            B2[i] += zr[i] * vcc


@nb.njit(inline="always", **_JIT1)
def _ray_state(x, y, cst, R00, R01, R02, R10, R11, R12):
    """Ray, ground offset and ``Q = d xy / d q`` of one pixel of the general kernel:
    ``(dxr, dyr, dn, lam, ox, oy, Q00, Q01, Q10, Q11)``."""
    g0, g1 = cst[3], cst[4]
    dxr = R00 * x + R01 * y + R02
    dyr = R10 * x + R11 * y + R12
    dn = g0 * x + g1 * y + cst[29]
    lam, ox, oy, Q00, Q01, Q10, Q11 = core.ground_of_ray(cst[2], cst[5], cst[6], cst[7], cst[8], g0, g1, dxr, dyr,
                                                         dn)
    return dxr, dyr, dn, lam, ox, oy, Q00, Q01, Q10, Q11


@nb.njit(inline="always", **_JIT1)
def _ray_cov(x, y, xdi, m00_, m01_, m10_, m11_, b00, b01, b11, pre, Omt):
    """Total ray-state covariance ``C_qq`` of one pixel: the mixed columns' part ``b`` + ``M C_pre M^T``
    (intrinsics and pixel noise, ``C_pre`` a polynomial in ``x_d`` with coefficients ``pre``) + the
    rotations' ``G Om G^T`` (``Omt`` the upper triangle of ``Om``).  Shared by the pixel pass and the
    flag pass, which recomputes it (a few dozen vectorised multiply-adds) rather than have the pixel
    loop store it: a loop that stores to rows of ``buf`` it also reads no longer vectorises."""
    c00_0, c00_1, c00_2, c01_0, c01_1, c11_0 = pre
    O00, O01, O02, O11, O12, O22 = Omt
    e00 = c00_0 + xdi * (c00_1 + xdi * c00_2)
    e01 = c01_0 + xdi * c01_1
    e11 = c11_0
    T00 = m00_ * e00 + m01_ * e01
    T01 = m00_ * e01 + m01_ * e11
    T10 = m10_ * e00 + m11_ * e01
    T11 = m10_ * e01 + m11_ * e11
    # rotations: dq = G omega, G = [[-x y, 1 + x^2, -y], [-(1 + y^2), x y, x]], Cov(omega) = Om
    xy_ = x * y
    G00, G01, G02, G10, G11, G12 = -xy_, 1.0 + x * x, -y, -(1.0 + y * y), xy_, x
    H0 = G00 * O00 + G01 * O01 + G02 * O02
    H1 = G00 * O01 + G01 * O11 + G02 * O12
    H2 = G00 * O02 + G01 * O12 + G02 * O22
    K0 = G10 * O00 + G11 * O01 + G12 * O02
    K1 = G10 * O01 + G11 * O11 + G12 * O12
    K2 = G10 * O02 + G11 * O12 + G12 * O22
    a00 = b00 + T00 * m00_ + T01 * m01_ + H0 * G00 + H1 * G01 + H2 * G02
    a01 = b01 + T00 * m10_ + T01 * m11_ + H0 * G10 + H1 * G11 + H2 * G12
    a11 = b11 + T10 * m10_ + T11 * m11_ + K0 * G10 + K1 * G11 + K2 * G12
    return a00, a01, a11


@nb.njit(**_JIT1)
def _row_pixels(cst, R, Omt, pre, buf, xr, cr, vr, rr):
    """Per pixel: ray, ground point, Q, the ray-state covariance (:func:`_ray_cov`), the covariance; codes
    into ``rr``."""
    cs = to_fixed_tuple(cst, 30)  # constants as scalars: stores to the outputs cannot make the loop reload them
    x0, y0, iHn = cst[0], cst[1], cst[26]
    p00, p01, p11 = cst[11], cst[12], cst[13]
    s0, s1, s2, s3, s4, s5 = cst[14], cst[15], cst[16], cst[17], cst[18], cst[19]
    m00, m01, m02, m10, m11, m12 = cst[20], cst[21], cst[22], cst[23], cst[24], cst[25]
    R00, R01, R02, R10, R11, R12 = R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2]
    xd, xn, yn = buf[_XD], buf[_XN], buf[_YN]
    M00, M01, M10, M11 = buf[_M00], buf[_M01], buf[_M10], buf[_M11]
    q00, q01, q11 = buf[_Q00], buf[_Q01], buf[_Q11]
    cv = buf[_CONV]
    ok = vr
    for i in range(vr.shape[0]):
        x = xn[i]
        y = yn[i]
        dxr, dyr, dn, lam, ox, oy, Q00, Q01, Q10, Q11 = _ray_state(x, y, cs, R00, R01, R02, R10, R11, R12)
        lens = ok[i]
        oki = lens & (dn < 0.0)
        a00, a01, a11 = _ray_cov(x, y, xd[i], M00[i], M01[i], M10[i], M11[i], q00[i], q01[i], q11[i], pre, Omt)
        A00 = Q00 * a00 + Q01 * a01
        A01 = Q00 * a01 + Q01 * a11
        A10 = Q10 * a00 + Q11 * a01
        A11 = Q10 * a01 + Q11 * a11
        c00 = A00 * Q00 + A01 * Q01 + p00
        c01 = A00 * Q10 + A01 * Q11 + p01
        c11 = A10 * Q10 + A11 * Q11 + p11
        ax = ox * iHn
        ay = oy * iHn
        sv = s0 + ox * (s1 + s3 * ox + s4 * oy) + oy * (s2 + s5 * oy)
        mx = m00 + m01 * ox + m02 * oy
        my = m10 + m11 * ox + m12 * oy
        c00 += (sv * ax + 2.0 * mx) * ax
        c01 += sv * ax * ay + mx * ay + ax * my
        c11 += (sv * ay + 2.0 * my) * ay
        _store_pixel(xr, cr, vr, i, oki, x0 + ox, y0 + oy, c00, c01, c11)  # (checks the outputs: OVERFLOW)
    # codes in a loop of their own (an int8 store in the pixel loop keeps LLVM from vectorising it): OK,
    # UNDISTORT_FAILED where the lens did not let the pixel through (cv NaN), else OVERFLOW where the ray
    # meets the ground (dn < 0, as in _ray_state) but an output was not finite, else ABOVE_HORIZON
    g0, g1, g2 = cs[3], cs[4], cs[29]
    for i in range(vr.shape[0]):
        dn = g0 * xn[i] + g1 * yn[i] + g2
        miss = status.OVERFLOW if dn < 0.0 else status.ABOVE_HORIZON
        rr[i] = status.OK if ok[i] else (status.UNDISTORT_FAILED if cv[i] != cv[i] else miss)


@nb.njit(**_JIT1)
def _row_qc(cst, R, buf, BQ, cr, vr):
    """Adds the ray / constant cross terms (``BQ``, full budgets) to the covariances of a row."""
    R00, R01, R02, R10, R11, R12 = R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2]
    cs = to_fixed_tuple(cst, 30)
    iHn = cs[26]
    xn, yn = buf[_XN], buf[_YN]
    bq = np.empty((2, 6))
    for i in range(vr.shape[0]):
        if not vr[i]:
            continue
        _, _, _, _, ox, oy, Q00, Q01, Q10, Q11 = _ray_state(xn[i], yn[i], cs, R00, R01, R02, R10, R11, R12)
        for c in range(6):
            bq[0, c] = BQ[c, i]
            bq[1, c] = BQ[6 + c, i]
        d00, d01, d11 = _qc_terms(Q00, Q01, Q10, Q11, ox * iHn, oy * iHn, ox, oy, bq)
        cr[4 * i] += d00
        cr[4 * i + 1] += d01
        cr[4 * i + 2] += d01
        cr[4 * i + 3] += d11


@nb.njit(inline="always", **_JIT1)
def _pixel_flag(i, cs, R, Om, pre, cc, has_qc, buf, BQ, cr, bq, bz):
    """The linearity flag of pixel ``i`` of a row of the general kernel (:func:`_flag`).

    The rotation-only factor columns (``Om``, upper triangle) add ``C_qz = G Om h`` and
    ``C_zz = h^T Om h`` with ``z = h . omega``, ``h = (y, -x, 0)``; the mixed columns' parts are in
    ``buf`` and ``BQ``; the total ``C_qq`` is recomputed (:func:`_ray_cov`, ``pre`` as there).
    ``buf`` is indexed as a 2-D array (one base pointer: the loop needs few alias checks).
    """
    x = buf[_XN, i]
    y = buf[_YN, i]
    dxr, dyr, dn, lam, ox, oy, Q00, Q01, Q10, Q11 = _ray_state(x, y, cs, R[0], R[1], R[2], R[3], R[4], R[5])
    Oh0 = Om[0] * y - Om[1] * x
    Oh1 = Om[1] * y - Om[3] * x
    Oh2 = Om[2] * y - Om[4] * x
    zq0 = buf[_QZ0, i] - x * y * Oh0 + (1.0 + x * x) * Oh1 - y * Oh2
    zq1 = buf[_QZ1, i] - (1.0 + y * y) * Oh0 + x * y * Oh1 + x * Oh2
    zz = buf[_ZZ, i] + y * Oh0 - x * Oh1
    if has_qc:
        for c in range(6):
            bq[0, c] = BQ[c, i]
            bq[1, c] = BQ[6 + c, i]
            bz[c] = BQ[12 + c, i]
    a00, a01, a11 = _ray_cov(x, y, buf[_XD, i], buf[_M00, i], buf[_M01, i], buf[_M10, i], buf[_M11, i],
                             buf[_Q00, i], buf[_Q01, i], buf[_Q11, i], pre, Om)
    iHn = cs[26]
    return _flag(cr[4 * i], cr[4 * i + 1], cr[4 * i + 3], dn, -lam * iHn, lam, dxr, dyr, ox, oy, ox * iHn, oy * iHn,
                 Q00, Q01, Q10, Q11, cs[3], cs[4], a00, a01, a11, zq0, zq1, zz, cc, has_qc, bq, bz)


@nb.njit(**_JIT1)
def _row_flag(cst, R, Omt, pre, Ccc, has_qc, buf, BQ, cr, vr, nr):
    """The linearity flag of every pixel of a row (:func:`_pixel_flag`) into ``nr`` (NaN where not valid).

    Constants travel as tuples and ``buf`` is read as one 2-D array, so that the loop without the
    full budget's cross terms vectorises (its square roots and divisions dominate otherwise).
    """
    cs = to_fixed_tuple(cst, 30)
    cc = to_fixed_tuple(Ccc.ravel(), 36)
    Rt = (R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2])
    bq = np.zeros((2, 6))
    bz = np.zeros(6)
    nan = np.nan
    if has_qc:
        for i in range(vr.shape[0]):
            nl = _pixel_flag(i, cs, Rt, Omt, pre, cc, True, buf, BQ, cr, bq, bz)
            nr[i] = nl if vr[i] else nan
    else:
        for i in range(vr.shape[0]):
            nl = _pixel_flag(i, cs, Rt, Omt, pre, cc, False, buf, BQ, cr, bq, bz)
            nr[i] = nl if vr[i] else nan


@nb.njit(**_JIT1)
def _row_general(v, prm, R, om, colptr, rowidx, vals, vc, colkind, Om, Ccc, has_qc, has_dist, dom, warm, cst, Suv,
                 buf, BQ, xr, cr, vr, rr, nr):
    """One image row of the general kernel: undistortion, then the covariance (all loops vectorise).

    Stages: :func:`_row_undistort`, :func:`_row_intrinsics` and :func:`_row_mixed` (the factor
    columns), :func:`_row_pixels`, with a full budget :func:`_row_qc`, and with ``nr`` of the row's
    length the linearity flag (:func:`_row_flag`).  ``rr`` receives the :mod:`footprint_uq.status`
    code of each pixel.
    """
    flag = nr.shape[0] == vr.shape[0]
    yd = _row_undistort(v, prm, has_dist, dom, warm, cst[27], buf, vr)
    buf[_Q00][:] = 0.0
    buf[_Q01][:] = 0.0
    buf[_Q11][:] = 0.0
    if flag:
        buf[_QZ0][:] = 0.0
        buf[_QZ1][:] = 0.0
        buf[_ZZ][:] = 0.0
    if has_qc:
        BQ[:] = 0.0
    pre = _row_intrinsics(yd, prm, colptr, rowidx, vals, colkind, Suv)
    _row_mixed(yd, prm, om, colptr, rowidx, vals, vc, colkind, has_qc, flag, buf, BQ)
    Omt = (Om[0, 0], Om[0, 1], Om[0, 2], Om[1, 1], Om[1, 2], Om[2, 2])
    _row_pixels(cst, R, Omt, pre, buf, xr, cr, vr, rr)
    if has_qc:
        _row_qc(cst, R, buf, BQ, cr, vr)
        _finish_row(xr, cr, vr, rr)  # the cross terms may overflow what _row_pixels checked
    if flag:
        _row_flag(cst, R, Omt, pre, Ccc, has_qc, buf, BQ, cr, vr, nr)


@nb.njit(**_JIT1)
def _finish_row(xr, cr, vr, rr):
    """Outputs are checked again after :func:`_row_qc`: a pixel whose position or covariance is not finite is
    OVERFLOW (NaN)."""
    nan = np.nan
    for i in range(vr.shape[0]):
        if vr[i] and not (np.isfinite(xr[2 * i]) and np.isfinite(xr[2 * i + 1]) and np.isfinite(cr[4 * i])
                          and np.isfinite(cr[4 * i + 1]) and np.isfinite(cr[4 * i + 3])):
            vr[i] = False
            rr[i] = status.OVERFLOW
            xr[2 * i] = xr[2 * i + 1] = nan
            cr[4 * i] = cr[4 * i + 1] = cr[4 * i + 2] = cr[4 * i + 3] = nan


@nb.njit(**_JIT)
def _map_general(prm, R, om, colptr, rowidx, vals, vc, colkind, Om, Ccc, has_qc, dom, cst, Suv, step, xyf, covf,
                 validf, reasonf, nlf, W, nblk):
    """Blocks of contiguous rows of the general kernel in parallel; ``nlf`` (H W,) receives the
    nonlinearity, or has 0 rows."""
    Hh = validf.shape[0] // W
    flag = nlf.shape[0] == validf.shape[0]
    has_dist = False
    for i in range(5, 13):
        if prm[i] != 0.0:
            has_dist = True
    per = (Hh + nblk - 1) // nblk
    for blk in nb.prange(nblk):
        buf = np.empty((_NBUF, W))
        BQ = np.empty((_NBQ, W))
        for iv in range(blk * per, min(Hh, (blk + 1) * per)):
            _row_general(np.float64(iv * step), prm, R, om, colptr, rowidx, vals, vc, colkind, Om, Ccc, has_qc,
                         has_dist, dom, iv > blk * per, cst, Suv, buf, BQ,
                         xyf[2 * W * iv:2 * W * (iv + 1)], covf[4 * W * iv:4 * W * (iv + 1)],
                         validf[W * iv:W * (iv + 1)], reasonf[W * iv:W * (iv + 1)],
                         nlf[W * iv:W * (iv + 1)] if flag else nlf[0:0])


@nb.njit(**_JIT)
def _points_general(uv, Suv, prm, R, om, colptr, rowidx, vals, vc, Ccc, has_qc, dom, xy, cov, valid, reason, nlin):
    """Every point of ``uv`` (n, 2); ``nlin`` (n,) receives the nonlinearity, or has 0 rows (not computed)."""
    n = uv.shape[0]
    flag = nlin.shape[0] == n and n > 0
    has_dist = False
    for i in range(5, 13):
        if prm[i] != 0.0:
            has_dist = True
    nchunk = 64
    for c in nb.prange((n + nchunk - 1) // nchunk):
        sq = np.empty((22, 2))
        bq = np.zeros((2, 6))
        bz = np.zeros(6)
        for i in range(c * nchunk, min(n, (c + 1) * nchunk)):
            u = uv[i, 0]
            v = uv[i, 1]
            if not (np.isfinite(u) and np.isfinite(v)):
                code, x, y, c00, c01, c11, nl = status.NOT_FINITE, np.nan, np.nan, np.nan, np.nan, np.nan, np.nan
            else:
                code, x, y, c00, c01, c11, nl = _point_general(u, v, Suv[i, 0, 0], Suv[i, 0, 1], Suv[i, 1, 1], prm,
                                                               R, om, colptr, rowidx, vals, vc, Ccc, has_qc, has_dist,
                                                               dom, sq, bq, bz, flag)
            if flag:
                nlin[i] = nl
            xy[i, 0] = x
            xy[i, 1] = y
            cov[i, 0, 0] = c00
            cov[i, 0, 1] = c01
            cov[i, 1, 0] = c01
            cov[i, 1, 1] = c11
            valid[i] = code == status.OK
            reason[i] = code


# the same kernel without threads: for small batches the thread start-up costs more than the work
_points_general_serial = nb.njit(**_JIT1)(_points_general.py_func)
_SERIAL_BELOW = 4096
#: below this many points ``covariance_points`` runs the serial kernel
SERIAL_BELOW = _SERIAL_BELOW


# --------------------------------------------------------------------------------------
# array-level entries (the public covariance_map / covariance_points are in products.covariance)
# --------------------------------------------------------------------------------------
def _column_kinds(k: dict):
    """Kind of each factor column (1: intrinsics only, 2: rotations only, 0: other) and the
    covariance (3, 3) of the rotation vector from the rotation-only columns."""
    colptr, rowidx, vals, om = k["colptr"], k["rowidx"], k["vals"], k["omega"]
    r = colptr.size - 1
    kind = np.zeros(r, dtype=np.int64)
    Om = np.zeros((3, 3))
    for j in range(r):
        ks = rowidx[colptr[j]:colptr[j + 1]]
        if ks.size and np.all(ks <= P.SKEW):
            kind[j] = 1
        elif ks.size and np.all((ks >= P.PAN) & (ks <= P.ROLL)):
            kind[j] = 2
            w = vals[colptr[j]:colptr[j + 1]] @ om[ks - P.PAN]
            Om += np.outer(w, w)
    return kind, np.ascontiguousarray(Om)


def _pixel_cov_q(prm, Suv):
    fx, fy, sk = prm[0], prm[1], prm[4]
    A = np.array([[1.0 / fx, -sk / (fx * fy)], [0.0, 1.0 / fy]])
    return np.ascontiguousarray(A @ Suv @ A.T)


def map_into(k: dict, dom, step: int, xy, cov, valid, reason, nlin) -> None:
    """Fill a map's preallocated outputs (the kernel behind :func:`footprint_uq.products.covariance.covariance_map`).

    Parameters
    ----------
    k : dict
        Camera and budget constants (:func:`footprint_uq.products.covariance.kernel_constants`).
    dom : ndarray
        The camera's packed lens domain (``camera.lens_domain.packed``).
    step : int
        Grid step in pixels, > 0.
    xy, cov, valid : ndarray (H, W, 2), (H, W, 2, 2), (H, W)
        C-contiguous outputs, filled in place.
    reason : ndarray of int8 (H, W) or None
        Status codes, filled in place; None when the caller does not want them.
    nlin : ndarray (H, W) or None
        The linearity flag's nonlinearity, filled in place; None: not computed.
    """
    H, W = valid.shape
    prm = k["params"]
    general = bool(np.any(prm[P.DIST_SLICE]))
    # the general kernel needs the codes in any case: a per-thread buffer when not returned (fast.buffers: a
    # fresh 2 MB array first touched by both kernel threads cost up to 40 % of a full-HD map); the undistorted
    # kernel writes them only when asked for
    if reason is None:
        reason = thread_buffer("map_reason", (H, W), np.int8) if general else np.empty((0, W), dtype=np.int8)
    if nlin is None:
        nlin = np.empty((0, W))
    if not prm[P.HM] - prm[P.GDZ] > 0:  # camera at or below the ground: no pixel sees it
        xy[:] = np.nan
        cov[:] = np.nan
        valid[:] = False
        reason[:] = status.ABOVE_HORIZON
        nlin[:] = np.nan
        return
    # dynamic scheduling in small chunks: on a shared machine a descheduled thread then
    # delays only its current chunk instead of half of the image
    old_chunk = nb.set_parallel_chunksize(1)
    try:
        nblk = min(H, _ROWS_PER_BLOCK_DIV * nb.get_num_threads())
        if general:
            colkind, Om = _column_kinds(k)
            _map_general(prm, k["R"], k["omega"], k["colptr"], k["rowidx"], k["vals"], k["vc"], colkind, Om,
                         k["Ccc"], k["has_qc"], dom, _undistorted_constants(k, step), k["Suv"],
                         step, xy.reshape(-1), cov.reshape(-1), valid.reshape(-1), reason.reshape(-1),
                         nlin.reshape(-1), W, nblk)
        else:
            _map_undistorted(prm, k["R"], k["omega"], k["colptr"], k["rowidx"], k["vals"], k["vc"], k["has_qc"],
                             _pixel_cov_q(prm, k["Suv"]), k["Ccc"], _undistorted_constants(k, step), step,
                             xy.reshape(-1), cov.reshape(-1), valid.reshape(-1), reason.reshape(-1),
                             nlin.reshape(-1), W, nblk)
    finally:
        nb.set_parallel_chunksize(old_chunk)


def points_into(k: dict, dom, uv, Suv, xy, cov, valid, reason, nlin, *, threaded: bool | None = None) -> None:
    """Fill the outputs of scattered points (the kernel behind
    :func:`footprint_uq.products.covariance.covariance_points`).

    ``k`` as in :func:`map_into`; ``uv`` (n, 2) pixels, ``Suv`` (n, 2, 2) per-point pixel covariance,
    C-contiguous; outputs ``xy`` (n, 2), ``cov`` (n, 2, 2), ``valid`` (n,) bool, ``reason`` (n,) int8 and
    ``nlin`` (n,) or (0,) (not computed), filled in place.  Below :data:`SERIAL_BELOW` points the kernel
    runs on the calling thread only, and so it does when no second core is free at the moment of the call
    (:func:`footprint_uq.fast.cores.free_cores`: a threaded call would wait for a busy core, up to a scheduler
    slice, instead of using one).  ``threaded`` True / False forces the threaded / serial kernel (warm-up).
    """
    if threaded is None:
        threaded = uv.shape[0] >= SERIAL_BELOW
        if threaded:
            free = free_cores()
            threaded = free is None or free >= 2
    kernel = _points_general if threaded else _points_general_serial
    kernel(uv, Suv, k["params"], k["R"], k["omega"], k["colptr"], k["rowidx"], k["vals"], k["vc"],
           k["Ccc"], k["has_qc"], dom, xy, cov, valid, reason, nlin)


#: the entry kernels, by use (:mod:`footprint_uq.products.warmup` checks their cache and compiles them ahead)
MAP_KERNELS = (_map_general, _map_undistorted)
POINT_KERNELS = (_points_general_serial, _points_general)
