"""Schmidt-Kalman (consider-state) filter over many tracks at once, with a split measurement model.

A frame's measurement of an object's centre is

    z = H x + B w + e,      H = [I 0],   w ~ N(0, I_r) shared,   e ~ N(0, R) new every frame,

where ``B = dC/dp L`` (``centre_shared_m`` of :class:`~footprint_uq.products.footprints.FootprintEstimate`,
2 x r) maps the camera's calibration error (one whitened draw ``w`` of the budget's parameter covariance
``L L^T``, the same in every frame) to this frame's position, and ``R`` (``centre_cov_frame_m2``) is the imaging,
resolution and detector noise.  ``w`` is a *consider* state (Schmidt 1966; Simon, *Optimal State Estimation*,
7.5 / Brown & Hwang 9.x): it is never estimated (from one camera's positions alone it cannot be told from
where the object is), but the filter carries the cross-covariance ``C = cov(x - x_hat, w)`` (n, 4, r), so that

* the position keeps the whole calibration error (averaging frames does not shrink it), and
* the velocity sees only the frame noise and the *change* of ``B w`` along the path (a scale error of the
  camera's height makes a radial velocity error proportional to the speed; a position error none).

Every array carries the tracks as its leading dimension ``n``; there is no loop over tracks.  Errors are
``truth - estimate``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from .models import ConstantVelocity

__all__ = ["TrackState", "SplitMeasurement", "SchmidtPredictor", "SchmidtUpdater", "Initiator", "InteractingModels",
           "mode_switch_probabilities"]


class TrackState(NamedTuple):
    """Gaussian state of n tracks with their consider cross-covariance.

    x : (n, 4)        ``[x_m, y_m, vx_mps, vy_mps]`` in W
    P : (n, 4, 4)     covariance of the error ``x - x_hat`` (the calibration's share included)
    C : (n, 4, r)     ``cov(x - x_hat, w)`` with the shared whitened calibration error ``w ~ N(0, I_r)``
    """

    x: np.ndarray
    P: np.ndarray
    C: np.ndarray


class SplitMeasurement(NamedTuple):
    """n centres of one frame with their covariance split into the two parts.

    xy_m : (n, 2)            measured centre in W, m
    cov_frame_m2 : (n, 2, 2) per-frame part (imaging, resolution, detector), m^2
    shared_m : (n, 2, r)     ``B``: the centre moves by ``B w`` under the shared calibration error, m
    """

    xy_m: np.ndarray
    cov_frame_m2: np.ndarray
    shared_m: np.ndarray


def _sym(A: np.ndarray) -> np.ndarray:
    return 0.5 * (A + np.swapaxes(A, -1, -2))


def _inv2(S: np.ndarray) -> np.ndarray:
    """Inverses of (n, 2, 2) matrices (closed form)."""
    a, b, c, d = S[:, 0, 0], S[:, 0, 1], S[:, 1, 0], S[:, 1, 1]
    det = a * d - b * c
    out = np.empty_like(S)
    out[:, 0, 0], out[:, 0, 1], out[:, 1, 0], out[:, 1, 1] = d / det, -b / det, -c / det, a / det
    return out


class SchmidtPredictor:
    """Moves track states forward by ``dt`` under a transition model (the consider state does not move)."""

    def __init__(self, model: ConstantVelocity):
        self.model = model

    def predict(self, state: TrackState, dt_s) -> TrackState:
        """``x <- F x``, ``P <- F P F^T + Q``, ``C <- F C`` for steps ``dt_s (n,)`` (s)."""
        F, Q = self.model.matrices(dt_s)
        x = np.einsum("nij,nj->ni", F, state.x)
        P = F @ state.P @ np.swapaxes(F, -1, -2) + Q
        return TrackState(x, P, F @ state.C)


class SchmidtUpdater:
    """Updates predicted track states with one measurement each (the consider state is not updated)."""

    @staticmethod
    def innovation(state: TrackState, meas: SplitMeasurement) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Innovation ``y = z - H x`` (n, 2), its covariance ``S`` (n, 2, 2) and ``D = H C + B`` (n, 2, r).

        ``S = H P H^T + H C B^T + B C^T H^T + B B^T + R``: the shared error already in the track (``C``) and the
        new frame's share of it (``B``) are one and the same ``w``.
        """
        y = meas.xy_m - state.x[:, :2]
        Cp, B = state.C[:, :2, :], meas.shared_m
        CB = Cp @ np.swapaxes(B, -1, -2)
        S = state.P[:, :2, :2] + CB + np.swapaxes(CB, -1, -2) + B @ np.swapaxes(B, -1, -2) + meas.cov_frame_m2
        return y, _sym(S), Cp + B

    def update(self, state: TrackState, meas: SplitMeasurement) -> tuple[TrackState, np.ndarray]:
        """Posterior states and each innovation's squared Mahalanobis distance ``y^T S^-1 y`` (n,).

        Gain ``K = (P H^T + C B^T) S^-1``; ``x <- x + K y``, ``P <- P - K S K^T``, ``C <- C - K (H C + B)``.
        """
        y, S, D = self.innovation(state, meas)
        Si = _inv2(S)
        cross = state.P[:, :, :2] + state.C @ np.swapaxes(meas.shared_m, -1, -2)  # cov(x - x_hat, y): (n, 4, 2)
        K = cross @ Si
        x = state.x + np.einsum("nij,nj->ni", K, y)
        P = _sym(state.P - K @ np.swapaxes(cross, -1, -2))
        C = state.C - K @ D
        d2 = np.einsum("ni,nij,nj->n", y, Si, y)
        return TrackState(x, P, C), d2


class Initiator:
    """New tracks from a first measurement: the position is the measurement (its whole error, the calibration
    share as ``C = -B``), the velocity unknown: zero with a wide prior ``sigma_v0_mps`` per axis."""

    def __init__(self, sigma_v0_mps: float = 50.0):
        self.sigma_v0_mps = float(sigma_v0_mps)

    def initiate(self, meas: SplitMeasurement) -> TrackState:
        n, r = meas.shared_m.shape[0], meas.shared_m.shape[2]
        x = np.zeros((n, 4))
        x[:, :2] = meas.xy_m
        P = np.zeros((n, 4, 4))
        B = meas.shared_m
        P[:, :2, :2] = _sym(meas.cov_frame_m2 + B @ np.swapaxes(B, -1, -2))
        P[:, 2, 2] = P[:, 3, 3] = self.sigma_v0_mps ** 2
        C = np.zeros((n, 4, r))
        C[:, :2] = -B
        return TrackState(x, P, C)


def mode_switch_probabilities(dt_s, rates_hz) -> np.ndarray:
    """``Pi[n, a, b]`` = P(mode b after a step ``dt_s[n]`` | mode a before it) of two modes (or one) switching as a
    continuous-time Markov chain that leaves mode a at ``rates_hz[a]`` (1/s, the inverse of its mean sojourn)."""
    dt = np.asarray(dt_s, dtype=np.float64)
    rates = np.asarray(rates_hz, dtype=np.float64)
    if rates.shape[0] == 1:
        return np.ones((dt.shape[0], 1, 1))
    a, b = rates
    e = -np.expm1(-(a + b) * dt) / (a + b)
    return np.stack([np.stack([1 - a * e, a * e], -1), np.stack([b * e, 1 - b * e], -1)], -2)


class InteractingModels:
    """Interacting multiple model filter (Blom and Bar-Shalom 1988; Bar-Shalom et al. 11.6.6) over constant-velocity
    modes of different acceleration noise, each mode a Schmidt filter with the same consider state ``w``.

    One step: *mixing* (each mode's start state is the moment-matched mixture of all modes' states, weighted by
    the switching probabilities; the cross-covariances with ``w`` mix linearly, as ``w`` has zero mean in every
    mode), each mode's predict + update, the mode probabilities from the innovations' likelihoods, and the
    moment-matched combination that is reported.  The readable reference of the compiled
    :func:`~footprint_uq.tracking.kernels.update_slots` (held to it in tests/test_tracking.py).
    """

    def __init__(self, models: Sequence[ConstantVelocity], sojourn_s: Sequence[float]):
        self.predictors = [SchmidtPredictor(m) for m in models]
        self.rates_hz = 1.0 / np.asarray(sojourn_s, dtype=np.float64)
        self.updater = SchmidtUpdater()

    @staticmethod
    def _moments(w: np.ndarray, xs: list, Ps: list) -> tuple[np.ndarray, np.ndarray]:
        x = sum(w[:, i, None] * xs[i] for i in range(len(xs)))
        P = sum(w[:, i, None, None] * (Ps[i] + np.einsum("ni,nj->nij", xs[i] - x, xs[i] - x)) for i in range(len(xs)))
        return x, P

    def step(self, modes: list[TrackState], mu: np.ndarray, dt_s, meas: SplitMeasurement):
        """Modes' states and probabilities ``mu (n, M)`` after a step ``dt_s (n,)`` and a measurement each.

        Returns the modes' posteriors, their probabilities, the combined ``x (n, 4)``, ``P (n, 4, 4)`` and the
        smallest of the modes' squared Mahalanobis distances ``d2 (n,)``.
        """
        M = len(modes)
        Pi = mode_switch_probabilities(dt_s, self.rates_hz)
        cbar = np.einsum("nij,ni->nj", Pi, mu)
        post, loglik, d2 = [], [], []
        for j in range(M):
            w = Pi[:, :, j] * mu / cbar[:, j, None]
            x0, P0 = self._moments(w, [m.x for m in modes], [m.P for m in modes])
            C0 = sum(w[:, i, None, None] * modes[i].C for i in range(M))
            pred = self.predictors[j].predict(TrackState(x0, P0, C0), dt_s)
            S = self.updater.innovation(pred, meas)[1]
            st, m2 = self.updater.update(pred, meas)
            post.append(st)
            d2.append(m2)
            loglik.append(-0.5 * m2 - 0.5 * np.log(np.linalg.det(S)) + np.log(cbar[:, j]))
        ll = np.stack(loglik, -1)
        lik = np.maximum(np.exp(ll - ll.max(-1, keepdims=True)), 1e-9)  # a mode never dies out
        mu_new = lik / lik.sum(-1, keepdims=True)
        x, P = self._moments(mu_new, [s.x for s in post], [s.P for s in post])
        return post, mu_new, x, P, np.min(np.stack(d2, -1), -1)
