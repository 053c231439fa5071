"""One object list per roadside unit: the per-camera tracks of several cameras fused into one list of objects.

Each camera runs its own :class:`~footprint_uq.tracking.table.TrackTable` (a Schmidt-Kalman filter with the
camera's calibration error as a consider state).  :class:`RsuFusion` takes, per camera frame, that camera's tracked
objects (track ids, time, position / velocity and their covariances, class) and keeps ONE list for the unit
(docs/rsu-fusion.md, "One object list per roadside unit"):

**Association** (per camera frame, in two steps).  A (camera, track id) pair that is already part of a fused object
stays in it (*sticky*) while its position passes the *leave gate* (chi-square, 2 dof, ``leave_confidence`` 99.9 %:
13.8; wider than the joining gate: hysteresis) against the object's estimate from the *other* cameras (predicted to
the frame's time); once that gate is broken in ``unstick_frames`` consecutive frames of that camera the pair leaves
the object and is associated afresh.  Every other row (a new pair, a pair that left, a pair whose
object no other camera sees) is associated by one globally optimal assignment per frame
(:func:`scipy.optimize.linear_sum_assignment` on the squared Mahalanobis distances): cost
``d^2 = (x_c - x_o)^T (P_c + P_o)^-1 (x_c - x_o)`` between the row and the object's estimate from the other cameras,
infeasible above the gate (chi-square, 2 dof, ``gate_confidence`` 99 %: 9.21).  A fused object is a candidate for a
row of camera c only if no other row of c in this frame is in it (never two tracks of one camera on one object);
an object that only camera c's *lapsed* track holds (a track not in this frame: it ended or restarted) is a
candidate too, against that member's own prediction: a camera's new track takes over its old one's object.
A row that matches no object starts one; when a row's object has no other camera's fresh contribution and the
row matches another object, the two merge (the older ``objectId`` survives; a camera in both keeps its newer
member).
``P_c + P_o`` is the difference's covariance because the two estimates come from cameras with independent
calibration errors (and independent pixel noise).

**Fresh and stale contributions.**  A camera's contribution is *fresh* while its track was updated within
``report_timeout_s`` (0.3 s); :meth:`RsuFusion.objects` reports an object only while one of its contributions is
fresh and fuses only those; the stale ones stay, until ``member_timeout_s`` (1 s), for re-association only (a
track that comes back, another camera's track of the same road user).

**Fused estimate** (:meth:`RsuFusion.objects`).  Each camera's latest fresh estimate of the object is predicted to the
asked time at constant velocity (:func:`~footprint_uq.uncertainty.timing.predict_position`, with the camera's clock
term ``sigma_t^2 (v v^T + P_v)`` and the acceleration noise ``q tau^3 / 3``), then fused in information form,
``P = (sum_c P_c^-1)^-1``, ``x = P sum_c P_c^-1 x_c`` (position and velocity separately: the tracker reports no
position-velocity cross-covariance).  A camera's calibration error is shared by all its objects and is part of every
``P_c`` (the tracker's consider state); it is independent between cameras, so the information form is exact for it.
Neglected: the *common process noise* (the truth's own random accelerations enter every camera's filter error in
the same direction, Bar-Shalom and Campo 1986) and the position-velocity cross-covariance in the prediction.  The
``method="ci"`` option (covariance intersection, weights ``1 / trace P_c``: consistent for any unknown correlation,
larger) is kept for comparison; the Monte Carlo of :mod:`.rsu_synthetic` decides the default (docs/rsu-fusion.md).
The information form's fused covariance is no larger than any camera's predicted one (``P^-1 = sum_c P_c^-1 >=
P_c^-1`` in the Loewner order); covariance intersection does not promise that.

**Identity.**  ``objectId`` is 16-bit (0..65535), handed out in order and reused only after its object ended (all
its cameras' contributions timed out, ``member_timeout_s``), oldest freed first.  ``sensorIdList``: the sensor ids
of the cameras whose contribution is fresh.  ``objectAge``: from the first detection of any camera (the earliest
``time - age_s`` of the tracks that joined the object).

**Clocks.**  Per camera ``clock_offset_sigma_s`` (and ``clock_jitter_sigma_s``) enter every prediction as above.
A camera frame earlier than that camera's previous frame is that frame's error (:attr:`FrameFusion.status`
``"clock_backwards"``, nothing fused, every track kept); a frame older than the unit's latest fused time is *late
data*: fused (its estimates are predicted like any other, status ``"late"``) when at most ``max_lateness_s`` old,
else counted as dropped (status ``"dropped_late"``); never reordered.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.optimize import linear_sum_assignment

from .._checks import as_float, as_int
from ..errors import InputError
from ..uncertainty.timing import clock_sigma_s, predict_position

__all__ = ["RsuFusionConfig", "RsuFusion", "FrameFusion", "FusedObjects", "FUSION_METHODS", "MAX_OBJECT_ID",
           "gate_chi2"]

#: ``objectId`` is an ``Identifier2B`` (0..65535)
MAX_OBJECT_ID = 65535
#: how the cameras' estimates are combined: information form (independent errors) or covariance intersection
FUSION_METHODS = ("information", "ci")
_BIG = 1e12


def gate_chi2(confidence: float) -> float:
    """The chi-square quantile of 2 degrees of freedom at ``confidence`` (``-2 ln(1 - p)``; 0.99 -> 9.21)."""
    p = as_float("gate_confidence", confidence)
    if not 0.0 < p < 1.0:
        raise InputError("gate_confidence", confidence, "a probability in (0, 1), e.g. 0.99")
    return -2.0 * math.log1p(-p)


@dataclass(frozen=True)
class RsuFusionConfig:
    """Options of :class:`RsuFusion` (module doc).

    gate_confidence : float           chi-square (2 dof) level of the association gate (0.99: d^2 <= 9.21)
    leave_confidence : float          chi-square level a sticky pair must break (``unstick_frames`` times running)
                                      to leave its object (0.999: d^2 > 13.8; >= ``gate_confidence``: hysteresis)
    unstick_frames : int              consecutive frames of a camera with the gate broken before its pair leaves
                                      its fused object
    member_timeout_s : float          a camera's contribution not updated for this long leaves the object (s)
    report_timeout_s : float          a contribution is *fresh* while its camera's track was updated within this
                                      (s, <= ``member_timeout_s``); :meth:`RsuFusion.objects` reports an object
                                      only while one is, and fuses only the fresh ones (the stale ones stay, until
                                      ``member_timeout_s``, for re-association only)
    max_lateness_s : float            a frame older than the unit's latest fused time by more is dropped (s)
    accel_psd_m2ps3 : float           acceleration noise of the prediction to a common time (m^2/s^3)
    unknown_velocity_sigma_mps : float  sigma per axis of the velocity of a track's first detection (no velocity
                                      yet), for its prediction (m/s)
    method : {"information", "ci"}    :data:`FUSION_METHODS`
    """

    gate_confidence: float = 0.99
    leave_confidence: float = 0.999
    unstick_frames: int = 3
    member_timeout_s: float = 1.0
    report_timeout_s: float = 0.3
    max_lateness_s: float = 0.5
    accel_psd_m2ps3: float = 30.0
    unknown_velocity_sigma_mps: float = 15.0
    method: str = "information"

    def __post_init__(self):
        object.__setattr__(self, "gate_confidence", as_float("gate_confidence", self.gate_confidence))
        gate_chi2(self.gate_confidence)
        object.__setattr__(self, "leave_confidence", as_float("leave_confidence", self.leave_confidence))
        if not self.gate_confidence <= self.leave_confidence < 1.0:
            raise InputError("leave_confidence", self.leave_confidence,
                             f"a probability in [gate_confidence ({self.gate_confidence}), 1)")
        object.__setattr__(self, "unstick_frames", as_int("unstick_frames", self.unstick_frames, minimum=1,
                                                                   expected="an integer >= 1"))
        for name in ("member_timeout_s", "report_timeout_s", "accel_psd_m2ps3", "unknown_velocity_sigma_mps"):
            object.__setattr__(self, name, as_float(name, getattr(self, name), positive=True))
        if self.report_timeout_s > self.member_timeout_s:
            raise InputError("report_timeout_s", self.report_timeout_s,
                             f"at most member_timeout_s ({self.member_timeout_s} s)")
        object.__setattr__(self, "max_lateness_s", as_float("max_lateness_s", self.max_lateness_s,
                                                            nonnegative=True))
        if self.method not in FUSION_METHODS:
            raise InputError("method", self.method, f"one of {FUSION_METHODS}")


class FrameFusion(NamedTuple):
    """What one camera frame did (n rows, the frame's order).

    object_id : (n,) int64     the fused ``objectId`` of each row (-1: not fused, see ``rejected``)
    status : str               "ok", "late" (fused as late data), "dropped_late" or "clock_backwards"
    error : str or None        the frame's one-line error ("clock_backwards", "dropped_late")
    rejected : list of (int, str)  rows not fused: (index, reason)
    """

    object_id: np.ndarray
    status: str
    error: str | None
    rejected: list


class FusedObjects(NamedTuple):
    """The unit's object list at ``time_s`` (m objects, ordered by ``object_id``).

    object_id : (m,) int64                  16-bit ``objectId``
    xy_m : (m, 2), cov_xy_m2 : (m, 2, 2)    fused position in W (m) and its covariance (m^2) at ``time_s``
    v_mps : (m, 2), cov_v_m2ps2 : (m, 2, 2) fused velocity (m/s; NaN if no camera has one yet) and covariance
    age_s : (m,)                            ``objectAge``: since the first detection of any camera (s)
    sensor_ids : list of m tuples           ``sensorIdList``: the contributing cameras' sensor ids, sorted
    class_id : list of m                    the class of the most recently updated contribution
    n_sources : (m,) int64                  cameras fused
    time_s : float
    last_time_s : (m,)                      the newest frame time of any live contribution (the object's latest
                                            measurement, s)
    """

    object_id: np.ndarray
    xy_m: np.ndarray
    cov_xy_m2: np.ndarray
    v_mps: np.ndarray
    cov_v_m2ps2: np.ndarray
    age_s: np.ndarray
    sensor_ids: list
    class_id: list
    n_sources: np.ndarray
    time_s: float
    last_time_s: np.ndarray | None = None


@dataclass
class _Camera:
    sensor_id: int
    sigma_t_s: float
    last_time_s: float = -math.inf


@dataclass
class _Member:
    """One camera's latest estimate of a fused object.

    ``state`` (12,): position (m), its covariance (m^2, row-major), velocity (m/s), its covariance (m^2/s^2) -- a
    row of its frame's block (:func:`_state_block`), so that :meth:`RsuFusion._contributions` stacks every member
    with one ``np.array`` call.
    """

    track_id: int
    time_s: float
    state: np.ndarray
    class_id: object
    misses: int = 0

    @property
    def xy_m(self) -> np.ndarray:
        return self.state[0:2]

    @property
    def cov_xy_m2(self) -> np.ndarray:
        return self.state[2:6].reshape(2, 2)

    @property
    def v_mps(self) -> np.ndarray:
        return self.state[6:8]

    @property
    def cov_v_m2ps2(self) -> np.ndarray:
        return self.state[8:12].reshape(2, 2)


def _state_block(xy, P, v, Pv) -> np.ndarray:
    """A frame's rows as :attr:`_Member.state` ``(n, 12)`` (a new array: the members never alias the caller's)."""
    n = xy.shape[0]
    return np.concatenate([xy, P.reshape(n, 4), v, Pv.reshape(n, 4)], axis=1)


@dataclass
class _Object:
    first_time_s: float
    members: dict = field(default_factory=dict)  # camera id -> _Member


class _IdPool:
    """16-bit ids: fresh ones in order, then the freed ones oldest first (an id is reused only after it ended)."""

    def __init__(self):
        self._next = 0
        self._freed: deque = deque()

    def take(self) -> int | None:
        if self._next <= MAX_OBJECT_ID:
            self._next += 1
            return self._next - 1
        return self._freed.popleft() if self._freed else None

    def free(self, oid: int) -> None:
        self._freed.append(oid)


class RsuFusion:
    """The roadside unit's one object list from its cameras' tracks (module doc).

    Parameters
    ----------
    config : RsuFusionConfig, optional

    Cameras are declared with :meth:`add_camera`; each frame of a camera goes through :meth:`step` (or
    :meth:`step_tracks` with a :class:`~footprint_uq.tracking.table.TrackOutput`); :meth:`objects` gives the list.
    """

    def __init__(self, config: RsuFusionConfig | None = None):
        self.config = config or RsuFusionConfig()
        self.gate = gate_chi2(self.config.gate_confidence)
        self.leave_gate = gate_chi2(self.config.leave_confidence)
        self.cameras: dict = {}
        self._objects: dict[int, _Object] = {}
        self._pairs: dict = {}  # (camera id, track id) -> object id
        self._ids = _IdPool()
        #: the unit's latest fused time (the latest frame time of any camera), s
        self.last_time_s = -math.inf
        # a lower bound of every member's time (exact after each scan of _expire, lowered by every frame stored)
        self._oldest_member_s = -math.inf
        #: frames by outcome: "ok", "late", "dropped_late", "clock_backwards"
        self.counts = {"ok": 0, "late": 0, "dropped_late": 0, "clock_backwards": 0}
        #: objects merged (one camera's object found to be another's), pairs that left their object (gate broken)
        self.n_merged = 0
        self.n_unstuck = 0

    def __len__(self) -> int:
        return len(self._objects)

    def add_camera(self, camera_id, sensor_id: int, *, clock_offset_sigma_s: float = 0.0,
                   clock_jitter_sigma_s: float = 0.0) -> None:
        """Declare a camera: its ``sensorId`` (0..255, the CPM's ``Identifier1B``) and its clock's sigmas (s)."""
        sid = as_int("sensor_id", sensor_id, minimum=0, expected="a sensor id in 0..255")
        if sid > 255:
            raise InputError("sensor_id", sensor_id, "a sensor id in 0..255")
        if camera_id in self.cameras:
            raise InputError("camera_id", camera_id, "a camera not declared yet")
        if any(c.sensor_id == sid for c in self.cameras.values()):
            raise InputError("sensor_id", sensor_id, "a sensor id not used by another camera")
        self.cameras[camera_id] = _Camera(sid, clock_sigma_s(clock_offset_sigma_s, clock_jitter_sigma_s))

    # -- one camera frame -------------------------------------------------------------------------------------
    def step_tracks(self, camera_id, time_s: float, tracks, class_id=None) -> FrameFusion:
        """:meth:`step` with a :class:`~footprint_uq.tracking.table.TrackOutput` of the camera's frame."""
        return self.step(camera_id, time_s, tracks.track_id, tracks.xy_m, tracks.cov_xy_m2, tracks.v_mps,
                         tracks.cov_v_m2ps2, tracks.age_s, class_id)

    def step(self, camera_id, time_s: float, track_id, xy_m, cov_xy_m2, v_mps, cov_v_m2ps2, age_s=None,
             class_id=None) -> FrameFusion:
        """Fuse one frame of camera ``camera_id`` (n tracked objects).

        Parameters
        ----------
        time_s : float                 the frame's time on the camera's clock, s
        track_id : (n,) int            the camera's track ids (-1: not tracked; rejected)
        xy_m : (n, 2), cov_xy_m2 : (n, 2, 2)        filtered positions in W (m) and covariances (m^2)
        v_mps : (n, 2), cov_v_m2ps2 : (n, 2, 2)     velocities (m/s; NaN before a track's second detection)
        age_s : (n,), optional         the tracks' ages (s; the object's age counts from ``time_s - age_s``)
        class_id : sequence of n, optional

        Returns
        -------
        FrameFusion
        """
        if camera_id not in self.cameras:
            raise InputError("camera_id", camera_id, f"a declared camera (one of {list(self.cameras)})")
        t = as_float("time_s", time_s)
        tid, xy, P, v, Pv, age, cls = _frame_columns(track_id, xy_m, cov_xy_m2, v_mps, cov_v_m2ps2, age_s, class_id)
        n = tid.shape[0]
        cam = self.cameras[camera_id]
        status, error = self._frame_status(cam, camera_id, t)
        out = np.full(n, -1, np.int64)
        if error is not None:
            self.counts[status] += 1
            return FrameFusion(out, status, error, [(i, status) for i in range(n)])
        self.counts[status] += 1
        cam.last_time_s = t
        self.last_time_s = max(self.last_time_s, t)
        self._expire(self.last_time_s)
        rejected, rows = _usable_rows(tid, xy, P)
        free_rows = self._keep_sticky(camera_id, t, rows, tid, xy, P, v, Pv, out)
        self._assign(camera_id, t, free_rows, tid, xy, P, v, Pv, out)
        rejected += [(i, "no free objectId (65,536 objects live)") for i in free_rows if out[i] < 0]
        block = _state_block(xy, P, v, Pv)
        first = np.where(np.isfinite(age), t - age, t).tolist()
        oids, tids = out.tolist(), tid.tolist()
        for i in rows:
            self._store(camera_id, oids[i], t, tids[i], block[i], cls[i], first[i])
        if rows:
            self._oldest_member_s = min(self._oldest_member_s, t)
        return FrameFusion(out, status, None, rejected)

    def _frame_status(self, cam: _Camera, camera_id, t: float) -> tuple[str, str | None]:
        if t < cam.last_time_s:
            return "clock_backwards", (f"camera {camera_id!r}: time_s {t!r} is earlier than its previous frame "
                                       f"({cam.last_time_s!r}); frame not fused, tracks kept")
        if t < self.last_time_s - self.config.max_lateness_s:
            return "dropped_late", (f"camera {camera_id!r}: time_s {t!r} is more than max_lateness_s "
                                    f"({self.config.max_lateness_s} s) before the fused time {self.last_time_s!r}; "
                                    "frame dropped (counted)")
        return ("late" if t < self.last_time_s else "ok"), None

    def _expire(self, now_s: float) -> None:
        """Drop contributions older than ``member_timeout_s``; an object without any ends (its id is freed)."""
        limit = self.config.member_timeout_s
        if now_s - self._oldest_member_s <= limit:
            return  # no member can be older than the limit
        oldest = math.inf
        for oid in list(self._objects):
            obj = self._objects[oid]
            for cid in [c for c, m in obj.members.items() if now_s - m.time_s > limit]:
                del self._pairs[(cid, obj.members.pop(cid).track_id)]
            if not obj.members:
                del self._objects[oid]
                self._ids.free(oid)
            else:
                oldest = min(oldest, min(m.time_s for m in obj.members.values()))
        self._oldest_member_s = oldest

    def _keep_sticky(self, camera_id, t, rows, tid, xy, P, v, Pv, out) -> list:
        """Rows whose pair has an object: kept there unless the gate against the other cameras is broken
        ``unstick_frames`` times in a row (then detached).  Returns the rows left to :meth:`_assign`: new pairs,
        detached ones and those whose object has no other camera (they may belong to another object)."""
        free, check = [], []
        pairs, objects, tids = self._pairs, self._objects, tid.tolist()
        for i in rows:
            oid = pairs.get((camera_id, tids[i]))
            if oid is None:
                free.append(i)
            elif not self._fresh_other(objects[oid].members, camera_id, t):
                out[i] = oid
                free.append(i)  # alone (no other camera's fresh member): may still join another object
            else:
                out[i] = oid
                check.append(i)
        if not check:
            return free
        oids = [int(out[i]) for i in check]
        xo, Po, _, _ = self._estimates(oids, t, exclude=camera_id)
        d2 = _mahalanobis2(xy[check] - xo, self._row_cov(camera_id, check, P, v, Pv) + Po)
        for i, oid, dd in zip(check, oids, d2.tolist(), strict=True):
            member = self._objects[oid].members[camera_id]
            member.misses = 0 if dd <= self.leave_gate else member.misses + 1
            if member.misses >= self.config.unstick_frames:
                self._detach((camera_id, int(tid[i])), oid)
                self.n_unstuck += 1
                out[i] = -1
                free.append(i)
        return free

    def _row_cov(self, camera_id, rows, P, v, Pv) -> np.ndarray:
        """The rows' position covariances ``(k, 2, 2)`` with their camera's clock term (none where the velocity is
        not known yet)."""
        vr = v[rows]
        known = np.isfinite(vr).all(1)[:, None, None]
        vr = np.where(np.isfinite(vr), vr, 0.0)
        s2 = self.cameras[camera_id].sigma_t_s ** 2
        return P[rows] + np.where(known, s2 * (vr[:, :, None] * vr[:, None, :] + np.nan_to_num(Pv[rows])), 0.0)

    def _detach(self, key, oid: int) -> None:
        obj = self._objects[oid]
        del obj.members[key[0]]
        del self._pairs[key]
        if not obj.members:
            del self._objects[oid]
            self._ids.free(oid)

    def _assign(self, camera_id, t, free, tid, xy, P, v, Pv, out) -> None:
        """One globally optimal assignment of the free rows to the objects they may join (module doc)."""
        if not free:
            return
        taken = set(out.tolist())  # the objects this frame's rows are in: never a second row of the camera
        in_frame = set(tid.tolist())
        cands, lapsed = [], []
        for o, obj in self._objects.items():
            if o in taken:
                continue
            if not _only(obj.members, camera_id):
                cands.append(o)
            elif obj.members and obj.members[camera_id].track_id not in in_frame:
                lapsed.append(o)  # this camera's track of it ended or restarted: a new track may take it over
        cost = np.concatenate([self._cost(camera_id, t, free, cands, xy, P, v, Pv),
                               self._cost(camera_id, t, free, lapsed, xy, P, v, Pv, exclude=None)], axis=1)
        cands += lapsed
        match = {}
        if cands:
            cost = np.where(cost <= self.gate, cost, _BIG)
            for a, b in zip(*linear_sum_assignment(cost), strict=True):
                if cost[a, b] <= self.gate:
                    match[free[a]] = cands[b]
        for i in free:
            key = (camera_id, int(tid[i]))
            own = int(out[i])
            if i in match:
                out[i] = self._join(key, own, match[i])
            elif own < 0:
                oid = self._ids.take()
                if oid is None:
                    continue  # (reported by _store: no free objectId)
                self._objects[oid] = _Object(t)
                self._pairs[key] = out[i] = oid

    def _cost(self, camera_id, t, free, cands, xy, P, v, Pv, exclude=True) -> np.ndarray:
        """``d^2 (len(free), len(cands))`` of the free rows to the candidates' estimates from the other cameras
        (``exclude=None``: from every member, the camera's lapsed one included): each candidate's estimate once, then
        every pair at once (no Python loop over pairs)."""
        if not cands:
            return np.zeros((len(free), 0))
        xo, Po, _, _ = self._estimates(cands, t, exclude=camera_id if exclude else None)
        Pc = self._row_cov(camera_id, free, P, v, Pv)
        return _mahalanobis2(xy[free][:, None] - xo[None], Pc[:, None] + Po[None])

    def _fresh_other(self, members: dict, camera_id, t: float) -> bool:
        """Whether a camera other than ``camera_id`` has a fresh member (updated within ``report_timeout_s``)."""
        oldest = t - self.config.report_timeout_s
        return any(c != camera_id and m.time_s >= oldest for c, m in members.items())

    def _join(self, key, own: int, oid: int) -> int:
        """Pair ``key`` (in object ``own``, -1 if none, where it is alone) joins object ``oid``; two objects
        merge under the older id.  Returns the surviving id."""
        camera_id = key[0]
        target = self._objects[oid]
        old = target.members.pop(camera_id, None)  # a lapsed track of the same camera: replaced
        if old is not None:
            self._pairs.pop((camera_id, old.track_id), None)
        if own < 0:
            self._pairs[key] = oid
            return oid
        src = self._objects.pop(own)
        self.n_merged += 1
        keep, drop = (own, oid) if src.first_time_s < target.first_time_s else (oid, own)
        members = dict(target.members)
        for cid, m in src.members.items():  # a camera in both: its newer member stays, the older one leaves
            other = members.get(cid)
            if other is None or m.time_s >= other.time_s:
                members[cid], other = m, other
            else:
                other = m
            if other is not None:
                self._pairs.pop((cid, other.track_id), None)
        merged = _Object(min(src.first_time_s, target.first_time_s), members)
        self._objects[keep] = merged
        self._objects.pop(drop, None)
        self._ids.free(drop)
        for cid, m in merged.members.items():
            self._pairs[(cid, m.track_id)] = keep
        return keep

    def _store(self, camera_id, oid, t, tid, state, cls, first_s) -> None:
        if oid < 0:
            return
        obj = self._objects[oid]
        prev = obj.members.get(camera_id)
        misses = prev.misses if prev is not None and prev.track_id == tid else 0
        obj.members[camera_id] = _Member(tid, t, state, cls, misses)
        obj.first_time_s = min(obj.first_time_s, first_s)

    # -- estimates -------------------------------------------------------------------------------------------
    def _contributions(self, oids, t: float, exclude=None, fresh: bool = False):
        """Every member of objects ``oids`` (but camera ``exclude``'s; only the fresh ones with ``fresh``: updated
        within ``report_timeout_s`` of ``t``) predicted to ``t``, all at once (module doc): the object index of each
        ``(K,)``, positions ``(K, 2)``, covariances ``(K, 2, 2)``, whether its velocity is known ``(K,)``, velocities
        ``(K, 2)`` and their covariances ``(K, 2, 2)`` at ``t``."""
        cfg = self.config
        idx, times, states, sig = [], [], [], []
        sigma = {cid: c.sigma_t_s for cid, c in self.cameras.items()}
        objects = self._objects
        oldest = t - cfg.report_timeout_s if fresh else -math.inf
        for k, oid in enumerate(oids):
            for cid, m in objects[oid].members.items():
                if cid != exclude and m.time_s >= oldest:
                    idx.append(k)
                    times.append(m.time_s)
                    states.append(m.state)
                    sig.append(sigma[cid])
        if not idx:
            z = np.zeros((0, 2))
            return np.zeros(0, np.int64), z, np.zeros((0, 2, 2)), np.zeros(0, bool), z, np.zeros((0, 2, 2))
        tau = t - np.array(times)
        S = np.array(states)  # (K, 12): one call for every member (_Member.state)
        K = S.shape[0]
        v = S[:, 6:8]
        known = np.isfinite(v).all(1)
        v = np.where(known[:, None], v, 0.0)
        Pv = np.where(known[:, None, None], S[:, 8:12].reshape(K, 2, 2),
                      cfg.unknown_velocity_sigma_mps ** 2 * np.eye(2))
        x, Px = predict_position(S[:, 0:2], S[:, 2:6].reshape(K, 2, 2), v, Pv, tau, sigma_t_s=np.array(sig))
        q = cfg.accel_psd_m2ps3 * np.abs(tau)
        Px = Px + (q * tau ** 2 / 3.0)[:, None, None] * np.eye(2)
        return np.array(idx, np.int64), x, Px, known, v, Pv + q[:, None, None] * np.eye(2)

    def _estimates(self, oids, t: float, exclude=None, fresh: bool = False):
        """Fused position ``(m, 2)``, its covariance, velocity and its covariance of objects ``oids`` at ``t`` from
        their members but camera ``exclude``'s (only the fresh ones with ``fresh``; NaN where none is left / no
        velocity is known)."""
        idx, x, Px, known, v, Pv = self._contributions(oids, t, exclude, fresh)
        m = len(oids)
        xf, Pf = _fuse_groups(idx, x, Px, m, self.config.method)
        vf, Pvf = _fuse_groups(idx[known], v[known], Pv[known], m, self.config.method)
        return xf, Pf, vf, Pvf

    def objects(self, time_s: float | None = None) -> FusedObjects:
        """The unit's object list predicted to ``time_s`` (default: the latest fused time): the objects with a fresh
        contribution (updated within ``report_timeout_s`` of ``time_s``), each fused from its fresh ones only."""
        t = self.last_time_s if time_s is None else as_float("time_s", time_s)
        oldest = t - self.config.report_timeout_s
        live = [(o, [(c, m) for c, m in self._objects[o].members.items() if m.time_s >= oldest])
                for o in sorted(self._objects)]
        live = [(o, ms) for o, ms in live if ms]
        ids = [o for o, _ in live]
        xy, P, v, Pv = self._estimates(ids, t, fresh=True)
        return FusedObjects(np.array(ids, np.int64), xy, P, v, Pv,
                            np.array([t - self._objects[o].first_time_s for o in ids], np.float64),
                            [tuple(sorted(self.cameras[c].sensor_id for c, _ in ms)) for _, ms in live],
                            [max(ms, key=lambda cm: cm[1].time_s)[1].class_id for _, ms in live],
                            np.array([len(ms) for _, ms in live], np.int64), t,
                            np.array([max(m.time_s for _, m in ms) for _, ms in live], np.float64))

    def contributions(self, object_id: int, time_s: float) -> tuple[list, np.ndarray, np.ndarray]:
        """Each camera's own estimate of object ``object_id`` predicted to ``time_s``, before fusion -- the fresh
        ones, as :meth:`objects` fuses them: the camera ids, positions ``(k, 2)`` (m) and covariances ``(k, 2, 2)``
        (m^2; the clock term included)."""
        obj = self._objects.get(object_id)
        if obj is None:
            raise InputError("object_id", object_id, "the objectId of a live fused object")
        t = as_float("time_s", time_s)
        _, xs, Ps, _, _, _ = self._contributions([object_id], t, fresh=True)
        oldest = t - self.config.report_timeout_s
        return [c for c, m in obj.members.items() if m.time_s >= oldest], xs, Ps

    def pairs(self) -> dict:
        """``(camera id, track id) -> objectId`` of every live contribution (a copy)."""
        return dict(self._pairs)


def fuse_estimates(x, P, method: str = "information") -> tuple[np.ndarray, np.ndarray]:
    """Fuse k estimates ``x (k, d=2)`` with covariances ``P (k, 2, 2)`` of one quantity.

    ``"information"``: ``P_f = (sum P_i^-1)^-1``, ``x_f = P_f sum P_i^-1 x_i`` (independent errors).
    ``"ci"``: covariance intersection with the weights ``w_i = (1 / tr P_i) / sum_j (1 / tr P_j)`` (Niehsen's fast
    CI): ``P_f = (sum w_i P_i^-1)^-1``, consistent whatever the correlation between the estimates.
    """
    x = np.asarray(x, dtype=np.float64)
    P = np.asarray(P, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 2 or P.shape != (x.shape[0], 2, 2) or x.shape[0] < 1:
        raise InputError("x, P", (x.shape, P.shape), "shapes (k, 2) and (k, 2, 2) with k >= 1")
    if method not in FUSION_METHODS:
        raise InputError("method", method, f"one of {FUSION_METHODS}")
    xf, Pf = _fuse_groups(np.zeros(x.shape[0], np.int64), x, P, 1, method)
    return xf[0], Pf[0]


def _fuse_groups(idx, x, P, m: int, method: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fuse_estimates` of m groups at once: estimate j belongs to group ``idx[j]`` (NaN: an empty group)."""
    info = _inv2(P)
    if method == "ci":
        w = 1.0 / np.trace(P, axis1=1, axis2=2)
        info = info * (w / np.bincount(idx, w, m)[idx])[:, None, None]
    # the sums per group by bincount (in the estimates' order, as np.add.at would add them; several times faster)
    total = np.stack([np.bincount(idx, info[:, i, j], m) for i in (0, 1) for j in (0, 1)], -1).reshape(m, 2, 2)
    ix = np.einsum("kij,kj->ki", info, x)
    eta = np.stack([np.bincount(idx, ix[:, 0], m), np.bincount(idx, ix[:, 1], m)], -1)
    has = np.bincount(idx, minlength=m) > 0
    Pf = _inv2(np.where(has[:, None, None], total, np.eye(2)))
    Pf = 0.5 * (Pf + np.swapaxes(Pf, -1, -2))
    xf = np.einsum("mij,mj->mi", Pf, eta)
    return np.where(has[:, None], xf, np.nan), np.where(has[:, None, None], Pf, np.nan)


def _only(members: dict, camera_id) -> bool:
    """Whether no camera but ``camera_id`` contributes (an object without members too)."""
    return not members or (len(members) == 1 and camera_id in members)


def _inv2(S: np.ndarray) -> np.ndarray:
    """Inverses of ``(..., 2, 2)`` matrices (closed form)."""
    a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    det = a * d - b * c
    out = np.empty(np.shape(S))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = d / det, -b / det, -c / det, a / det
    return out


def _mahalanobis2(d: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``d^T S^-1 d`` of ``d (..., 2)``, ``S (..., 2, 2)`` (closed form)."""
    a, b, c, e = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
    return (e * d[..., 0] ** 2 - (b + c) * d[..., 0] * d[..., 1] + a * d[..., 1] ** 2) / (a * e - b * c)


def _frame_columns(track_id, xy_m, cov_xy_m2, v_mps, cov_v_m2ps2, age_s, class_id):
    """A frame's columns checked for shape (kornia style: at entry, one line naming the field)."""
    tid = np.asarray(track_id)
    if tid.ndim != 1 or not (np.issubdtype(tid.dtype, np.integer) or tid.size == 0):
        raise InputError("track_id", getattr(tid, "shape", tid), "a 1-D array of integer track ids")
    n = tid.shape[0]
    cols = []
    for name, a, tail in (("xy_m", xy_m, (2,)), ("cov_xy_m2", cov_xy_m2, (2, 2)), ("v_mps", v_mps, (2,)),
                          ("cov_v_m2ps2", cov_v_m2ps2, (2, 2))):
        arr = np.asarray(a, dtype=np.float64)
        if arr.shape != (n,) + tail:
            raise InputError(name, arr.shape, f"shape {(n,) + tail} (one row per track id)")
        cols.append(arr)
    age = np.full(n, np.nan) if age_s is None else np.asarray(age_s, dtype=np.float64)
    if age.shape != (n,):
        raise InputError("age_s", age.shape, f"shape ({n},)")
    cls = [None] * n if class_id is None else list(class_id)
    if len(cls) != n:
        raise InputError("class_id", len(cls), f"{n} classes, one per track id")
    return (tid.astype(np.int64), *cols, age, cls)


def _usable_rows(tid, xy, P) -> tuple[list, list]:
    """Rows that can be fused and the others with their reason (nothing dropped silently), in row order: a track id
    -1, a track id already accepted in an earlier row, a non-finite position or covariance, a covariance that is
    not positive definite (column-wise; a Python loop only over the rejected rows)."""
    n = tid.shape[0]
    finite = np.isfinite(xy).all(1) & np.isfinite(P).all((1, 2))
    with np.errstate(invalid="ignore"):
        pd = (P[:, 0, 0] > 0) & (P[:, 0, 0] * P[:, 1, 1] - P[:, 0, 1] * P[:, 1, 0] > 0)
    valid = (tid >= 0) & finite & pd
    earlier = np.zeros(n, bool)  # an earlier row with the same track id was accepted
    if valid.any():
        u, first = np.unique(tid[valid], return_index=True)
        first = np.flatnonzero(valid)[first]
        pos = np.minimum(np.searchsorted(u, tid), len(u) - 1)
        earlier = (u[pos] == tid) & (first[pos] < np.arange(n))
    ok = valid & ~earlier
    rejected = []
    for i in np.flatnonzero(~ok).tolist():
        if tid[i] < 0:
            rejected.append((i, "not tracked (track_id -1)"))
        elif earlier[i]:
            rejected.append((i, f"track_id {int(tid[i])} repeated in the frame"))
        elif not finite[i]:
            rejected.append((i, "position or covariance not finite"))
        else:
            rejected.append((i, "covariance not positive definite"))
    return rejected, np.flatnonzero(ok).tolist()
