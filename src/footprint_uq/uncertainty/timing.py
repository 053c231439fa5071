"""Time as a source of position error: a camera's clock offset and jitter, and the prediction to a message's time.

A detection is stamped by the camera's clock.  If that stamp is off by ``dt`` (the clock's offset from the roadside
unit's time, plus the jitter of when the frame was exposed), an object moving at velocity ``v`` is reported ``v dt``
away from where it was at the stated time.  With ``dt ~ N(0, sigma_t^2)``, ``sigma_t^2 = offset^2 + jitter^2``,
independent of the velocity's estimation error (``v ~ N(v_hat, P_v)``)::

    E[(v dt)(v dt)^T] = sigma_t^2 (v_hat v_hat^T + P_v)

which is added to the position covariance like the other terms of the budget (:func:`timing_covariance`).  The
offset is one number per camera, so this part of the error is shared by all objects of a camera (like its
calibration error), the jitter is not.

:func:`predict_position` moves a position to another time (a CPM states every object at its
``referenceTime + measurementDeltaTime``; a fused list predicts each camera's objects to one time): ``p + v tau``
with covariance ``P_p + tau (P_pv + P_pv^T) + tau^2 P_v``, plus :func:`timing_covariance`.

Shapes broadcast over leading dimensions: ``(..., 2)`` velocities, ``(..., 2, 2)`` covariances.
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError

__all__ = ["clock_sigma_s", "timing_covariance", "dcov_dv", "predict_position"]


def clock_sigma_s(clock_offset_sigma_s: float = 0.0, clock_jitter_sigma_s: float = 0.0) -> float:
    """``sqrt(offset^2 + jitter^2)`` (s) of a camera's clock; each must be finite and >= 0."""
    out = 0.0
    for name, v in (("clock_offset_sigma_s", clock_offset_sigma_s), ("clock_jitter_sigma_s", clock_jitter_sigma_s)):
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise InputError(name, v, "a standard deviation in seconds (>= 0)") from None
        if not (np.isfinite(x) and x >= 0.0):
            raise InputError(name, v, "a finite standard deviation in seconds (>= 0)")
        out += x * x
    return float(np.sqrt(out))


def _as(name, a, tail):
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape[len(arr.shape) - len(tail):] != tail:
        raise InputError(name, arr.shape, f"an array of shape (..., {', '.join(map(str, tail))})")
    return arr


def timing_covariance(v_mps, cov_v_m2ps2, sigma_t_s) -> np.ndarray:
    """Position covariance ``(..., 2, 2)`` (m^2) from a clock error of ``sigma_t_s`` (s) on an object moving at
    ``v_mps`` ``(..., 2)`` (m/s) with velocity covariance ``cov_v_m2ps2`` ``(..., 2, 2)``.

    ``sigma_t_s`` broadcasts too (a scalar, or one per object).  NaN velocities give NaN (unknown motion: the
    term cannot be bounded, and is not silently zero).
    """
    v = _as("v_mps", v_mps, (2,))
    P = _as("cov_v_m2ps2", cov_v_m2ps2, (2, 2))
    s = np.asarray(sigma_t_s, dtype=np.float64)
    if np.any(~np.isfinite(s) | (s < 0)):
        raise InputError("sigma_t_s", s.tolist() if s.ndim else float(s), "finite standard deviations >= 0 (s)")
    return (s ** 2)[..., None, None] * (v[..., :, None] * v[..., None, :] + P)


def dcov_dv(v_mps, sigma_t_s) -> np.ndarray:
    """Derivative of :func:`timing_covariance` with respect to ``v``: ``(..., 2, 2, 2)``, ``[..., i, j, k] =
    d cov[i, j] / d v[k] = sigma_t^2 (delta_ik v_j + v_i delta_jk)``."""
    v = _as("v_mps", v_mps, (2,))
    s2 = np.asarray(sigma_t_s, dtype=np.float64)[..., None, None, None] ** 2
    eye = np.eye(2)
    return s2 * (eye[:, None, :] * v[..., None, :, None] + v[..., :, None, None] * eye[None, :, :])


def predict_position(xy_m, cov_xy_m2, v_mps, cov_v_m2ps2, tau_s, *, cov_xv_m2ps=None, sigma_t_s=0.0):
    """Position and covariance moved by ``tau_s`` (s) at constant velocity, with the clock's term.

    Parameters
    ----------
    xy_m : (..., 2), cov_xy_m2 : (..., 2, 2)
        Position (m) and its covariance at its own time.
    v_mps : (..., 2), cov_v_m2ps2 : (..., 2, 2)
        Velocity (m/s) and its covariance.
    tau_s : float or (...)
        Target time minus the position's time (s); negative moves back.
    cov_xv_m2ps : (..., 2, 2), optional
        Cross-covariance of position and velocity (``E[dp dv^T]``); zero when not given.
    sigma_t_s : float or (...)
        The clock's standard deviation (:func:`clock_sigma_s`).

    Returns
    -------
    xy_m : (..., 2), cov_m2 : (..., 2, 2)
    """
    p = _as("xy_m", xy_m, (2,))
    Pp = _as("cov_xy_m2", cov_xy_m2, (2, 2))
    v = _as("v_mps", v_mps, (2,))
    Pv = _as("cov_v_m2ps2", cov_v_m2ps2, (2, 2))
    tau = np.asarray(tau_s, dtype=np.float64)
    if np.any(~np.isfinite(tau)):
        raise InputError("tau_s", tau.tolist() if tau.ndim else float(tau), "finite time differences (s)")
    Pxv = np.zeros_like(Pv) if cov_xv_m2ps is None else _as("cov_xv_m2ps", cov_xv_m2ps, (2, 2))
    t1 = tau[..., None]
    t2 = tau[..., None, None]
    cross = Pxv + np.swapaxes(Pxv, -1, -2)
    cov = Pp + t2 * cross + t2 ** 2 * Pv + timing_covariance(v, Pv, sigma_t_s)
    return p + t1 * v, cov
