"""Camera orientation from pan, tilt and roll, its derivatives and its inverse.

Frames (see ``docs/conventions.md``):

* ``W``  world, Z up, right-handed: x east, y north, z up.
* ``G``  the paper's earth frame: X north, Y east, Z down (NED).
* ``P``  the paper's camera frame: x boresight, y image columns (right), z image rows (down).
* ``C``  the OpenCV camera frame: x right, y down, z boresight.

The paper orients the camera by a pan ``alpha`` about Z (from north towards east,
i.e. a compass heading), then a pitch down by ``theta``; we add a roll ``phi``
about the boresight: ``R_G_P = Rz(alpha) @ Ry(-theta) @ Rx(phi)``.
``R_W_C = R_W_G @ R_G_P @ R_P_C`` maps OpenCV camera coordinates to the world.

The forward rotations live in :mod:`footprint_uq.fast.rotation` (the compiled layer needs them and
imports nothing above itself); they are re-exported here beside the inverse.
"""

from __future__ import annotations

import numpy as np

from ..fast.rotation import R_G_P, R_P_C, R_W_C, R_W_G, dR_W_C

__all__ = ["R_W_G", "R_P_C", "R_G_P", "R_W_C", "dR_W_C", "pan_tilt_roll_from_R_W_C"]


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
