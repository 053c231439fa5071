"""Fused per-pixel kernels: ground point and 2x2 covariance of every pixel (numba).

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

from .. import params as P
from .. import status
from .._checks import as_points, check_cov
from ..cameras.rotation import R_W_C, dR_W_C
from ..errors import InputError
from ..uncertainty.budget import load_budget
from . import core

__all__ = ["covariance_map", "covariance_points", "kernel_constants"]

_JIT = dict(parallel=True, fastmath={"contract"}, cache=True, error_model="numpy")
_JIT1 = dict(fastmath={"contract"}, cache=True, error_model="numpy")

# index of the constant state rows for the position/height/ground parameters
_CONST_ROW = {P.XM: 0, P.YM: 1, P.HM: 2, P.GDZ: 3, P.GSX: 4, P.GSY: 5}


# --------------------------------------------------------------------------------------
# camera / budget constants
# --------------------------------------------------------------------------------------
def kernel_constants(camera, budget) -> dict:
    """Camera- and budget-level constants the kernels use (exposed for tests and debugging).

    Returns a dict with ``params`` (22,), ``R`` (3, 3) camera->world rotation,
    ``omega`` (3, 3) rotation generators (row k: ``R^T dR/d angle_k`` as a vector),
    the sparse factor ``colptr``, ``rowidx``, ``vals`` of the budget's parameter
    covariance, ``vc`` (r, 6) the constant state rows of each factor column,
    ``Ccc`` (6, 6) their covariance, ``has_qc`` (ray/constant cross-covariance
    present) and ``Suv`` (2, 2) the budget's per-point pixel covariance.
    """
    budget = load_budget(budget)
    p = np.ascontiguousarray(camera.params, dtype=np.float64)
    if p.shape != (P.N_PARAMS,) or not np.all(np.isfinite(p)):
        raise InputError("camera.params", p, f"{P.N_PARAMS} finite numbers")
    ang = (p[P.PAN], p[P.TILT], p[P.ROLL])
    R = np.ascontiguousarray(R_W_C(*ang))
    dR = dR_W_C(*ang)
    omega = np.empty((3, 3))
    for k in range(3):
        A = R.T @ dR[k]
        omega[k] = (A[2, 1], A[0, 2], A[1, 0])
    colptr, rowidx, vals = budget.param_factor()
    r = colptr.size - 1
    vc = np.zeros((r, 6))
    has_qc = False
    for j in range(r):
        ray = False
        const = False
        for nz in range(colptr[j], colptr[j + 1]):
            k = int(rowidx[nz])
            if k in _CONST_ROW:
                vc[j, _CONST_ROW[k]] += vals[nz]
                const = True
            else:
                ray = True
        has_qc = has_qc or (ray and const)
    Ccc = vc.T @ vc
    return dict(params=p, R=R, omega=np.ascontiguousarray(omega), colptr=colptr, rowidx=rowidx, vals=vals,
                vc=np.ascontiguousarray(vc), Ccc=np.ascontiguousarray(Ccc), has_qc=has_qc,
                Suv=np.ascontiguousarray(budget.pixel_covariance()))


# --------------------------------------------------------------------------------------
# shared numba helpers
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


# --------------------------------------------------------------------------------------
# kernel 1: zero nominal distortion (the paper's pan-tilt camera), per-row polynomials
# --------------------------------------------------------------------------------------
@nb.njit(**_JIT1)
def _row_polys(yn, prm, om, colptr, rowidx, vals, vc, has_qc, Cpq, P00, P01, P11, BQ):
    """Per-row polynomial coefficients of C_qq (degree 14) and of the q/constant cross terms (degree 7)."""
    P00[:] = 0.0
    P01[:] = 0.0
    P11[:] = 0.0
    BQ[:] = 0.0
    a = np.empty(8)
    b = np.empty(8)
    r = colptr.size - 1
    for j in range(r):
        a[:] = 0.0
        b[:] = 0.0
        ray = False
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            if k < 13 or (k >= 16 and k <= 18):
                _add_ray_poly(k, vals[nz], yn, prm, om, a, b)
                ray = True
        if not ray:
            continue
        for i in range(8):
            ai = a[i]
            bi = b[i]
            for m in range(8):
                P00[i + m] += ai * a[m]
                P01[i + m] += ai * b[m]
                P11[i + m] += bi * b[m]
        if has_qc:
            for c in range(6):
                v = vc[j, c]
                if v != 0.0:
                    for i in range(8):
                        BQ[0, c, i] += a[i] * v
                        BQ[1, c, i] += b[i] * v
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

    Returns ``(ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11)``.
    """
    Hn = cst[2]
    g0 = cst[3]
    g1 = cst[4]
    dxr = dx0 + x * cst[9]
    dyr = dy0 + x * cst[10]
    dn = dn0 + x * g0
    ok = dn < 0.0
    w = -1.0 / dn
    lam = Hn * w
    ox = lam * dxr
    oy = lam * dyr
    Q00 = w * (cst[5] + ox * g0)
    Q01 = w * (cst[6] + ox * g1)
    Q10 = w * (cst[7] + oy * g0)
    Q11 = w * (cst[8] + oy * g1)
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
    return ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11


@nb.njit(inline="always", **_JIT1)
def _store_pixel(xr, cr, vr, iu, ok, x, y, c00, c01, c11):
    nan = np.nan
    xr[2 * iu] = x if ok else nan
    xr[2 * iu + 1] = y if ok else nan
    cr[4 * iu] = c00 if ok else nan
    cr[4 * iu + 1] = c01 if ok else nan
    cr[4 * iu + 2] = c01 if ok else nan
    cr[4 * iu + 3] = c11 if ok else nan
    vr[iu] = ok


@nb.njit(**_JIT1)
def _row_undistorted(cst, cxs, dx0, dy0, dn0, P00, P01, P11, xr, cr, vr):
    """One image row (1-D views of the outputs, so that LLVM vectorises the pixel loop)."""
    x0 = cst[0]
    y0 = cst[1]
    stepf = cst[27]
    ifx = cst[28]
    for iu in range(vr.shape[0]):
        x = (np.float64(iu) * stepf - cxs) * ifx
        ok, ox, oy, _, _, _, _, _, _, c00, c01, c11 = _pixel_undistorted(cst, x, dx0, dy0, dn0, P00, P01, P11)
        _store_pixel(xr, cr, vr, iu, ok, x0 + ox, y0 + oy, c00, c01, c11)


@nb.njit(**_JIT1)
def _row_undistorted_qc(cst, cxs, dx0, dy0, dn0, P00, P01, P11, BQ, xr, cr, vr):
    """As :func:`_row_undistorted`, with ray/position/ground cross-covariances (full budgets)."""
    x0 = cst[0]
    y0 = cst[1]
    stepf = cst[27]
    ifx = cst[28]
    bq = np.zeros((2, 6))
    for iu in range(vr.shape[0]):
        x = (np.float64(iu) * stepf - cxs) * ifx
        ok, ox, oy, Q00, Q01, Q10, Q11, ax, ay, c00, c01, c11 = _pixel_undistorted(cst, x, dx0, dy0, dn0,
                                                                                   P00, P01, P11)
        for a_ in range(2):
            for c_ in range(6):
                bq[a_, c_] = _horner7(BQ[a_, c_], x)
        E00 = Q00 * bq[0, 0] + Q01 * bq[1, 0]
        E01 = Q00 * bq[0, 1] + Q01 * bq[1, 1]
        E10 = Q10 * bq[0, 0] + Q11 * bq[1, 0]
        E11 = Q10 * bq[0, 1] + Q11 * bq[1, 1]
        rx, ry = -ox, -oy
        h0 = bq[0, 2] - bq[0, 3] + bq[0, 4] * rx + bq[0, 5] * ry
        h1 = bq[1, 2] - bq[1, 3] + bq[1, 4] * rx + bq[1, 5] * ry
        n0 = Q00 * h0 + Q01 * h1
        n1 = Q10 * h0 + Q11 * h1
        c00 += 2.0 * E00 + 2.0 * n0 * ax
        c01 += E01 + E10 + n0 * ay + ax * n1
        c11 += 2.0 * E11 + 2.0 * n1 * ay
        _store_pixel(xr, cr, vr, iu, ok, x0 + ox, y0 + oy, c00, c01, c11)


@nb.njit(**_JIT)
def _map_undistorted(prm, R, om, colptr, rowidx, vals, vc, has_qc, Cpq, cst, step, xyf, covf, validf, reasonf, W):
    Hh = validf.shape[0] // W
    fy, cx, cy, sk = prm[1], prm[2], prm[3], prm[4]
    gx, gy = prm[20], prm[21]
    g1 = R[2, 1] - gx * R[0, 1] - gy * R[1, 1]
    g2 = R[2, 2] - gx * R[0, 2] - gy * R[1, 2]
    for iv in nb.prange(Hh):
        yn = (iv * step - cy) / fy
        P00 = np.empty(15)
        P01 = np.empty(15)
        P11 = np.empty(15)
        BQ = np.zeros((2, 6, 8))
        _row_polys(yn, prm, om, colptr, rowidx, vals, vc, has_qc, Cpq, P00, P01, P11, BQ)
        xr = xyf[2 * W * iv:2 * W * (iv + 1)]
        cr = covf[4 * W * iv:4 * W * (iv + 1)]
        vr = validf[W * iv:W * (iv + 1)]
        cxs, dx0, dy0, dn0 = cx + sk * yn, R[0, 1] * yn + R[0, 2], R[1, 1] * yn + R[1, 2], g1 * yn + g2
        if has_qc:
            _row_undistorted_qc(cst, cxs, dx0, dy0, dn0, P00, P01, P11, BQ, xr, cr, vr)
        else:
            _row_undistorted(cst, cxs, dx0, dy0, dn0, P00, P01, P11, xr, cr, vr)
        rr = reasonf[W * iv:W * (iv + 1)]
        for i in range(W):  # without distortion a pixel is fine or at / above the horizon
            rr[i] = status.OK if vr[i] else status.ABOVE_HORIZON
        _finish_row(xr, cr, vr, rr)


# --------------------------------------------------------------------------------------
# kernel 2: general (OpenCV with distortion), per point
# --------------------------------------------------------------------------------------
@nb.njit(**_JIT1)
def _point_general(u, v, S00, S01, S11, prm, R, om, colptr, rowidx, vals, vc, Ccc, has_qc, has_dist, dom, sq, bq):
    """Ground point and covariance of one pixel; sq (22, 2), bq (2, 6) scratch arrays.

    Returns ``(code, x, y, c00, c01, c11)`` with ``code`` a :mod:`footprint_uq.status` code
    (precedence as the reference: not finite, then undistortion, then horizon).
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
        return status.UNDISTORT_FAILED, np.nan, np.nan, np.nan, np.nan, np.nan
    if not ((dn < 0.0) and (Hn > 0.0)):
        return status.ABOVE_HORIZON, np.nan, np.nan, np.nan, np.nan, np.nan
    w = -1.0 / dn
    lam = Hn * w
    ox = lam * dxr
    oy = lam * dyr
    Q00 = w * (Hn * R[0, 0] + ox * g0)
    Q01 = w * (Hn * R[0, 1] + ox * g1)
    Q10 = w * (Hn * R[1, 0] + oy * g0)
    Q11 = w * (Hn * R[1, 1] + oy * g1)
    # d q / d param for every ray parameter (pre-M for intrinsics)
    for k in range(19):
        sq[k, 0] = 0.0
        sq[k, 1] = 0.0
    # intrinsics act on x_d: dq = M dx_d
    a0, a1 = -xd / fx, 0.0
    sq[0, 0] = M00 * a0 + M01 * a1
    sq[0, 1] = M10 * a0 + M11 * a1
    a0, a1 = sk * yd / (fx * fy), -yd / fy
    sq[1, 0] = M00 * a0 + M01 * a1
    sq[1, 1] = M10 * a0 + M11 * a1
    a0, a1 = -1.0 / fx, 0.0
    sq[2, 0] = M00 * a0 + M01 * a1
    sq[2, 1] = M10 * a0 + M11 * a1
    a0, a1 = sk / (fx * fy), -1.0 / fy
    sq[3, 0] = M00 * a0 + M01 * a1
    sq[3, 1] = M10 * a0 + M11 * a1
    a0, a1 = -yd / fx, 0.0
    sq[4, 0] = M00 * a0 + M01 * a1
    sq[4, 1] = M10 * a0 + M11 * a1
    # distortion: dq = -M d distort / dk at (xn, yn)
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
    # rotations
    for i in range(3):
        w0, w1, w2 = om[i, 0], om[i, 1], om[i, 2]
        sq[16 + i, 0] = w1 - w2 * yn - w0 * xn * yn + w1 * xn * xn
        sq[16 + i, 1] = -w0 * (1.0 + yn * yn) + w2 * xn + w1 * xn * yn
    # pixel noise: dq/duv = M A, A = [[1/fx, -sk/(fx fy)], [0, 1/fy]]
    B00 = M00 / fx
    B01 = -M00 * sk / (fx * fy) + M01 / fy
    B10 = M10 / fx
    B11 = -M10 * sk / (fx * fy) + M11 / fy
    T00 = B00 * S00 + B01 * S01
    T01 = B00 * S01 + B01 * S11
    T10 = B10 * S00 + B11 * S01
    T11 = B10 * S01 + B11 * S11
    q00 = T00 * B00 + T01 * B01
    q01 = T00 * B10 + T01 * B11
    q11 = T10 * B10 + T11 * B11
    bq[:] = 0.0
    r = colptr.size - 1
    for j in range(r):
        v0 = 0.0
        v1 = 0.0
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            if k < 13 or (k >= 16 and k <= 18):
                v0 += vals[nz] * sq[k, 0]
                v1 += vals[nz] * sq[k, 1]
        q00 += v0 * v0
        q01 += v0 * v1
        q11 += v1 * v1
        if has_qc:
            for c in range(6):
                bq[0, c] += v0 * vc[j, c]
                bq[1, c] += v1 * vc[j, c]
    c00, c01, c11 = _finish(q00, q01, q11, Q00, Q01, Q10, Q11, ox / Hn, oy / Hn, ox, oy, Ccc, bq, has_qc)
    x, y = x0 + ox, y0 + oy
    if not (np.isfinite(x) and np.isfinite(y) and np.isfinite(c00) and np.isfinite(c01) and np.isfinite(c11)):
        return status.OVERFLOW, np.nan, np.nan, np.nan, np.nan, np.nan
    return status.OK, x, y, c00, c01, c11


#: blocks of contiguous rows per thread in the general kernel (Newton warm-starts within a block)
_ROWS_PER_BLOCK_DIV = 16

# row buffers of the general map kernel
_XD, _XN, _YN, _M00, _M01, _M10, _M11, _Q00, _Q01, _Q11, _V0, _V1, _CONV, _IDEN, _YDB = range(15)
_NBUF = 15


@nb.njit(**_JIT1)
def _acc_param(k, lv, yd, prm, om, buf, W, sq):
    """Add ``lv * dq_k`` of every pixel of the row to ``buf[V0/V1]`` or, with ``sq``, add
    ``lv^2 dq_k dq_k^T`` to ``buf[Q00/Q01/Q11]`` (one vectorised loop per parameter type)."""
    fx, fy, sk = prm[0], prm[1], prm[4]
    xd, xn, yn = buf[_XD], buf[_XN], buf[_YN]
    M00, M01, M10, M11 = buf[_M00], buf[_M01], buf[_M10], buf[_M11]
    v0, v1 = buf[_V0], buf[_V1]
    q00, q01, q11 = buf[_Q00], buf[_Q01], buf[_Q11]
    if k <= 4:  # intrinsics act on x_d: dq = M dx_d, dx_d = (a0 + a1 x_d, b0)
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
        if sq:
            for i in range(W):
                e = a0 + a1 * xd[i]
                f0 = M00[i] * e + M01[i] * b0
                f1 = M10[i] * e + M11[i] * b0
                q00[i] += f0 * f0
                q01[i] += f0 * f1
                q11[i] += f1 * f1
        else:
            for i in range(W):
                e = a0 + a1 * xd[i]
                v0[i] += M00[i] * e + M01[i] * b0
                v1[i] += M10[i] * e + M11[i] * b0
    elif k <= 12:  # distortion: dq = -M d distort / dk at (x_n, y_n)
        i8 = k - 5
        d = prm[5:13]
        k1, k2, k3 = d[0], d[1], d[4]
        iden_ = buf[_IDEN]  # 1 / (1 + k4 r2 + k5 r2^2 + k6 r2^3) at (x_n, y_n), from the Newton pass
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
    elif k >= 16 and k <= 18:
        w0, w1, w2 = lv * om[k - 16, 0], lv * om[k - 16, 1], lv * om[k - 16, 2]
        if sq:
            for i in range(W):
                x = xn[i]
                y = yn[i]
                f0 = w1 - w2 * y - w0 * x * y + w1 * x * x
                f1 = -w0 * (1.0 + y * y) + w2 * x + w1 * x * y
                q00[i] += f0 * f0
                q01[i] += f0 * f1
                q11[i] += f1 * f1
        else:
            for i in range(W):
                x = xn[i]
                y = yn[i]
                v0[i] += w1 - w2 * y - w0 * x * y + w1 * x * x
                v1[i] += -w0 * (1.0 + y * y) + w2 * x + w1 * x * y


@nb.njit(**_JIT1)
def _row_general(v, prm, R, om, colptr, rowidx, vals, vc, colkind, Om, has_qc, has_dist, dom, warm, cst, Suv, buf,
                 BQ, xr, cr, vr, rr):
    """One image row of the general kernel: undistortion, then the covariance (all loops vectorise).

    Undistortion is the scalar core's (:func:`footprint_uq.fast.core.undistort_vec`: the
    lens's valid domain, Newton, the reference's acceptance test and its robust retry).  With
    ``warm``, ``buf`` holds the previous row's solution: Newton then starts from its
    first-order continuation ``x_n,prev + M_prev (x_d - x_d,prev)`` where that pixel
    converged (2-3 iterations instead of 5-8), else from ``x_d``.  ``rr`` receives the
    :mod:`footprint_uq.status` code of each pixel.
    """
    W = vr.shape[0]
    fx, fy, cx, cy, sk = prm[0], prm[1], prm[2], prm[3], prm[4]
    d = prm[5:13]
    stepf = cst[27]
    yd = (v - cy) / fy
    xd, xn, yn = buf[_XD], buf[_XN], buf[_YN]
    M00, M01, M10, M11 = buf[_M00], buf[_M01], buf[_M10], buf[_M11]
    cv = buf[_CONV]
    idn_b = buf[_IDEN]
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
    ok = vr
    if has_dist:
        # the scalar core's undistortion, vectorised over the row (same answer as the reference)
        ydb = buf[_YDB]
        ydb[:] = yd
        core.undistort_vec(dom, d, xd, ydb, xn, yn, M00, M01, M10, M11, idn_b, ok)
        for i in range(W):
            cv[i] = yd if ok[i] else np.nan
    else:
        for i in range(W):
            ok[i] = True
            idn_b[i] = 1.0
            M00[i] = 1.0
            M01[i] = 0.0
            M10[i] = 0.0
            M11[i] = 1.0
    # camera-level covariance in q-space, factor column by factor column
    q00, q01, q11, v0, v1 = buf[_Q00], buf[_Q01], buf[_Q11], buf[_V0], buf[_V1]
    q00[:] = 0.0
    q01[:] = 0.0
    q11[:] = 0.0
    if has_qc:
        BQ[:] = 0.0
    r = colptr.size - 1
    # factor columns acting on the intrinsics only: dx_d = (A0 + A1 x_d, B0), summed as polynomials
    # in x_d (row constants); with the pixel noise A Suv A^T they form the pre-M covariance C_pre
    fx, fy, sk = prm[0], prm[1], prm[4]
    ifx, ify, skf = 1.0 / fx, 1.0 / fy, -sk / (fx * fy)
    S00, S01, S11 = Suv[0, 0], Suv[0, 1], Suv[1, 1]
    c00_0 = ifx * ifx * S00 + 2.0 * ifx * skf * S01 + skf * skf * S11
    c01_0 = ifx * ify * S01 + skf * ify * S11
    c11_0 = ify * ify * S11
    c00_1, c00_2, c01_1 = 0.0, 0.0, 0.0
    for j in range(r):
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
    for j in range(r):
        if colkind[j] != 0:
            continue  # intrinsics-only (above) and rotation-only (Om, in the last loop) columns
        if colptr[j + 1] - colptr[j] == 1:
            k = rowidx[colptr[j]]
            if k < 13 or (k >= 16 and k <= 18):  # a ray parameter alone: no constant part
                _acc_param(k, vals[colptr[j]], yd, prm, om, buf, W, True)
            continue
        v0[:] = 0.0
        v1[:] = 0.0
        ray = False
        for nz in range(colptr[j], colptr[j + 1]):
            k = rowidx[nz]
            if k < 13 or (k >= 16 and k <= 18):
                _acc_param(k, vals[nz], yd, prm, om, buf, W, False)
                ray = True
        if not ray:
            continue
        for i in range(W):
            a = v0[i]
            b = v1[i]
            q00[i] += a * a
            q01[i] += a * b
            q11[i] += b * b
        if has_qc:
            for c in range(6):
                vcc = vc[j, c]
                if vcc != 0.0:
                    B0 = BQ[c]
                    B1 = BQ[6 + c]
                    for i in range(W):
                        B0[i] += v0[i] * vcc
                        B1[i] += v1[i] * vcc
    # per pixel: ray, ground point, Q, pixel noise, finish
    x0, y0, Hn, g0, g1 = cst[0], cst[1], cst[2], cst[3], cst[4]
    HR00, HR01, HR10, HR11 = cst[5], cst[6], cst[7], cst[8]
    p00, p01, p11 = cst[11], cst[12], cst[13]
    s0, s1, s2, s3, s4, s5 = cst[14], cst[15], cst[16], cst[17], cst[18], cst[19]
    m00, m01, m02, m10, m11, m12, iHn = cst[20], cst[21], cst[22], cst[23], cst[24], cst[25], cst[26]
    g2 = cst[29]
    R00, R01, R02, R10, R11, R12 = R[0, 0], R[0, 1], R[0, 2], R[1, 0], R[1, 1], R[1, 2]
    O00, O01, O02, O11, O12, O22 = Om[0, 0], Om[0, 1], Om[0, 2], Om[1, 1], Om[1, 2], Om[2, 2]
    nan = np.nan
    for i in range(W):
        x = xn[i]
        y = yn[i]
        dxr = R00 * x + R01 * y + R02
        dyr = R10 * x + R11 * y + R12
        dn = g0 * x + g1 * y + g2
        lens = ok[i]
        oki = lens & (dn < 0.0)
        rr[i] = status.OK if oki else (status.ABOVE_HORIZON if lens else status.UNDISTORT_FAILED)
        w = -1.0 / dn
        lam = Hn * w
        ox = lam * dxr
        oy = lam * dyr
        Q00 = w * (HR00 + ox * g0)
        Q01 = w * (HR01 + ox * g1)
        Q10 = w * (HR10 + oy * g0)
        Q11 = w * (HR11 + oy * g1)
        # intrinsics + pixel noise: M C_pre M^T, C_pre polynomial in x_d
        xdi = xd[i]
        e00 = c00_0 + xdi * (c00_1 + xdi * c00_2)
        e01 = c01_0 + xdi * c01_1
        e11 = c11_0
        m00_, m01_, m10_, m11_ = M00[i], M01[i], M10[i], M11[i]
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
        a00 = q00[i] + T00 * m00_ + T01 * m01_ + H0 * G00 + H1 * G01 + H2 * G02
        a01 = q01[i] + T00 * m10_ + T01 * m11_ + H0 * G10 + H1 * G11 + H2 * G12
        a11 = q11[i] + T10 * m10_ + T11 * m11_ + K0 * G10 + K1 * G11 + K2 * G12
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
        xr[2 * i] = x0 + ox if oki else nan
        xr[2 * i + 1] = y0 + oy if oki else nan
        cr[4 * i] = c00 if oki else nan
        cr[4 * i + 1] = c01 if oki else nan
        cr[4 * i + 2] = c01 if oki else nan
        cr[4 * i + 3] = c11 if oki else nan
        ok[i] = oki
    if has_qc:
        for i in range(W):
            if not ok[i]:
                continue
            x = xn[i]
            y = yn[i]
            dxr = R00 * x + R01 * y + R02
            dyr = R10 * x + R11 * y + R12
            dn = g0 * x + g1 * y + g2
            w = -1.0 / dn
            lam = Hn * w
            ox = lam * dxr
            oy = lam * dyr
            Q00 = w * (HR00 + ox * g0)
            Q01 = w * (HR01 + ox * g1)
            Q10 = w * (HR10 + oy * g0)
            Q11 = w * (HR11 + oy * g1)
            ax = ox * iHn
            ay = oy * iHn
            E00 = Q00 * BQ[0, i] + Q01 * BQ[6, i]
            E01 = Q00 * BQ[1, i] + Q01 * BQ[7, i]
            E10 = Q10 * BQ[0, i] + Q11 * BQ[6, i]
            E11 = Q10 * BQ[1, i] + Q11 * BQ[7, i]
            h0 = BQ[2, i] - BQ[3, i] - BQ[4, i] * ox - BQ[5, i] * oy
            h1 = BQ[8, i] - BQ[9, i] - BQ[10, i] * ox - BQ[11, i] * oy
            n0 = Q00 * h0 + Q01 * h1
            n1 = Q10 * h0 + Q11 * h1
            cr[4 * i] += 2.0 * E00 + 2.0 * n0 * ax
            c01 = E01 + E10 + n0 * ay + ax * n1
            cr[4 * i + 1] += c01
            cr[4 * i + 2] += c01
            cr[4 * i + 3] += 2.0 * E11 + 2.0 * n1 * ay
    _finish_row(xr, cr, vr, rr)


@nb.njit(**_JIT1)
def _finish_row(xr, cr, vr, rr):
    """Outputs are checked too: a pixel whose position or covariance is not finite is OVERFLOW (NaN)."""
    nan = np.nan
    for i in range(vr.shape[0]):
        if vr[i] and not (np.isfinite(xr[2 * i]) and np.isfinite(xr[2 * i + 1]) and np.isfinite(cr[4 * i])
                          and np.isfinite(cr[4 * i + 1]) and np.isfinite(cr[4 * i + 3])):
            vr[i] = False
            rr[i] = status.OVERFLOW
            xr[2 * i] = xr[2 * i + 1] = nan
            cr[4 * i] = cr[4 * i + 1] = cr[4 * i + 2] = cr[4 * i + 3] = nan


@nb.njit(**_JIT)
def _map_general(prm, R, om, colptr, rowidx, vals, vc, colkind, Om, has_qc, dom, cst, Suv, step, xyf, covf, validf,
                 reasonf, W, nblk):
    Hh = validf.shape[0] // W
    has_dist = False
    for i in range(5, 13):
        if prm[i] != 0.0:
            has_dist = True
    per = (Hh + nblk - 1) // nblk
    for blk in nb.prange(nblk):
        buf = np.empty((_NBUF, W))
        BQ = np.empty((12, W))
        for iv in range(blk * per, min(Hh, (blk + 1) * per)):
            _row_general(np.float64(iv * step), prm, R, om, colptr, rowidx, vals, vc, colkind, Om, has_qc, has_dist,
                         dom, iv > blk * per, cst, Suv, buf, BQ,
                         xyf[2 * W * iv:2 * W * (iv + 1)], covf[4 * W * iv:4 * W * (iv + 1)],
                         validf[W * iv:W * (iv + 1)], reasonf[W * iv:W * (iv + 1)])


@nb.njit(**_JIT)
def _points_general(uv, Suv, prm, R, om, colptr, rowidx, vals, vc, Ccc, has_qc, dom, xy, cov, valid, reason):
    n = uv.shape[0]
    has_dist = False
    for i in range(5, 13):
        if prm[i] != 0.0:
            has_dist = True
    nchunk = 64
    for c in nb.prange((n + nchunk - 1) // nchunk):
        sq = np.empty((22, 2))
        bq = np.zeros((2, 6))
        for i in range(c * nchunk, min(n, (c + 1) * nchunk)):
            u = uv[i, 0]
            v = uv[i, 1]
            if not (np.isfinite(u) and np.isfinite(v)):
                code, x, y, c00, c01, c11 = status.NOT_FINITE, np.nan, np.nan, np.nan, np.nan, np.nan
            else:
                code, x, y, c00, c01, c11 = _point_general(u, v, Suv[i, 0, 0], Suv[i, 0, 1], Suv[i, 1, 1], prm, R,
                                                           om, colptr, rowidx, vals, vc, Ccc, has_qc, has_dist, dom,
                                                           sq, bq)
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


# --------------------------------------------------------------------------------------
# public API
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


def _check_out(out, H, W):
    if not (isinstance(out, tuple | list) and len(out) == 3):
        raise InputError("out", type(out).__name__, "a tuple (xy_world_m, cov_m2, valid) of preallocated arrays")
    xy, cov, valid = out
    for name, a, shape, dt in (("out[0] (xy_world_m)", xy, (H, W, 2), np.float64),
                               ("out[1] (cov_m2)", cov, (H, W, 2, 2), np.float64),
                               ("out[2] (valid)", valid, (H, W), np.bool_)):
        if not isinstance(a, np.ndarray) or a.shape != shape or a.dtype != dt or not a.flags.c_contiguous \
                or not a.flags.writeable:
            got = (getattr(a, "shape", None), str(getattr(a, "dtype", type(a).__name__)))
            raise InputError(name, got, f"a writeable C-contiguous {np.dtype(dt).name} array of shape {shape}")
    return xy, cov, valid


def _pixel_cov_q(prm, Suv):
    fx, fy, sk = prm[0], prm[1], prm[4]
    A = np.array([[1.0 / fx, -sk / (fx * fy)], [0.0, 1.0 / fy]])
    return np.ascontiguousarray(A @ Suv @ A.T)


def covariance_map(camera, budget, step_px: int = 1, *, out=None, get_reason: bool = False):
    """Ground point, 2x2 covariance and validity of every pixel of a regular grid.

    Parameters
    ----------
    camera : Camera
        :class:`~footprint_uq.cameras.pantilt.PanTiltCamera` or
        :class:`~footprint_uq.cameras.opencv.OpenCVCamera`.  Cameras with zero
        nominal distortion use the closed-form kernel (per-row polynomials), others
        the general kernel with Newton undistortion.
    budget : ErrorBudget, preset name, path or mapping
        Every source is honoured, including a full parameter covariance; per-point
        imaging and resolution noise come from ``budget.pixel_covariance()``.
    step_px : int
        Grid step: pixel centres ``camera.pixel_grid(step_px)``.
    out : tuple of ndarray, optional
        Preallocated ``(xy_world_m (H, W, 2) float64, cov_m2 (H, W, 2, 2) float64,
        valid (H, W) bool)``, C-contiguous, for the grid's H, W; filled in place.
    get_reason : bool
        Also return the :mod:`footprint_uq.status` code of every pixel.

    Returns
    -------
    xy_world_m : ndarray (H, W, 2)
        Ground points in W (x east, y north), metres; NaN where invalid.
    cov_m2 : ndarray (H, W, 2, 2)
        Covariance, m^2; NaN where invalid.
    valid : ndarray of bool (H, W)
        False at or above the horizon, or outside the lens's valid domain.
    reason : ndarray of int8 (H, W), with ``get_reason``
        The same codes as :func:`footprint_uq.cameras.general.backproject`.
    """
    try:
        step = int(step_px)
    except (TypeError, ValueError):
        raise InputError("step_px", step_px, "a positive integer") from None
    if step != step_px or step <= 0:
        raise InputError("step_px", step_px, "a positive integer")
    w_img, h_img = camera.image_size_px
    W = (w_img + step - 1) // step
    H = (h_img + step - 1) // step
    if out is None:
        out = (np.empty((H, W, 2)), np.empty((H, W, 2, 2)), np.empty((H, W), dtype=np.bool_))
    xy, cov, valid = _check_out(out, H, W)
    k = kernel_constants(camera, budget)
    prm = k["params"]
    reason = np.empty((H, W), dtype=np.int8)
    if not prm[P.HM] - prm[P.GDZ] > 0:  # camera at or below the ground: no pixel sees it
        xy[:] = np.nan
        cov[:] = np.nan
        valid[:] = False
        reason[:] = status.ABOVE_HORIZON
        return (xy, cov, valid, reason) if get_reason else (xy, cov, valid)
    # dynamic scheduling in small chunks: on a shared machine a descheduled thread then
    # delays only its current chunk instead of half of the image
    old_chunk = nb.set_parallel_chunksize(1)
    try:
        if np.any(prm[P.DIST_SLICE]):
            colkind, Om = _column_kinds(k)
            nblk = min(H, _ROWS_PER_BLOCK_DIV * nb.get_num_threads())
            _map_general(prm, k["R"], k["omega"], k["colptr"], k["rowidx"], k["vals"], k["vc"], colkind, Om,
                         k["has_qc"], camera.lens_domain.packed, _undistorted_constants(k, step), k["Suv"], step,
                         xy.reshape(-1), cov.reshape(-1), valid.reshape(-1), reason.reshape(-1), W, nblk)
        else:
            _map_undistorted(prm, k["R"], k["omega"], k["colptr"], k["rowidx"], k["vals"], k["vc"], k["has_qc"],
                             _pixel_cov_q(prm, k["Suv"]), _undistorted_constants(k, step), step,
                             xy.reshape(-1), cov.reshape(-1), valid.reshape(-1), reason.reshape(-1), W)
    finally:
        nb.set_parallel_chunksize(old_chunk)
    return (xy, cov, valid, reason) if get_reason else (xy, cov, valid)


def covariance_points(camera, budget, uv_px, pixel_cov_px2=None, *, get_reason: bool = False):
    """Ground point, 2x2 covariance and validity of scattered pixels (general kernel).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    uv_px : array_like (..., 2)
        Pixel coordinates (u right, v down); non-finite rows give ``valid = False``.
    pixel_cov_px2 : array_like (2, 2) or (..., 2, 2), optional
        Extra per-point pixel covariance (e.g. a detector's), added to the budget's
        imaging and resolution noise, as in :func:`footprint_uq.uncertainty.propagation.propagate`.
    get_reason : bool
        Also return the :mod:`footprint_uq.status` code of every point.

    Returns
    -------
    xy_world_m : ndarray (..., 2)
    cov_m2 : ndarray (..., 2, 2)
    valid : ndarray of bool (...)
    reason : ndarray of int8 (...), with ``get_reason``
        The same codes as :func:`footprint_uq.cameras.general.backproject`.
    """
    budget = load_budget(budget)
    uv = as_points("uv_px", uv_px, 2)
    lead = uv.shape[:-1]
    flat = np.ascontiguousarray(uv.reshape(-1, 2))
    n = flat.shape[0]
    Suv = budget.pixel_covariance()
    if pixel_cov_px2 is not None:
        c = check_cov("pixel_cov_px2", pixel_cov_px2, 2)
        try:
            Suv = np.broadcast_to(Suv + c, lead + (2, 2))
        except ValueError:
            raise InputError("pixel_cov_px2", c.shape, f"a covariance of shape (2, 2) or {lead + (2, 2)}") from None
    Suv = np.ascontiguousarray(np.broadcast_to(Suv, lead + (2, 2)).reshape(n, 2, 2))
    k = kernel_constants(camera, budget)
    xy = np.empty((n, 2))
    cov = np.empty((n, 2, 2))
    valid = np.empty(n, dtype=np.bool_)
    reason = np.empty(n, dtype=np.int8)
    kernel = _points_general_serial if n < _SERIAL_BELOW else _points_general
    kernel(flat, Suv, k["params"], k["R"], k["omega"], k["colptr"], k["rowidx"], k["vals"], k["vc"],
           k["Ccc"], k["has_qc"], camera.lens_domain.packed, xy, cov, valid, reason)
    out = xy.reshape(lead + (2,)), cov.reshape(lead + (2, 2)), valid.reshape(lead)
    return out + (reason.reshape(lead),) if get_reason else out
