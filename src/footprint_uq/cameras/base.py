"""Camera base class: a nominal parameter vector plus image size and ground height."""

from __future__ import annotations

import numpy as np

from .. import params as P
from .._checks import as_points
from . import general
from .lens_domain import LensDomain, lens_domain
from .rotation import R_W_C

__all__ = ["Camera"]


class Camera:
    """A calibrated camera looking at a ground plane ``z = ground_z_m`` of the world frame W.

    Subclasses set :attr:`params` (shape (22,), :data:`footprint_uq.params.PARAM_NAMES`),
    :attr:`image_size_px` ``(width, height)`` and :attr:`ground_z_m`.

    Every method broadcasts over leading dimensions.
    """

    model: str = "camera"
    params: np.ndarray
    image_size_px: tuple[int, int]
    ground_z_m: float = 0.0

    # -- the trio ------------------------------------------------------------------
    def backproject(self, uv_px, *, get_gradients: bool = False) -> general.Backprojection:
        """Pixels ``(..., 2)`` -> ground points ``xy_world_m`` ``(..., 2)`` (see :class:`general.Backprojection`)."""
        return general.backproject(self.params, as_points("uv_px", uv_px, 2), get_gradients=get_gradients,
                                   domain=self.lens_domain)

    def project(self, xyz_world_m, *, get_gradients: bool = False) -> general.Projection:
        """World points ``(..., 3)`` (frame W, metres) -> pixels ``(..., 2)``."""
        xyz = as_points("xyz_world_m", xyz_world_m, 3) - np.array([0.0, 0.0, self.ground_z_m])
        return general.project(self.params, xyz, get_gradients=get_gradients, domain=self.lens_domain)

    def project_ground(self, xy_world_m, *, get_gradients: bool = False) -> general.Projection:
        """Ground points ``(..., 2)`` on the nominal ground plane -> pixels ``(..., 2)``.

        The inverse of :meth:`backproject`; ``duv_dxyz`` then holds ``duv_dxy`` ``(..., 2, 2)``.
        """
        xy = as_points("xy_world_m", xy_world_m, 2)
        xyz = np.concatenate([xy, np.zeros(xy.shape[:-1] + (1,))], -1)
        pr = general.project(self.params, xyz, get_gradients=get_gradients, domain=self.lens_domain)
        if get_gradients:
            pr = pr._replace(duv_dxyz=pr.duv_dxyz[..., :2])
        return pr

    # -- functional form, for Monte Carlo and finite differences --------------------
    def backproject_with(self, params, uv_px) -> general.Backprojection:
        """Back-project with another parameter vector ``(..., 22)`` (same model).

        The pixels' validity is judged in this camera's lens domain (:attr:`lens_domain`), also
        for perturbed distortion coefficients: a Monte Carlo sample never answers where the
        nominal camera does not.
        """
        return general.backproject(params, uv_px, domain=self.lens_domain)

    # -- derived quantities ---------------------------------------------------------
    @property
    def lens_domain(self) -> LensDomain:
        """Where the lens model can be inverted (:mod:`footprint_uq.cameras.lens_domain`), cached."""
        return lens_domain(self.params[P.DIST_SLICE])

    @property
    def K(self) -> np.ndarray:
        fx, fy, cx, cy, sk = self.params[:5]
        return np.array([[fx, sk, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])

    @property
    def dist(self) -> np.ndarray:
        """Distortion (k1, k2, p1, p2, k3, k4, k5, k6)."""
        return self.params[P.DIST_SLICE].copy()

    @property
    def R_world_cam(self) -> np.ndarray:
        """Rotation from the OpenCV camera frame to the world frame W (3, 3)."""
        return R_W_C(self.params[P.PAN], self.params[P.TILT], self.params[P.ROLL])

    @property
    def position_world_m(self) -> np.ndarray:
        """Camera centre in W (x, y, z), metres."""
        x, y, h = self.params[P.XM:P.HM + 1]
        return np.array([x, y, h + self.ground_z_m])

    @property
    def T_world_cam(self) -> np.ndarray:
        """4x4 transform from OpenCV camera coordinates to world coordinates."""
        T = np.eye(4)
        T[:3, :3] = self.R_world_cam
        T[:3, 3] = self.position_world_m
        return T

    @property
    def T_cam_world(self) -> np.ndarray:
        """4x4 transform from world to OpenCV camera coordinates (OpenCV's [R|t])."""
        T = np.eye(4)
        R = self.R_world_cam.T
        T[:3, :3] = R
        T[:3, 3] = -R @ self.position_world_m
        return T

    @property
    def height_m(self) -> float:
        return float(self.params[P.HM])

    @property
    def pan_deg(self) -> float:
        return float(np.rad2deg(self.params[P.PAN]))

    @property
    def tilt_deg(self) -> float:
        return float(np.rad2deg(self.params[P.TILT]))

    @property
    def roll_deg(self) -> float:
        return float(np.rad2deg(self.params[P.ROLL]))

    def in_image(self, uv_px) -> np.ndarray:
        """True where ``uv_px`` lies inside the image (pixel centres at integers, edges at -0.5)."""
        uv = np.asarray(uv_px, dtype=np.float64)
        w, h = self.image_size_px
        return (uv[..., 0] >= -0.5) & (uv[..., 0] <= w - 0.5) & (uv[..., 1] >= -0.5) & (uv[..., 1] <= h - 0.5)

    def pixel_grid(self, step_px: int = 1) -> np.ndarray:
        """Pixel centres of the whole image, ``(H/step, W/step, 2)``."""
        w, h = self.image_size_px
        u = np.arange(0, w, step_px, dtype=np.float64)
        v = np.arange(0, h, step_px, dtype=np.float64)
        uu, vv = np.meshgrid(u, v)
        return np.stack([uu, vv], -1)

    def horizon_v_px(self, u_px) -> np.ndarray:
        """Row of the horizon at columns ``u_px`` for an undistorted camera (NaN if none)."""
        R = self.R_world_cam
        fx, fy, cx, cy, sk = self.params[:5]
        u = np.asarray(u_px, dtype=np.float64)
        x = (u - cx) / fx
        # ray (x, y, 1) horizontal: R[2,0] x + R[2,1] y + R[2,2] = 0 (ignoring skew)
        with np.errstate(divide="ignore", invalid="ignore"):
            y = -(R[2, 0] * x + R[2, 2]) / R[2, 1]
        return y * fy + cy
