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

import warnings

import numpy as np

from .. import params as P
from .. import status
from .._checks import as_float, as_points
from ..errors import ConsistencyWarning, InputError
from . import general
from .base import Camera
from .opencv import OpenCVCamera

__all__ = ["PanTiltCamera", "paper_xy", "paper_partials", "closed_form_backproject"]


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


def _radial_tangential_dq(xn, yn):
    """``d(x_n, y_n)/d(dist)`` at zero nominal distortion: ``(..., 2, 8)`` (OpenCV order).

    Undistortion at zero distortion is the identity, so by the implicit-function
    theorem the derivative is minus the distortion's own derivative at ``(xn, yn)``:
    radial ``-(x, y) r^2k`` for k1, k2, k3, ``+(x, y) r^2k`` for k4, k5, k6 (the
    denominator), tangential ``-(2xy, r^2 + 2y^2)`` (p1) and ``-(r^2 + 2x^2, 2xy)`` (p2).
    """
    r2 = xn * xn + yn * yn
    r4 = r2 * r2
    r6 = r4 * r2
    out = np.empty(np.shape(xn) + (2, 8))
    for i, rr in ((0, r2), (1, r4), (4, r6)):
        out[..., 0, i] = -xn * rr
        out[..., 1, i] = -yn * rr
    for i, rr in ((5, r2), (6, r4), (7, r6)):
        out[..., 0, i] = xn * rr
        out[..., 1, i] = yn * rr
    out[..., 0, 2] = -2.0 * xn * yn
    out[..., 1, 2] = -(r2 + 2.0 * yn * yn)
    out[..., 0, 3] = -(r2 + 2.0 * xn * xn)
    out[..., 1, 3] = -2.0 * xn * yn
    return out


def closed_form_backproject(params, uv_px, *, get_gradients=False) -> general.Backprojection:
    """The paper's closed form, extended with roll, as a :class:`~.general.Backprojection`.

    Requires zero nominal distortion and zero nominal ground perturbations
    (``params[k1..k6] = params[ground_*] = 0``); any fx, fy, skew are accepted.

    Method: the image point is written in the paper's pixel variables
    ``c = u - cx - skew (v - cy) / fy`` (column) and ``r = fx (v - cy) / fy`` (row),
    so that ``(f, c, r) = fx (1, x_n, y_n)`` with ``f = fx`` (for the paper's camera,
    fx = fy and skew = 0, this is just ``c = u - cx``, ``r = v - cy``).  The roll
    ``phi`` turns the image about the boresight: ``c' = cos(phi) c - sin(phi) r``,
    ``r' = sin(phi) c + cos(phi) r``; then :func:`paper_xy` gives (X, Y) in frame G
    and the world point is ``(x0 + Y, y0 + X)``.

    Chain rule (``G = (X, Y)``; ``G_c, G_r, G_f, G_h, G_alpha, G_theta`` from :func:`paper_partials`
    at ``(c', r')``)::

        dG/dphi = -r' G_c + c' G_r
        dG/dc   =  cos(phi) G_c + sin(phi) G_r        dG/dr = -sin(phi) G_c + cos(phi) G_r
        dG/du   =  dG/dc                              dG/dv = -skew/fy dG/dc + fx/fy dG/dr
        dG/dfx  =  G_f + (r/fx) dG/dr                 dG/dfy = skew (v-cy)/fy^2 dG/dc - (r/fy) dG/dr
        dG/dcx  = -dG/dc                              dG/dcy = skew/fy dG/dc - fx/fy dG/dr
        dG/dskew = -(v - cy)/fy dG/dc
        dG/dk   =  fx (dG/dc dxn/dk + dG/dr dyn/dk)   (k a distortion coefficient, at zero)

    Ground plane (offset ``dz``, slopes ``gx, gy`` pivoting about the camera foot):
    with the offset ``o = (Y, X)`` in W, ``d xy/d dz = -o / h``,
    ``d xy/d gx = -o o_x / h``, ``d xy/d gy = -o o_y / h``.
    """
    p = np.asarray(params, dtype=np.float64)
    uv = np.asarray(uv_px, dtype=np.float64)
    shape = np.broadcast_shapes(p.shape[:-1], uv.shape[:-1])
    finite = np.broadcast_to(np.isfinite(uv).all(-1), shape) & np.broadcast_to(np.isfinite(p).all(-1), shape)
    fx, fy, cx, cy, sk = (p[..., i] for i in range(5))
    x0, y0, h = p[..., P.XM], p[..., P.YM], p[..., P.HM]
    alpha, theta, phi = p[..., P.PAN], p[..., P.TILT], p[..., P.ROLL]
    u, v = uv[..., 0], uv[..., 1]
    dv = v - cy
    c = u - cx - sk * dv / fy
    r = fx * dv / fy
    cphi, sphi = np.cos(phi), np.sin(phi)
    c1 = cphi * c - sphi * r
    r1 = sphi * c + cphi * r
    X, Y, vg = paper_xy(fx, c1, r1, h, alpha, theta)
    valid = np.broadcast_to(vg & finite, shape)
    reason = np.full(shape, status.OK, dtype=np.int8)
    reason[~vg] = status.ABOVE_HORIZON
    reason[~finite] = status.NOT_FINITE
    xy = np.stack([x0 + Y, y0 + X], -1)
    xy = np.where(valid[..., None], xy, np.nan)
    if not get_gradients:
        return general.Backprojection(xy, valid, reason)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        J, dxy_duv = _closed_form_jacobians(fx, fy, sk, dv, c, r, c1, r1, cphi, sphi, h, alpha, theta, X, Y, shape)
    bad = ~valid
    J[bad] = np.nan
    dxy_duv = np.where(bad[..., None, None], np.nan, dxy_duv)
    return general.Backprojection(xy, valid, reason, dxy_duv, J)


def _closed_form_jacobians(fx, fy, sk, dv, c, r, c1, r1, cphi, sphi, h, alpha, theta, X, Y, shape):
    """``dxy_dp`` (..., 2, 22) and ``dxy_duv`` (..., 2, 2) by the chain rule of :func:`closed_form_backproject`."""
    d = paper_partials(fx, c1, r1, h, alpha, theta)

    def w(pair):  # paper (dX, dY) -> world (dx, dy) = (dY, dX)
        return np.stack([pair[1], pair[0]], -1)

    G_c, G_r = w(d["c"]), w(d["r"])
    cphi_, sphi_ = cphi[..., None], sphi[..., None]
    dc = cphi_ * G_c + sphi_ * G_r
    dr = -sphi_ * G_c + cphi_ * G_r
    col = lambda a: np.asarray(a)[..., None]  # noqa: E731
    J = np.zeros(shape + (2, P.N_PARAMS))
    J[..., P.FX] = w(d["f"]) + col(r / fx) * dr
    J[..., P.FY] = col(sk * dv / fy**2) * dc - col(r / fy) * dr
    J[..., P.CX] = -dc
    J[..., P.CY] = col(sk / fy) * dc - col(fx / fy) * dr
    J[..., P.SKEW] = -col(dv / fy) * dc
    xn, yn = c / fx, dv / fy
    dq = _radial_tangential_dq(xn, yn)  # (..., 2, 8)
    J[..., P.DIST_SLICE] = col(fx) * (dc[..., :, None] * dq[..., 0:1, :] + dr[..., :, None] * dq[..., 1:2, :])
    J[..., 0, P.XM] = 1.0
    J[..., 1, P.YM] = 1.0
    J[..., P.HM] = w(d["h"])
    J[..., P.PAN] = w(d["alpha"])
    J[..., P.TILT] = w(d["theta"])
    J[..., P.ROLL] = -col(r1) * w(d["c"]) + col(c1) * w(d["r"])
    o = np.stack([Y, X], -1)
    J[..., P.GDZ] = -o / col(h)
    J[..., P.GSX] = -o * col(Y / h)
    J[..., P.GSY] = -o * col(X / h)
    dxy_duv = np.stack([dc, -col(sk / fy) * dc + col(fx / fy) * dr], -1)
    return J, dxy_duv


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
        Roll about the boresight, degrees: positive turns the camera clockwise as seen from behind it, so the
        scene appears rotated counter-clockwise in the image (docs/conventions.md, section 3).
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

    def backproject(self, uv_px, *, get_gradients: bool = False) -> general.Backprojection:
        """Pixels ``(..., 2)`` -> ground points ``xy_world_m`` ``(..., 2)`` by the paper's closed form.

        Same result as the general path (:func:`footprint_uq.cameras.general.backproject`),
        computed with :func:`paper_xy` / :func:`paper_partials` extended with roll
        (see :func:`closed_form_backproject`).  ``dxy_dp`` has all 22 columns of
        :data:`~footprint_uq.params.PARAM_NAMES`: fx and fy separately (the focal
        budget moves both together), distortion derivatives at zero nominal
        distortion, ground columns as in :mod:`footprint_uq.cameras.ground`.  If the
        parameter vector has been given non-zero nominal distortion or ground
        perturbations, the general path is used.  :meth:`backproject_with`
        (Monte Carlo, finite differences) always uses the general path.
        """
        uv = as_points("uv_px", uv_px, 2)
        if np.any(self.params[P.DIST_SLICE]) or np.any(self.params[P.GDZ:P.GSY + 1]):
            return general.backproject(self.params, uv, get_gradients=get_gradients, domain=self.lens_domain)
        return closed_form_backproject(self.params, uv, get_gradients=get_gradients)

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

    @classmethod
    def from_opencv(cls, camera, *, strict: bool = True, rtol: float = 1e-9) -> PanTiltCamera:
        """The paper's pan-tilt camera equal to an :class:`~footprint_uq.cameras.opencv.OpenCVCamera`.

        The pose always converts exactly.  The intrinsics convert exactly only when
        ``fx == fy``, skew is 0 and there is no distortion; otherwise ``strict``
        raises :class:`InputError`, and ``strict=False`` uses ``f = (fx + fy) / 2``,
        drops skew and distortion and warns.
        """
        fx, fy, cx, cy, sk = camera.params[:5]
        exact = abs(fx - fy) <= rtol * fx and abs(sk) <= rtol * fx and not np.any(camera.dist)
        if not exact:
            msg = (f"fx={fx:g}, fy={fy:g}, skew={sk:g}, dist={camera.dist.tolist()}")
            if strict:
                raise InputError("camera intrinsics", msg,
                                 "fx == fy, zero skew and zero distortion for an exact pan-tilt camera "
                                 "(use strict=False to approximate)")
            warnings.warn(f"approximating OpenCV camera as pan-tilt: {msg}", ConsistencyWarning, stacklevel=2)
        x, y, h = camera.params[P.XM:P.HM + 1]
        return cls((fx + fy) / 2.0, camera.image_size_px, h, camera.pan_deg, camera.tilt_deg,
                   camera.roll_deg, (x, y), (cx, cy), camera.ground_z_m)

    def to_opencv(self) -> OpenCVCamera:
        """The same camera as an :class:`~footprint_uq.cameras.opencv.OpenCVCamera`."""
        T = self.T_cam_world
        return OpenCVCamera(self.K, np.zeros(5), T[:3, :3], T[:3, 3], self.image_size_px,
                            ground_z_m=self.ground_z_m)

    def __repr__(self) -> str:
        return (f"PanTiltCamera(focal_px={self.focal_px:g}, image_size_px={self.image_size_px}, "
                f"height_m={self.height_m:g}, pan_deg={self.pan_deg:g}, tilt_deg={self.tilt_deg:g}, "
                f"roll_deg={self.roll_deg:g}, position_m={self.position_m})")
