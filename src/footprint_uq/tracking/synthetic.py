"""Seeded Monte Carlo of the tracker: trajectories seen through a miscalibrated camera.

Each run is one object on a seeded trajectory (``straight``, ``turning`` or ``stopping``) seen at ``rate_hz``
for ``duration_s``.  The camera's calibration error is drawn **once per run** (the true camera is the nominal
one moved by ``L w``, ``w ~ N(0, I_r)``; every frame of the run sees the same error), the pixel noise (the
budget's imaging and resolution noise and the detector's ``detector_sigma_px``) **every frame**.  The pixels
of the true camera are back-projected with the nominal camera by :class:`~footprint_uq.products.footprints.
FrameProcessor` -- exactly what the service does with a real detector -- and tracked by a
:class:`~footprint_uq.tracking.table.TrackTable` (all runs of a sweep at once: one object per run).

The truth's motion: the scenario's deterministic manoeuvre plus random accelerations drawn from the filter's
own model (continuous white noise of density ``truth_accel_psd_m2ps3``, exact per step); a stopped vehicle stands
still.  :func:`coverage` returns how often the 95 % velocity ellipses, heading intervals and position ellipses
contain the truth.
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from .. import params as P
from ..cameras import general
from ..cameras.lens_domain import lens_domain
from ..cameras.pantilt import PanTiltCamera
from ..errors import InputError
from ..products.footprints import FrameProcessor
from ..uncertainty.budget import load_budget
from .models import ConstantVelocity
from .motion import object_motion
from .table import SharedJacobianAt, TrackerConfig, TrackTable

__all__ = ["SCENARIOS", "Trajectories", "trajectories", "CoverageResult", "coverage", "default_camera", "true_pixels"]

_XM, _YM, _GDZ, _GSX, _GSY = (P.PARAM_NAMES.index(k) for k in ("x_m", "y_m", "ground_dz_m", "ground_slope_x",
                                                                 "ground_slope_y"))
SCENARIOS = ("straight", "turning", "stopping")
#: chi-square 95 % quantile of 2 dof (-2 ln 0.05) and the two-sided normal 95 % factor
CHI2_95_2D = -2.0 * math.log(0.05)
Z95 = 1.959963984540054


class Trajectories(NamedTuple):
    """Truth of R runs over F frames: ``xy_m (F, R, 2)``, ``v_mps (F, R, 2)`` in W, times ``t_s (F,)``."""

    t_s: np.ndarray
    xy_m: np.ndarray
    v_mps: np.ndarray


def default_camera() -> PanTiltCamera:
    """The sweep's camera: 1400 px focal length, full HD, 8 m above the ground, looking north 12 deg down."""
    return PanTiltCamera(1400.0, (1920, 1080), 8.0, 0.0, 12.0)


def trajectories(scenario: str, n_runs: int, rate_hz: float, duration_s: float, rng, *,
                 truth_accel_psd_m2ps3: float = 2.5) -> Trajectories:
    """Seeded truth of ``n_runs`` objects in front of :func:`default_camera` (25-55 m north of it at the start).

    straight: 3-15 m/s in any direction; turning: 6-12 m/s at a turn rate of +-(8-20) deg/s (centripetal
    acceleration up to ~4 m/s^2); stopping: 8-14 m/s braking at 2-4 m/s^2 from a random time in the first
    half, then standing.  Random accelerations of density ``truth_accel_psd_m2ps3`` are added (not while
    standing).
    """
    if scenario not in SCENARIOS:
        raise InputError("scenario", scenario, f"one of {SCENARIOS}")
    n_f = int(round(duration_s * rate_hz)) + 1
    dt = 1.0 / rate_hz
    t = np.arange(n_f) * dt
    R = n_runs
    start = np.column_stack([rng.uniform(-12, 12, R), rng.uniform(25, 55, R)])
    course = rng.uniform(-np.pi, np.pi, R)  # direction of motion, rad counter-clockwise from +x
    speed0 = {"straight": (3, 15), "turning": (6, 12), "stopping": (8, 14)}[scenario]
    speed = rng.uniform(*speed0, R)
    omega = np.zeros(R)
    if scenario == "turning":
        omega = np.deg2rad(rng.uniform(8, 20, R)) * rng.choice([-1.0, 1.0], R)
    decel = rng.uniform(2, 4, R) if scenario == "stopping" else np.zeros(R)
    t_brake = rng.uniform(0, 0.5 * duration_s, R) if scenario == "stopping" else np.full(R, np.inf)
    # deterministic part by fine Euler steps (10 per frame) -> velocity and position at frame times
    xy = np.empty((n_f, R, 2))
    v = np.empty((n_f, R, 2))
    F, Q = ConstantVelocity(max(truth_accel_psd_m2ps3, 1e-300)).matrices(np.full(1, dt))
    # one axis: (position, velocity); a calm truth (density 0) moves at constant velocity
    Lq = np.linalg.cholesky(Q[0][np.ix_([0, 2], [0, 2])]) if truth_accel_psd_m2ps3 > 0 else np.zeros((2, 2))
    pos, spd, ang = start.copy(), speed.copy(), course.copy()
    noise_p, noise_v = np.zeros((R, 2)), np.zeros((R, 2))
    sub = 10
    for k in range(n_f):
        stopped = spd <= 0.0
        xy[k] = pos + noise_p
        v[k] = np.where(stopped[:, None], 0.0, np.column_stack([spd * np.cos(ang), spd * np.sin(ang)]) + noise_v)
        for _ in range(sub):
            h = dt / sub
            tt = t[k]
            braking = tt >= t_brake
            pos = pos + h * np.column_stack([spd * np.cos(ang), spd * np.sin(ang)])
            ang = ang + h * omega
            spd = np.maximum(spd - h * decel * braking, 0.0)
        z = rng.standard_normal((2, R, 2))
        moving = (spd > 0.0)[:, None]
        step_p = noise_p + dt * noise_v + Lq[0, 0] * z[0]
        step_v = noise_v + Lq[1, 0] * z[0] + Lq[1, 1] * z[1]
        noise_p = np.where(moving, step_p, noise_p)
        noise_v = np.where(moving, step_v, 0.0)
    return Trajectories(t, xy, v)


class CoverageResult(NamedTuple):
    """Share of the evaluated (run, frame) pairs whose 95 % region contains the truth, and the counts."""

    velocity: float
    heading: float
    position: float
    n_velocity: int
    n_heading: int
    n_runs: int
    mean_sigma_v_mps: float
    rms_error_v_mps: float


def coverage(scenario: str, rate_hz: float, *, n_runs: int = 500, duration_s: float = 3.0, seed: int = 0,
             budget="basler1@deg", detector_sigma_px: float = 1.5, calibration: str = "consider",
             config: TrackerConfig | None = None, truth_accel_psd_m2ps3: float = 2.5, camera=None) -> CoverageResult:
    """Run the seeded sweep (module doc) and count how often the tracker's 95 % regions hold the truth.

    Every frame from the second detection on is evaluated (velocity: 2-D ellipse, ``chi2 = 5.99``; heading:
    ``+-1.96 sigma`` where its sigma is given; position: the filtered position's ellipse).
    """
    rng = np.random.default_rng(seed)
    camera = camera or default_camera()
    budget = load_budget(budget)
    cfg = config or TrackerConfig()
    cfg = dataclasses.replace(cfg, calibration=calibration)
    tr = trajectories(scenario, n_runs, rate_hz, duration_s, rng, truth_accel_psd_m2ps3=truth_accel_psd_m2ps3)
    proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, shared_jacobian=True,
                          v2x_policy="linear")
    L = budget.param_factor().dense()
    p_true = camera.params + rng.standard_normal((n_runs, L.shape[1])) @ L.T  # one calibration error per run
    det = np.broadcast_to(detector_sigma_px ** 2 * np.eye(2), (n_runs, 2, 2))
    A_px = np.linalg.cholesky(budget.pixel_covariance() + detector_sigma_px ** 2 * np.eye(2))
    table = TrackTable(cfg, rank=L.shape[1], shared_at=SharedJacobianAt(camera, budget))
    ids = list(range(n_runs))
    hits = np.zeros(3)
    counts = np.zeros(3)
    sig_sum = err_sum = 0.0
    for k, t in enumerate(tr.t_s):
        uv = true_pixels(camera, p_true, tr.xy_m[k]) + rng.standard_normal((n_runs, 2)) @ A_px.T
        est = proc.corners(uv[:, None, :], pixel_cov_px2=det)
        out = table.step(t, ids, est.centre_xy_world_m, est.centre_cov_frame_m2, est.centre_shared_m)
        mo = object_motion(out)
        ok = np.isfinite(out.v_mps).all(1)
        if not ok.any():
            continue
        dv = out.v_mps[ok] - tr.v_mps[k, ok]
        d2 = np.einsum("ni,nij,nj->n", dv, np.linalg.inv(out.cov_v_m2ps2[ok]), dv)
        dp = out.xy_m[ok] - tr.xy_m[k, ok]
        p2 = np.einsum("ni,nij,nj->n", dp, np.linalg.inv(out.cov_xy_m2[ok]), dp)
        true_speed = np.hypot(*tr.v_mps[k].T)
        hok = ok & np.isfinite(mo.sigma_heading_deg) & (true_speed > 0)
        true_head = np.rad2deg(np.arctan2(tr.v_mps[k, :, 0], tr.v_mps[k, :, 1]))
        dh = np.mod(mo.heading_deg[hok] - true_head[hok] + 180.0, 360.0) - 180.0
        hits += [np.count_nonzero(d2 <= CHI2_95_2D), np.count_nonzero(np.abs(dh) <= Z95 * mo.sigma_heading_deg[hok]),
                 np.count_nonzero(p2 <= CHI2_95_2D)]
        counts += [ok.sum(), hok.sum(), ok.sum()]
        sig_sum += np.sqrt(np.trace(out.cov_v_m2ps2[ok], axis1=1, axis2=2) / 2).sum()
        err_sum += (dv ** 2).sum() / 2
    cv, ch, cp = (hits / np.maximum(counts, 1)).tolist()
    nv = max(int(counts[0]), 1)
    return CoverageResult(cv, ch, cp, int(counts[0]), int(counts[1]), n_runs, sig_sum / nv, math.sqrt(err_sum / nv))


def true_pixels(camera, p_true: np.ndarray, xy_m: np.ndarray) -> np.ndarray:
    """Pixels ``(R, 2)`` of ground points ``xy_m (R, 2)`` in the true cameras ``p_true (R, 22)`` (each on its own
    ground); NaN where a point lies outside its true lens's valid region (:func:`~footprint_uq.cameras.lens_domain.
    lens_domain` of the drawn distortion: past its fold the polynomial sends a ray from far outside the field of
    view -- a road user 70 deg to the side of the camera -- back into the image, where no real lens images it).

    ``camera`` is the nominal camera (kept for the signature; the true cameras' parameters are ``p_true``)."""
    p = np.asarray(p_true, dtype=np.float64)
    z = p[:, _GDZ] + p[:, _GSX] * (xy_m[:, 0] - p[:, _XM]) + p[:, _GSY] * (xy_m[:, 1] - p[:, _YM])
    xyz = np.column_stack([xy_m, z])
    uv = np.empty((p.shape[0], 2))
    lenses, lens_of = np.unique(p[:, P.DIST_SLICE], axis=0, return_inverse=True)
    for j, dist in enumerate(lenses):  # (one lens per drawn camera: a few per frame)
        sel = lens_of.ravel() == j
        uv[sel] = general.project(p[sel], xyz[sel], domain=lens_domain(dist)).uv_px
    return uv
