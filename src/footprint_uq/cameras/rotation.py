"""Camera orientation from pan, tilt and roll, and its derivatives.

Frames (see ``docs/conventions.md``):

* ``W``  world, Z up, right-handed: x east, y north, z up.
* ``G``  the paper's earth frame: X north, Y east, Z down (NED).
* ``P``  the paper's camera frame: x boresight, y image columns (right), z image rows (down).
* ``C``  the OpenCV camera frame: x right, y down, z boresight.

The paper orients the camera by a pan ``alpha`` about Z (from north towards east,
i.e. a compass heading), then a pitch down by ``theta``; we add a roll ``phi``
about the boresight: ``R_G_P = Rz(alpha) @ Ry(-theta) @ Rx(phi)``.
``R_W_C = R_W_G @ R_G_P @ R_P_C`` maps OpenCV camera coordinates to the world.
"""

from __future__ import annotations

import numpy as np

__all__ = ["R_W_G", "R_P_C", "R_G_P", "R_W_C", "dR_W_C", "pan_tilt_roll_from_R_W_C"]

#: paper earth frame (NED) -> world (ENU)
R_W_G = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
#: OpenCV camera frame -> paper camera frame
R_P_C = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2)


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], -2)


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], -2)


def _drz(a):
    c, s = np.cos(a), np.sin(a)
    z = np.zeros_like(c)
    return np.stack([np.stack([-s, -c, z], -1), np.stack([c, -s, z], -1), np.stack([z, z, z], -1)], -2)


def _dry(a):
    c, s = np.cos(a), np.sin(a)
    z = np.zeros_like(c)
    return np.stack([np.stack([-s, z, c], -1), np.stack([z, z, z], -1), np.stack([-c, z, -s], -1)], -2)


def _drx(a):
    c, s = np.cos(a), np.sin(a)
    z = np.zeros_like(c)
    return np.stack([np.stack([z, z, z], -1), np.stack([z, -s, -c], -1), np.stack([z, c, -s], -1)], -2)


def R_G_P(pan_rad, tilt_rad, roll_rad=0.0):
    """Paper camera frame -> paper earth frame, ``(..., 3, 3)``; the paper's T_{c->e} at zero roll."""
    a, t, r = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (pan_rad, tilt_rad, roll_rad)))
    return _rz(a) @ _ry(-t) @ _rx(r)


def R_W_C(pan_rad, tilt_rad, roll_rad=0.0):
    """OpenCV camera frame -> world (ENU) rotation, ``(..., 3, 3)``."""
    return R_W_G @ R_G_P(pan_rad, tilt_rad, roll_rad) @ R_P_C


def dR_W_C(pan_rad, tilt_rad, roll_rad=0.0):
    """Derivatives of :func:`R_W_C` with respect to (pan, tilt, roll): ``(..., 3, 3, 3)``.

    The first of the three trailing-leading axes indexes the angle:
    ``out[..., k, :, :] = dR/d(angle_k)`` with angles in radians.
    """
    a, t, r = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (pan_rad, tilt_rad, roll_rad)))
    Rz, Ry, Rx = _rz(a), _ry(-t), _rx(r)
    d_pan = _drz(a) @ Ry @ Rx
    d_tilt = -(Rz @ _dry(-t) @ Rx)
    d_roll = Rz @ Ry @ _drx(r)
    d = np.stack([d_pan, d_tilt, d_roll], axis=-3)
    return R_W_G @ d @ R_P_C


def pan_tilt_roll_from_R_W_C(R):
    """Inverse of :func:`R_W_C`: ``(pan_rad, tilt_rad, roll_rad)`` from ``(..., 3, 3)``.

    Pan is wrapped to (-pi, pi]; tilt is in [-pi/2, pi/2].  At tilt = +-90 deg
    (camera looking straight down or up) pan and roll are not separable; the
    roll is then reported as 0 and the whole rotation about the vertical goes to pan.
    """
    R = np.asarray(R, dtype=np.float64)
    A = R_W_G.T @ R @ R_P_C.T  # = R_G_P
    # boresight in G: (cos t cos a, cos t sin a, sin t); atan2 keeps full precision near +-90 deg,
    # where arcsin(sin t) would lose half the digits
    c_t = np.hypot(A[..., 0, 0], A[..., 1, 0])
    tilt = np.arctan2(A[..., 2, 0], c_t)
    gimbal = c_t < 1e-12
    # at tilt = +90 deg only pan + roll is defined, at -90 deg only pan - roll: both read
    # atan2(-A01, A11) with roll = 0
    pan = np.where(gimbal, np.arctan2(-A[..., 0, 1], A[..., 1, 1]), np.arctan2(A[..., 1, 0], A[..., 0, 0]))
    roll = np.where(gimbal, 0.0, np.arctan2(A[..., 2, 1], A[..., 2, 2]))
    return pan, tilt, roll
