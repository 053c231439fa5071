"""The compiled pieces of one constant-velocity Kalman step with the consider state, written once for every kernel
of the tracker and of the motion fit.

State ``x = [x, y, vx, vy]`` (m, m/s) in W; the constant-velocity model over a step ``h`` (s) with white
acceleration of density ``q`` (m^2/s^3): ``F = [[I, h I], [0, I]]``, ``Q = q [[h^3/3 I, h^2/2 I], [h^2/2 I, h I]]``.
The split measurement model of :mod:`footprint_uq.tracking.filter`: ``z = H x + B w + e``, ``H = [I 0]``, ``w ~
N(0, I_r)`` the camera's calibration error shared by all its detections (the consider state: ``C (4, r)`` the
cross-covariance of ``x`` with ``w``, never updated itself), ``e ~ N(0, R)`` the per-frame noise.

Callers: :mod:`~footprint_uq.tracking.kernels` (the tracker's compiled reference), :mod:`~footprint_uq.tracking.
likelihood_kernels` (the motion fit's bank of Schmidt filters) and :mod:`~footprint_uq.tracking.joint_likelihood_
kernels` (the bank of augmented filters ``[x, w]``: :func:`predict_cov_cv`, :func:`innovation_distance` and
:func:`gain` on ``(4 + r)``-sized states).  Every piece is inlined into its caller (``inline="always"``: numba's IR,
compiled with the caller's flags), so each caller runs the same arithmetic in the same order as when it was
written out in each of them (bit-identical results, checked when they were merged).

Cost: inlined in a kernel that counts references, every array argument of every helper is an atomic increment and
decrement per call (~20 per step here).  The motion fit's banks therefore run their loops compiled without reference
counting (``_nrt=False``, scratch from the caller): measured on the 2-core VM, the Schmidt bank was ~6 % slower with
the helpers under counting and is ~45 % faster than before without it (``bench/motion_fit_bank_cost.py``).
"""

from __future__ import annotations

import math

from numba import njit

__all__ = ["predict_position", "predict_cov_cv", "predict_consider", "innovation_consider", "innovation_distance",
           "gain", "update_consider", "schmidt_step", "start_cov2", "pick_shared"]

_JIT = dict(cache=True, nogil=True, error_model="numpy")
_INL = dict(_JIT, inline="always")


@njit(**_INL)
def predict_position(x, h):  # pragma: no cover - compiled
    """Position ``(x0, x1)`` (m) of state ``x (>= 4,)`` predicted by ``h`` (s) at constant velocity."""
    return x[0] + h * x[2], x[1] + h * x[3]


@njit(**_INL)
def predict_cov_cv(P, h, q, n):  # pragma: no cover - compiled
    """``P (n, n)`` (n >= 4, its first 4 entries the state's) predicted in place: ``F P F^T + Q`` over ``h`` (s)
    with acceleration density ``q`` (m^2/s^3); entries past the 4th (an augmented state's ``w``) do not move.
    ``n`` is passed, not read from ``P``: a literal 4 lets the compiler unroll the loops (as written out before)."""
    for a in range(n):  # F P
        P[0, a] += h * P[2, a]
        P[1, a] += h * P[3, a]
    for a in range(n):  # (F P) F^T
        P[a, 0] += h * P[a, 2]
        P[a, 1] += h * P[a, 3]
    q3, q2, q1 = q * h * h * h / 3.0, q * h * h / 2.0, q * h
    P[0, 0] += q3
    P[1, 1] += q3
    P[2, 2] += q1
    P[3, 3] += q1
    P[0, 2] += q2
    P[2, 0] += q2
    P[1, 3] += q2
    P[3, 1] += q2


@njit(**_INL)
def predict_consider(C, h, Cp):  # pragma: no cover - compiled
    """The consider columns ``C (4, r)`` predicted by ``h`` (s) into ``Cp (4, r)``: ``F C``."""
    for c in range(C.shape[1]):
        Cp[0, c] = C[0, c] + h * C[2, c]
        Cp[1, c] = C[1, c] + h * C[3, c]
        Cp[2, c] = C[2, c]
        Cp[3, c] = C[3, c]


@njit(**_INL)
def innovation_consider(Pp, Cp, R, B, cross):  # pragma: no cover - compiled
    """The innovation covariance of a predicted ``Pp (4, 4)``, ``Cp (4, r)`` measured with ``R (2, 2)``, ``B (2,
    r)`` (m^2, m): returns its entries ``(s00, s01, s11)`` of ``S = H Pp H^T + H Cp B^T + B Cp^T H^T + B B^T + R``
    and writes the cross term ``cross (4, 2) = Pp H^T + Cp B^T`` (the gain's numerator)."""
    s00, s01, s11 = Pp[0, 0] + R[0, 0], Pp[0, 1] + R[0, 1], Pp[1, 1] + R[1, 1]
    for a in range(4):
        cross[a, 0], cross[a, 1] = Pp[a, 0], Pp[a, 1]
    for c in range(Cp.shape[1]):
        b0, b1 = B[0, c], B[1, c]
        s00 += 2.0 * Cp[0, c] * b0 + b0 * b0
        s01 += Cp[0, c] * b1 + b0 * Cp[1, c] + b0 * b1
        s11 += 2.0 * Cp[1, c] * b1 + b1 * b1
        for a in range(4):
            cross[a, 0] += Cp[a, c] * b0
            cross[a, 1] += Cp[a, c] * b1
    return s00, s01, s11


@njit(**_INL)
def innovation_distance(s00, s01, s11, y0, y1):  # pragma: no cover - compiled
    """The innovation ``y (2,)`` (m) against ``S = [[s00, s01], [s01, s11]]`` (m^2): returns ``(y^T S^-1 y, det
    S, i00, i01, i11)`` with ``S^-1 = [[i00, i01], [i01, i11]]`` (not finite when ``S`` is singular)."""
    det = s00 * s11 - s01 * s01
    i00, i01, i11 = s11 / det, -s01 / det, s00 / det
    m = y0 * y0 * i00 + 2.0 * y0 * y1 * i01 + y1 * y1 * i11
    return m, det, i00, i01, i11


@njit(**_INL)
def gain(cross, i00, i01, i11, K, n):  # pragma: no cover - compiled
    """The Kalman gain ``K (n, 2) = cross S^-1`` of the cross term ``cross (n, 2)`` and ``S^-1 = [[i00, i01], [i01,
    i11]]`` (``n`` passed: see :func:`predict_cov_cv`)."""
    for a in range(n):
        K[a, 0] = cross[a, 0] * i00 + cross[a, 1] * i01
        K[a, 1] = cross[a, 0] * i01 + cross[a, 1] * i11


@njit(**_INL)
def update_consider(x, P, C, x0, x1, y0, y1, Pp, Cp, K, cross, B):  # pragma: no cover - compiled
    """The Schmidt update in place: ``x (4,)`` from its predicted position ``(x0, x1)`` (m) and velocity (its own
    entries 2, 3) with the innovation ``(y0, y1)`` (m); ``P (4, 4) = Pp - K cross^T`` (symmetrised); the consider
    columns ``C (4, r) = Cp - K (H Cp + B)``; ``K (4, 2)`` from :func:`gain`, ``B (2, r)`` the measurement's."""
    x[0], x[1] = x0 + K[0, 0] * y0 + K[0, 1] * y1, x1 + K[1, 0] * y0 + K[1, 1] * y1
    x[2] += K[2, 0] * y0 + K[2, 1] * y1
    x[3] += K[3, 0] * y0 + K[3, 1] * y1
    for a in range(4):
        for b in range(a, 4):
            v = Pp[a, b] - (K[a, 0] * cross[b, 0] + K[a, 1] * cross[b, 1])
            w = Pp[b, a] - (K[b, 0] * cross[a, 0] + K[b, 1] * cross[a, 1])
            P[a, b] = P[b, a] = 0.5 * (v + w)
    for c in range(Cp.shape[1]):
        e0, e1 = Cp[0, c] + B[0, c], Cp[1, c] + B[1, c]
        for a in range(4):
            C[a, c] = Cp[a, c] - (K[a, 0] * e0 + K[a, 1] * e1)


@njit(**_INL)
def schmidt_step(x, P, C, h, q, z, R, B, gate, Pp, Cp, K, cross):  # pragma: no cover - compiled
    """One mode of one track: predict by ``h`` (s) with acceleration density ``q`` (m^2/s^3) and update in place
    with ``z (2,)``, ``R (2, 2)``, ``B (2, r)`` if the innovation's squared Mahalanobis distance is ``<= gate``
    (``inf``: always, when finite).

    Parameters
    ----------
    x, P, C : arrays ``(4,)``, ``(4, 4)``, ``(4, r)``
        The state, its covariance and consider columns (views into the caller's storage; written only on update).
    Pp, Cp, K, cross : arrays ``(4, 4)``, ``(4, r)``, ``(4, 2)``, ``(4, 2)``
        Scratch.

    Returns
    -------
    tuple ``(d2, det S, y0, y1, s00, s01, s11)``
        The distance (NaN if it or ``det S`` is not finite or ``det S <= 0``: the state is then left as it was),
        the innovation (m) and its covariance's entries (m^2).
    """
    for a in range(4):
        for b in range(4):
            Pp[a, b] = P[a, b]
    predict_cov_cv(Pp, h, q, 4)
    predict_consider(C, h, Cp)
    x0, x1 = predict_position(x, h)
    s00, s01, s11 = innovation_consider(Pp, Cp, R, B, cross)
    y0, y1 = z[0] - x0, z[1] - x1
    m, det, i00, i01, i11 = innovation_distance(s00, s01, s11, y0, y1)
    if not (math.isfinite(m) and det > 0.0):
        return math.nan, det, y0, y1, s00, s01, s11
    if not m <= gate:
        return m, det, y0, y1, s00, s01, s11
    gain(cross, i00, i01, i11, K, 4)
    update_consider(x, P, C, x0, x1, y0, y1, Pp, Cp, K, cross, B)
    return m, det, y0, y1, s00, s01, s11


@njit(**_INL)
def start_cov2(R, B):  # pragma: no cover - compiled
    """A new track's position covariance from its first measurement, ``R (2, 2) + B (2, r) B^T`` (m^2) with its
    off-diagonal symmetrised: returns ``(p00, p01, p11)``."""
    acc00 = acc01 = acc11 = 0.0
    for c in range(B.shape[1]):
        acc00 += B[0, c] * B[0, c]
        acc01 += B[0, c] * B[1, c]
        acc11 += B[1, c] * B[1, c]
    return R[0, 0] + acc00, 0.5 * ((R[0, 1] + acc01) + (R[1, 0] + acc01)), R[1, 1] + acc11


@njit(**_INL)
def pick_shared(B_pred, k, B_frame, i):  # pragma: no cover - compiled
    """``B_pred[k] (2, r)`` (``B`` at a track's predicted position) where it is given and finite, else
    ``B_frame[i]``; ``B_pred (0, 2, r)``: none given."""
    if B_pred.shape[0] == 0:
        return B_frame[i]
    for c in range(B_pred.shape[2]):
        if not (math.isfinite(B_pred[k, 0, c]) and math.isfinite(B_pred[k, 1, c])):
            return B_frame[i]
    return B_pred[k]
