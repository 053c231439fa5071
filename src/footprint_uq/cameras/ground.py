"""Ground surfaces: ray intersection with the (perturbed) ground plane.

The ground is the plane ``z = ground_dz + gx (x - x_cam) + gy (y - y_cam)`` in
coordinates relative to the nominal ground ``z = z0`` of the world frame W
(Z up).  ``ground_dz`` is a height offset and ``(gx, gy)`` the slope (dz/dx,
dz/dy), pivoting about the camera's foot point; all three are zero nominally and
exist so that their uncertainty can be propagated.  A random slope with
independent components of standard deviation ``tan(sigma_slope)`` gives a
vertical error at horizontal distance ``d`` of ``d tan(sigma_slope)``, which
with the offset reproduces ``sigma_z(d) = sqrt(sigma_z0^2 + (d tan sigma_slope)^2)``.

A ray that does not descend towards the plane (at or above the horizon) does
not hit the ground: it is flagged invalid and its result is NaN, never a point
behind the camera.
"""

from __future__ import annotations

import numpy as np

__all__ = ["intersect_ground", "sigma_ground_z"]


def sigma_ground_z(distance_m, sigma_z0_m, sigma_slope_deg):
    """Ground-height standard deviation at horizontal distance ``distance_m`` from the camera."""
    d = np.asarray(distance_m, dtype=np.float64)
    return np.sqrt(sigma_z0_m**2 + (d * np.tan(np.deg2rad(sigma_slope_deg))) ** 2)


def intersect_ground(cam_xyz, ray_w, ground, *, get_gradients=False):
    """Intersect rays with the ground plane.

    Parameters
    ----------
    cam_xyz : array_like, shape (..., 3)
        Camera centre (x, y, height above the nominal ground), metres, frame W.
    ray_w : array_like, shape (..., 3)
        Ray direction in frame W (any length).
    ground : array_like, shape (..., 3)
        (ground_dz_m, ground_slope_x, ground_slope_y).
    get_gradients : bool
        Also return ``dxy_dcam`` (..., 2, 3), ``dxy_dray`` (..., 2, 3) and
        ``dxy_dground`` (..., 2, 3).

    Returns
    -------
    xy_w_m : ndarray, shape (..., 2)
        Intersection in frame W, NaN where ``valid`` is False.
    valid : ndarray of bool, shape (...)
        True where the ray meets the ground in front of the camera.
    """
    C = np.asarray(cam_xyz, dtype=np.float64)
    d = np.asarray(ray_w, dtype=np.float64)
    g = np.asarray(ground, dtype=np.float64)
    dz, gx, gy = g[..., 0], g[..., 1], g[..., 2]
    N = dz - C[..., 2]
    Dn = d[..., 2] - gx * d[..., 0] - gy * d[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = N / Dn
        valid = (Dn < 0) & (N < 0) & np.isfinite(lam)
        lam = np.where(valid, lam, np.nan)
        xy = C[..., :2] + lam[..., None] * d[..., :2]
    if not get_gradients:
        return xy, valid
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / Dn
        dxy = d[..., :2]
        z = np.zeros_like(lam)
        o = np.ones_like(lam)
        # lam = N / Dn;  xy = C_xy + lam d_xy
        dxy_dcam = np.stack([np.stack([o, z, -dxy[..., 0] * inv], -1),
                             np.stack([z, o, -dxy[..., 1] * inv], -1)], -2)
        dlam_dray = (-lam * inv)[..., None] * np.stack([-gx + z, -gy + z, o], -1)
        dxy_dray = lam[..., None, None] * np.stack([np.stack([o, z, z], -1),
                                                    np.stack([z, o, z], -1)], -2)
        dxy_dray = dxy_dray + dxy[..., :, None] * dlam_dray[..., None, :]
        dlam_dg = np.stack([inv, lam * d[..., 0] * inv, lam * d[..., 1] * inv], -1)
        dxy_dground = dxy[..., :, None] * dlam_dg[..., None, :]
    return xy, valid, dxy_dcam, dxy_dray, dxy_dground
