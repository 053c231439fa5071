"""Transition models of the tracker (state ``[x_m, y_m, vx_mps, vy_mps]`` in the world frame W)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._checks import as_float

__all__ = ["ConstantVelocity", "STATE_DIM"]

#: state: position (x east, y north of W, m) and velocity (m/s)
STATE_DIM = 4


@dataclass(frozen=True)
class ConstantVelocity:
    """Nearly constant velocity: continuous white-noise acceleration of spectral density ``accel_psd_m2ps3``
    on each axis (Bar-Shalom et al., *Estimation with Applications to Tracking and Navigation*, 6.2.2).

    Over a step ``dt`` the velocity changes by a random amount of variance ``q dt`` per axis: ``q`` = 3 m^2/s^3
    lets a road user's velocity wander by about 1.7 m/s in one second.  One such model lags a sustained manoeuvre
    (a turn at 4 m/s^2 of centripetal acceleration, braking at 2-8 m/s^2), and a larger ``q`` over-covers
    straight driving: the tracker runs two of them, a quiet and a manoeuvre mode, in an interacting-multiple-model
    filter (:class:`~footprint_uq.tracking.filter.InteractingModels`; docs/uncertainty-model.md, section 11).

    Parameters
    ----------
    accel_psd_m2ps3 : float
        Spectral density ``q`` of the acceleration noise, m^2/s^3 (> 0).
    """

    accel_psd_m2ps3: float = 3.0

    def __post_init__(self):
        object.__setattr__(self, "accel_psd_m2ps3", as_float("accel_psd_m2ps3", self.accel_psd_m2ps3, positive=True))

    def matrices(self, dt_s) -> tuple[np.ndarray, np.ndarray]:
        """Transition ``F`` and process noise ``Q`` of steps ``dt_s (n,)`` (s): two ``(n, 4, 4)`` arrays.

        ``F = [[I, dt I], [0, I]]``; ``Q = q [[dt^3/3 I, dt^2/2 I], [dt^2/2 I, dt I]]`` (exact for the
        continuous model).
        """
        dt = np.asarray(dt_s, dtype=np.float64)
        n = dt.shape[0]
        F = np.zeros((n, 4, 4))
        F[:, [0, 1, 2, 3], [0, 1, 2, 3]] = 1.0
        F[:, 0, 2] = F[:, 1, 3] = dt
        q = self.accel_psd_m2ps3
        Q = np.zeros((n, 4, 4))
        Q[:, 0, 0] = Q[:, 1, 1] = q * dt ** 3 / 3.0
        Q[:, 0, 2] = Q[:, 2, 0] = Q[:, 1, 3] = Q[:, 3, 1] = q * dt ** 2 / 2.0
        Q[:, 2, 2] = Q[:, 3, 3] = q * dt
        return F, Q
