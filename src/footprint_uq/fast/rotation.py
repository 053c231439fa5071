"""Camera orientation from pan, tilt and roll, and its derivatives (numpy; the floor of the package).

Frames (see ``docs/conventions.md``):

* ``W``  world, Z up, right-handed: x east, y north, z up.
* ``G``  the paper's earth frame: X north, Y east, Z down (NED).
* ``P``  the paper's camera frame: x boresight, y image columns (right), z image rows (down).
* ``C``  the OpenCV camera frame: x right, y down, z boresight.

The paper orients the camera by a pan ``alpha`` about Z (from north towards east,
i.e. a compass heading), then a pitch down by ``theta``; we add a roll ``phi``
about the boresight: ``R_G_P = Rz(alpha) @ Ry(-theta) @ Rx(phi)``.
``R_W_C = R_W_G @ R_G_P @ R_P_C`` maps OpenCV camera coordinates to the world.

It lives in ``fast/`` because the compiled layer needs it (the kernels' camera constants) and may
import nothing above itself; :mod:`footprint_uq.cameras.rotation` re-exports it with the inverse.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["R_W_G", "R_P_C", "R_G_P", "R_W_C", "dR_W_C"]

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


def _scalar_angles(*angles):
    """The three angles as floats when all are scalars (the per-call path of the kernels' camera constants), else
    None (the broadcasting path)."""
    if all(isinstance(x, float | int | np.floating | np.integer) for x in angles):
        return tuple(float(x) for x in angles)
    return None


def _factors(a, t, r):
    """``Rz(a), Ry(-t), Rx(r)`` and their derivatives with respect to a, -t, r for scalar angles: six (3, 3)
    arrays from ``math`` (the stacked forms above cost ~40 numpy calls for one camera)."""
    ca, sa, ct, st, cr, sr = math.cos(a), math.sin(a), math.cos(-t), math.sin(-t), math.cos(r), math.sin(r)
    Rz = np.array([[ca, -sa, 0.0], [sa, ca, 0.0], [0.0, 0.0, 1.0]])
    Ry = np.array([[ct, 0.0, st], [0.0, 1.0, 0.0], [-st, 0.0, ct]])
    Rx = np.array([[1.0, 0.0, 0.0], [0.0, cr, -sr], [0.0, sr, cr]])
    dRz = np.array([[-sa, -ca, 0.0], [ca, -sa, 0.0], [0.0, 0.0, 0.0]])
    dRy = np.array([[-st, 0.0, ct], [0.0, 0.0, 0.0], [-ct, 0.0, -st]])
    dRx = np.array([[0.0, 0.0, 0.0], [0.0, -sr, -cr], [0.0, cr, -sr]])
    return Rz, Ry, Rx, dRz, dRy, dRx


def R_G_P(pan_rad, tilt_rad, roll_rad=0.0):
    """Paper camera frame -> paper earth frame, ``(..., 3, 3)``; the paper's T_{c->e} at zero roll."""
    scalar = _scalar_angles(pan_rad, tilt_rad, roll_rad)
    if scalar is not None:
        Rz, Ry, Rx = _factors(*scalar)[:3]
        return Rz @ Ry @ Rx
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
    scalar = _scalar_angles(pan_rad, tilt_rad, roll_rad)
    if scalar is not None:
        Rz, Ry, Rx, dRz, dRy, dRx = _factors(*scalar)
    else:
        a, t, r = np.broadcast_arrays(*(np.asarray(x, dtype=np.float64) for x in (pan_rad, tilt_rad, roll_rad)))
        Rz, Ry, Rx, dRz, dRy, dRx = _rz(a), _ry(-t), _rx(r), _drz(a), _dry(-t), _drx(r)
    d_pan = dRz @ Ry @ Rx
    d_tilt = -(Rz @ dRy @ Rx)
    d_roll = Rz @ Ry @ dRx
    d = np.stack([d_pan, d_tilt, d_roll], axis=-3)
    return R_W_G @ d @ R_P_C
