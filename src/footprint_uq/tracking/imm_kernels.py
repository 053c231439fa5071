"""The tracker's frame update as one compiled pass (the production path of :class:`~footprint_uq.tracking.table.
TrackTable`): per track the IMM mixing, each mode's Schmidt-Kalman predict and update with the consider columns
(the cross-covariances with the camera's calibration error), the mode probabilities and the combination.

The same filter as :func:`~footprint_uq.tracking.kernels.frame_update` (the compiled reference, itself held to the
numpy classes of :mod:`~footprint_uq.tracking.filter`), arranged for speed; ``tests/test_tracking_fast.py`` holds
the two to 1e-9 over frame sequences.  What is different (the arithmetic, not the model):

* two modes mix and combine in closed form: ``sum_i w_i (x_i - x)(x_i - x)^T = w_0 w_1 d d^T`` with
  ``d = x_0 - x_1`` (the weights sum to one), and only the 10 entries of each symmetric 4 x 4 are computed;
* the consider columns (4 x r per mode) of two modes are walked twice, and written once: the first walk reads
  both stored modes' columns and accumulates ``D_i = C_i B^T`` (16 running sums in registers) and ``B B^T``, from
  which ``G_j = C_p,j B^T = F (W_0j D_0 + W_1j D_1)`` (the innovation's and the gain's share; the mix and the
  predict are linear); the second forms each column's two predicted columns again and writes both posteriors
  ``C = C_p - K (H C_p + B)`` over the stored ones (2026-11-28, wave 9: before, the first walk wrote the predicted
  columns to a scratch that the second read back, 16 loads and stores more per column; in the bench's frame the
  pass 21.0-22.7 us against main's 21.6-26.6 in the same sessions, ~0.5-1 us less); one mode mixes and predicts
  into the scratch as before; the reference's scratch copies and per-mode zeroing are gone;
* the mode likelihoods' ratio takes one ``exp`` and one ``sqrt`` (the reference: four logs and two exps);
* the table stores each mode's consider columns column by column (``Cm (cap, M, r, 4)``: a column's 4 entries
  adjacent), so each walk over the columns reads and writes whole columns (~3 us less per 100-object frame than the
  row-by-row ``(4, r)`` on the frozen frame below; the reference reads the same storage);
* the mode switching factor ``(1 - exp(-(a + b) h)) / (a + b)`` is computed once per distinct step ``h`` of a frame
  (most tracks share it), not once per track (the same numbers to the bit);
* FMA contraction (``fastmath={"contract"}``, NaN / inf semantics kept), as the package's other kernels;
* no reference counting (numba's ``_nrt=False``; the scratch comes from the caller): every inlined helper's array
  arguments were an atomic increment and decrement each, ~25 arrays per track, ~160 ns of the ~430 ns a track
  cost (measured on the 2-core VM, 87 tracks of a 100-object frame: 38 us with, 24 us without).

:func:`frame_step` is a table's whole frame in one compiled call when its ``shared_at`` forms ``B`` in the rows' call
(the id look-up, :func:`~footprint_uq.tracking.kernels.frame_rows_shared`, the new ids' rows and :func:`frame_pass`;
before 2026-11-29, wave 11 c, four calls with the table's Python between them; docs/service.md has the figures).

Measured on the frame it was built for (``bench/bench_tracking.py``'s 100 objects, 87 of them updated, r = 13, on
the 2-core VM, one process): the reference pass 67 us; the same arithmetic without per-mode views, scratch copies
and zeroing 55 us (of which the 7 transcendental calls per track ~5 us); the closed forms, upper triangles and
one log + one exp 38 us; without reference counting 24 us; the two modes' columns in one walk ~9 % less.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .kernels import (
    ROW_START,
    claim_rows,
    expire_rows,
    frame_rows_shared,
    id_lookup,
    motion_fields,
    starts_and_outputs,
)

__all__ = ["frame_pass", "frame_step", "scratch"]


def scratch(n_modes: int, rank: int) -> tuple:
    """The working arrays of :func:`frame_pass` for ``n_modes`` modes (1 or 2) and consider rank ``rank``
    (allocated once per table: the pass itself allocates nothing; the predicted columns ``(M, r, 4)`` are used by
    one mode only)."""
    M = int(n_modes)
    return (np.empty((2, 2)), np.empty((M, 4)), np.empty((M, 4, 4)), np.empty((M, 4, 2)), np.empty((M, 4, 2)),
            np.empty((M, int(rank), 4)), np.empty((M, 3)))


_INL = dict(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, inline="always")
_JIT = dict(cache=True, nogil=True, error_model="numpy", fastmath={"contract"}, _nrt=False)


@njit(**_INL)
def _switching(h, rates):  # pragma: no cover - compiled
    """The two-mode chain's ``(1 - exp(-(a + b) h)) / (a + b)`` over a step ``h`` (s) with switching rates ``rates
    = (a, b)`` (1/s): ``P(0 -> 1) = a e``, ``P(1 -> 0) = b e`` (one mode: 0)."""
    if rates.shape[0] == 1:
        return 0.0
    tot = rates[0] + rates[1]
    return -math.expm1(-tot * h) / tot if tot > 0.0 else 0.0


@njit(**_INL)
def _weights(s, e, mu, rates, W):  # pragma: no cover - compiled
    """Mixing weights ``W[i, j]`` = P(mode i before | mode j after a step with :func:`_switching` factor ``e``) of
    track row ``s``; returns the predicted mode probabilities ``(cbar_0, cbar_1)`` (one mode: ``(1, 1)``)."""
    if rates.shape[0] == 1:
        W[0, 0] = 1.0
        return 1.0, 1.0
    a, b = rates[0], rates[1]
    p01, p10 = a * e, b * e
    p00, p11 = 1.0 - p01, 1.0 - p10
    m0, m1 = mu[s, 0], mu[s, 1]
    cb0, cb1 = p00 * m0 + p10 * m1, p01 * m0 + p11 * m1
    W[0, 0], W[1, 0] = p00 * m0 / cb0, p10 * m1 / cb0
    W[0, 1], W[1, 1] = p01 * m0 / cb1, p11 * m1 / cb1
    return cb0, cb1


@njit(**_INL)
def _columns_mix_predict(s, j, h, Cm, W, B, bi, Cps):  # pragma: no cover - compiled
    """Mode ``j``'s consider columns mixed and predicted into ``Cps[j] (r, 4)`` (``F C``: rows 0, 1 gain ``h``
    times rows 2, 3); returns ``G = C_p B^T`` (4 x 2, row-major, 8 floats) with ``B = B[bi] (2, r)``."""
    r = Cm.shape[2]
    two = Cm.shape[1] == 2
    w0 = W[0, j]
    w1 = W[1, j] if two else 0.0
    g00 = g01 = g10 = g11 = g20 = g21 = g30 = g31 = 0.0
    for c in range(r):
        c0, c1, c2, c3 = w0 * Cm[s, 0, c, 0], w0 * Cm[s, 0, c, 1], w0 * Cm[s, 0, c, 2], w0 * Cm[s, 0, c, 3]
        if two:
            c0 += w1 * Cm[s, 1, c, 0]
            c1 += w1 * Cm[s, 1, c, 1]
            c2 += w1 * Cm[s, 1, c, 2]
            c3 += w1 * Cm[s, 1, c, 3]
        c0 += h * c2
        c1 += h * c3
        Cps[j, c, 0], Cps[j, c, 1], Cps[j, c, 2], Cps[j, c, 3] = c0, c1, c2, c3
        b0, b1 = B[bi, 0, c], B[bi, 1, c]
        g00 += c0 * b0
        g01 += c0 * b1
        g10 += c1 * b0
        g11 += c1 * b1
        g20 += c2 * b0
        g21 += c2 * b1
        g30 += c3 * b0
        g31 += c3 * b1
    return g00, g01, g10, g11, g20, g21, g30, g31


@njit(**_INL)
def _columns_shares(s, h, Cm, W, B, bi):  # pragma: no cover - compiled
    """Both modes' ``G_j = C_p,j B^T`` (4 x 2, row-major, 8 floats each), ``B B^T``'s 3 entries and whether every
    entry of ``B[bi]`` is finite, from one walk over the stored columns that writes nothing: ``D_i = C_i B^T`` of
    each stored mode (16 running sums), then ``G_j = F (W[0, j] D_0 + W[1, j] D_1)`` (the mix and the predict are
    linear: ``C_p,j = F sum_i W[i, j] C_i``).  The predicted columns themselves are formed again in
    :func:`_columns_posterior`, column by column."""
    r = Cm.shape[2]
    a00 = a01 = a10 = a11 = a20 = a21 = a30 = a31 = 0.0
    d00 = d01 = d10 = d11 = d20 = d21 = d30 = d31 = 0.0
    bb00 = bb01 = bb11 = fin = 0.0
    for c in range(r):
        b0, b1 = B[bi, 0, c], B[bi, 1, c]
        fin += (b0 - b0) + (b1 - b1)  # (0 if both finite, else NaN: stays 0 only if all are)
        bb00 += b0 * b0
        bb01 += b0 * b1
        bb11 += b1 * b1
        x0, x1, x2, x3 = Cm[s, 0, c, 0], Cm[s, 0, c, 1], Cm[s, 0, c, 2], Cm[s, 0, c, 3]
        a00 += x0 * b0
        a01 += x0 * b1
        a10 += x1 * b0
        a11 += x1 * b1
        a20 += x2 * b0
        a21 += x2 * b1
        a30 += x3 * b0
        a31 += x3 * b1
        y0, y1, y2, y3 = Cm[s, 1, c, 0], Cm[s, 1, c, 1], Cm[s, 1, c, 2], Cm[s, 1, c, 3]
        d00 += y0 * b0
        d01 += y0 * b1
        d10 += y1 * b0
        d11 += y1 * b1
        d20 += y2 * b0
        d21 += y2 * b1
        d30 += y3 * b0
        d31 += y3 * b1
    return (_mixed_share(W[0, 0], W[1, 0], h, a00, a01, a10, a11, a20, a21, a30, a31, d00, d01, d10, d11, d20, d21,
                         d30, d31),
            _mixed_share(W[0, 1], W[1, 1], h, a00, a01, a10, a11, a20, a21, a30, a31, d00, d01, d10, d11, d20, d21,
                         d30, d31),
            (bb00, bb01, bb11), fin == 0.0)


@njit(**_INL)
def _mixed_share(w0, w1, h, a00, a01, a10, a11, a20, a21, a30, a31, d00, d01, d10, d11, d20, d21, d30,
                 d31):  # pragma: no cover - compiled
    """``F (w0 D_0 + w1 D_1)`` of :func:`_columns_shares` (``D_0`` = the a's, ``D_1`` = the d's), row-major."""
    g20, g21 = w0 * a20 + w1 * d20, w0 * a21 + w1 * d21
    g30, g31 = w0 * a30 + w1 * d30, w0 * a31 + w1 * d31
    g00, g01 = w0 * a00 + w1 * d00 + h * g20, w0 * a01 + w1 * d01 + h * g21
    g10, g11 = w0 * a10 + w1 * d10 + h * g30, w0 * a11 + w1 * d11 + h * g31
    return g00, g01, g10, g11, g20, g21, g30, g31


@njit(**_INL)
def _columns_posterior(s, h, Cm, W, B, bi, Kg):  # pragma: no cover - compiled
    """Both modes' posterior consider columns in place, one walk: per column the two stored modes' columns read,
    each mode's predicted column ``c = F (W[0, j] x + W[1, j] y)`` formed and
    ``c - K_j (H c + B)`` written over mode j's column."""
    w00, w10, w01, w11 = W[0, 0], W[1, 0], W[0, 1], W[1, 1]
    k00, k01, k10, k11 = Kg[0, 0, 0], Kg[0, 0, 1], Kg[0, 1, 0], Kg[0, 1, 1]
    k20, k21, k30, k31 = Kg[0, 2, 0], Kg[0, 2, 1], Kg[0, 3, 0], Kg[0, 3, 1]
    m00, m01, m10, m11 = Kg[1, 0, 0], Kg[1, 0, 1], Kg[1, 1, 0], Kg[1, 1, 1]
    m20, m21, m30, m31 = Kg[1, 2, 0], Kg[1, 2, 1], Kg[1, 3, 0], Kg[1, 3, 1]
    for c in range(Cm.shape[2]):
        x0, x1, x2, x3 = Cm[s, 0, c, 0], Cm[s, 0, c, 1], Cm[s, 0, c, 2], Cm[s, 0, c, 3]
        y0, y1, y2, y3 = Cm[s, 1, c, 0], Cm[s, 1, c, 1], Cm[s, 1, c, 2], Cm[s, 1, c, 3]
        b0, b1 = B[bi, 0, c], B[bi, 1, c]
        c2, c3 = w00 * x2 + w10 * y2, w00 * x3 + w10 * y3
        c0, c1 = w00 * x0 + w10 * y0 + h * c2, w00 * x1 + w10 * y1 + h * c3
        e0, e1 = c0 + b0, c1 + b1
        p2, p3 = w01 * x2 + w11 * y2, w01 * x3 + w11 * y3
        p0, p1 = w01 * x0 + w11 * y0 + h * p2, w01 * x1 + w11 * y1 + h * p3
        f0, f1 = p0 + b0, p1 + b1
        Cm[s, 0, c, 0] = c0 - (k00 * e0 + k01 * e1)
        Cm[s, 0, c, 1] = c1 - (k10 * e0 + k11 * e1)
        Cm[s, 0, c, 2] = c2 - (k20 * e0 + k21 * e1)
        Cm[s, 0, c, 3] = c3 - (k30 * e0 + k31 * e1)
        Cm[s, 1, c, 0] = p0 - (m00 * f0 + m01 * f1)
        Cm[s, 1, c, 1] = p1 - (m10 * f0 + m11 * f1)
        Cm[s, 1, c, 2] = p2 - (m20 * f0 + m21 * f1)
        Cm[s, 1, c, 3] = p3 - (m30 * f0 + m31 * f1)


@njit(**_INL)
def _mode_predict(s, j, h, q, Xm, Pm, W, xp, Pp):  # pragma: no cover - compiled
    """Mode ``j``'s mixed state predicted by ``h`` (acceleration density ``q``) into ``xp[j] (4,)``, ``Pp[j] (4, 4)``
    (symmetric: the upper triangle computed, mirrored)."""
    two = Xm.shape[1] == 2
    w0 = W[0, j]
    w1 = W[1, j] if two else 0.0
    ww = w0 * w1
    for a in range(4):
        d_a = Xm[s, 0, a] - Xm[s, 1, a] if two else 0.0
        xp[j, a] = w0 * Xm[s, 0, a] + (w1 * Xm[s, 1, a] if two else 0.0)
        for b in range(a, 4):
            v = w0 * Pm[s, 0, a, b]
            if two:
                v += w1 * Pm[s, 1, a, b] + ww * d_a * (Xm[s, 0, b] - Xm[s, 1, b])
            Pp[j, a, b] = v
    xp[j, 0] += h * xp[j, 2]
    xp[j, 1] += h * xp[j, 3]
    # F P F^T on the upper triangle (F = [[I, h I], [0, I]]; the position block first, from the old cross block)
    for a in range(2):
        for b in range(a, 2):
            Pp[j, a, b] += h * (Pp[j, a, b + 2] + Pp[j, b, a + 2]) + h * h * Pp[j, a + 2, b + 2]
    for a in range(2):
        for b in range(2, 4):
            Pp[j, a, b] += h * Pp[j, min(a + 2, b), max(a + 2, b)]
    q3, q2, q1 = q * h * h * h / 3.0, q * h * h / 2.0, q * h
    Pp[j, 0, 0] += q3
    Pp[j, 1, 1] += q3
    Pp[j, 2, 2] += q1
    Pp[j, 3, 3] += q1
    Pp[j, 0, 2] += q2
    Pp[j, 1, 3] += q2


@njit(**_INL)
def _mode_gain(j, G, bb, R, z, zi, xp, Pp, Kg, Cx, Sm):  # pragma: no cover - compiled
    """Mode ``j``'s innovation: ``S = P_pp + G_p + G_p^T + B B^T + R`` (``G`` from :func:`_columns_mix_predict`,
    ``bb`` = the 3 entries of ``B B^T``; into ``Sm[j] (3,)``: s00, s01, s11), the gain ``K = (P H^T + G) S^-1``
    into ``Kg[j] (4, 2)`` and ``P H^T + G`` into ``Cx[j] (4, 2)``; returns the squared Mahalanobis distance (NaN
    if ``S`` is singular or anything is not finite) and ``det S``."""
    s00 = Pp[j, 0, 0] + R[zi, 0, 0] + 2.0 * G[0] + bb[0]
    s01 = Pp[j, 0, 1] + R[zi, 0, 1] + G[1] + G[2] + bb[1]
    s11 = Pp[j, 1, 1] + R[zi, 1, 1] + 2.0 * G[3] + bb[2]
    Sm[j, 0], Sm[j, 1], Sm[j, 2] = s00, s01, s11
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    y0, y1 = z[zi, 0] - xp[j, 0], z[zi, 1] - xp[j, 1]
    m = y0 * y0 * i00 + 2.0 * y0 * y1 * i01 + y1 * y1 * i11
    for a in range(4):
        k0 = Pp[j, min(a, 0), max(a, 0)] + G[2 * a]
        k1 = Pp[j, min(a, 1), max(a, 1)] + G[2 * a + 1]
        Cx[j, a, 0], Cx[j, a, 1] = k0, k1
        Kg[j, a, 0], Kg[j, a, 1] = k0 * i00 + k1 * i01, k0 * i01 + k1 * i11
    return (m if math.isfinite(m) and det > 0.0 else math.nan), det


@njit(**_INL)
def _mode_posterior(s, j, z, zi, B, bi, xp, Pp, Kg, Cx, Cps, Xm, Pm, Cm, columns):  # pragma: no cover - compiled
    """Mode ``j``'s posterior into the storage row ``s``: ``x = x_p + K y``, ``P = P_p - K cross^T`` (upper
    triangle, mirrored) and, if ``columns``, ``C = C_p - K (H C_p + B)`` column by column from ``Cps[j]``."""
    y0, y1 = z[zi, 0] - xp[j, 0], z[zi, 1] - xp[j, 1]
    for a in range(4):
        Xm[s, j, a] = xp[j, a] + Kg[j, a, 0] * y0 + Kg[j, a, 1] * y1
        for b in range(a, 4):
            Pm[s, j, a, b] = Pm[s, j, b, a] = Pp[j, a, b] - (Kg[j, a, 0] * Cx[j, b, 0] + Kg[j, a, 1] * Cx[j, b, 1])
    if not columns:
        return
    k00, k01, k10, k11 = Kg[j, 0, 0], Kg[j, 0, 1], Kg[j, 1, 0], Kg[j, 1, 1]
    k20, k21, k30, k31 = Kg[j, 2, 0], Kg[j, 2, 1], Kg[j, 3, 0], Kg[j, 3, 1]
    for c in range(Cm.shape[2]):
        c0, c1, c2, c3 = Cps[j, c, 0], Cps[j, c, 1], Cps[j, c, 2], Cps[j, c, 3]
        e0, e1 = c0 + B[bi, 0, c], c1 + B[bi, 1, c]
        Cm[s, j, c, 0] = c0 - (k00 * e0 + k01 * e1)
        Cm[s, j, c, 1] = c1 - (k10 * e0 + k11 * e1)
        Cm[s, j, c, 2] = c2 - (k20 * e0 + k21 * e1)
        Cm[s, j, c, 3] = c3 - (k30 * e0 + k31 * e1)


@njit(**_INL)
def _mode_probabilities(m0, det0, cb0, m1, det1, cb1):  # pragma: no cover - compiled
    """The two modes' posterior probabilities from their squared distances, ``det S`` and predicted probabilities:
    ``l_j = exp(-m_j / 2) cbar_j / sqrt(det_j)`` relative to the larger, floored at 1e-9 (a mode never dies out),
    normalised; the reference's four logs and two exps as one exp and one square root (the ratio ``l_1 / l_0``;
    before 2026-11-29, wave 12: one log and one exp, ~0.4 us more per 100-object frame)."""
    q = math.exp(-0.5 * (m1 - m0)) * (cb1 / cb0) * math.sqrt(det0 / det1)  # l_1 / l_0 (0 or inf past the floor)
    l0, l1 = (max(1.0 / q, 1e-9), 1.0) if q >= 1.0 else (1.0, max(q, 1e-9))
    tot = l0 + l1
    return l0 / tot, l1 / tot


@njit(**_INL)
def _mixture_nis(z, zi, xp, Sm, cb0, cb1):  # pragma: no cover - compiled
    """The normalised innovation squared ``y^T S^-1 y`` of the two modes' predicted mixture's moments
    (``y = sum cbar_j y_j``, ``S = sum cbar_j (S_j + (y_j - y)(y_j - y)^T)``; the on-line consistency check's
    statistic, :mod:`~footprint_uq.tracking.likelihood_kernels` computes the same for its bank)."""
    y00, y01 = z[zi, 0] - xp[0, 0], z[zi, 1] - xp[0, 1]
    y10, y11 = z[zi, 0] - xp[1, 0], z[zi, 1] - xp[1, 1]
    ym0, ym1 = cb0 * y00 + cb1 * y10, cb0 * y01 + cb1 * y11
    d00, d01, d10, d11 = y00 - ym0, y01 - ym1, y10 - ym0, y11 - ym1
    s00 = cb0 * (Sm[0, 0] + d00 * d00) + cb1 * (Sm[1, 0] + d10 * d10)
    s01 = cb0 * (Sm[0, 1] + d00 * d01) + cb1 * (Sm[1, 1] + d10 * d11)
    s11 = cb0 * (Sm[0, 2] + d01 * d01) + cb1 * (Sm[1, 2] + d11 * d11)
    return (ym0 * ym0 * s11 - 2.0 * ym0 * ym1 * s01 + ym1 * ym1 * s00) / (s00 * s11 - s01 * s01)


@njit(**_INL)
def _combine(s, X, P, Xm, Pm, mu):  # pragma: no cover - compiled
    """The reported state of row ``s``: the modes' moment-matched combination (two modes: ``sum mu_j P_j +
    mu_0 mu_1 e e^T``, ``e = x_0 - x_1``)."""
    two = Xm.shape[1] == 2
    u0 = mu[s, 0]
    u1 = mu[s, 1] if two else 0.0
    uu = u0 * u1
    for a in range(4):
        X[s, a] = u0 * Xm[s, 0, a] + (u1 * Xm[s, 1, a] if two else 0.0)
        e_a = Xm[s, 0, a] - Xm[s, 1, a] if two else 0.0
        for b in range(a, 4):
            v = u0 * Pm[s, 0, a, b]
            if two:
                v += u1 * Pm[s, 1, a, b] + uu * e_a * (Xm[s, 0, b] - Xm[s, 1, b])
            P[s, a, b] = P[s, b, a] = v


@njit(**_INL)
def _track_step(s, X, P, Xm, Pm, Cm, mu, t_last, n_upd, t, e, qs, rates, z, R, zi, B, bi, B_frame, gate, W, xp, Pp,
                Kg, Cx, Cps, Sm, nis):  # pragma: no cover - compiled
    """One track's IMM Schmidt step (storage row ``s``, measurement ``z[zi]``, ``R[zi]``, ``B[bi]``; two modes: if
    ``B[bi]`` is not all finite, ``B_frame[zi]``, found in the shares' walk), in place if
    the smallest of its modes' squared Mahalanobis distances is ``<= gate`` (returned; NaN if a mode's is not
    finite: the track is then left as it was, as one beyond the gate), with its innovation's NIS (one mode: the
    distance; two: :func:`_mixture_nis`) into ``nis[zi]``.  The rest are scratch."""
    M, r = Xm.shape[1], Cm.shape[2]
    h = t - t_last[s]
    cb0, cb1 = _weights(s, e, mu, rates, W)
    if M == 2:
        G0, G1, bb, finite = _columns_shares(s, h, Cm, W, B, bi)
        if not finite:  # (B at the predicted position unknown: the frame's B, as frame_update picks it)
            B, bi = B_frame, zi
            G0, G1, bb, finite = _columns_shares(s, h, Cm, W, B, bi)
        _mode_predict(s, 0, h, qs[0], Xm, Pm, W, xp, Pp)
        m0, det0 = _mode_gain(0, G0, bb, R, z, zi, xp, Pp, Kg, Cx, Sm)
        _mode_predict(s, 1, h, qs[1], Xm, Pm, W, xp, Pp)
        m1, det1 = _mode_gain(1, G1, bb, R, z, zi, xp, Pp, Kg, Cx, Sm)
    else:
        bb00 = bb01 = bb11 = 0.0
        for c in range(r):
            b0, b1 = B[bi, 0, c], B[bi, 1, c]
            bb00 += b0 * b0
            bb01 += b0 * b1
            bb11 += b1 * b1
        bb = (bb00, bb01, bb11)
        _mode_predict(s, 0, h, qs[0], Xm, Pm, W, xp, Pp)
        m0, det0 = _mode_gain(0, _columns_mix_predict(s, 0, h, Cm, W, B, bi, Cps), bb, R, z, zi, xp, Pp, Kg, Cx,
                              Sm)
        m1, det1 = m0, det0
    best = min(m0, m1) if (math.isfinite(m0) and math.isfinite(m1)) else math.nan
    if not best <= gate:
        return best
    nis[zi] = _mixture_nis(z, zi, xp, Sm, cb0, cb1) if M == 2 else m0
    if M == 2:
        mu[s, 0], mu[s, 1] = _mode_probabilities(m0, det0, cb0, m1, det1, cb1)
    for j in range(M):
        _mode_posterior(s, j, z, zi, B, bi, xp, Pp, Kg, Cx, Cps, Xm, Pm, Cm, M == 1)
    if M == 2:
        _columns_posterior(s, h, Cm, W, B, bi, Kg)
    _combine(s, X, P, Xm, Pm, mu)
    t_last[s] = t
    n_upd[s] += 1
    return best


@njit(**_JIT)
def frame_pass(act, slots, old, n_old, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, next_id, t, qs, rates,
               mu0, var_v0, z, R, B_pred, B_frame, gate, o_tid, o_new, o_n, o_age, o_xy, o_cxy, o_v,
               o_cv, W, xp, Pp, Kg, Cx, Cps, Sm, nis):  # pragma: no cover - compiled
    """:func:`~footprint_uq.tracking.kernels.frame_update` (same arguments, same results to rounding) with the
    caller's scratch (:func:`scratch`: ``W (2, 2)``, ``xp (M, 4)``, ``Pp (M, 4, 4)``, ``Kg, Cx (M, 4, 2)``,
    ``Cps (M, r, 4)`` (one mode only), ``Sm (M, 3)``; compiled without numba's reference counting, it allocates
    nothing) and ``nis (n,)``, which receives the NIS of each updated object's innovation (left as it is for the others;
    the on-line consistency check's statistic, :class:`~footprint_uq.tracking.consistency.NisMonitor`): the objects
    ``old[:n_old]`` get :func:`_track_step` (``B_pred[k]``, ``B`` at the k-th one's predicted position, where given
    and finite, else ``B_frame``); one beyond the gate becomes a start; then the starts and every object's
    outputs.  Returns the next free track id."""
    r = Cm.shape[2]
    has_pred = B_pred.shape[0] > 0
    h_last, e = math.nan, 0.0
    for k in range(n_old):
        i = old[k]
        h = t - t_last[slots[i]]
        if h != h_last:  # (most tracks of a frame share their step: one expm1 per distinct one)
            h_last, e = h, _switching(h, rates)
        use_pred = has_pred
        if has_pred and Xm.shape[1] == 1:  # (two modes: B_pred's finiteness is summed in the shares' walk, ~2 us
            for c in range(r):  # less a frame than this loop before it)
                use_pred &= math.isfinite(B_pred[k, 0, c]) & math.isfinite(B_pred[k, 1, c])
        Bs, bi = (B_pred, k) if use_pred else (B_frame, i)
        d2 = _track_step(slots[i], X, P, Xm, Pm, Cm, mu, t_last, n_upd, t, e, qs, rates, z, R, i, Bs, bi, B_frame, gate,
                         W, xp, Pp, Kg, Cx, Cps, Sm, nis)
        if not d2 <= gate:  # NaN (a singular S) fails the gate too
            act[i] = ROW_START
    return starts_and_outputs(act, slots, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, next_id, t, mu0,
                              var_v0, z, R, B_frame, o_tid, o_new, o_n, o_age, o_xy, o_cxy, o_v, o_cv)


# (no reference counting: with it, each of its ~60 array arguments is unboxed into a new meminfo, ~3 us a call; its
# callees set their own -- frame_rows_shared keeps it for its point kernel's scratch; no fastmath: a callee that
# does not set its own inherits it, and the rows' arithmetic stays that of the calls it replaces, to the bit)
@njit(cache=True, nogil=True, error_model="numpy", _nrt=False)
def frame_step(ids, slots, xy_rows, cov_rows, B, subtract, t, stamp, n_free, next_id, sweep, S, o_tid, o_new, o_n,
               o_age, o_xy, o_cxy, o_v, o_cv, nis, id_keys, id_vals, id_shift, free_rows, timeout_s, gone, gone_keys,
               z, R, act, old, pred, uv, B_pred, claimed, cam_f, has_dist, dist, cam_R, dom, dR, Lr, Lc, Lv, X, P,
               Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, seen, qs, rates, mu0, var_v0, gate, W, xp, Pp, Kg, Cx, Cps,
               Sm, m_ch, m_sh, m_ratio, m_yaw, m_syaw, m_h, m_out, m_cov):  # pragma: no cover
    """A frame of n objects through a :class:`~footprint_uq.tracking.table.TrackTable` whose ``B`` at the predicted
    positions is formed in the rows' call, in one call: the deleter's sweep if due, the ids' rows,
    :func:`~footprint_uq.tracking.kernels.frame_rows_shared`, the new ids' rows (:func:`~footprint_uq.tracking.
    kernels.claim_rows`) and :func:`frame_pass` -- what the table otherwise does in five calls, the same numbers to
    the bit.

    ``sweep``: the deleter's sweep is due (:func:`~footprint_uq.tracking.kernels.expire_rows` with ``timeout_s``,
    the free stack ``free_rows[:n_free]``, ``gone`` and ``gone_keys``), run before the ids are looked up (an id
    whose track expires now starts a new one); False where the caller's dictionary looked the ids up (it swept
    before).  ``ids (n,)`` int64: looked up in the id table ``id_keys, id_vals, id_shift`` (:func:`~footprint_uq.
    tracking.kernels.id_lookup`) into ``slots``; ``(0,)``: ``slots[:n]`` holds the rows already (the table's
    dictionary, which found every id).  The frame: ``xy_rows (2, n)``, ``cov_rows (2, 2, n)``, ``B (n, 2, r)``,
    ``subtract``, ``t``, ``stamp``, as :func:`~footprint_uq.tracking.kernels.frame_rows` takes them, ``S`` the
    point kernel's scratch; its outputs ``o_tid ... o_cv`` and ``nis (n,)`` (NaN where not updated) as
    :func:`frame_pass` writes them.  The new ids' rows come from the top of the free stack (the last first);
    ``claimed`` receives the objects given them.  The working arrays ``z, R, act, old, pred, uv, B_pred, claimed``
    have at least n rows; the camera's and ``B``'s inputs ``cam_f ... Lv`` are :func:`~footprint_uq.tracking.
    kernels.frame_rows_shared`'s, the storage ``X ... tid`` and the rest :func:`frame_pass`'s, ``seen``
    :func:`~footprint_uq.tracking.kernels.frame_rows`'.  ``m_ch ... m_cov``:
    :func:`~footprint_uq.tracking.kernels.motion_fields`' arguments after the velocities (``m_out (8, n)``), run
    on the outputs ``o_v, o_cv`` at the end of a frame that passed (:func:`~footprint_uq.tracking.motion.
    track_motion`: the motion fields in the step's call); ``m_out (8, 0)``: not run.

    Returns ``(k, u, m, next_id, n_gone, n_free, oldest)``: the tracks to update and the unknown ids (what
    ``frame_rows`` returns), the rows taken from the free stack, the next free track id; the sweep's rows gone
    (``gone[:n_gone]``), the free stack's height after it (before the claim of the m rows) and the earliest update
    left (``expire_rows``' answers; without a sweep: 0, the ``n_free`` given, inf).  ``m == -1``: unknown ids
    without ``ids`` to claim them by, or more of them than free rows or than the id table has room for (it is
    kept at most half full): it stopped after the rows (and the sweep), nothing claimed, nothing passed; the caller
    makes room, claims their rows and runs :func:`frame_pass` on ``slots[:n]``, ``act[:n]``, ``z[:n]``, ``R[:n]``,
    ``old`` and ``B_pred``."""
    n = xy_rows.shape[1]
    sl, ac, zn, Rn = slots[:n], act[:n], z[:n], R[:n]
    n_gone, oldest = 0, math.inf
    if sweep:  # (the deleter's, before the ids are looked up: an id whose track expired now starts a new one)
        n_gone, n_free, oldest = expire_rows(t, timeout_s, t_last, free_rows, n_free, gone, gone_keys, id_keys,
                                             id_vals, id_shift)
    if ids.shape[0]:
        id_lookup(id_keys, id_vals, id_shift, ids, sl)
    k, u = frame_rows_shared(sl, xy_rows, cov_rows, B, subtract, zn, Rn, t, t_last, seen, stamp, X, ac, old, pred,
                             cam_f, has_dist, dist, cam_R, dom, dR, Lr, Lc, Lv, uv, B_pred, S)
    m = 0
    if u:
        if not ids.shape[0] or u > n_free or 2 * (t_last.shape[0] - n_free + u) > id_keys.shape[0]:
            return k, u, -1, next_id, n_gone, n_free, oldest
        m = claim_rows(ids, old, u, ac, sl, free_rows[n_free - u:n_free][::-1], id_keys, id_vals, id_shift, claimed)
    for i in range(n):
        nis[i] = math.nan
    next_id = frame_pass(ac, sl, old, k, X, P, Xm, Pm, Cm, mu, t_last, t_first, n_upd, tid, next_id, t, qs, rates,
                         mu0, var_v0, zn, Rn, B_pred, B, gate, o_tid, o_new, o_n, o_age, o_xy, o_cxy, o_v, o_cv, W,
                         xp, Pp, Kg, Cx, Cps, Sm, nis)
    if m_out.shape[1] == n:  # (the motion fields of the outputs, as object_motion's pass: the same to the bit)
        motion_fields(o_v, o_cv, m_ch, m_sh, m_ratio, m_yaw, m_syaw, m_h, m_out, m_cov)
    return k, u, m, next_id, n_gone, n_free, oldest
