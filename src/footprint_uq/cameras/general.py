"""General ground back-projection and projection on the shared parameter vector.

This is the reference path for both camera models: pixel -> normalised
(:mod:`.pinhole`) -> undistorted (:mod:`.distortion`) -> ray in the world
(:mod:`.rotation`) -> ground intersection (:mod:`footprint_uq.cameras.ground`).  The
paper's closed form (:mod:`.pantilt`) must agree with it for zero distortion.

All functions broadcast: ``params`` is ``(..., 22)`` (see
:mod:`footprint_uq.params`), pixels ``(..., 2)``, world points ``(..., 3)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .. import params as P
from .. import status
from .distortion import distort, in_principal_region, undistort
from .ground import intersect_ground
from .pinhole import normalised_to_pixel, pixel_to_normalised
from .rotation import R_W_C, dR_W_C

__all__ = ["Backprojection", "Projection", "backproject", "project"]


class Backprojection(NamedTuple):
    """Result of a pixel -> ground back-projection.

    Attributes
    ----------
    xy_world_m : ndarray (..., 2)
        Ground point in the world frame W (x east, y north), metres; NaN where invalid.
    valid : ndarray of bool (...)
    reason : ndarray of int8 (...)
        :mod:`footprint_uq.status` code.
    dxy_duv : ndarray (..., 2, 2) or None
        d(x, y)/d(u, v), metres per pixel.
    dxy_dp : ndarray (..., 2, 22) or None
        d(x, y)/d(params), columns in :data:`footprint_uq.params.PARAM_NAMES` order.
    """

    xy_world_m: np.ndarray
    valid: np.ndarray
    reason: np.ndarray
    dxy_duv: np.ndarray | None = None
    dxy_dp: np.ndarray | None = None


class Projection(NamedTuple):
    """Result of a world -> pixel projection (``duv_dxyz`` (..., 2, 3), ``duv_dp`` (..., 2, 22))."""

    uv_px: np.ndarray
    valid: np.ndarray
    reason: np.ndarray
    duv_dxyz: np.ndarray | None = None
    duv_dp: np.ndarray | None = None


def backproject(params, uv_px, *, get_gradients=False, domain=None) -> Backprojection:
    """Back-project pixels onto the ground.

    Parameters
    ----------
    params : array_like, shape (..., 22)
        Camera parameters (:data:`footprint_uq.params.PARAM_NAMES`).
    uv_px : array_like, shape (..., 2)
        Pixel coordinates (u right, v down), possibly distorted.
    get_gradients : bool
        Fill ``dxy_duv`` and ``dxy_dp``.
    domain : LensDomain, optional
        Valid domain of the lens (:mod:`footprint_uq.cameras.lens_domain`); default: that of
        each point's own distortion coefficients.  Pixels outside it are ``UNDISTORT_FAILED``.
    """
    p = np.asarray(params, dtype=np.float64)
    uv = np.asarray(uv_px, dtype=np.float64)
    shape = np.broadcast_shapes(p.shape[:-1], uv.shape[:-1])
    finite = np.broadcast_to(np.isfinite(uv).all(-1), shape) & np.broadcast_to(
        np.isfinite(p).all(-1), shape)
    fx, fy, cx, cy, sk = (p[..., i] for i in range(5))
    dist = p[..., P.DIST_SLICE]
    cam = p[..., P.XM:P.HM + 1]
    ground = p[..., P.GDZ:P.GSY + 1]
    ang = (p[..., P.PAN], p[..., P.TILT], p[..., P.ROLL])
    R = R_W_C(*ang)
    if not get_gradients:
        xd = pixel_to_normalised(uv, fx, fy, cx, cy, sk)
        xn, conv = undistort(xd, dist, domain=domain)
        ray_c = np.concatenate([xn, np.ones(xn.shape[:-1] + (1,))], -1)
        ray_w = (R @ ray_c[..., None])[..., 0]
        xy, vg = intersect_ground(cam, ray_w, ground)
        valid = vg & conv & finite
        xy = np.where(valid[..., None], xy, np.nan)
        return Backprojection(xy, valid, status.backprojection_reason(vg, conv, finite))
    xd, dxd_duv, dxd_dk = pixel_to_normalised(uv, fx, fy, cx, cy, sk, get_gradients=True)
    xn, conv, dxn_dxd, dxn_ddist = undistort(xd, dist, domain=domain, get_gradients=True)
    ray_c = np.concatenate([xn, np.ones(xn.shape[:-1] + (1,))], -1)
    ray_w = (R @ ray_c[..., None])[..., 0]
    xy, vg, dxy_dcam, dxy_dray, dxy_dg = intersect_ground(cam, ray_w, ground, get_gradients=True)
    valid = vg & conv & finite
    dR = dR_W_C(*ang)  # (..., 3 angles, 3, 3)
    dray_dang = (dR @ ray_c[..., None, :, None])[..., 0]  # (..., 3 angles, 3)
    dxy_dang = dxy_dray @ np.swapaxes(dray_dang, -1, -2)  # (..., 2, 3)
    dxy_dxn = dxy_dray @ R[..., :, :2]  # (..., 2, 2)
    dxy_dxd = dxy_dxn @ dxn_dxd
    J = np.zeros(shape + (2, P.N_PARAMS))
    J[..., 0:5] = dxy_dxd @ dxd_dk
    J[..., P.DIST_SLICE] = dxy_dxn @ dxn_ddist
    J[..., P.XM:P.HM + 1] = dxy_dcam
    J[..., P.PAN:P.ROLL + 1] = dxy_dang
    J[..., P.GDZ:P.GSY + 1] = dxy_dg
    dxy_duv = dxy_dxd @ dxd_duv
    nan = ~valid
    xy = np.where(nan[..., None], np.nan, xy)
    J[nan] = np.nan
    dxy_duv = np.where(nan[..., None, None], np.nan, dxy_duv)
    return Backprojection(xy, valid, status.backprojection_reason(vg, conv, finite), dxy_duv, J)


def project(params, xyz_rel_m, *, get_gradients=False, domain=None) -> Projection:
    """Project world points into the image.

    Parameters
    ----------
    params : array_like, shape (..., 22)
    xyz_rel_m : array_like, shape (..., 3)
        World points (x east, y north, z up) with z measured from the nominal
        ground plane, metres.  The ground parameters do not enter.
    get_gradients : bool
        Fill ``duv_dxyz`` and ``duv_dp``.
    domain : LensDomain, optional
        As in :func:`backproject`.

    Points behind the camera (``BEHIND_CAMERA``), non-finite input (``NOT_FINITE``)
    and points outside the lens model's valid region, where the distortion
    polynomial folds back (``UNDISTORT_FAILED``), give NaN and ``valid`` False.
    """
    p = np.asarray(params, dtype=np.float64)
    X = np.asarray(xyz_rel_m, dtype=np.float64)
    shape = np.broadcast_shapes(p.shape[:-1], X.shape[:-1])
    fx, fy, cx, cy, sk = (p[..., i] for i in range(5))
    dist = p[..., P.DIST_SLICE]
    ang = (p[..., P.PAN], p[..., P.TILT], p[..., P.ROLL])
    R = R_W_C(*ang)
    Rt = np.swapaxes(R, -1, -2)
    rel = X - p[..., P.XM:P.HM + 1]
    pc = (Rt @ rel[..., None])[..., 0]
    finite = np.broadcast_to(np.isfinite(X).all(-1), shape) & np.broadcast_to(
        np.isfinite(p).all(-1), shape)
    with np.errstate(divide="ignore", invalid="ignore"):
        zc = pc[..., 2]
        front = zc > 0
        xn = pc[..., :2] / zc[..., None]
    valid = front & finite
    reason = np.full(shape, status.OK, dtype=np.int8)
    reason[~front] = status.BEHIND_CAMERA
    reason[~finite] = status.NOT_FINITE
    if np.any(dist):
        # past the fold of the distortion polynomial a point maps to a meaningless pixel (possibly
        # near the image centre, or on the opposite side): flag it like an undistortion failure
        with np.errstate(all="ignore"):
            x0 = np.where(valid[..., None], xn, 0.0)
            lens_ok = in_principal_region(x0, dist) if domain is None else domain.contains_undistorted(x0)
        reason[valid & ~lens_ok] = status.UNDISTORT_FAILED
        valid = valid & lens_ok
    xn = np.where(valid[..., None], xn, np.nan)
    if not get_gradients:
        xd = distort(xn, dist)
        uv = normalised_to_pixel(xd, fx, fy, cx, cy, sk)
        return Projection(uv, valid, reason)
    xd, dxd_dxn, dxd_ddist = distort(xn, dist, get_gradients=True)
    uv, duv_dxd, duv_dk = normalised_to_pixel(xd, fx, fy, cx, cy, sk, get_gradients=True)
    with np.errstate(divide="ignore", invalid="ignore"):
        iz = 1.0 / zc
        z0 = np.zeros_like(iz)
        dxn_dpc = np.stack([np.stack([iz, z0, -xn[..., 0] * iz], -1),
                            np.stack([z0, iz, -xn[..., 1] * iz], -1)], -2)
    duv_dxn = duv_dxd @ dxd_dxn
    duv_dpc = duv_dxn @ dxn_dpc
    duv_dxyz = duv_dpc @ Rt
    dR = dR_W_C(*ang)
    dpc_dang = (np.swapaxes(dR, -1, -2) @ rel[..., None, :, None])[..., 0]  # (..., 3, 3)
    J = np.zeros(shape + (2, P.N_PARAMS))
    J[..., 0:5] = duv_dk
    J[..., P.DIST_SLICE] = duv_dxd @ dxd_ddist
    J[..., P.XM:P.HM + 1] = -duv_dxyz
    J[..., P.PAN:P.ROLL + 1] = duv_dpc @ np.swapaxes(dpc_dang, -1, -2)
    # no derivative of an undefined point (the principal-point columns would otherwise read 1)
    J[~valid] = np.nan
    duv_dxyz = np.where(valid[..., None, None], duv_dxyz, np.nan)
    return Projection(uv, valid, reason, duv_dxyz, J)
