"""Compiled exact likelihood of a track for a bank of motion models: the calibration error estimated jointly.

The tracker's Schmidt filter (:mod:`footprint_uq.tracking.filter`) never updates the calibration error ``w`` (its
consider state).  Each of its innovations has the right covariance, but they are correlated with the track's past
through ``w``: the product of their densities is not the track's likelihood, and its maximum sits at a manoeuvre
noise above the truth (a more agile filter follows the calibration error's drift along the path better; with the
full ``basler1@deg`` budget +37 % at q = 0.5 m^2/s^3 with an exact linear measurement model,
docs/motion-fit.md, section 2a).  The likelihood of a track is the prediction-error decomposition of the filter
that *does* estimate ``w``: the Kalman filter of the augmented state ``s = [x (4), w (r)]``, ``w`` a random
constant of prior ``N(0, I_r)``, measured by the split model of the tracker

    z = H_s s + e,    H_s = [I_2  0  B],    e ~ N(0, R),

so ``log L(q) = sum_k log N(y_k; 0, S_k)`` with ``y_k = z_k - H_s s_k|k-1`` and ``S_k = H_s P_k|k-1 H_s^T + R``
(exact for a linear model; the IMM members mix the augmented states as the tracker mixes its modes).

Storage of a bank of ``cap`` rows (tracks), ``G`` members, at most two modes, ``n = 4 + r``:
``X (cap, G, 2, n)``, ``P (cap, G, 2, n, n)``, ``MU (cap, G, 2)``, ``t_last (cap,)``.
``tests/test_motion_fit.py`` holds these kernels to a numpy augmented-state Kalman filter.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kalman_kernels import gain, innovation_distance, pick_shared, predict_cov_cv, predict_position
from .likelihood_kernels import LOG_2PI, add_member_terms, mix2_moments, mix2_weights, mixture_terms, mode_terms

__all__ = ["joint_bank_frame"]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _predict(x, P, h, q):  # pragma: no cover - compiled
    """Constant velocity over ``h`` (s) with acceleration density ``q``, in place (``w`` does not move)."""
    x[0], x[1] = predict_position(x, h)
    predict_cov_cv(P, h, q, x.shape[0])


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _update(x, P, z, R, B, PH, K):  # pragma: no cover - compiled
    """Update a predicted augmented state in place with ``z (2,)``, ``R (2, 2)``, ``B (2, r)``.  Returns ``(y^T
    S^-1 y, det S, y0, y1, s00, s01, s11)``; NaN distance (state not updated) if ``S`` is singular."""
    n, r = x.shape[0], B.shape[1]
    y0, y1 = z[0] - x[0], z[1] - x[1]
    for c in range(r):
        y0 -= B[0, c] * x[4 + c]
        y1 -= B[1, c] * x[4 + c]
    for a in range(n):  # PH = P H_s^T
        p0, p1 = P[a, 0], P[a, 1]
        for c in range(r):
            p0 += P[a, 4 + c] * B[0, c]
            p1 += P[a, 4 + c] * B[1, c]
        PH[a, 0], PH[a, 1] = p0, p1
    s00, s01, s10, s11 = PH[0, 0] + R[0, 0], PH[0, 1] + R[0, 1], PH[1, 0] + R[1, 0], PH[1, 1] + R[1, 1]
    for c in range(r):
        s00 += B[0, c] * PH[4 + c, 0]
        s01 += B[0, c] * PH[4 + c, 1]
        s10 += B[1, c] * PH[4 + c, 0]
        s11 += B[1, c] * PH[4 + c, 1]
    s01 = 0.5 * (s01 + s10)
    m, det, i00, i01, i11 = innovation_distance(s00, s01, s11, y0, y1)
    if not (math.isfinite(m) and det > 0.0):
        return math.nan, det, y0, y1, s00, s01, s11
    gain(PH, i00, i01, i11, K, n)
    for a in range(n):
        x[a] += K[a, 0] * y0 + K[a, 1] * y1
    for a in range(n):  # P - K S K^T = P - K PH^T (symmetric)
        for b in range(a, n):
            v = P[a, b] - (K[a, 0] * PH[b, 0] + K[a, 1] * PH[b, 1])
            P[a, b] = v
            P[b, a] = v
    return m, det, y0, y1, s00, s01, s11


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _store(Xm, Pm, j, xs, Ps):  # pragma: no cover - compiled
    n = Xm.shape[1]
    for a in range(n):
        Xm[j, a] = xs[j, a]
        for b in range(n):
            Pm[j, a, b] = Ps[j, a, b]


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _member_step(Xm, Pm, mu, h, q, nm, rates, z, R, B, PH, K, W, xs, Ps, cbar, lik, ys):  # pragma: no cover
    """One member's step on one track (in place): returns ``(log-likelihood, NIS)`` of the measurement (NaN: a
    singular innovation covariance; the state is then left as it was)."""
    if nm == 1:
        _store(xs, Ps, 0, Xm, Pm)  # (predicted and updated in the scratch: kept only if S is regular)
        _predict(xs[0], Ps[0], h, q[0])
        m, det, _, _, _, _, _ = _update(xs[0], Ps[0], z, R, B, PH, K)
        if not math.isfinite(m):
            return math.nan, math.nan
        _store(Xm, Pm, 0, xs, Ps)
        return -0.5 * m - 0.5 * math.log(det) - LOG_2PI, m
    mix2_weights(mu, h, rates, cbar, W)
    mix2_moments(Xm, Pm, W, xs, Ps)
    for j in range(2):
        _predict(xs[j], Ps[j], h, q[j])
        if not mode_terms(j, _update(xs[j], Ps[j], z, R, B, PH, K), cbar, lik, ys):
            return math.nan, math.nan
    ll, nis = mixture_terms(lik, cbar, ys, mu)
    for j in range(2):
        _store(Xm, Pm, j, xs, Ps)
    return ll, nis


@njit(cache=True, nogil=True, error_model="numpy", inline="always")
def _start(Xm, Pm, mu, mu0, var_v0, z, R, B):  # pragma: no cover - compiled
    """A new track in every mode of one member: position the measurement (error ``-(B w + e)``: covariance ``R + B
    B^T``, cross-covariance ``-B`` with ``w``), velocity zero with variance ``var_v0``, ``w`` its prior ``N(0, I)``."""
    n, r = Xm.shape[1], B.shape[1]
    for j in range(Xm.shape[0]):
        mu[j] = mu0[j]
        for a in range(n):
            Xm[j, a] = z[a] if a < 2 else 0.0
            for b in range(n):
                Pm[j, a, b] = 0.0
        for a in range(2):
            for b in range(2):
                acc = 0.0
                for c in range(r):
                    acc += B[a, c] * B[b, c]
                Pm[j, a, b] = 0.5 * (R[a, b] + R[b, a]) + acc
            for c in range(r):
                Pm[j, a, 4 + c] = Pm[j, 4 + c, a] = -B[a, c]
        Pm[j, 2, 2] = Pm[j, 3, 3] = var_v0
        for c in range(r):
            Pm[j, 4 + c, 4 + c] = 1.0


@njit(cache=True, nogil=True, error_model="numpy")
def joint_bank_frame(rows, start, cls, t, z, R, B_pred, B_frame, X, P, MU, t_last, qs, nm, rates, mu0, var_v0, LL,
                     NIS, n_upd, n_bad):  # pragma: no cover - compiled
    """One frame through a bank of augmented-state filters, in place: the arguments of
    :func:`~footprint_uq.tracking.likelihood_kernels.bank_frame`, with ``X (cap, G, 2, 4 + r)`` and ``P (cap, G,
    2, 4 + r, 4 + r)`` the members' augmented states (no consider cross-covariance: ``w`` is in the state)."""
    G, n = qs.shape[0], X.shape[3]
    _joint_rows(rows, start, cls, t, z, R, B_pred, B_frame, X, P, MU, t_last, qs, nm, rates, mu0, var_v0, LL, NIS,
                n_upd, n_bad, np.empty((n, 2)), np.empty((n, 2)), np.empty((2, 2)), np.empty((2, n)),
                np.empty((2, n, n)), np.empty(2), np.empty(2), np.empty((2, 5)), np.empty(G), np.empty(G))


@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)  # (no refcounting: the scratch comes from the caller)
def _joint_rows(rows, start, cls, t, z, R, B_pred, B_frame, X, P, MU, t_last, qs, nm, rates, mu0, var_v0, LL, NIS,
                n_upd, n_bad, PH, K, W, xs, Ps, cbar, lik, ys, ll_g, nis_g):  # pragma: no cover - compiled
    """:func:`joint_bank_frame`'s loop over the frame's objects, the working arrays given."""
    G = qs.shape[0]
    for i in range(rows.shape[0]):
        s = rows[i]
        if s < 0:
            continue
        if start[i]:
            for g in range(G):
                _start(X[s, g], P[s, g], MU[s, g], mu0[g], var_v0, z[i], R[i], B_frame[i])
            t_last[s] = t
            continue
        h = t - t_last[s]
        B = pick_shared(B_pred, i, B_frame, i)
        ok = True
        for g in range(G):
            ll_g[g], nis_g[g] = _member_step(X[s, g], P[s, g], MU[s, g], h, qs[g], nm[g], rates[g], z[i], R[i], B,
                                             PH, K, W, xs, Ps, cbar, lik, ys)
            ok = ok and math.isfinite(ll_g[g])
        t_last[s] = t
        add_member_terms(cls[i], ok, ll_g, nis_g, LL, NIS, n_upd, n_bad)
