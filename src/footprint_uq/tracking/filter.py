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

from typing import NamedTuple

import numpy as np

from .models import ConstantVelocity

__all__ = ["TrackState", "SplitMeasurement", "SchmidtPredictor", "SchmidtUpdater", "Initiator"]


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
