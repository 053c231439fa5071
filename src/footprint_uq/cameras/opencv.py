"""The general OpenCV camera: K (with skew), distortion k1..k6/p1/p2, pose [R|t]."""

from __future__ import annotations

import warnings

import cv2
import numpy as np

from .. import params as P
from .._checks import as_float
from ..errors import ConsistencyWarning, InputError
from .base import Camera
from .rotation import pan_tilt_roll_from_R_W_C

__all__ = ["OpenCVCamera"]


def _matrix(name, value, shape):
    try:
        a = np.array(value, dtype=np.float64, order="C")  # C order: results independent of the layout
    except (TypeError, ValueError):
        raise InputError(name, value, f"a numeric {shape[0]}x{shape[1]} matrix") from None
    if a.size == shape[0] * shape[1] and a.shape != shape:
        a = a.reshape(shape)
    if a.shape != shape:
        raise InputError(name, f"shape {a.shape}", f"a {shape[0]}x{shape[1]} matrix")
    if not np.all(np.isfinite(a)):
        raise InputError(name, value, "finite numbers")
    return a


class OpenCVCamera(Camera):
    """A camera in OpenCV's conventions looking at the ground plane ``z = ground_z_m``.

    Parameters
    ----------
    K : array_like (3, 3)
        Intrinsic matrix ``[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]`` in pixels.
    dist : array_like (n,)
        OpenCV distortion coefficients, n in {0, 4, 5, 8}: (k1, k2, p1, p2[, k3[, k4, k5, k6]]).
    R, t : array_like (3, 3), (3,)
        World -> camera pose (OpenCV: ``x_cam = R x_world + t``); world frame W is Z up.
    image_size_px : (int, int)
        (width, height).
    ground_z_m : float
        Height of the ground plane in W.
    orthonormal_tol : float
        Maximum ``|R R^T - I|`` accepted; above 1e-9 and below this a
        :class:`ConsistencyWarning` is issued and R is re-orthonormalised.
    """

    model = "opencv"

    def __init__(self, K, dist, R, t, image_size_px, ground_z_m=0.0, *, orthonormal_tol=1e-3):
        K = _matrix("K", K, (3, 3))
        if K[2, 0] != 0 or K[2, 1] != 0 or K[1, 0] != 0 or not np.isclose(K[2, 2], 1.0):
            raise InputError("K", K.tolist(), "[[fx, skew, cx], [0, fy, cy], [0, 0, 1]]")
        if K[0, 0] <= 0 or K[1, 1] <= 0:
            raise InputError("K (fx, fy)", (K[0, 0], K[1, 1]), "focal lengths > 0 px")
        d = np.asarray(dist if dist is not None else [], dtype=np.float64).ravel()
        if d.size not in (0, 4, 5, 8) or not np.all(np.isfinite(d)):
            raise InputError("dist", d.tolist(), "0, 4, 5 or 8 finite coefficients (k1 k2 p1 p2 [k3 [k4 k5 k6]])")
        d8 = np.zeros(8)
        d8[: d.size] = d
        R = _matrix("R", R, (3, 3))
        err = np.abs(R @ R.T - np.eye(3)).max()
        if err > orthonormal_tol or np.linalg.det(R) <= 0:
            raise InputError("R", f"|R R^T - I| = {err:.3g}, det = {np.linalg.det(R):.4g}",
                             "a rotation matrix (orthonormal, det +1)")
        if err > 1e-9:
            warnings.warn(f"R: not orthonormal (|R R^T - I| = {err:.3g}); re-orthonormalised by SVD",
                          ConsistencyWarning, stacklevel=2)
            U, _, Vt = np.linalg.svd(R)
            R = U @ Vt
        t = np.asarray(t, dtype=np.float64).ravel()
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise InputError("t", t.tolist(), "3 finite numbers (metres)")
        try:
            w, h = (int(v) for v in image_size_px)
        except (TypeError, ValueError):
            raise InputError("image_size_px", image_size_px, "[width, height] in pixels") from None
        if w <= 0 or h <= 0 or list(image_size_px) != [w, h]:  # 1920.5 is not silently 1920
            raise InputError("image_size_px", image_size_px, "two positive integers [width, height]")
        self.image_size_px = (w, h)
        self.ground_z_m = as_float("ground_z_m", ground_z_m)
        C = -R.T @ t
        if C[2] <= self.ground_z_m:
            raise InputError("camera height (from R, t)", float(C[2] - self.ground_z_m),
                             "a camera centre above the ground plane (height_m > 0)")
        pan, tilt, roll = pan_tilt_roll_from_R_W_C(R.T)
        p = np.zeros(P.N_PARAMS)
        p[[P.FX, P.FY, P.CX, P.CY, P.SKEW]] = K[0, 0], K[1, 1], K[0, 2], K[1, 2], K[0, 1]
        p[P.DIST_SLICE] = d8
        p[[P.XM, P.YM, P.HM]] = C[0], C[1], C[2] - self.ground_z_m
        p[[P.PAN, P.TILT, P.ROLL]] = pan, tilt, roll
        self.params = p
        self._R = R
        self._t = t

    @classmethod
    def from_projection_matrix(cls, Pm, image_size_px, dist=None, ground_z_m=0.0):
        """Build from a 3x4 projection matrix ``P = K [R | t]`` (RQ decomposition)."""

        Pm = _matrix("P", Pm, (3, 4))
        K, R, c_h = cv2.decomposeProjectionMatrix(Pm)[:3]
        K = K / K[2, 2]
        # make the focal lengths positive
        S = np.diag(np.sign(np.diag(K)))
        K, R = K @ S, S @ R
        if np.linalg.det(R) < 0:
            R = -R
        C = (c_h[:3] / c_h[3]).ravel()
        t = -R @ C
        return cls(K, dist, R, t, image_size_px, ground_z_m)

    @property
    def R(self) -> np.ndarray:
        """World -> camera rotation (OpenCV)."""
        return self._R.copy()

    @property
    def t(self) -> np.ndarray:
        return self._t.copy()

    @property
    def P(self) -> np.ndarray:
        """3x4 projection matrix ``K [R | t]``."""
        return self.K @ np.hstack([self._R, self._t[:, None]])

    def to_dict(self) -> dict:
        return {
            "model": "opencv",
            "image_size_px": list(self.image_size_px),
            "K": self.K.tolist(),
            "dist": self.dist.tolist() if np.any(self.dist[5:]) else self.dist[:5].tolist(),
            "R": self._R.tolist(),
            "t": self._t.tolist(),
            "ground_z_m": self.ground_z_m,
        }

    def __repr__(self) -> str:
        return (f"OpenCVCamera(fx={self.params[0]:g}, fy={self.params[1]:g}, image_size_px={self.image_size_px}, "
                f"height_m={self.height_m:g}, pan_deg={self.pan_deg:g}, tilt_deg={self.tilt_deg:g})")
