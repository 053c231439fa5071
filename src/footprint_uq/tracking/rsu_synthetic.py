"""Seeded Monte Carlo of the roadside unit's fusion: three cameras over a signalised intersection.

The geometry is the case study's (:mod:`footprint_uq.scenario.intersection` defaults: two roads crossing at the
origin, two 3.5 m lanes per direction, right-hand traffic) without importing it (the tracker's layer is below
``scenario/``): the eight straight-through lanes run 50 m each side of the centre.  A two-phase signal lets the
north-south lanes and the east-west lanes drive in turn (``phase_s`` each; vehicles enter during the first 40 % of
their phase, so crossing streams never meet in the box).  Vehicles enter a lane at random headways (>= 2.5 s) at
the lane's speed for that phase (+-0.4 m/s each) with random longitudinal accelerations of density
``truth_accel_psd_m2ps3``.

Three roadside cameras see it (:func:`intersection_cameras`; the case study's two and a third on the south-west
corner looking north-east), each with its own calibration error drawn once per run from the budget and its own
clock offset (drawn once per run, ``N(0, clock_offset_sigma_s^2)``: the camera stamps its frames ``t + offset``).
Per frame, a vehicle whose centre the true camera images inside the picture within ``max_range_m`` is detected
with the budget's pixel noise plus ``detector_sigma_px``, back-projected by the nominal camera
(:class:`~footprint_uq.products.footprints.FrameProcessor`), tracked by the camera's
:class:`~footprint_uq.tracking.table.TrackTable` (the truth's id as ``object_id``) and handed to one
:class:`~footprint_uq.tracking.rsu_fusion.RsuFusion`; after the three cameras, the unit's list at the true time
``t`` is compared with the truth (:class:`RsuSimResult`).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from .. import params as P
from ..cameras import general
from ..cameras.pantilt import PanTiltCamera
from ..products.footprints import FrameProcessor
from ..uncertainty.budget import load_budget
from .rsu_fusion import RsuFusion, RsuFusionConfig
from .synthetic import CHI2_95_2D
from .table import SharedJacobianAt, TrackerConfig, TrackOutput, TrackTable

__all__ = ["intersection_cameras", "LANES", "RsuSimResult", "simulate", "coverage_sweep", "camera_frames",
           "CameraFrame", "UnitFrame", "evaluate", "score_positions", "GHOST_RADIUS_M"]

_XM, _YM, _GDZ, _GSX, _GSY = (P.PARAM_NAMES.index(k) for k in ("x_m", "y_m", "ground_dz_m", "ground_slope_x",
                                                                 "ground_slope_y"))
_HALF_M = 7.0  # half the paved width: 2 lanes x 3.5 m
#: the eight straight-through lanes: (a point on the centre line, the unit travel direction, phase 0 or 1)
LANES = tuple(
    (np.array(p, dtype=float), np.array(d, dtype=float), ph) for p, d, ph in (
        ((1.75, 0.0), (0.0, 1.0), 0), ((5.25, 0.0), (0.0, 1.0), 0),        # northbound (east of the centre line)
        ((-1.75, 0.0), (0.0, -1.0), 0), ((-5.25, 0.0), (0.0, -1.0), 0),    # southbound
        ((0.0, -1.75), (1.0, 0.0), 1), ((0.0, -5.25), (1.0, 0.0), 1),      # eastbound (south of the centre line)
        ((0.0, 1.75), (-1.0, 0.0), 1), ((0.0, 5.25), (-1.0, 0.0), 1)))     # westbound
_LANE_HALF_LENGTH_M = 50.0
#: a reported object farther than this from every true road user is a ghost (:func:`score_positions`), m
GHOST_RADIUS_M = 3.0


def intersection_cameras() -> list[PanTiltCamera]:
    """Three 1920x1080 roadside cameras, 2 m back from the corners of the box: north-east (8 m, looking south-west,
    80 deg), on the north arm 12 m further (10 m, pan 190 deg, 90 deg) and south-west (8 m, looking north-east,
    80 deg); tilted 20 deg down (the case study's first two and a third across from them)."""
    c = _HALF_M + 2.0
    out = []
    for pos, h, pan, hfov in (((c, c), 8.0, 225.0, 80.0), ((-c, c + 12.0), 10.0, 190.0, 90.0),
                              ((-c, -c), 8.0, 45.0, 80.0)):
        f = 1920 / (2.0 * math.tan(math.radians(hfov) / 2.0))
        out.append(PanTiltCamera(f, (1920, 1080), h, pan, 20.0, position_m=pos, principal_point_px=(960, 540)))
    return out


@dataclass
class RsuSimResult:
    """Counts of a run (or of several, :meth:`add`).

    n_frames                   unit frames (all cameras' frames at one time, then the list)
    n_truth_frames             (frame, vehicle) pairs with the vehicle fused from at least one camera's track
    n_duplicates               of those, a vehicle in more than one fused object
    n_missing                  a vehicle detected by a camera this frame and in no fused object
    n_mixed                    (frame, fused object) pairs holding tracks of more than one vehicle
    n_cover, n_cover_hits      fused objects (one vehicle, every contribution with a velocity) evaluated / whose
                               95 % position ellipse holds the truth at ``t``
    n_multi, n_multi_hits      the same for objects fused from 2 or more cameras
    n_camera, n_camera_hits    the cameras' own predicted estimates of the same objects (the baseline)
    n_larger                   multi-camera objects whose fused covariance exceeds a camera's (Loewner order)
    max_objects                most fused objects in one frame
    """

    n_frames: int = 0
    n_truth_frames: int = 0
    n_duplicates: int = 0
    n_missing: int = 0
    n_mixed: int = 0
    n_cover: int = 0
    n_cover_hits: int = 0
    n_multi: int = 0
    n_multi_hits: int = 0
    n_camera: int = 0
    n_camera_hits: int = 0
    n_larger: int = 0
    max_objects: int = 0
    fusion_counts: dict = field(default_factory=dict)

    def add(self, other: RsuSimResult) -> RsuSimResult:
        for k, v in vars(other).items():
            if k == "max_objects":
                self.max_objects = max(self.max_objects, v)
            elif k == "fusion_counts":
                for kk, vv in v.items():
                    self.fusion_counts[kk] = self.fusion_counts.get(kk, 0) + vv
            else:
                setattr(self, k, getattr(self, k) + v)
        return self

    @property
    def coverage(self) -> float:
        return self.n_cover_hits / max(self.n_cover, 1)

    @property
    def coverage_multi(self) -> float:
        return self.n_multi_hits / max(self.n_multi, 1)

    @property
    def coverage_camera(self) -> float:
        return self.n_camera_hits / max(self.n_camera, 1)


def _traffic(n_frames: int, rate_hz: float, phase_s: float, accel_psd: float, rng):
    """Truth: ``xy (F, V, 2)`` (NaN off the lanes) of V vehicles over F frames at ``rate_hz``."""
    dt = 1.0 / rate_hz
    duration = n_frames * dt
    starts, lanes, speeds = [], [], []
    n_cycles = int(duration // (2 * phase_s)) + 1
    for li, (_, _, ph) in enumerate(LANES):
        for cyc in range(n_cycles):
            lane_speed = rng.uniform(8.0, 12.0)
            t0 = (2 * cyc + ph) * phase_s + rng.uniform(0.0, 2.0)
            while t0 < (2 * cyc + ph + 0.4) * phase_s:
                starts.append(t0)
                lanes.append(li)
                speeds.append(lane_speed + rng.uniform(-0.4, 0.4))
                t0 += 2.5 + rng.exponential(2.0)
    V = len(starts)
    t = np.arange(n_frames) * dt
    s = np.full((n_frames, V), np.nan)  # distance along the lane from its entry, m
    pert = np.zeros(V)
    pv = np.zeros(V)
    q = accel_psd
    for k in range(n_frames):
        tau = t[k] - np.asarray(starts)
        s[k] = np.where(tau >= 0, np.asarray(speeds) * np.maximum(tau, 0) + pert, np.nan)
        z = rng.standard_normal((2, V))
        pert = pert + dt * pv + math.sqrt(q * dt ** 3 / 12.0) * z[0]  # (exact CV noise, approximately)
        pv = pv + math.sqrt(q * dt) * z[1]
    s[s > 2 * _LANE_HALF_LENGTH_M] = np.nan
    xy = np.full((n_frames, V, 2), np.nan)
    for v in range(V):
        p, d, _ = LANES[lanes[v]]
        xy[:, v] = p - _LANE_HALF_LENGTH_M * d + s[:, v, None] * d
    return t, xy


@dataclass
class _Camera:
    camera: PanTiltCamera
    p_true: np.ndarray
    offset_s: float
    proc: FrameProcessor
    table: TrackTable
    track_truth: dict = field(default_factory=dict)


def _detect(cam: _Camera, xy: np.ndarray, A_px: np.ndarray, max_range_m: float, rng):
    """Pixels of the vehicles the true camera sees this frame (indices, (n, 2))."""
    live = np.flatnonzero(np.isfinite(xy).all(1))
    if live.size == 0:
        return live, np.zeros((0, 2))
    p = cam.p_true
    rel = xy[live] - p[[_XM, _YM]]
    z = p[_GDZ] + rel @ p[[_GSX, _GSY]]  # on the true camera's ground
    pr = general.project(p, np.column_stack([xy[live], z]), domain=cam.camera.lens_domain)
    w, h = cam.camera.image_size_px
    uv = pr.uv_px + rng.standard_normal((live.size, 2)) @ A_px.T
    pan = math.radians(cam.camera.pan_deg)
    fwd = rel @ np.array([math.sin(pan), math.cos(pan)])
    side = rel @ np.array([math.cos(pan), -math.sin(pan)])
    # inside the horizontal field of view (a point behind the camera, or far off its axis where the drawn
    # distortion folds back, can project into the picture too)
    ahead = (fwd > 0.0) & (np.abs(side) < fwd * (0.5 * w / cam.camera.focal_px))
    ok = (pr.valid & ahead & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
          & (np.hypot(*rel.T) <= max_range_m))
    return live[ok], uv[ok]


class CameraFrame(NamedTuple):
    """One camera's frame of a run: the camera's index, its stamp (its own clock: ``t + offset``, s), its
    :class:`~footprint_uq.tracking.table.TrackTable` output and the truth index of every row."""

    camera: int
    stamp_s: float
    tracks: TrackOutput
    truth_index: np.ndarray


class UnitFrame(NamedTuple):
    """One unit frame: its number, the true time ``t_s`` (s from the run's start), the truth ``(V, 2)`` (NaN: not
    on the road), the cameras' frames, and per camera the map track id -> truth index (live, updated per frame)."""

    k: int
    t_s: float
    truth_xy: np.ndarray
    cameras: list
    track_truth: list


def camera_frames(n_frames: int = 300, *, rate_hz: float = 10.0, seed: int = 0, budget="basler1@deg",
                  detector_sigma_px: float = 1.5, clock_offset_sigma_s: float = 0.005, phase_s: float = 20.0,
                  max_range_m: float = 60.0, truth_accel_psd_m2ps3: float = 1.0,
                  tracker: TrackerConfig | None = None, relabel_rate: float = 0.0) -> Iterator[UnitFrame]:
    """The run's unit frames, one after the other (module doc): the three cameras' tracked frames of every true
    time, for any fusion (:func:`simulate` feeds an :class:`~.rsu_fusion.RsuFusion`; the CP service's proof feeds
    a :class:`~footprint_uq.service.cp_service.CpBasicService`).

    ``relabel_rate``: the probability per camera, vehicle and frame that the camera's detector gives the vehicle a
    new ``object_id`` (its track restarts under a new track id: track churn; drawn from a stream of its own, so that
    0 leaves every other draw of the run as it was)."""
    rng = np.random.default_rng(seed)
    churn = np.random.default_rng([seed, 32])
    budget = load_budget(budget)
    t, truth = _traffic(n_frames, rate_hz, phase_s, truth_accel_psd_m2ps3, rng)
    L = budget.param_factor().dense()
    det = detector_sigma_px ** 2 * np.eye(2)
    A_px = np.linalg.cholesky(budget.pixel_covariance() + det)
    cams = []
    for camera in intersection_cameras():
        proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, shared_jacobian=True,
                              v2x_policy="linear")
        table = TrackTable(tracker, rank=L.shape[1], shared_at=SharedJacobianAt(camera, budget))
        p_true = camera.params + L @ rng.standard_normal(L.shape[1])
        cams.append(_Camera(camera, p_true, float(rng.normal(0.0, clock_offset_sigma_s)), proc, table))
    n_veh = truth.shape[1]
    label = np.zeros((len(cams), n_veh), np.int64)  # each camera's detector's label generation per vehicle
    for k in range(n_frames):
        frames = []
        for j, cam in enumerate(cams):
            idx, uv = _detect(cam, truth[k], A_px, max_range_m, rng)
            est = cam.proc.corners(uv[:, None, :], pixel_cov_px2=np.broadcast_to(det, (idx.size, 2, 2)))
            stamp = t[k] + cam.offset_s
            if relabel_rate > 0.0:
                label[j] += churn.random(n_veh) < relabel_rate
            out = cam.table.step(stamp, (idx + n_veh * label[j, idx]).astype(np.int64), est.centre_xy_world_m,
                                 est.centre_cov_frame_m2, est.centre_shared_m)
            for i, tid in zip(idx.tolist(), out.track_id.tolist(), strict=True):
                cam.track_truth[tid] = i
            frames.append(CameraFrame(j, stamp, out, idx))
        yield UnitFrame(k, float(t[k]), truth[k], frames, [c.track_truth for c in cams])


def simulate(n_frames: int = 300, *, rate_hz: float = 10.0, seed: int = 0, budget="basler1@deg",
             detector_sigma_px: float = 1.5, clock_offset_sigma_s: float = 0.005, phase_s: float = 20.0,
             max_range_m: float = 60.0, truth_accel_psd_m2ps3: float = 1.0, config: RsuFusionConfig | None = None,
             tracker: TrackerConfig | None = None, warmup_frames: int = 0) -> RsuSimResult:
    """One seeded run (module doc); frames before ``warmup_frames`` are run but not counted."""
    fusion = RsuFusion(config)
    for j in range(len(intersection_cameras())):
        fusion.add_camera(j, j + 1, clock_offset_sigma_s=clock_offset_sigma_s)
    res = RsuSimResult()
    for fr in camera_frames(n_frames, rate_hz=rate_hz, seed=seed, budget=budget, detector_sigma_px=detector_sigma_px,
                            clock_offset_sigma_s=clock_offset_sigma_s, phase_s=phase_s, max_range_m=max_range_m,
                            truth_accel_psd_m2ps3=truth_accel_psd_m2ps3, tracker=tracker):
        seen = set()
        for cf in fr.cameras:
            ff = fusion.step_tracks(cf.camera, cf.stamp_s, cf.tracks, ["vehicle"] * cf.truth_index.size)
            seen.update(cf.truth_index[ff.object_id >= 0].tolist())
        if fr.k >= warmup_frames:
            objs = fusion.objects(fr.t_s)
            res.add(evaluate(fusion.pairs(), fr.track_truth, objs.object_id, objs.xy_m, objs.cov_xy_m2, objs.v_mps,
                             fr.truth_xy, seen, lambda oid, _t=fr.t_s: fusion.contributions(oid, _t)))
    res.fusion_counts = {**fusion.counts, "merged": fusion.n_merged, "unstuck": fusion.n_unstuck}
    return res


def evaluate(pairs: dict, track_truth: list, object_id, xy_m, cov_xy_m2, v_mps, truth_xy: np.ndarray, seen: set,
             contributions=None) -> RsuSimResult:
    """One unit frame's counts (:class:`RsuSimResult`) of a fused list against the truth.

    Parameters
    ----------
    pairs : dict
        ``(camera index, track id) -> objectId`` of the live contributions (:meth:`RsuFusion.pairs`).
    track_truth : list of dict
        Per camera, track id -> truth index (:attr:`UnitFrame.track_truth`).
    object_id : (m,), xy_m : (m, 2), cov_xy_m2 : (m, 2, 2), v_mps : (m, 2)
        The fused list at the truth's time (m, m^2, m/s; W).
    truth_xy : (V, 2)
        The truth at that time.
    seen : set
        Truth indices some camera's row was fused for this frame.
    contributions : callable, optional
        ``objectId -> (camera ids, xs (k, 2), Ps (k, 2, 2))`` at that time (:meth:`RsuFusion.contributions`): the
        cameras' own estimates (the baseline, and the Loewner check); None: not evaluated.
    """
    r = RsuSimResult(n_frames=1)
    oids = np.asarray(object_id).tolist()
    reported = set(oids)
    members: dict = {}
    for (cid, tid), oid in pairs.items():
        if oid in reported:  # (an object not in the list -- no fresh contribution -- is not sent)
            members.setdefault(oid, set()).add(track_truth[cid][tid])
    r.max_objects = len(oids)
    where: dict = {}
    for oid, vs in members.items():
        for v in vs:
            where.setdefault(v, []).append(oid)
        r.n_mixed += len(vs) > 1
    r.n_truth_frames = len(where)
    r.n_duplicates = sum(len(o) > 1 for o in where.values())
    r.n_missing = len(seen - set(where))
    for k, oid in enumerate(oids):
        vs = members.get(oid, set())
        if len(vs) != 1 or not np.isfinite(v_mps[k]).all():
            continue
        truth = truth_xy[next(iter(vs))]
        if not np.isfinite(truth).all():
            continue
        hit = _inside(xy_m[k], cov_xy_m2[k], truth)
        r.n_cover += 1
        r.n_cover_hits += hit
        if contributions is None:
            continue
        _, xs, Ps = contributions(oid)
        for xc, Pc in zip(xs, Ps, strict=True):
            r.n_camera += 1
            r.n_camera_hits += _inside(xc, Pc, truth)
        if len(xs) > 1:
            r.n_multi += 1
            r.n_multi_hits += hit
            scale = np.abs(Ps).max()
            r.n_larger += any(np.linalg.eigvalsh(Pc - cov_xy_m2[k]).min() < -1e-9 * scale for Pc in Ps)
    return r


def score_positions(xy_m, truth_xy, radius_m: float = GHOST_RADIUS_M) -> tuple[int, int]:
    """Ghosts and duplicates of one reported list by position alone (what a receiver sees).

    The reported objects are matched one-to-one to the road users within ``radius_m`` (the assignment of least
    total distance, :func:`scipy.optimize.linear_sum_assignment`): two road users close together are two matches,
    not a duplicate.

    Parameters
    ----------
    xy_m : (m, 2)
        The reported objects' positions (m, W).
    truth_xy : (V, 2)
        The true road users at the same time (m, W; NaN rows: not on the road, ignored).
    radius_m : float
        The matching radius (m).

    Returns
    -------
    ghosts : int
        Reported objects farther than ``radius_m`` from every road user.
    duplicates : int
        Road users with a second reported object: the nearest road user of each object left unmatched within
        ``radius_m`` (counted once per road user).
    """
    xy = np.asarray(xy_m, np.float64).reshape(-1, 2)
    truth = np.asarray(truth_xy, np.float64).reshape(-1, 2)
    truth = truth[np.isfinite(truth).all(1)]
    if xy.shape[0] == 0:
        return 0, 0
    if truth.shape[0] == 0:
        return xy.shape[0], 0
    dist = np.hypot(*(xy[:, None, :] - truth[None]).transpose(2, 0, 1))  # (m, V)
    near = dist.min(1) <= radius_m
    rows, cols = linear_sum_assignment(np.where(dist <= radius_m, dist, 1e9))
    matched = np.zeros(xy.shape[0], bool)
    matched[rows[dist[rows, cols] <= radius_m]] = True
    extra = near & ~matched
    return int((~near).sum()), len(set(dist[extra].argmin(1).tolist()))


def _inside(x, P, truth) -> bool:
    d = truth - x
    return bool(d @ np.linalg.solve(P, d) <= CHI2_95_2D)


def coverage_sweep(n_runs: int, n_frames: int, *, seed: int = 0, **kw) -> RsuSimResult:
    """``n_runs`` independent runs (each its own calibration draws and clock offsets), counts summed."""
    total = RsuSimResult()
    for r in range(n_runs):
        total.add(simulate(n_frames, seed=seed + r, **kw))
    return total
