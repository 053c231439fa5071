"""The paper's pan-tilt camera model (Kusari et al., "Object level footprint
uncertainty quantification in infrastructure based sensing").

A pinhole camera with one focal length ``f`` (px), no distortion, at height
``h`` above a flat ground, panned by ``alpha`` (compass heading: from north
towards east) and pitched down by ``theta``; we add a roll ``phi`` about the
boresight (the paper omits it, default 0).

The paper's closed form, in its earth frame G (X north, Y east, Z down, origin at
the focal point), for an image point ``c = u - cx`` (column), ``r = v - cy`` (row)::

    s = sin(theta) f + cos(theta) r
    X = h (cos(theta) cos(alpha) f - sin(alpha) c - sin(theta) cos(alpha) r) / s
    Y = h (cos(theta) sin(alpha) f + cos(alpha) c - sin(theta) sin(alpha) r) / s

valid where ``s > 0`` (below the horizon).  :func:`paper_xy` implements exactly
that and :func:`paper_partials` the paper's Table-1 partial derivatives.  In the
world frame W (x east, y north) the ground point is ``(x0 + Y, y0 + X)``.
"""

from __future__ import annotations

import numpy as np

from .. import params as P
from .._checks import as_float
from ..errors import InputError
from .base import Camera

__all__ = ["PanTiltCamera", "paper_xy", "paper_partials"]


def paper_xy(f, c, r, h, alpha, theta):
    """The paper's equations for (X, Y): returns ``(X, Y, valid)`` in frame G (metres).

    All arguments broadcast; angles in radians.  Where the ray is at or above the
    horizon (``sin(theta) f + cos(theta) r <= 0``) X and Y are NaN and valid is False.
    """
    f, c, r, h, alpha, theta = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64)
                                                    for a in (f, c, r, h, alpha, theta)))
    st, ct, sa, ca = np.sin(theta), np.cos(theta), np.sin(alpha), np.cos(alpha)
    s = st * f + ct * r
    valid = s > 0
    with np.errstate(divide="ignore", invalid="ignore"):
        X = h * (ct * ca * f - sa * c - st * ca * r) / s
        Y = h * (ct * sa * f + ca * c - st * sa * r) / s
    X = np.where(valid, X, np.nan)
    Y = np.where(valid, Y, np.nan)
    return X, Y, valid


def paper_partials(f, c, r, h, alpha, theta):
    """The paper's closed-form partial derivatives (its Table 1 equations).

    Returns a dict ``{"f": (dX, dY), "c": ..., "r": ..., "h": ..., "alpha": ...,
    "theta": ..., "X0": (1, 0), "Y0": (0, 1)}``, each pair in frame G; angles in
    radians.  Transcribed term by term from the paper.
    """
    f, c, r, h, alpha, theta = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64)
                                                    for a in (f, c, r, h, alpha, theta)))
    st, ct, sa, ca = np.sin(theta), np.cos(theta), np.sin(alpha), np.cos(alpha)
    s = st * f + ct * r
    nx = ct * ca * f - sa * c - st * ca * r
    ny = ct * sa * f + ca * c - st * sa * r
    with np.errstate(divide="ignore", invalid="ignore"):
        out = {
            "f": (ct * ca * h / s - nx * h * st / s**2, ct * sa * h / s - ny * h * st / s**2),
            "c": (-sa * h / s, ca * h / s),
            "r": (-st * ca * h / s - nx * h * ct / s**2, -st * sa * h / s - ny * h * ct / s**2),
            "h": (nx / s, ny / s),
            "alpha": ((-ct * sa * f - ca * c + st * sa * r) * h / s, nx * h / s),
            "theta": ((-st * ca * f - ct * ca * r) * h / s - nx * h * (ct * f - st * r) / s**2,
                      (-st * sa * f - ct * sa * r) * h / s - ny * h * (ct * f - st * r) / s**2),
        }
    one, zero = np.ones_like(s), np.zeros_like(s)
    out["X0"] = (one, zero)
    out["Y0"] = (zero, one)
    return out


class PanTiltCamera(Camera):
    """The paper's camera: one focal length, no nominal distortion, pan/tilt/roll, height.

    Parameters
    ----------
    focal_px : float
        Focal length f in pixels (> 0).
    image_size_px : (int, int)
        (width, height) in pixels.
    height_m : float
        Height of the focal point above the ground plane (> 0), metres.
    pan_deg : float
        Pan alpha: compass heading of the boresight, degrees clockwise from north (+y of W).
    tilt_deg : float
        Tilt theta: pitch of the boresight below the horizontal, degrees (positive = down).
    roll_deg : float, optional
        Roll about the boresight, degrees (positive: image rotates clockwise... see docs/conventions.md).
    position_m : (float, float), optional
        Camera foot point (x east, y north) in the world frame W, metres.
    principal_point_px : (float, float), optional
        (cx, cy); defaults to the image centre ((w - 1) / 2, (h - 1) / 2).
    ground_z_m : float, optional
        Height of the ground plane in W, metres.
    """

    model = "pan-tilt"

    def __init__(self, focal_px, image_size_px, height_m, pan_deg, tilt_deg, roll_deg=0.0,
                 position_m=(0.0, 0.0), principal_point_px=None, ground_z_m=0.0):
        f = as_float("focal_px", focal_px, positive=True)
        try:
            w, h = (int(v) for v in image_size_px)
        except (TypeError, ValueError):
            raise InputError("image_size_px", image_size_px, "[width, height] in pixels") from None
        if w <= 0 or h <= 0 or list(image_size_px) != [w, h]:
            raise InputError("image_size_px", image_size_px, "two positive integers [width, height]")
        hm = as_float("height_m", height_m, positive=True)
        pan = as_float("pan_deg", pan_deg, lo=-360, hi=360)
        tilt = as_float("tilt_deg", tilt_deg, lo=-90, hi=90)
        roll = as_float("roll_deg", roll_deg, lo=-180, hi=180)
        try:
            x0, y0 = (float(v) for v in position_m)
        except (TypeError, ValueError):
            raise InputError("position_m", position_m, "[x, y] in metres") from None
        for name, v in (("position_m[0]", x0), ("position_m[1]", y0)):
            as_float(name, v)
        if principal_point_px is None:
            cx, cy = (w - 1) / 2.0, (h - 1) / 2.0
        else:
            try:
                cx, cy = (float(v) for v in principal_point_px)
            except (TypeError, ValueError):
                raise InputError("principal_point_px", principal_point_px, "[cx, cy] in pixels") from None
            as_float("principal_point_px[0]", cx)
            as_float("principal_point_px[1]", cy)
        p = np.zeros(P.N_PARAMS)
        p[[P.FX, P.FY, P.CX, P.CY]] = f, f, cx, cy
        p[[P.XM, P.YM, P.HM]] = x0, y0, hm
        p[[P.PAN, P.TILT, P.ROLL]] = np.deg2rad([pan, tilt, roll])
        self.params = p
        self.image_size_px = (w, h)
        self.ground_z_m = as_float("ground_z_m", ground_z_m)

    @property
    def focal_px(self) -> float:
        return float(self.params[P.FX])

    @property
    def principal_point_px(self) -> tuple[float, float]:
        return float(self.params[P.CX]), float(self.params[P.CY])

    @property
    def position_m(self) -> tuple[float, float]:
        return float(self.params[P.XM]), float(self.params[P.YM])

    def to_dict(self) -> dict:
        """The camera file content (see docs/file-formats.md)."""
        return {
            "model": "pan-tilt",
            "image_size_px": list(self.image_size_px),
            "focal_px": self.focal_px,
            "principal_point_px": list(self.principal_point_px),
            "position_m": list(self.position_m),
            "height_m": self.height_m,
            "pan_deg": self.pan_deg,
            "tilt_deg": self.tilt_deg,
            "roll_deg": self.roll_deg,
            "ground_z_m": self.ground_z_m,
        }

    def to_opencv(self):
        """The same camera as an :class:`~footprint_uq.cameras.opencv.OpenCVCamera`."""
        from .opencv import OpenCVCamera

        T = self.T_cam_world
        return OpenCVCamera(self.K, np.zeros(5), T[:3, :3], T[:3, 3], self.image_size_px,
                            ground_z_m=self.ground_z_m)

    def __repr__(self) -> str:
        return (f"PanTiltCamera(focal_px={self.focal_px:g}, image_size_px={self.image_size_px}, "
                f"height_m={self.height_m:g}, pan_deg={self.pan_deg:g}, tilt_deg={self.tilt_deg:g}, "
                f"roll_deg={self.roll_deg:g}, position_m={self.position_m})")
