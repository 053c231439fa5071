"""Compiled innovation likelihood of a bank of trackers run side by side on the same tracks (the motion fit).

Each *member* of the bank is one motion model of the tracker (:class:`~footprint_uq.tracking.table.TrackTable`'s
filter: constant-velocity modes, Schmidt consider state for the calibration error, IMM mixing with the same
switching chain and the same 1e-9 floor of a mode's probability) with its own acceleration densities.  Every
member sees the same measurements; per measurement it adds the log-density of its innovation,
``log sum_j cbar_j N(y_j; 0, S_j)`` (one mode: ``log N(y; 0, S)``), to the likelihood of the object's class, and
its normalised innovation squared ``y^T S^-1 y`` (of the mode-mixture's moments) to a sum of NIS.

Storage of a bank of ``cap`` rows (tracks), ``G`` members, at most two modes, calibration rank ``r``:
``X (cap, G, 2, 4)``, ``P (cap, G, 2, 4, 4)``, ``C (cap, G, 2, 4, r)``, ``MU (cap, G, 2)``, ``t_last (cap,)``.
``tests/test_motion_fit.py`` holds these kernels to the numpy reference (:class:`~footprint_uq.tracking.filter.
InteractingModels`, :class:`~footprint_uq.tracking.filter.SchmidtUpdater`).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["bank_frame", "bank_predicted", "pick_shared", "LOG_2PI"]

LOG_2PI = math.log(2.0 * math.pi)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _predict_update(x, P, C, h, q, z, R, B, Pp, Cp, K, cross):  # pragma: no cover - compiled
    """One mode of one track, in place: predict by ``h`` (s) with acceleration density ``q`` and update with
    ``z (2,)``, ``R (2, 2)``, ``B (2, r)`` (the split measurement model of :mod:`footprint_uq.tracking.filter`).
    Returns ``(y^T S^-1 y, det S, y0, y1, s00, s01, s11)``; NaN distance (state untouched) if S is singular."""
    r = C.shape[1]
    for a in range(4):
        for b in range(4):
            Pp[a, b] = P[a, b]
    for a in range(4):
        Pp[0, a] += h * Pp[2, a]
        Pp[1, a] += h * Pp[3, a]
    for a in range(4):
        Pp[a, 0] += h * Pp[a, 2]
        Pp[a, 1] += h * Pp[a, 3]
    q3, q2, q1 = q * h * h * h / 3.0, q * h * h / 2.0, q * h
    Pp[0, 0] += q3
    Pp[1, 1] += q3
    Pp[2, 2] += q1
    Pp[3, 3] += q1
    Pp[0, 2] += q2
    Pp[2, 0] += q2
    Pp[1, 3] += q2
    Pp[3, 1] += q2
    for c in range(r):
        Cp[0, c] = C[0, c] + h * C[2, c]
        Cp[1, c] = C[1, c] + h * C[3, c]
        Cp[2, c] = C[2, c]
        Cp[3, c] = C[3, c]
    x0, x1 = x[0] + h * x[2], x[1] + h * x[3]
    s00, s01, s11 = Pp[0, 0] + R[0, 0], Pp[0, 1] + R[0, 1], Pp[1, 1] + R[1, 1]
    for a in range(4):
        cross[a, 0], cross[a, 1] = Pp[a, 0], Pp[a, 1]
    for c in range(r):
        b0, b1 = B[0, c], B[1, c]
        s00 += 2.0 * Cp[0, c] * b0 + b0 * b0
        s01 += Cp[0, c] * b1 + b0 * Cp[1, c] + b0 * b1
        s11 += 2.0 * Cp[1, c] * b1 + b1 * b1
        for a in range(4):
            cross[a, 0] += Cp[a, c] * b0
            cross[a, 1] += Cp[a, c] * b1
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    y0, y1 = z[0] - x0, z[1] - x1
    m = y0 * y0 * i00 + 2.0 * y0 * y1 * i01 + y1 * y1 * i11
    if not (math.isfinite(m) and det > 0.0):
        return math.nan, det, y0, y1, s00, s01, s11
    for a in range(4):
        K[a, 0] = cross[a, 0] * i00 + cross[a, 1] * i01
        K[a, 1] = cross[a, 0] * i01 + cross[a, 1] * i11
    x[0], x[1] = x0 + K[0, 0] * y0 + K[0, 1] * y1, x1 + K[1, 0] * y0 + K[1, 1] * y1
    x[2] += K[2, 0] * y0 + K[2, 1] * y1
    x[3] += K[3, 0] * y0 + K[3, 1] * y1
    for a in range(4):
        for b in range(a, 4):
            v = Pp[a, b] - (K[a, 0] * cross[b, 0] + K[a, 1] * cross[b, 1])
            w = Pp[b, a] - (K[b, 0] * cross[a, 0] + K[b, 1] * cross[a, 1])
            P[a, b] = P[b, a] = 0.5 * (v + w)
    for c in range(r):
        e0, e1 = Cp[0, c] + B[0, c], Cp[1, c] + B[1, c]
        for a in range(4):
            C[a, c] = Cp[a, c] - (K[a, 0] * e0 + K[a, 1] * e1)
    return m, det, y0, y1, s00, s01, s11


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _mix2(Xm, Pm, Cm, mu, h, rates, xs, Ps, Cs, cbar):  # pragma: no cover - compiled
    """IMM mixing of one member's two modes (``Xm (2, 4)``, ``Pm``, ``Cm``, ``mu (2,)``) over a step ``h``: the
    start states ``xs, Ps, Cs`` of each mode and the predicted mode probabilities ``cbar (2,)``."""
    r = Cm.shape[2]
    a_, b_ = rates[0], rates[1]
    tot = a_ + b_
    e = -math.expm1(-tot * h) / tot if tot > 0.0 else 0.0
    p01, p10 = a_ * e, b_ * e
    pij = ((1.0 - p01, p01), (p10, 1.0 - p10))
    for j in range(2):
        cb = pij[0][j] * mu[0] + pij[1][j] * mu[1]
        cbar[j] = cb
        w0, w1 = pij[0][j] * mu[0] / cb, pij[1][j] * mu[1] / cb
        for a in range(4):
            xs[j, a] = w0 * Xm[0, a] + w1 * Xm[1, a]
            for c in range(r):
                Cs[j, a, c] = w0 * Cm[0, a, c] + w1 * Cm[1, a, c]
        for a in range(4):
            d0, d1 = Xm[0, a] - xs[j, a], Xm[1, a] - xs[j, a]
            for b in range(4):
                Ps[j, a, b] = (w0 * (Pm[0, a, b] + d0 * (Xm[0, b] - xs[j, b]))
                               + w1 * (Pm[1, a, b] + d1 * (Xm[1, b] - xs[j, b])))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _member_step(Xm, Pm, Cm, mu, h, q, nm, rates, z, R, B, Pp, Cp, K, cross, xs, Ps, Cs, cbar, lik,
                 ys):  # pragma: no cover - compiled
    """One member's step on one track (in place): returns ``(log-likelihood, NIS)`` of the measurement (NaN: a
    singular innovation covariance; the state is then left as it was)."""
    if nm == 1:
        m, det, _, _, _, _, _ = _predict_update(Xm[0], Pm[0], Cm[0], h, q[0], z, R, B, Pp, Cp, K, cross)
        if not math.isfinite(m):
            return math.nan, math.nan
        return -0.5 * m - 0.5 * math.log(det) - LOG_2PI, m
    _mix2(Xm, Pm, Cm, mu, h, rates, xs, Ps, Cs, cbar)
    for j in range(2):
        m, det, y0, y1, s00, s01, s11 = _predict_update(xs[j], Ps[j], Cs[j], h, q[j], z, R, B, Pp, Cp, K, cross)
        if not math.isfinite(m):
            return math.nan, math.nan
        lik[j] = -0.5 * m - 0.5 * math.log(det) + math.log(cbar[j])
        ys[j, 0], ys[j, 1], ys[j, 2], ys[j, 3], ys[j, 4] = y0, y1, s00, s01, s11
    top = max(lik[0], lik[1])
    ll = top + math.log(math.exp(lik[0] - top) + math.exp(lik[1] - top)) - LOG_2PI
    # NIS of the predicted mixture's moments: y = sum cbar_j y_j, S = sum cbar_j (S_j + (y_j - y)(y_j - y)^T)
    ym0 = cbar[0] * ys[0, 0] + cbar[1] * ys[1, 0]
    ym1 = cbar[0] * ys[0, 1] + cbar[1] * ys[1, 1]
    s00 = s01 = s11 = 0.0
    for j in range(2):
        d0, d1 = ys[j, 0] - ym0, ys[j, 1] - ym1
        s00 += cbar[j] * (ys[j, 2] + d0 * d0)
        s01 += cbar[j] * (ys[j, 3] + d0 * d1)
        s11 += cbar[j] * (ys[j, 4] + d1 * d1)
    nis = (ym0 * ym0 * s11 - 2.0 * ym0 * ym1 * s01 + ym1 * ym1 * s00) / (s00 * s11 - s01 * s01)
    tot = 0.0
    for j in range(2):
        lik[j] = max(math.exp(lik[j] - top), 1e-9)  # as the tracker: a mode never dies out
        tot += lik[j]
    for j in range(2):
        mu[j] = lik[j] / tot
        for a in range(4):
            Xm[j, a] = xs[j, a]
            for b in range(4):
                Pm[j, a, b] = Ps[j, a, b]
            for c in range(Cm.shape[2]):
                Cm[j, a, c] = Cs[j, a, c]
    return ll, nis


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _start(Xm, Pm, Cm, mu, mu0, var_v0, z, R, B):  # pragma: no cover - compiled
    """A new track in every mode of one member (the tracker's initiator: the position is the measurement, its
    calibration share ``C = -B``; the velocity zero with variance ``var_v0``)."""
    r = B.shape[1]
    for j in range(Xm.shape[0]):
        mu[j] = mu0[j]
        for a in range(4):
            Xm[j, a] = z[a] if a < 2 else 0.0
            for b in range(4):
                Pm[j, a, b] = 0.0
            for c in range(r):
                Cm[j, a, c] = -B[a, c] if a < 2 else 0.0
        for a in range(2):
            for b in range(2):
                acc = 0.0
                for c in range(r):
                    acc += B[a, c] * B[b, c]
                Pm[j, a, b] = R[a, b] + acc
        off = 0.5 * (Pm[j, 0, 1] + Pm[j, 1, 0])
        Pm[j, 0, 1] = Pm[j, 1, 0] = off
        Pm[j, 2, 2] = Pm[j, 3, 3] = var_v0


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def pick_shared(B_pred, i, B_frame):  # pragma: no cover - compiled
    """``B_pred[i]`` where it is given and finite, else ``B_frame[i]`` (as the tracker)."""
    if B_pred.shape[0] == 0:
        return B_frame[i]
    for c in range(B_pred.shape[2]):
        if not (math.isfinite(B_pred[i, 0, c]) and math.isfinite(B_pred[i, 1, c])):
            return B_frame[i]
    return B_pred[i]


@njit(cache=True, nogil=True, error_model="numpy")
def bank_frame(rows, start, cls, t, z, R, B_pred, B_frame, X, P, C, MU, t_last, qs, nm, rates, mu0, var_v0, LL,
               NIS, n_upd, n_bad):  # pragma: no cover - compiled
    """One frame through a bank, in place.

    Object ``i`` of the frame is bank row ``rows[i]`` (-1: not tracked, skipped); ``start[i]``: its track starts
    here (every member initiated from ``z[i]``, ``R[i]``, ``B_frame[i]``, mode probabilities ``mu0[g]``); else
    every member ``g`` (modes ``nm[g]`` of densities ``qs[g]``, leaving rates ``rates[g]`` in 1/s) steps from
    ``t_last`` to ``t`` with ``B_pred[i]`` (``B`` at the track's predicted position; ``(0, 2, 0)``: none) where
    finite, else ``B_frame[i]``, and adds its innovation's log-density to ``LL[cls[i], g]`` and its NIS to
    ``NIS[cls[i], g]``; ``n_upd[cls[i]]`` counts the updates, ``n_bad[cls[i]]`` those where a member's innovation
    covariance was singular (the whole update is then left out)."""
    G, r = qs.shape[0], C.shape[4]
    Pp, Cp, K, cross = np.empty((4, 4)), np.empty((4, r)), np.empty((4, 2)), np.empty((4, 2))
    xs, Ps, Cs = np.empty((2, 4)), np.empty((2, 4, 4)), np.empty((2, 4, r))
    cbar, lik, ys = np.empty(2), np.empty(2), np.empty((2, 5))
    ll_g, nis_g = np.empty(G), np.empty(G)
    for i in range(rows.shape[0]):
        s = rows[i]
        if s < 0:
            continue
        if start[i]:
            for g in range(G):
                _start(X[s, g], P[s, g], C[s, g], MU[s, g], mu0[g], var_v0, z[i], R[i], B_frame[i])
            t_last[s] = t
            continue
        h = t - t_last[s]
        B = pick_shared(B_pred, i, B_frame)
        ok = True
        for g in range(G):
            ll_g[g], nis_g[g] = _member_step(X[s, g], P[s, g], C[s, g], MU[s, g], h, qs[g], nm[g], rates[g], z[i],
                                             R[i], B, Pp, Cp, K, cross, xs, Ps, Cs, cbar, lik, ys)
            ok = ok and math.isfinite(ll_g[g])
        t_last[s] = t
        k = cls[i]
        if not ok:
            n_bad[k] += 1
            continue
        n_upd[k] += 1
        for g in range(G):
            LL[k, g] += ll_g[g]
            NIS[k, g] += nis_g[g]


@njit(cache=True, nogil=True, error_model="numpy")
def bank_predicted(rows, start, t, X, MU, t_last, g_ref, pred):  # pragma: no cover - compiled
    """Positions ``pred (n, 2)`` of the frame's continuing tracks predicted to ``t`` by member ``g_ref`` (its modes'
    combination; NaN for starts and untracked objects): where ``B`` is evaluated for the update."""
    for i in range(rows.shape[0]):
        s = rows[i]
        if s < 0 or start[i]:
            pred[i, 0] = pred[i, 1] = math.nan
            continue
        h = t - t_last[s]
        x0 = x1 = 0.0
        for j in range(MU.shape[2]):
            w = MU[s, g_ref, j]
            x0 += w * (X[s, g_ref, j, 0] + h * X[s, g_ref, j, 2])
            x1 += w * (X[s, g_ref, j, 1] + h * X[s, g_ref, j, 3])
        pred[i, 0], pred[i, 1] = x0, x1
