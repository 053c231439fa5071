"""How well a layout of cameras sees a site: per-sample information, fused 95 % semi-major, met area.

For each ground sample the planner needs the covariance of the ground point a camera would report
there.  The map kernels go from pixels to the ground; here the direction is the inverse: every
ground sample is projected into the candidate camera (:meth:`Camera.project_ground`), samples that
land in the image, in the lens's valid domain and are not occluded (:func:`geometry.occluded`) are
back-projected with their covariance (:func:`footprint_uq.products.covariance.covariance_points`,
the same numbers as :func:`footprint_uq.uncertainty.propagation.propagate`).

Covariances are kept in information form ``I = C^-1`` (3 numbers per sample: I_xx, I_xy, I_yy):
cameras with independent errors fuse by adding information, exactly as
:func:`footprint_uq.products.fusion.fuse_by_id` does (``P = (sum_i C_i^-1)^-1``).  A sample
meets its zone's requirement ``max_semi_major_m = X`` at confidence ``p`` when the semi-major axis
``k sqrt(lambda_max(P))`` (``k = chi2_scale(p)``, 2.4477 at 95 %) is at most X, i.e. when
``lambda_min(I) >= k^2 / X^2``.  Without fusion (``fusion=False``) a sample is met only by a single
camera that meets it alone.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..cameras.opencv import OpenCVCamera
from ..cameras.pantilt import PanTiltCamera
from ..errors import InputError
from ..products.covariance import covariance_points
from ..uncertainty.ellipse import chi2_scale
from .geometry import GroundSamples, occluded

__all__ = ["CameraConfig", "build_camera", "camera_information", "information_lambda_min", "semi_major_from_info",
           "ZoneResult", "LayoutEvaluation", "evaluate_information", "evaluate_layout", "requirement_threshold"]


@dataclass(frozen=True)
class CameraConfig:
    """One camera of a layout: which mount, camera type and lens, and its height, pan and tilt."""

    mount: str
    camera_type: str
    lens: str
    height_m: float
    pan_deg: float
    tilt_deg: float

    def replace(self, **kw) -> CameraConfig:
        d = {**self.__dict__, **kw}
        return CameraConfig(**d)


def build_camera(site, cfg: CameraConfig):
    """The camera model of ``cfg`` on ``site``: a :class:`PanTiltCamera`, or an :class:`OpenCVCamera` with
    the lens's distortion (same pose)."""
    m = site.mount(cfg.mount)
    ct = site.camera_type(cfg.camera_type)
    lens = next((x for x in ct.lenses if x.name == cfg.lens), None)
    if lens is None:
        raise InputError("lens", cfg.lens, f"one of camera {ct.name!r}'s lenses {[x.name for x in ct.lenses]}")
    pan = float(np.mod(cfg.pan_deg + 180.0, 360.0) - 180.0)
    cam = PanTiltCamera(lens.focal_px, ct.image_size_px, cfg.height_m, pan, cfg.tilt_deg, position_m=m.position_m)
    if not any(lens.dist):
        return cam
    cv = cam.to_opencv()
    return OpenCVCamera(cv.K, np.asarray(lens.dist, dtype=np.float64), cv.R, cv.t, cv.image_size_px)


def camera_information(camera, budget, xy_world_m, occluders=()) -> tuple[np.ndarray, np.ndarray]:
    """Which ground samples ``(S, 2)`` a camera sees, and their information matrices.

    Returns
    -------
    index : (n,) int64
        Samples seen: in the image, in the lens's valid domain, in front of the camera, not occluded,
        with a finite positive definite covariance.
    info_m2inv : (n, 3)
        ``(I_xx, I_xy, I_yy)`` of ``I = C^-1``, 1/m^2, C the ground covariance under ``budget``.
    """
    xy = np.asarray(xy_world_m, dtype=np.float64)
    pr = camera.project_ground(xy)
    ok = pr.valid & camera.in_image(pr.uv_px) & np.isfinite(pr.uv_px).all(-1)
    idx = np.flatnonzero(ok)
    if occluders and idx.size:
        c = camera.position_world_m
        idx = idx[~occluded(xy[idx], (c[0], c[1], c[2] - camera.ground_z_m), occluders)]
    if idx.size == 0:
        return idx, np.zeros((0, 3))
    _, cov, valid = covariance_points(camera, budget, pr.uv_px[idx])
    a, b, d = cov[:, 0, 0], 0.5 * (cov[:, 0, 1] + cov[:, 1, 0]), cov[:, 1, 1]
    det = a * d - b * b
    good = valid & np.isfinite(det) & (det > 0) & (a > 0)
    info = np.stack([d, -b, a], -1)[good] / det[good, None]
    return idx[good], info


def information_lambda_min(info) -> np.ndarray:
    """Smaller eigenvalue of ``(..., 3)`` packed 2x2 information matrices (I_xx, I_xy, I_yy)."""
    a, b, d = info[..., 0], info[..., 1], info[..., 2]
    return 0.5 * (a + d) - np.hypot(0.5 * (a - d), b)


def semi_major_from_info(info, confidence: float = 0.95) -> np.ndarray:
    """Semi-major axis (m) at ``confidence`` of the covariance ``I^-1``; inf where not positive definite."""
    lam = information_lambda_min(np.asarray(info, dtype=np.float64))
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lam > 0, chi2_scale(confidence) / np.sqrt(np.where(lam > 0, lam, 1.0)), np.inf)


def requirement_threshold(max_semi_major_m, confidence: float = 0.95) -> np.ndarray:
    """``lambda_min(I)`` needed for a semi-major axis of at most ``max_semi_major_m`` at ``confidence``."""
    return chi2_scale(confidence) ** 2 / np.asarray(max_semi_major_m, dtype=np.float64) ** 2


@dataclass
class ZoneResult:
    """One zone of an evaluated layout (areas in m^2, the worst sample's semi-major in m)."""

    name: str
    max_semi_major_m: float
    weight: float
    area_m2: float
    area_met_m2: float
    worst_semi_major_m: float
    worst_xy_m: tuple[float, float]

    @property
    def fraction_met(self) -> float:
        return self.area_met_m2 / self.area_m2 if self.area_m2 > 0 else 0.0

    def row(self) -> dict:
        return {"zone": self.name, "requirement_m": self.max_semi_major_m, "weight": self.weight,
                "area_m2": self.area_m2, "area_met_m2": self.area_met_m2, "fraction_met": self.fraction_met,
                "worst_semi_major_m": self.worst_semi_major_m, "worst_x_m": self.worst_xy_m[0],
                "worst_y_m": self.worst_xy_m[1]}


@dataclass
class LayoutEvaluation:
    """Per-sample and per-zone results of a layout (see :func:`evaluate_layout`).

    Attributes
    ----------
    semi_major_m : (S,)      fused (or best single) 95 % semi-major axis; inf where no camera sees the sample
    met : (S,) bool          ``semi_major_m <= requirement`` of the sample's zone
    n_seen : (S,) int        cameras that see the sample
    value : float            weighted met area, sum of weight * area over met samples (m^2)
    fraction : float         ``value`` / the weighted area of all zones
    zones : list of ZoneResult
    """

    semi_major_m: np.ndarray
    met: np.ndarray
    n_seen: np.ndarray
    value: float
    fraction: float
    zones: list[ZoneResult] = field(default_factory=list)
    fusion: bool = True
    confidence: float = 0.95


def _zone_results(site, samples: GroundSamples, semi, met) -> list[ZoneResult]:
    out = []
    for k, z in enumerate(site.zones):
        m = samples.zone == k
        n = int(m.sum())
        if n == 0:
            out.append(ZoneResult(z.name, z.max_semi_major_m, z.weight, 0.0, 0.0, float("nan"),
                                  (float("nan"), float("nan"))))
            continue
        i = np.flatnonzero(m)[int(np.argmax(semi[m]))]
        out.append(ZoneResult(z.name, z.max_semi_major_m, z.weight, n * samples.area_m2,
                              float(met[m].sum()) * samples.area_m2, float(semi[i]),
                              (float(samples.xy_world_m[i, 0]), float(samples.xy_world_m[i, 1]))))
    return out


def evaluate_information(site, samples: GroundSamples, infos, *, fusion: bool = True,
                         confidence: float | None = None) -> LayoutEvaluation:
    """Evaluate a layout given each camera's ``(index, info)`` from :func:`camera_information`."""
    conf = site.search.confidence if confidence is None else confidence
    n = len(samples)
    req = np.array([z.max_semi_major_m for z in site.zones])[samples.zone]
    n_seen = np.zeros(n, dtype=np.int64)
    if fusion:
        total = np.zeros((n, 3))
        for idx, info in infos:
            np.add.at(total, idx, info)
            n_seen[idx] += 1
        semi = semi_major_from_info(total, conf)
    else:
        semi = np.full(n, np.inf)
        for idx, info in infos:
            semi[idx] = np.minimum(semi[idx], semi_major_from_info(info, conf))
            n_seen[idx] += 1
    met = semi <= req
    w = np.array([z.weight for z in site.zones])[samples.zone] * samples.area_m2
    value = float(w[met].sum())
    return LayoutEvaluation(semi, met, n_seen, value, value / float(w.sum()), _zone_results(site, samples, semi, met),
                            fusion, conf)


def evaluate_layout(site, samples: GroundSamples, cameras, *, fusion: bool = True,
                    confidence: float | None = None) -> LayoutEvaluation:
    """Evaluate a layout: ``cameras`` is a list of ``(camera, budget)`` pairs (any camera model)."""
    infos = [camera_information(cam, bud, samples.xy_world_m, site.occluders) for cam, bud in cameras]
    return evaluate_information(site, samples, infos, fusion=fusion, confidence=confidence)
