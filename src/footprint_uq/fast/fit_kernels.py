"""Per-group sums of the budget fit's likelihood (numba): one pass over compact per-object records.

The budget fit (:mod:`footprint_uq.validation.fit`) needs, per calibration group ``g`` and at the current
per-object variances ``v_q`` (``D_i = R_i + sum_q v_q E_qi``, ``E = I`` for ``object_m``, ``j j^T`` for
``object_ground_m``), the sums over the group's objects of

* ``M = U^T D^-1 U`` (k, k), ``b = U^T D^-1 r`` (k), ``P = U^T D^-1`` (k, 2), ``Ds = D^-1`` (2, 2),
  ``Dr = D^-1 r`` (2), ``rDr = r^T D^-1 r`` and ``ld = log det D`` (the likelihood),
* per per-object term ``q`` (its score): ``T = tr(D^-1 E)``, ``W = V^T E V`` (k, k), ``Y = V^T E D^-1``
  (k, 2), ``X = D^-1 E D^-1`` (2, 2), ``y = V^T E D^-1 r`` (k), ``x = D^-1 E D^-1 r`` (2),
  ``s = r^T D^-1 E D^-1 r`` with ``V = D^-1 U``.

Every term of the score w.r.t. ``v_q`` is a group-level expression in these sums (the group's Woodbury
matrices enter only through them), so a likelihood evaluation is one pass over the records and small
per-group algebra: no per-object array is ever materialised.  Sums are in float64, in record order.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

__all__ = ["group_sums", "N_BASE", "N_SCORE"]

_JIT = dict(cache=True, error_model="numpy", fastmath={"contract"})


@nb.njit(**_JIT)
def _group_sums(r, U, R3, jg, gid, n_groups, v_obj, kinds, with_score):
    n, _, k = U.shape
    q = v_obj.size
    M = np.zeros((n_groups, k, k))
    b = np.zeros((n_groups, k))
    P = np.zeros((n_groups, k, 2))
    Ds = np.zeros((n_groups, 2, 2))
    Dr = np.zeros((n_groups, 2))
    rDr = np.zeros(n_groups)
    ld = np.zeros(n_groups)
    qs = q if with_score else 0
    T = np.zeros((n_groups, qs))
    W = np.zeros((n_groups, qs, k, k))
    Y = np.zeros((n_groups, qs, k, 2))
    X = np.zeros((n_groups, qs, 2, 2))
    yv = np.zeros((n_groups, qs, k))
    xv = np.zeros((n_groups, qs, 2))
    s = np.zeros((n_groups, qs))
    V = np.zeros((2, k))
    E = np.zeros((q, 3))
    bad = -1
    for i in range(n):
        g = gid[i]
        for j in range(q):
            if kinds[j] == 0:
                E[j, 0], E[j, 1], E[j, 2] = 1.0, 0.0, 1.0
            else:
                E[j, 0], E[j, 1], E[j, 2] = jg[i, 0] * jg[i, 0], jg[i, 0] * jg[i, 1], jg[i, 1] * jg[i, 1]
        d00, d01, d11 = R3[i, 0], R3[i, 1], R3[i, 2]
        for j in range(q):
            d00 += v_obj[j] * E[j, 0]
            d01 += v_obj[j] * E[j, 1]
            d11 += v_obj[j] * E[j, 2]
        det = d00 * d11 - d01 * d01
        if not det > 0:
            bad = i
            break
        i00, i01, i11 = d11 / det, -d01 / det, d00 / det
        r0, r1 = r[i, 0], r[i, 1]
        for c in range(k):
            V[0, c] = i00 * U[i, 0, c] + i01 * U[i, 1, c]
            V[1, c] = i01 * U[i, 0, c] + i11 * U[i, 1, c]
        for c in range(k):
            for e in range(k):
                M[g, c, e] += U[i, 0, c] * V[0, e] + U[i, 1, c] * V[1, e]
            b[g, c] += V[0, c] * r0 + V[1, c] * r1
            P[g, c, 0] += V[0, c]
            P[g, c, 1] += V[1, c]
        dr0, dr1 = i00 * r0 + i01 * r1, i01 * r0 + i11 * r1
        Ds[g, 0, 0] += i00
        Ds[g, 0, 1] += i01
        Ds[g, 1, 0] += i01
        Ds[g, 1, 1] += i11
        Dr[g, 0] += dr0
        Dr[g, 1] += dr1
        rDr[g] += r0 * dr0 + r1 * dr1
        ld[g] += math.log(det)
        for j in range(qs):
            e00, e01, e11 = E[j, 0], E[j, 1], E[j, 2]
            T[g, j] += i00 * e00 + 2.0 * i01 * e01 + i11 * e11
            # E D^-1 (2x2, not symmetric) and E D^-1 r
            a00, a01 = e00 * i00 + e01 * i01, e00 * i01 + e01 * i11
            a10, a11 = e01 * i00 + e11 * i01, e01 * i01 + e11 * i11
            er0, er1 = e00 * dr0 + e01 * dr1, e01 * dr0 + e11 * dr1
            for c in range(k):
                ev0 = e00 * V[0, c] + e01 * V[1, c]
                ev1 = e01 * V[0, c] + e11 * V[1, c]
                for e in range(k):
                    W[g, j, e, c] += V[0, e] * ev0 + V[1, e] * ev1
                Y[g, j, c, 0] += V[0, c] * a00 + V[1, c] * a10
                Y[g, j, c, 1] += V[0, c] * a01 + V[1, c] * a11
                yv[g, j, c] += V[0, c] * er0 + V[1, c] * er1
            X[g, j, 0, 0] += i00 * a00 + i01 * a10
            X[g, j, 0, 1] += i00 * a01 + i01 * a11
            X[g, j, 1, 0] += i01 * a00 + i11 * a10
            X[g, j, 1, 1] += i01 * a01 + i11 * a11
            xv[g, j, 0] += i00 * er0 + i01 * er1
            xv[g, j, 1] += i01 * er0 + i11 * er1
            s[g, j] += dr0 * er0 + dr1 * er1
    return bad, (M, b, P, Ds, Dr, rDr, ld), (T, W, Y, X, yv, xv, s)


#: names of the likelihood sums and of the per-object-term score sums, in the order returned
N_BASE = ("M", "b", "P", "Dsum", "Dr", "rDr", "ld")
N_SCORE = ("T", "W", "Y", "X", "y", "x", "s")


def group_sums(r, U, R3, jg, gid, n_groups: int, v_obj, kinds, *, with_score: bool = True):
    """Per-group sums (see the module docstring) of the compact records.

    Parameters
    ----------
    r : (N, 2) float64              residuals, m
    U : (N, 2, k) float64           Jacobian columns kept, m per parameter unit
    R3 : (N, 3) float64             per-object covariance ``(R00, R01, R11)``, m^2
    jg : (N, 2) float64             d(xy)/d(ground_dz) (only read where a ``kinds`` entry is 1)
    gid : (N,) int                  group index in ``[0, n_groups)``
    n_groups : int
    v_obj : (q,) float64            per-object variances
    kinds : (q,) int                0: isotropic (``object_m``), 1: ground (``object_ground_m``)
    with_score : bool               also the per-object-term score sums

    Returns
    -------
    dict or None
        ``None`` where some ``D_i`` is not positive definite; else the sums by name (``N_BASE`` and,
        with ``with_score``, ``N_SCORE``; the latter with a leading ``(G, q, ...)`` shape).
    """
    bad, base, score = _group_sums(r, U, R3, jg, gid, int(n_groups), np.asarray(v_obj, dtype=np.float64),
                                   np.asarray(kinds, dtype=np.int64), bool(with_score))
    if bad >= 0:
        return None
    out = dict(zip(N_BASE, base, strict=True))
    if with_score:
        out.update(zip(N_SCORE, score, strict=True))
    return out
