"""Seeded campaigns of the motion fit: traffic of a known manoeuvre noise, fitted, then checked by coverage.

A *campaign* is one camera (one draw of its calibration error, shared by all its objects and frames) watching
``n_objects`` road users for ``duration_s`` at ``rate_hz``; the truth moves as the tracker's one-mode model says
(the ``straight`` trajectories of :func:`~footprint_uq.tracking.synthetic.trajectories`: constant velocity plus
white-noise acceleration of density ``q_true``; 0: calm, constant velocity).  Pixels of the true camera with the
per-frame pixel noise are back-projected by the nominal camera (:class:`~footprint_uq.products.footprints.
FrameProcessor`), associated by the tracker (the prior's :class:`~footprint_uq.tracking.table.TrackTable`) and
fed to a :class:`~footprint_uq.tracking.motion_fit.MotionBank`, every campaign as its own class: one pass fits all
campaigns.  A second pass over the same seeded frames tracks each campaign with its fitted model
(:class:`~footprint_uq.tracking.classes.ClassTracks`) and counts how often the 95 % velocity ellipse and heading
interval hold the truth (as :func:`~footprint_uq.tracking.synthetic.coverage`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..products.footprints import FrameProcessor
from ..uncertainty.budget import load_budget
from .classes import ClassTracks, tracker_configs
from .consistency import NisMonitor
from .motion import object_motion
from .motion_fit import MotionBank, MotionGrid, fit_class
from .synthetic import CHI2_95_2D, Z95, default_camera, trajectories, true_pixels
from .table import SharedJacobianAt, TrackerConfig, TrackTable

__all__ = ["CampaignResult", "campaign_frames", "coverage_pass", "run_campaigns", "MonitorRuns", "traffic_frames",
           "monitor_runs"]


class CampaignResult(NamedTuple):
    """Per campaign: the fitted density, its 95 % interval (``ci_hi`` inf: unbounded), whether the truth lies in
    it, the entry's status; the pooled 95 % coverage of velocity and heading after the fit (and before it, with
    the prior tracker), with their counts; and how many campaigns kept the two-mode model."""

    q_true: float
    q_hat: np.ndarray
    ci_lo: np.ndarray
    ci_hi: np.ndarray
    identified: np.ndarray
    within: np.ndarray
    coverage_velocity: float
    coverage_heading: float
    n_velocity: int
    n_heading: int
    prior_coverage_velocity: float
    prior_coverage_heading: float
    n_two_modes: int = 0


def campaign_frames(q_true: float, n_campaigns: int, n_objects: int, *, duration_s: float, rate_hz: float, seed: int,
                    budget="basler1@deg", detector_sigma_px: float = 1.5, camera=None, scenario: str = "straight"):
    """Yield the seeded frames of the campaigns: ``(t_s, ids (R,), classes (R,), xy_m (R, 2), cov_frame_m2
    (R, 2, 2), shared_m (R, 2, r), v_true_mps (R, 2))`` with ``R = n_campaigns * n_objects`` (object ``i`` is in
    campaign ``i // n_objects``, its class the campaign's number as text).  The same seed gives the same frames.
    ``scenario``: the trajectories' (:data:`~footprint_uq.tracking.synthetic.SCENARIOS`; "turning": sustained
    turns, a manoeuvre the one-mode model cannot explain)."""
    rng = np.random.default_rng(seed)
    camera = camera or default_camera()
    budget = load_budget(budget)
    R = n_campaigns * n_objects
    tr = trajectories(scenario, R, rate_hz, duration_s, rng, truth_accel_psd_m2ps3=q_true)
    proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, shared_jacobian=True, v2x_policy="linear")
    L = budget.param_factor().dense()
    p_cam = camera.params + rng.standard_normal((n_campaigns, L.shape[1])) @ L.T  # one calibration error per camera
    p_true = np.repeat(p_cam, n_objects, axis=0)
    det = np.broadcast_to(detector_sigma_px ** 2 * np.eye(2), (R, 2, 2))
    A_px = np.linalg.cholesky(budget.pixel_covariance() + detector_sigma_px ** 2 * np.eye(2))
    ids = list(range(R))
    classes = [str(i // n_objects) for i in range(R)]
    for k, t in enumerate(tr.t_s):
        uv = true_pixels(camera, p_true, tr.xy_m[k]) + rng.standard_normal((R, 2)) @ A_px.T
        est = proc.corners(uv[:, None, :], pixel_cov_px2=det)
        yield (float(t), ids, classes, est.centre_xy_world_m, est.centre_cov_frame_m2, est.centre_shared_m,
               tr.v_mps[k])


def coverage_pass(frames, tracks, hits: np.ndarray, counts: np.ndarray) -> None:
    """Track the frames with ``tracks`` (:class:`ClassTracks`) and add the 95 % velocity / heading hits."""
    for t, ids, classes, xy, cov, B, v_true in frames:
        out = tracks.step(t, ids, classes, xy, cov, B)
        ok = np.isfinite(out.v_mps).all(1)
        if not ok.any():
            continue
        mo = object_motion(out)
        dv = out.v_mps[ok] - v_true[ok]
        d2 = np.einsum("ni,nij,nj->n", dv, np.linalg.inv(out.cov_v_m2ps2[ok]), dv)
        speed = np.hypot(*v_true.T)
        hok = ok & np.isfinite(mo.sigma_heading_deg) & (speed > 0)
        head = np.rad2deg(np.arctan2(v_true[:, 0], v_true[:, 1]))
        dh = np.mod(mo.heading_deg[hok] - head[hok] + 180.0, 360.0) - 180.0
        hits += [np.count_nonzero(d2 <= CHI2_95_2D), np.count_nonzero(np.abs(dh) <= Z95 * mo.sigma_heading_deg[hok])]
        counts += [ok.sum(), hok.sum()]


def run_campaigns(q_true: float, *, n_campaigns: int = 200, n_objects: int = 20, duration_s: float = 5.0,
                  rate_hz: float = 30.0, seed: int = 0, grid: MotionGrid | None = None, budget="basler1@deg",
                  min_tracks: int = 10, min_updates: int = 300, prior_coverage: bool = True,
                  scenario: str = "straight") -> CampaignResult:
    """Fit ``n_campaigns`` seeded campaigns of traffic with manoeuvre noise ``q_true`` (module doc) and check the
    fit: is the truth in each interval, and what do the fitted trackers' 95 % regions cover."""
    grid = grid or MotionGrid()
    camera = default_camera()
    at = SharedJacobianAt(camera, load_budget(budget))
    kw = dict(duration_s=duration_s, rate_hz=rate_hz, seed=seed, budget=budget, camera=camera, scenario=scenario)
    assoc = TrackTable(grid.prior, rank=at.rank, shared_at=at)
    bank = MotionBank.from_grid(grid, rank=at.rank, shared_at=at)
    for t, ids, classes, xy, cov, B, _ in campaign_frames(q_true, n_campaigns, n_objects, **kw):
        bank.observe(t, assoc.step(t, ids, xy, cov, B), classes, xy, cov, B)
    sums, scale = bank.sums(), bank.scale_sigmas()
    entries = [fit_class(grid, sums[str(c)], min_tracks=min_tracks, min_updates=min_updates,
                         scale_sigma_log=scale[str(c)][0]) for c in range(n_campaigns)]
    n_imm = sum(e.get("manoeuvre_accel_psd_m2ps3") is not None for e in entries)
    q_hat = np.array([e["accel_psd_m2ps3"] for e in entries])
    ci = np.array([e.get("accel_psd_ci95_m2ps3", [0.0, None]) for e in entries], dtype=object)
    lo = ci[:, 0].astype(float)
    hi = np.array([math.inf if v is None else v for v in ci[:, 1]], dtype=float)
    ident = np.array([e["status"] == "identified" for e in entries])
    default, per_class = tracker_configs({"classes": {str(c): e for c, e in enumerate(entries)}}, grid.prior)
    hits, counts = np.zeros(2), np.zeros(2)
    coverage_pass(campaign_frames(q_true, n_campaigns, n_objects, **kw),
                   ClassTracks(default, per_class, rank=at.rank, shared_at=at), hits, counts)
    ph, pc = np.zeros(2), np.zeros(2)
    if prior_coverage:
        coverage_pass(campaign_frames(q_true, n_campaigns, n_objects, **kw),
                       ClassTracks(grid.prior, rank=at.rank, shared_at=at), ph, pc)
    cov = hits / np.maximum(counts, 1)
    pcov = ph / np.maximum(pc, 1) if prior_coverage else np.full(2, np.nan)
    return CampaignResult(float(q_true), q_hat, lo, hi, ident, (lo <= q_true) & (q_true <= hi), float(cov[0]),
                          float(cov[1]), int(counts[0]), int(counts[1]), float(pcov[0]), float(pcov[1]), n_imm)



class MonitorRuns(NamedTuple):
    """Per run of :func:`monitor_runs`: the time of the first inconsistent verdict (NaN: none) and its NIS ratio
    (mean NIS / 2) there; the run's last ratio."""

    first_flag_s: np.ndarray
    flag_ratio: np.ndarray
    last_ratio: np.ndarray


def _respawn(sel, rng, x):
    """New road users in slots ``sel``: 25-55 m north of the camera, 3-12 m/s in any direction."""
    n = sel.size
    course, speed = rng.uniform(-np.pi, np.pi, n), rng.uniform(3, 12, n)
    x[sel] = np.column_stack([rng.uniform(-12, 12, n), rng.uniform(25, 55, n), speed * np.cos(course),
                              speed * np.sin(course)])


def traffic_frames(q_before: float, q_after: float, change_s: float, n_runs: int, n_objects: int, *,
                   duration_s: float, rate_hz: float = 30.0, segment_s: float = 4.0, seed: int = 0,
                   budget="basler1@deg", detector_sigma_px: float = 1.5, camera=None):
    """Yield seeded frames of steady traffic: ``n_runs`` cameras (one calibration draw each) of ``n_objects``
    slots; every ``segment_s`` a slot's road user leaves and a new one (a new id) enters.  Motion: constant
    velocity plus white-noise acceleration of density ``q_before`` until ``change_s``, ``q_after`` from then on.
    Frames as :func:`campaign_frames` (``classes``: the run's number)."""
    rng = np.random.default_rng(seed)
    camera = camera or default_camera()
    budget = load_budget(budget)
    S = n_runs * n_objects
    proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, shared_jacobian=True, v2x_policy="linear")
    L = budget.param_factor().dense()
    p_true = np.repeat(camera.params + rng.standard_normal((n_runs, L.shape[1])) @ L.T, n_objects, axis=0)
    det = np.broadcast_to(detector_sigma_px ** 2 * np.eye(2), (S, 2, 2))
    A_px = np.linalg.cholesky(budget.pixel_covariance() + detector_sigma_px ** 2 * np.eye(2))
    dt = 1.0 / rate_hz
    x = np.empty((S, 4))
    _respawn(np.arange(S), rng, x)
    born = -rng.uniform(0, segment_s, S)  # staggered: the traffic is steady from the start
    ids = np.arange(S)
    next_id = S
    classes = [str(i // n_objects) for i in range(S)]
    for k in range(int(round(duration_s * rate_hz)) + 1):
        t = k * dt
        old = np.flatnonzero(t - born >= segment_s)
        if old.size:
            _respawn(old, rng, x)
            born[old] = t
            ids[old] = np.arange(next_id, next_id + old.size)
            next_id += old.size
        uv = true_pixels(camera, p_true, x[:, :2]) + rng.standard_normal((S, 2)) @ A_px.T
        est = proc.corners(uv[:, None, :], pixel_cov_px2=det)
        yield t, ids.tolist(), classes, est.centre_xy_world_m, est.centre_cov_frame_m2, est.centre_shared_m, x[:, 2:]
        q = q_before if t < change_s else q_after
        Lq = math.sqrt(q) * np.array([[dt ** 1.5 / math.sqrt(3.0), 0.0], [dt ** 0.5 * math.sqrt(3.0) / 2.0,
                                                                          dt ** 0.5 / 2.0]])
        z = rng.standard_normal((2, S, 2))  # (exact: the Cholesky factor of q [[dt^3/3, dt^2/2], [dt^2/2, dt]])
        x[:, :2] += dt * x[:, 2:] + Lq[0, 0] * z[0]
        x[:, 2:] += Lq[1, 0] * z[0] + Lq[1, 1] * z[1]


def monitor_runs(q_before: float, q_after: float, *, change_s: float, n_runs: int = 100, n_objects: int = 20,
                 duration_s: float = 60.0, config: TrackerConfig | None = None, window_s: float = 30.0,
                 seed: int = 0, budget="basler1@deg", check_every_s: float = 1.0, **monitor) -> MonitorRuns:
    """Run the on-line NIS check (:class:`~footprint_uq.tracking.consistency.NisMonitor`) on ``n_runs`` seeded runs
    of :func:`traffic_frames` tracked with ``config`` (default: one mode at ``q_before``), checking once per
    ``check_every_s`` as the service's health record does; when does it first flag each run?"""
    cfg = config or TrackerConfig(accel_psd_m2ps3=max(q_before, 1e-3), manoeuvre_accel_psd_m2ps3=None)
    camera = default_camera()
    at = SharedJacobianAt(camera, load_budget(budget))
    tracks = [ClassTracks(cfg, rank=at.rank, shared_at=at) for _ in range(n_runs)]
    mons = [NisMonitor(t, window_s=window_s, **monitor) for t in tracks]
    first, ratio_at, last = np.full(n_runs, np.nan), np.full(n_runs, np.nan), np.full(n_runs, np.nan)
    next_check = check_every_s
    for t, ids, classes, xy, cov, B, _ in traffic_frames(q_before, q_after, change_s, n_runs, n_objects,
                                                         duration_s=duration_s, seed=seed, budget=budget,
                                                         camera=camera):
        for r in range(n_runs):
            sl = slice(r * n_objects, (r + 1) * n_objects)
            out = tracks[r].step(t, ids[sl], classes[sl], xy[sl], cov[sl], B[sl])
            mons[r].observe(t, out, classes[sl], xy[sl], cov[sl], B[sl])
        if t + 1e-9 < next_check:
            continue
        next_check += check_every_s
        for r in range(n_runs):
            rec = mons[r].status().get(str(r))
            if rec is None or rec["nis_ratio"] is None:
                continue
            last[r] = rec["nis_ratio"]
            if rec["consistent"] is False and np.isnan(first[r]):
                first[r], ratio_at[r] = t, rec["nis_ratio"]
    return MonitorRuns(first, ratio_at, last)
