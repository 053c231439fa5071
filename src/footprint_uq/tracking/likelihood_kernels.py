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

from .kalman_kernels import pick_shared, schmidt_step, start_cov2

__all__ = ["bank_frame", "bank_predicted", "mix2_weights", "mix2_moments", "mixture_terms", "mode_terms",
           "add_member_terms", "LOG_2PI"]

LOG_2PI = math.log(2.0 * math.pi)


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def mix2_weights(mu, h, rates, cbar, W):  # pragma: no cover - compiled
    """IMM mixing weights of two modes with probabilities ``mu (2,)`` over a step ``h`` (s) of the chain leaving
    them at ``rates (2,)`` (1/s): ``W (2, 2)`` receives ``W[i, j]`` = P(mode i before | mode j after) and ``cbar
    (2,)`` the predicted mode probabilities."""
    a_, b_ = rates[0], rates[1]
    tot = a_ + b_
    e = -math.expm1(-tot * h) / tot if tot > 0.0 else 0.0
    p01, p10 = a_ * e, b_ * e
    pij = ((1.0 - p01, p01), (p10, 1.0 - p10))
    for j in range(2):
        cb = pij[0][j] * mu[0] + pij[1][j] * mu[1]
        cbar[j] = cb
        W[0, j], W[1, j] = pij[0][j] * mu[0] / cb, pij[1][j] * mu[1] / cb


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def mix2_moments(Xm, Pm, W, xs, Ps):  # pragma: no cover - compiled
    """The two modes' states ``Xm (2, n)`` and covariances ``Pm (2, n, n)`` mixed with the weights ``W (2, 2)`` of
    :func:`mix2_weights` into each mode's start ``xs (2, n)``, ``Ps (2, n, n)`` (moment matching)."""
    n = Xm.shape[1]
    for j in range(2):
        w0, w1 = W[0, j], W[1, j]
        for a in range(n):
            xs[j, a] = w0 * Xm[0, a] + w1 * Xm[1, a]
        for a in range(n):
            d0, d1 = Xm[0, a] - xs[j, a], Xm[1, a] - xs[j, a]
            for b in range(n):
                Ps[j, a, b] = (w0 * (Pm[0, a, b] + d0 * (Xm[0, b] - xs[j, b]))
                               + w1 * (Pm[1, a, b] + d1 * (Xm[1, b] - xs[j, b])))


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def mixture_terms(lik, cbar, ys, mu):  # pragma: no cover - compiled
    """A two-mode member's measurement terms from its modes' ``lik (2,)`` (``log cbar_j N(y_j; 0, S_j)`` without
    ``log 2 pi``), predicted probabilities ``cbar (2,)`` and innovations ``ys (2, 5)`` (``y0, y1, s00, s01, s11``):
    returns ``(log-likelihood, NIS)`` (the NIS of the predicted mixture's moments) and writes the posterior mode
    probabilities ``mu (2,)`` (each at least 1e-9 of the other, as the tracker: a mode never dies out)."""
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
        lik[j] = max(math.exp(lik[j] - top), 1e-9)
        tot += lik[j]
    for j in range(2):
        mu[j] = lik[j] / tot
    return ll, nis


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def mode_terms(j, step, cbar, lik, ys):  # pragma: no cover - compiled
    """Mode ``j``'s step ``(d2, det S, y0, y1, s00, s01, s11)`` (m, m^2) into ``lik[j] = log cbar_j N(y; 0, S)``
    (without ``log 2 pi``) and ``ys[j] (5,)``; returns False (nothing written) when its distance is not finite."""
    m, det = step[0], step[1]
    if not math.isfinite(m):
        return False
    lik[j] = -0.5 * m - 0.5 * math.log(det) + math.log(cbar[j])
    ys[j, 0], ys[j, 1], ys[j, 2], ys[j, 3], ys[j, 4] = step[2], step[3], step[4], step[5], step[6]
    return True


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def add_member_terms(k, ok, ll_g, nis_g, LL, NIS, n_upd, n_bad):  # pragma: no cover - compiled
    """One update's terms of every member, ``ll_g (G,)`` and ``nis_g (G,)``, added to class ``k``'s sums ``LL[k]``,
    ``NIS[k]`` and counted in ``n_upd[k]``; ``ok`` False (a member's innovation covariance was singular): counted
    in ``n_bad[k]`` only."""
    if not ok:
        n_bad[k] += 1
        return
    n_upd[k] += 1
    for g in range(ll_g.shape[0]):
        LL[k, g] += ll_g[g]
        NIS[k, g] += nis_g[g]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _member_step(Xm, Pm, Cm, mu, h, q, nm, rates, z, R, B, Pp, Cp, K, cross, W, xs, Ps, Cs, cbar, lik,
                 ys):  # pragma: no cover - compiled
    """One member's step on one track (in place): returns ``(log-likelihood, NIS)`` of the measurement (NaN: a
    singular innovation covariance; the state is then left as it was)."""
    if nm == 1:
        m, det, _, _, _, _, _ = schmidt_step(Xm[0], Pm[0], Cm[0], h, q[0], z, R, B, math.inf, Pp, Cp, K, cross)
        if not math.isfinite(m):
            return math.nan, math.nan
        return -0.5 * m - 0.5 * math.log(det) - LOG_2PI, m
    r = Cm.shape[2]
    mix2_weights(mu, h, rates, cbar, W)
    mix2_moments(Xm, Pm, W, xs, Ps)
    for j in range(2):  # the consider columns mix as the states
        w0, w1 = W[0, j], W[1, j]
        for a in range(4):
            for c in range(r):
                Cs[j, a, c] = w0 * Cm[0, a, c] + w1 * Cm[1, a, c]
    for j in range(2):
        if not mode_terms(j, schmidt_step(xs[j], Ps[j], Cs[j], h, q[j], z, R, B, math.inf, Pp, Cp, K, cross), cbar,
                          lik, ys):
            return math.nan, math.nan
    ll, nis = mixture_terms(lik, cbar, ys, mu)
    for j in range(2):
        for a in range(4):
            Xm[j, a] = xs[j, a]
            for b in range(4):
                Pm[j, a, b] = Ps[j, a, b]
            for c in range(r):
                Cm[j, a, c] = Cs[j, a, c]
    return ll, nis


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _start(Xm, Pm, Cm, mu, mu0, var_v0, z, R, B):  # pragma: no cover - compiled
    """A new track in every mode of one member (the tracker's initiator: the position is the measurement, its
    calibration share ``C = -B``; the velocity zero with variance ``var_v0``)."""
    r = B.shape[1]
    p00, p01, p11 = start_cov2(R, B)
    for j in range(Xm.shape[0]):
        mu[j] = mu0[j]
        for a in range(4):
            Xm[j, a] = z[a] if a < 2 else 0.0
            for b in range(4):
                Pm[j, a, b] = 0.0
            for c in range(r):
                Cm[j, a, c] = -B[a, c] if a < 2 else 0.0
        Pm[j, 0, 0], Pm[j, 1, 1] = p00, p11
        Pm[j, 0, 1] = Pm[j, 1, 0] = p01
        Pm[j, 2, 2] = Pm[j, 3, 3] = var_v0


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
    _bank_rows(rows, start, cls, t, z, R, B_pred, B_frame, X, P, C, MU, t_last, qs, nm, rates, mu0, var_v0, LL, NIS,
               n_upd, n_bad, np.empty((4, 4)), np.empty((4, r)), np.empty((4, 2)), np.empty((4, 2)), np.empty((2, 2)),
               np.empty((2, 4)), np.empty((2, 4, 4)), np.empty((2, 4, r)), np.empty(2), np.empty(2), np.empty((2, 5)),
               np.empty(G), np.empty(G))


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # (no refcounting: the scratch comes from the caller)
def _bank_rows(rows, start, cls, t, z, R, B_pred, B_frame, X, P, C, MU, t_last, qs, nm, rates, mu0, var_v0, LL, NIS,
               n_upd, n_bad, Pp, Cp, K, cross, W, xs, Ps, Cs, cbar, lik, ys, ll_g, nis_g):  # pragma: no cover
    """:func:`bank_frame`'s loop over the frame's objects, the working arrays given."""
    G = qs.shape[0]
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
        B = pick_shared(B_pred, i, B_frame, i)
        ok = True
        for g in range(G):
            ll_g[g], nis_g[g] = _member_step(X[s, g], P[s, g], C[s, g], MU[s, g], h, qs[g], nm[g], rates[g], z[i],
                                             R[i], B, Pp, Cp, K, cross, W, xs, Ps, Cs, cbar, lik, ys)
            ok = ok and math.isfinite(ll_g[g])
        t_last[s] = t
        add_member_terms(cls[i], ok, ll_g, nis_g, LL, NIS, n_upd, n_bad)


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
