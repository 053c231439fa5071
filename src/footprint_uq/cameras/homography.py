"""Image-to-ground homographies: the plane mapping ``H_ground_image`` with the uncertainty of its fit.

A homography ``H_ground_image`` (3, 3) maps a pixel ``(u, v, 1)`` to a ground point
``(x, y, 1)`` of the world frame W (metres, up to scale): ``q = H (u, v, 1)``,
``xy_world_m = q[:2] / q[2]``.  It is what four-point perspective transforms and most
traffic-analytics tools store.  It holds for an undistorted image of a flat ground.

* :class:`HomographyCamera` uses the mapping directly: ground points, ``dxy_duv`` and
  ``dxy_dh`` (derivatives with respect to the 9 entries of H, row-major), and the ground
  covariance from the covariance of H (from the fit of the points it came from) plus the
  pixel covariance.  Pixels with ``q[2]`` of the wrong sign are above the horizon (NaN,
  ``status.ABOVE_HORIZON``).
* :func:`fit_homography`: H and its 9x9 covariance from point pairs with pixel and survey
  sigmas (effective variance in the ground, Gauss-Newton on the unit sphere ``|H|_F = 1``;
  the covariance has H itself in its null space: the scale of H is not a parameter).
* :func:`camera_from_homography`: with intrinsics K, the pose ``K^-1 H^-1 = s [r1 r2 t]``
  (an :class:`OpenCVCamera`) and the 6x6 covariance of ``x_m, y_m, height_m, pan, tilt,
  roll`` (rad) propagated from the covariance of H.
* :func:`homography_from_camera`: the homography of any camera without distortion
  (the ground plane ``z = ground_z_m``).
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import cv2
import numpy as np

from .. import params as P
from .. import status
from .._checks import as_points, check_cov
from ..errors import ConsistencyWarning, InputError
from .opencv import OpenCVCamera

__all__ = ["HomographyCamera", "HomographyBackprojection", "fit_homography", "apply_homography",
           "camera_from_homography", "homography_from_camera"]


class HomographyBackprojection(NamedTuple):
    """``xy_world_m (..., 2)``, ``valid (...)``, ``reason (...)``, ``dxy_duv (..., 2, 2)``, ``dxy_dh (..., 2, 9)``."""

    xy_world_m: np.ndarray
    valid: np.ndarray
    reason: np.ndarray
    dxy_duv: np.ndarray | None = None
    dxy_dh: np.ndarray | None = None


def _as_H(name, H) -> np.ndarray:
    try:
        H = np.array(H, dtype=np.float64).reshape(3, 3)
    except (TypeError, ValueError):
        raise InputError(name, H, "a numeric 3x3 matrix") from None
    if not np.all(np.isfinite(H)):
        raise InputError(name, H.tolist(), "finite numbers")
    s = np.linalg.svd(H, compute_uv=False)
    if s[2] <= 1e-12 * s[0]:
        raise InputError(name, H.tolist(), "an invertible 3x3 matrix (a degenerate homography maps the image "
                                           "onto a line)")
    return H / np.linalg.norm(H)


def apply_homography(H, uv, get_gradients):
    """Map pixels through a homography: ``q = H [u, v, 1]``, ``xy = q[:2] / q[2]``.

    Parameters
    ----------
    H : (3, 3) array;  uv : (..., 2) pixels;  get_gradients : bool

    Returns
    -------
    q (..., 3), xy (..., 2), and with ``get_gradients`` ``dxy_duv`` (..., 2, 2) and ``dxy_dh``
    (..., 2, 9) (row-major entries of H), else None, None.
    """
    ph = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], -1)
    q = ph @ H.T
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = q[..., :2] / q[..., 2:3]
    if not get_gradients:
        return q, xy, None, None
    with np.errstate(divide="ignore", invalid="ignore"):
        iq = 1.0 / q[..., 2]
        z = np.zeros_like(iq)
        dxy_dq = np.stack([np.stack([iq, z, -xy[..., 0] * iq], -1), np.stack([z, iq, -xy[..., 1] * iq], -1)], -2)
    dxy_duv = dxy_dq @ H[:, :2]
    # dq/dh: q_i = sum_j H_ij p_j -> d q_i / d H_kj = delta_ik p_j
    dxy_dh = (dxy_dq[..., :, :, None] * ph[..., None, None, :]).reshape(xy.shape[:-1] + (2, 9))
    return q, xy, dxy_duv, dxy_dh


class HomographyCamera:
    """A plane mapping pixel -> ground, ``H_ground_image``, with an optional covariance of its entries.

    Parameters
    ----------
    H_ground_image : array_like (3, 3)
        Pixel ``(u, v, 1)`` -> ground ``(x, y, 1)`` in W (metres), up to scale; stored
        Frobenius-normalised with the sign that puts ``q[2] > 0`` on the ground.
    image_size_px : (int, int)
        (width, height).
    cov_h : array_like (9, 9), optional
        Covariance of the entries of the normalised H (row-major), e.g. from :func:`fit_homography`.
    ground_side_uv_px : array_like (2,), optional
        A pixel known to see the ground (default: the bottom centre of the image), to fix the sign.
    ground_z_m : float
        Height of the ground plane in W (reported only: the mapping is in x, y).
    points : dict, optional
        The correspondences H came from (``uv_px``, ``xy_world_m``, ``sigma_px``, ``sigma_m``), kept for the file.
    oriented : bool
        H already has ``q[2] > 0`` on the ground side (e.g. from a camera): keep its sign.
    """

    model = "homography"

    def __init__(self, H_ground_image, image_size_px, *, cov_h=None, ground_side_uv_px=None, ground_z_m=0.0,
                 points=None, oriented: bool = False):
        H = _as_H("H_ground_image", H_ground_image)
        try:
            w, h = (int(v) for v in image_size_px)
        except (TypeError, ValueError):
            raise InputError("image_size_px", image_size_px, "[width, height] in pixels") from None
        if w <= 0 or h <= 0:
            raise InputError("image_size_px", image_size_px, "two positive integers [width, height]")
        self.image_size_px = (w, h)
        ref = np.array([(w - 1) / 2.0, h - 1.0]) if ground_side_uv_px is None else np.asarray(ground_side_uv_px,
                                                                                              dtype=np.float64)
        q3 = H[2, :2] @ ref.reshape(-1, 2).T + H[2, 2]
        if np.all(np.abs(q3) < 1e-15):
            raise InputError("H_ground_image", H.tolist(), "a mapping whose reference pixel is not on the horizon")
        if not oriented and np.median(q3) < 0:
            H = -H
        self.H_ground_image = H
        self.ground_z_m = float(ground_z_m)
        self.cov_h = None
        if cov_h is not None:

            self.cov_h = check_cov("cov_H", cov_h, 9)
        self.points = points

    @property
    def H_image_ground(self) -> np.ndarray:
        """Ground ``(x, y, 1)`` -> pixel ``(u, v, 1)`` (the inverse mapping)."""
        return np.linalg.inv(self.H_ground_image)

    def backproject(self, uv_px, *, get_gradients: bool = False) -> HomographyBackprojection:
        """Pixels ``(..., 2)`` -> ground points ``xy_world_m (..., 2)``; NaN above the horizon."""
        uv = as_points("uv_px", uv_px, 2)
        q, xy, J_uv, J_h = apply_homography(self.H_ground_image, uv, get_gradients)
        finite = np.isfinite(uv).all(-1)
        valid = finite & (q[..., 2] > 0)
        reason = np.where(finite, np.where(valid, status.OK, status.ABOVE_HORIZON), status.NOT_FINITE).astype(np.int8)
        xy = np.where(valid[..., None], xy, np.nan)
        if get_gradients:
            J_uv = np.where(valid[..., None, None], J_uv, np.nan)
            J_h = np.where(valid[..., None, None], J_h, np.nan)
        return HomographyBackprojection(xy, valid, reason, J_uv, J_h)

    def project_ground(self, xy_world_m) -> np.ndarray:
        """Ground points ``(..., 2)`` -> pixels ``(..., 2)`` (NaN for points behind the camera)."""
        xy = as_points("xy_world_m", xy_world_m, 2)
        Hi = self.H_image_ground
        q, uv, _, _ = apply_homography(Hi, xy, False)
        # the pixel must map back to the ground side
        ph = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], -1)
        ok = (ph @ self.H_ground_image[2]) > 0
        return np.where(ok[..., None], uv, np.nan)

    def ground_covariance_m2(self, uv_px, pixel_cov_px2=None):
        """Ground points ``(..., 2)`` and covariances ``(..., 2, 2)`` (m^2): H's covariance plus pixel noise.

        ``pixel_cov_px2`` is ``(2, 2)`` or ``(..., 2, 2)`` px^2 (default none).
        """
        bp = self.backproject(uv_px, get_gradients=True)
        cov = np.zeros(bp.xy_world_m.shape + (2,))
        if self.cov_h is not None:
            cov = cov + bp.dxy_dh @ self.cov_h @ np.swapaxes(bp.dxy_dh, -1, -2)
        if pixel_cov_px2 is not None:
            S = np.asarray(pixel_cov_px2, dtype=np.float64)
            cov = cov + bp.dxy_duv @ S @ np.swapaxes(bp.dxy_duv, -1, -2)
        cov = np.where(bp.valid[..., None, None], cov, np.nan)
        return bp.xy_world_m, cov

    def to_dict(self) -> dict:
        d = {"model": "homography", "image_size_px": list(self.image_size_px),
             "H_ground_image": self.H_ground_image.tolist(), "ground_z_m": self.ground_z_m}
        if self.cov_h is not None:
            d["cov_H"] = self.cov_h.tolist()
        if self.points is not None:
            d["points"] = {k: (np.asarray(v).tolist() if not np.isscalar(v) else v) for k, v in self.points.items()}
        return d

    def __repr__(self) -> str:
        cov = "yes" if self.cov_h is not None else "no"
        return f"HomographyCamera(image_size_px={self.image_size_px}, cov_h={cov})"


# ---------------------------------------------------------------------------------------------
# fit
# ---------------------------------------------------------------------------------------------
def _tangent_basis(h):
    """(9, 8) orthonormal basis of the tangent space of the unit sphere at h."""
    _, _, Vt = np.linalg.svd(h[None, :])
    return Vt[1:].T


def fit_homography(uv_px, xy_world_m, *, sigma_px=1.0, sigma_m=0.05, max_iter: int = 50):
    """Fit ``H_ground_image`` to point pairs; returns ``(H (3, 3), cov_h (9, 9), rms_m)``.

    Parameters
    ----------
    uv_px : array_like (N, 2)
        Pixels, N >= 4, not three on one line.
    xy_world_m : array_like (N, 2)
        Their ground points in W, metres.
    sigma_px, sigma_m : float or array_like (N,)
        1-sigma pixel noise (per image axis) and survey noise (per ground axis).

    The residual ``xy - H(uv)`` has covariance ``sigma_m^2 I + sigma_px^2 J_uv J_uv^T``
    (effective variance); Gauss-Newton on ``|H|_F = 1`` from OpenCV's least-squares start.
    ``cov_h = B (J_B^T W J_B)^-1 B^T`` with B a tangent basis at H.
    """

    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    xy = np.asarray(xy_world_m, dtype=np.float64).reshape(-1, 2)
    n = len(uv)
    if n < 4 or len(xy) != n:
        raise InputError("homography points", f"{n} pixels, {len(xy)} ground points", "at least 4 pairs")
    if not (np.all(np.isfinite(uv)) and np.all(np.isfinite(xy))):
        raise InputError("homography points", "non-finite values", "finite pixels and ground points")
    for what, pts in (("pixels", uv), ("ground points", xy)):
        s = np.linalg.svd(pts - pts.mean(0), compute_uv=False)
        if s[0] == 0 or s[1] < 1e-3 * s[0]:
            raise InputError(f"homography points ({what})", "on one line", "points spread over the plane")
    spx2 = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64) ** 2, (n,))
    sm2 = np.broadcast_to(np.asarray(sigma_m, dtype=np.float64) ** 2, (n,))
    H0, _ = cv2.findHomography(uv, xy, 0)
    if H0 is None:
        raise InputError("homography points", "no homography fits", "four or more points, no three on one line")
    h = (H0 / np.linalg.norm(H0)).ravel()

    def pieces(h):
        _, f, Juv, Jh = apply_homography(h.reshape(3, 3), uv, True)
        r = xy - f
        S = sm2[:, None, None] * np.eye(2) + spx2[:, None, None] * (Juv @ np.swapaxes(Juv, -1, -2))
        Si = np.linalg.inv(S)
        return r, Si, Jh

    for _ in range(max_iter):
        r, Si, Jh = pieces(h)
        B = _tangent_basis(h)
        J = Jh @ B
        Hn = np.einsum("nik,nij,njl->kl", J, Si, J)
        g = np.einsum("nik,nij,nj->k", J, Si, r)
        step = np.linalg.solve(Hn, g)
        h = h + B @ step
        h /= np.linalg.norm(h)
        if np.max(np.abs(step) / np.sqrt(np.diag(np.linalg.inv(Hn)))) < 1e-8:
            break
    else:
        raise InputError("homography fit", f"no convergence in {max_iter} iterations", "consistent point pairs")
    r, Si, Jh = pieces(h)
    B = _tangent_basis(h)
    J = Jh @ B
    Hn = np.einsum("nik,nij,njl->kl", J, Si, J)
    cov = B @ np.linalg.inv(Hn) @ B.T
    rms = float(np.sqrt(np.mean(np.sum(r**2, -1))))
    return h.reshape(3, 3), 0.5 * (cov + cov.T), rms


# ---------------------------------------------------------------------------------------------
# to and from a camera
# ---------------------------------------------------------------------------------------------
def _decompose(H_ground_image, K):
    """``(R, t)`` (world -> camera) of ``K^-1 H^-1 = s [r1 r2 t]``, the sign putting the camera above."""
    M = np.linalg.solve(K, np.linalg.inv(H_ground_image))
    s = 2.0 / (np.linalg.norm(M[:, 0]) + np.linalg.norm(M[:, 1]))
    out = []
    for sg in (s, -s):
        m = sg * M
        r1, r2, t = m[:, 0], m[:, 1], m[:, 2]
        R = np.column_stack([r1, r2, np.cross(r1, r2)])
        U, _, Vt = np.linalg.svd(R)
        R = U @ Vt
        if np.linalg.det(R) < 0:
            continue
        C = -R.T @ t
        out.append((C[2], R, t))
    if not out:
        raise InputError("H_ground_image", "a reflection", "a homography of a right-handed ground frame (x east, "
                                                          "y north, z up)")
    C_z, R, t = max(out, key=lambda c: c[0])
    if C_z <= 0:
        raise InputError("H_ground_image with K", f"camera {C_z:.3g} m above the ground",
                         "a camera above the ground (a left-handed ground frame? x east, y north, z up)")
    return R, t


def camera_from_homography(H_ground_image, K, image_size_px, *, dist=None, cov_h=None, ground_z_m=0.0):
    """Decompose a homography with intrinsics into a camera; returns ``(OpenCVCamera, cov_pose or None)``.

    ``cov_pose`` (6, 6) is the covariance of ``x_m, y_m, height_m, pan_rad, tilt_rad, roll_rad``
    propagated from ``cov_h`` (central differences of the decomposition).  ``H`` must map
    undistorted pixels (``K`` applied to normalised coordinates); ``dist`` is only carried over.
    """

    hc = H_ground_image if isinstance(H_ground_image, HomographyCamera) else HomographyCamera(H_ground_image,
                                                                                             image_size_px)
    H = hc.H_ground_image
    K = np.asarray(K, dtype=np.float64)
    w, h_ = hc.image_size_px
    ref_uv = np.array([(w - 1) / 2.0, h_ - 1.0]) if hc.points is None else np.asarray(hc.points["uv_px"])[0]

    def params_of(Hm):
        R, t = _decompose(Hm, K)
        X = apply_homography(Hm, ref_uv, False)[1]  # a ground point the camera sees
        if (R[2, :2] @ X + t[2]) <= 0:
            raise InputError("H_ground_image with K", "the ground seen behind the camera",
                             "a homography of a right-handed ground frame (x east, y north, z up)")
        t = t - R[:, 2] * ground_z_m  # the plane z = ground_z_m of W
        cam = OpenCVCamera(K, dist, R, t, image_size_px, ground_z_m)
        return cam, cam.params[P.XM:P.ROLL + 1]

    cam, p0 = params_of(H)
    cov = None
    if cov_h is not None:
        C = np.asarray(cov_h, dtype=np.float64)
        h = H.ravel()
        J = np.zeros((6, 9))
        eps = 1e-6
        for j in range(9):
            e = np.zeros(9)
            e[j] = eps
            pp = params_of((h + e).reshape(3, 3))[1]
            pm = params_of((h - e).reshape(3, 3))[1]
            d = pp - pm
            d[3:] = (d[3:] + np.pi) % (2 * np.pi) - np.pi
            J[:, j] = d / (2 * eps)
        cov = J @ C @ J.T
        cov = 0.5 * (cov + cov.T)
    return cam, cov


def homography_from_camera(camera) -> np.ndarray:
    """``H_ground_image`` (3, 3), Frobenius-normalised, of a camera without distortion.

    Raises InputError for a camera with lens distortion (no homography maps its pixels).
    """

    d = camera.dist
    if np.any(d):
        raise InputError("camera dist", d.tolist(), "no lens distortion (a homography maps an undistorted image; "
                                                    "undistort the image first and convert a camera without dist)")
    if isinstance(camera, HomographyCamera):
        return camera.H_ground_image.copy()
    T = camera.T_cam_world
    R, t = T[:3, :3], T[:3, 3]
    t = t + R[:, 2] * camera.ground_z_m  # ground points (x, y, ground_z_m)
    G = camera.K @ np.column_stack([R[:, 0], R[:, 1], t])
    H = np.linalg.inv(G)
    if not np.all(np.isfinite(H)):
        warnings.warn("degenerate homography (camera in the ground plane)", ConsistencyWarning, stacklevel=2)
    return HomographyCamera(H, camera.image_size_px, oriented=True).H_ground_image
