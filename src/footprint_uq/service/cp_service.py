"""The Collective Perception basic service of one roadside unit (ETSI TS 103 324 V2.1.1) as one component.

:class:`CpBasicService` composes the project's parts, in the way vanetza keeps a CP service apart from its codec:

* **fusion**: every camera's tracks (:class:`~footprint_uq.tracking.table.TrackOutput`, one camera frame per
  :meth:`CpBasicService.ingest`) go into one :class:`~footprint_uq.tracking.rsu_fusion.RsuFusion`: one object list
  for the unit, a stable 16-bit ``objectId``, ``sensorIdList``, ``objectAge`` (docs/rsu-fusion.md);
* **generation** (:meth:`CpBasicService.poll`, called after each ingest with the newest frame time): a
  :class:`~.cp_rules.GenerationClock` says whether a generation event is due (every ``T_GenCpm`` on a fixed grid;
  a CPM at least every ``T_GenCpmMax``; the Sensor Information container at least once a second), an
  :class:`~.cp_rules.InclusionMemory` which objects the event includes (clause 6.1.2's rules: new objects at once,
  4 m, 0.5 m/s, 4 deg, 1 s, persons / cyclists / animals (the VRU classes) at least every 0.5 s; the heading rule
  only where the direction of motion is known: :func:`~footprint_uq.tracking.motion.object_motion` gives its sigma
  where the speed is at least 3 sigma of the velocity, so that a parked car's noisy velocity never triggers it; the
  speed rule likewise only between two states whose motion is known: starting and stopping are caught by the 4 m
  and 1 s rules);
* **time**: every fused object is **predicted to the event's referenceTime**: each camera's latest estimate is
  moved from its frame time to referenceTime at constant velocity and its covariance grown
  (:func:`~footprint_uq.uncertainty.timing.predict_position`: ``tau^2 P_v`` + the camera's clock term
  ``sigma_t^2 (v v^T + P_v)`` + the fusion's acceleration noise), then fused.  The standard's
  ``measurementDeltaTime`` is the time of the object's stated state minus ``referenceTime``
  (TS 102 894-2 ``PerceivedObject``: "the time difference from a reference time to the time of the measurement of
  the object"); the stated state *is* at referenceTime, so it is **0** for every object, always within the field's
  range (-2048..2047 ms).  How old the newest measurement behind it is goes into the record
  (``measurement_age_ms`` = referenceTime minus the newest contributing frame's time) -- it is part of the stated
  covariance already.  ``referenceTime`` is :func:`~.messages.cpm.timestamp_its_ms` of the event's time (the frame
  time given to :meth:`~CpBasicService.poll`, rounded to the millisecond; the prediction goes to that exact ms);
* **columns for the codec** (:class:`~.cp_segments.CpmObjectColumns`): east / north offsets from the reference
  position (W's origin, rotated by ``heading_offset_deg``), the confidences and correlation of the fused covariance
  (:func:`~footprint_uq.products.v2x.cpm_fields`), the velocity codes with their confidences from the fused
  velocity and its covariance (:func:`~footprint_uq.tracking.motion.object_motion`,
  :func:`~.messages.motion.motion_codes`; no yaw: the fused list has none),
  ``objectAge``, ``sensorIdList``, ``objectPerceptionQuality`` (:func:`~.cp_segments.object_perception_quality`:
  the frame's detection confidence, the age, the detection success rate, ``linear_ok``); then
  :func:`~.cp_segments.event_segments` writes the event's CPMs (segments of at most ``max_size_bytes``, the sensor
  containers when due in the first, or spread camera by camera over the first ones when they do not fit there);
* **SDSM** (:func:`~.cp_sdsm.fused_sdsm`): one per event with objects, the same fused objects at the same time
  (``measurementTime`` 0), at most 255 objects (the longest-unsent first), the rest counted.

Objects an event includes are sent in the order of their last inclusion (never-sent first): objects that did not
fit into 8 segments (``not_sent``) stay due and lead the next event.  An ``objectId`` that ended is forgotten by the
inclusion memory at the next event (so a reused id counts as new).

Per-object inputs of the quality rule, kept per ``objectId`` from the newest frame that contributed: the detection
confidence (``detection_confidence``, NaN = unknown), ``linear_ok`` (not given: False -- not shown to be linear, so
never the top quality), and the detection success rate ``n_updates / (1 + round(age_s / T_frame))`` of the row's
track (``T_frame``: the camera's median frame interval; unknown before its second frame).
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .._checks import as_float, as_int
from ..errors import InputError
from ..products.geo import GeoReference
from ..products.perception_region import PerceptionRegion
from ..products.v2x import K95_2D, cpm_fields, j2735_position_confidence
from ..tracking.motion import object_motion
from ..tracking.rsu_fusion import FrameFusion, FusedObjects, RsuFusion, RsuFusionConfig
from ..tracking.table import TrackOutput
from ..uncertainty.timing import clock_sigma_s
from .cp_rules import INCLUSION_REASONS, CpRules, GenerationClock, InclusionMemory
from .cp_sdsm import fused_sdsm
from .cp_segments import CpmObjectColumns, SensorRegion, event_segments, object_perception_quality, sensor_region
from .messages.asn1_cpm import DEFAULT_CDD
from .messages.cpm import (
    CPM_CLASS_OF,
    LATITUDE_UNAVAILABLE,
    LONGITUDE_UNAVAILABLE,
    check_cdd,
    coordinate_cm,
    object_class_json,
    timestamp_its_ms,
)
from .messages.motion import motion_codes
from .messages.sdsm import offset_dm
from .messages.uper_cpm import class_bits

__all__ = ["CpCamera", "CpEvent", "CpBasicService", "VRU_CLASSES"]

#: detector classes (lower case) the 0.5 s rule applies to: every class the CPM sends as a VRU sub-class
#: (persons, cyclists and light VRU vehicles, motorcyclists, animals)
VRU_CLASSES = frozenset(k for k, spec in CPM_CLASS_OF.items() if spec[0] == "vruSubClass")
_N_IDS = 65536
_CONFIDENCE_UNAVAILABLE = 101
_UNIX_2004_S = 1072915200.0


@dataclass(frozen=True)
class CpCamera:
    """One camera of the unit.

    camera_id : str                   the id its frames come with
    sensor_id : int                   0..255, unique in the unit (``SensorInformation.sensorId``)
    region : PerceptionRegion or None :func:`~footprint_uq.products.perception_region.perception_region` of the
                                      camera and its budget (None: sent without a region)
    clock_offset_sigma_s, clock_jitter_sigma_s : float   the camera clock's sigmas (s, >= 0)
    """

    camera_id: str
    sensor_id: int
    region: PerceptionRegion | None
    clock_offset_sigma_s: float = 0.0
    clock_jitter_sigma_s: float = 0.0

    def __post_init__(self):
        if not isinstance(self.camera_id, str) or not self.camera_id:
            raise InputError("camera_id", self.camera_id, "a non-empty camera id (str)")
        sid = as_int("sensor_id", self.sensor_id, minimum=0, expected="a sensor id in 0..255")
        if sid > 255:
            raise InputError("sensor_id", self.sensor_id, "a sensor id in 0..255")
        if self.region is not None and not isinstance(self.region, PerceptionRegion):
            raise InputError("region", type(self.region).__name__, "a PerceptionRegion or None")
        clock_sigma_s(self.clock_offset_sigma_s, self.clock_jitter_sigma_s)


class CpEvent(NamedTuple):
    """One generation event (module doc).

    time_s : float              the event's time (the unit's clock: frame timestamps, Unix s)
    reference_time_ms : int     CPM ``referenceTime`` (``TimestampIts``)
    segments : list of bytes    the UPER CPMs of this event, each a complete CPM ([] if nothing is owed)
    sdsm : dict or None         the J3224 SDSM of the same fused objects (<= 255 objects, the rest counted)
    record : dict               the event's JSON record: ``objects`` (objectId, xy_m, cov_m2, v_mps, sensorIdList,
                                segment, reason, ...) and ``counts``
    """

    time_s: float
    reference_time_ms: int
    segments: list
    sdsm: dict | None
    record: dict


class _EventObjects(NamedTuple):
    """The fused objects of an event at referenceTime, as the codec's columns and the rules' inputs."""

    fused: FusedObjects
    columns: CpmObjectColumns
    speed_mps: np.ndarray
    heading_deg: np.ndarray
    is_vru: np.ndarray
    classes: list
    pos_conf: np.ndarray
    east_dm: np.ndarray
    north_dm: np.ndarray


def _reference_time(t_s: float) -> tuple[int, float]:
    """``(referenceTime (ms, TimestampIts), the Unix time of that exact ms)``."""
    ref_ms = timestamp_its_ms(t_s)
    leap_ms = 1000.0 * round((ref_ms - (t_s - _UNIX_2004_S) * 1000.0) / 1000.0)
    return ref_ms, _UNIX_2004_S + (ref_ms - leap_ms) / 1000.0


def _column(name: str, a, n: int, default, dtype) -> np.ndarray:
    if a is None:
        return np.full(n, default, dtype=dtype)
    try:
        arr = np.asarray(a, dtype=dtype).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(name, a, f"{n} values of type {np.dtype(dtype).name}, one per track") from None
    if arr.shape != (n,):
        raise InputError(name, arr.shape, f"one value per track ({n})")
    return arr


class CpBasicService:
    """The CP basic service of one roadside unit (module doc).

    Parameters
    ----------
    cameras : sequence of CpCamera
        At least one; camera ids and sensor ids unique.
    station_id : int
        The unit's ``StationId`` (0..2^32 - 1).
    rules : CpRules, optional
        Generation, inclusion and segmentation rules (defaults: :class:`~.cp_rules.CpRules`).
    fusion : RsuFusionConfig, optional
        The fusion's options (docs/rsu-fusion.md).
    cdd : str
        The ETSI-ITS-CDD release of the CPM (``"2.1.1"`` or ``"2.2.1"``).
    heading_offset_deg : float
        Bearing of W's +y axis from true north (deg clockwise); positions, velocities and polygons are rotated
        into the messages' east / north.
    origin_lat_deg, origin_lon_deg : float, optional
        WGS84 position of W's origin: the CPM's reference position and the SDSM's ``refPos`` (unavailable when not
        given: positions are then offsets from an unknown point).
    """

    def __init__(self, cameras: Sequence[CpCamera], *, station_id: int, rules: CpRules | None = None,
                 fusion: RsuFusionConfig | None = None, cdd: str = DEFAULT_CDD, heading_offset_deg: float = 0.0,
                 origin_lat_deg: float | None = None, origin_lon_deg: float | None = None):
        cams = list(cameras)
        if not cams:
            raise InputError("cameras", 0, "at least one CpCamera")
        for k, c in enumerate(cams):
            if not isinstance(c, CpCamera):
                raise InputError(f"cameras[{k}]", type(c).__name__, "a CpCamera")
        self.station_id = as_int("station_id", station_id, minimum=0, expected="a StationId in 0..4294967295")
        if self.station_id > 4294967295:
            raise InputError("station_id", station_id, "a StationId in 0..4294967295")
        self.rules = rules if rules is not None else CpRules()
        if not isinstance(self.rules, CpRules):
            raise InputError("rules", type(rules).__name__, "a CpRules")
        self.cdd = check_cdd(cdd)
        self.georef = GeoReference(heading_offset_deg, origin_lat_deg, origin_lon_deg)
        self._lat = LATITUDE_UNAVAILABLE if origin_lat_deg is None else int(round(self.georef.origin_lat_deg * 1e7))
        self._lon = LONGITUDE_UNAVAILABLE if origin_lon_deg is None else int(round(self.georef.origin_lon_deg * 1e7))
        self.fusion = RsuFusion(fusion)
        self.cameras = {}
        for c in cams:
            self.fusion.add_camera(c.camera_id, c.sensor_id, clock_offset_sigma_s=c.clock_offset_sigma_s,
                                   clock_jitter_sigma_s=c.clock_jitter_sigma_s)
            self.cameras[c.camera_id] = c
        self.regions = [SensorRegion(c.sensor_id, None) if c.region is None else
                        sensor_region(c.sensor_id, c.region, (0.0, 0.0), self.georef.heading_offset_deg)
                        for c in cams]
        self.clock = GenerationClock(self.rules)
        self.memory = InclusionMemory(self.rules)
        # per objectId, from the newest frame that contributed (the quality rule's inputs)
        self._conf = np.full(_N_IDS, np.nan)
        self._linear = np.zeros(_N_IDS, bool)
        self._rate = np.full(_N_IDS, np.nan)
        self._intervals = {c.camera_id: deque(maxlen=15) for c in cams}
        self._last_frame_s = {c.camera_id: -math.inf for c in cams}
        self._class_codes: dict = {}
        self._events = 0
        self._last_event_s = -math.inf
        self._frames_at_event = dict(self.fusion.counts)
        self._counts = {"events": 0, "cpms": 0, "cpm_bytes": 0, "included": 0, "sent": 0, "not_sent": 0,
                        "sdsm": 0, "sdsm_objects": 0, "sdsm_not_sent": 0, "late_after_event": 0, "frames": 0}

    # -- frames in ---------------------------------------------------------------------------------------------
    def ingest(self, camera_id, time_s: float, tracks: TrackOutput, *, class_id=None, linear_ok=None,
               detection_confidence=None) -> FrameFusion:
        """Fuse one camera frame's tracks.

        Parameters
        ----------
        camera_id : str
            A declared camera.
        time_s : float
            The frame's time (the camera's clock, Unix s).
        tracks : TrackOutput
            The camera's :class:`~footprint_uq.tracking.table.TrackTable` output of the frame (n rows).
        class_id : sequence of n class names, optional
        linear_ok : bool (n,), optional
            Whether each row's centre covariance is a trustworthy linearisation (False when not given).
        detection_confidence : float (n,), optional
            The detector's confidence in [0, 1] (NaN = unknown).

        Returns
        -------
        FrameFusion
            ``error`` is the frame's one-line error (clock backwards: nothing fused, tracks kept; more than
            ``max_lateness_s`` late: counted as dropped); rows not fused are in ``rejected`` with their index.
        """
        if camera_id not in self.cameras:
            raise InputError("camera_id", camera_id, f"a declared camera (one of {list(self.cameras)})")
        if not isinstance(tracks, TrackOutput):
            raise InputError("tracks", type(tracks).__name__, "a TrackOutput (TrackTable.step's output)")
        t = as_float("time_s", time_s)
        n = tracks.track_id.shape[0]
        conf = _column("detection_confidence", detection_confidence, n, np.nan, np.float64)
        bad = np.flatnonzero(~np.isnan(conf) & ~((conf >= 0.0) & (conf <= 1.0)))
        if len(bad):
            raise InputError(f"detection_confidence[{bad[0]}]", float(conf[bad[0]]), "a number in [0, 1] or NaN")
        lin = _column("linear_ok", linear_ok, n, False, bool)
        ff = self.fusion.step_tracks(camera_id, t, tracks, class_id)
        self._counts["frames"] += 1
        if ff.error is not None:
            return ff
        if t < self._last_event_s:
            self._counts["late_after_event"] += 1
        rate = self._detection_rate(camera_id, t, tracks)
        ok = ff.object_id >= 0
        oid = ff.object_id[ok]
        self._conf[oid], self._linear[oid], self._rate[oid] = conf[ok], lin[ok], rate[ok]
        return ff

    def _detection_rate(self, camera_id, t: float, tracks: TrackOutput) -> np.ndarray:
        """Each row's detection success rate (module doc); NaN before the camera's frame interval is known."""
        prev = self._last_frame_s[camera_id]
        if t > prev > -math.inf:
            self._intervals[camera_id].append(t - prev)
        self._last_frame_s[camera_id] = max(prev, t)
        dts = self._intervals[camera_id]
        if not dts:
            return np.full(tracks.track_id.shape[0], np.nan)
        period = float(np.median(dts))
        with np.errstate(invalid="ignore"):
            expected = 1.0 + np.rint(np.asarray(tracks.age_s, dtype=np.float64) / period)
            return np.clip(np.asarray(tracks.n_updates, dtype=np.float64) / expected, 0.0, 1.0)

    # -- generation events -------------------------------------------------------------------------------------
    def poll(self, time_s: float) -> CpEvent | None:
        """The generation event due at ``time_s`` (the newest frame time, Unix s), or None (module doc)."""
        t = as_float("time_s", time_s)
        if t < _UNIX_2004_S:  # (checked before the clock moves: a refused poll changes nothing)
            raise InputError("time_s", time_s, "Unix time in seconds (UTC), on or after 2004-01-01 (TimestampIts)")
        if not self.clock.tick(t):
            return None
        ref_ms, t_ref = _reference_time(t)
        ev = self._event_objects(t_ref)
        ids = ev.fused.object_id
        self.memory.retain(ids)
        reasons = self.memory.reasons(t, ids, ev.fused.xy_m, ev.speed_mps, ev.heading_deg, ev.is_vru)
        due = np.flatnonzero(reasons > 0)
        due = due[np.argsort(self.memory.last_included_s(ids[due]), kind="stable")]
        out = event_segments(self.station_id, ref_ms, ev.columns.take(due), self.regions, self.clock, t,
                             cdd=self.cdd, rules=self.rules, latitude=self._lat, longitude=self._lon,
                             number_of_perceived_objects=len(ids))
        segment = np.zeros(len(ids), np.int64)  # 1-based segment of each object, 0: not in this event's CPMs
        for k, idx in enumerate(out.segments):
            segment[due[idx]] = k + 1
        sent = np.flatnonzero(segment > 0)
        self.memory.included(t, ids[sent], ev.fused.xy_m[sent], ev.speed_mps[sent], ev.heading_deg[sent])
        order = np.argsort(self.memory.last_included_s(ids), kind="stable")  # the SDSM: longest-unsent first
        sdsm, sdsm_left = fused_sdsm(
            self.station_id, self._events, t_ref, ids[order], ev.east_dm[order], ev.north_dm[order],
            ev.pos_conf[order], [ev.classes[i] for i in order], np.zeros(len(ids), np.int64),
            None if ev.columns.motion is None else type(ev.columns.motion)(*(a[order] for a in ev.columns.motion)),
            lat_1e7deg=None if self._lat == LATITUDE_UNAVAILABLE else self._lat,
            lon_1e7deg=None if self._lon == LONGITUDE_UNAVAILABLE else self._lon)
        record = self._record(t, ref_ms, t_ref, ev, reasons, segment, due[out.not_sent], out, sdsm, sdsm_left)
        self._events += 1
        self._last_event_s = t
        return CpEvent(t, ref_ms, list(out.payloads), sdsm, record)

    def _class_code(self, cls) -> tuple[int, int]:
        """``(class_bits value, width)`` of a detector class (width 0: no classification)."""
        key = None if cls is None else str(cls).lower()
        code = self._class_codes.get(key)
        if code is None:
            spec = CPM_CLASS_OF.get(key) if key is not None else None
            code = (0, 0) if spec is None else class_bits(object_class_json(spec, self.cdd), self.cdd)
            self._class_codes[key] = code
        return code

    def _event_objects(self, t_ref: float) -> _EventObjects:
        """The fused objects predicted to ``t_ref`` as the codec's columns (module doc)."""
        f = self.fusion.objects(t_ref)
        n = len(f.object_id)
        h = self.georef.heading_offset_deg
        en = self.georef.world_to_enu(f.xy_m) if n else np.zeros((0, 2))
        fields = cpm_fields(f.cov_xy_m2, h) if n else {k: np.zeros(0, np.int64) for k in
                                                         ("cpm_x_confidence", "cpm_y_confidence",
                                                          "cpm_xy_correlation")}
        # a first detection stamped by a camera clock ahead of referenceTime: age 0, not negative
        age = np.maximum(f.age_s, 0.0)
        tracks = TrackOutput(f.object_id, np.zeros(n, bool), np.zeros(n, np.int64), age, f.xy_m, f.cov_xy_m2,
                             f.v_mps, f.cov_v_m2ps2)
        motion = object_motion(tracks, heading_offset_deg=h)
        mc = motion_codes(motion, n)
        classes = [None if c is None else str(c) for c in f.class_id]
        codes = np.array([self._class_code(c) for c in classes], np.int64).reshape(n, 2)
        oid = f.object_id
        quality = object_perception_quality(self._conf[oid], age, self._rate[oid], self._linear[oid])
        fx, fy, fr = (fields[k].astype(np.int64) for k in ("cpm_x_confidence", "cpm_y_confidence",
                                                           "cpm_xy_correlation"))
        cols = CpmObjectColumns(oid, coordinate_cm(en[:, 0]), coordinate_cm(en[:, 1]), fx, fy, fr, codes[:, 0],
                                codes[:, 1],
                                np.full(n, _CONFIDENCE_UNAVAILABLE, np.int64), motion=mc,
                                measurement_delta_ms=np.zeros(n, np.int64), quality=quality,
                                sensor_ids=[list(s) for s in f.sensor_ids])
        is_vru = np.array([c is not None and c.lower() in VRU_CLASSES for c in classes], bool)
        semi = _semi_major_95(f.cov_xy_m2)
        # the heading rule only where the direction of motion is known (its sigma is given only where the speed is at
        # least 3 sigma of the velocity): a parked car's noisy velocity points anywhere and must not trigger it
        moving = ~np.isnan(motion.sigma_heading_deg)
        heading = np.where(moving, motion.heading_deg, np.nan)
        # the speed rule likewise only between states whose motion is known (a parked car's fused speed reads
        # 0.3-1.5 m/s of noise and changed by more than 0.5 m/s at most events; treating it as 0 instead makes each
        # 3-sigma excursion and its return two changes); starting and stopping are caught by the 4 m and 1 s rules
        speed = np.where(moving, motion.speed_mps, np.nan)
        return _EventObjects(f, cols, speed, heading, is_vru, classes,
                             j2735_position_confidence(semi).astype(np.int64), offset_dm(en[:, 0]),
                             offset_dm(en[:, 1]))

    def _record(self, t, ref_ms, t_ref, ev: _EventObjects, reasons, segment, not_sent, out, sdsm, sdsm_left) -> dict:
        """The event's JSON record (see :class:`CpEvent`); the running counts updated."""
        f = ev.fused
        n = len(f.object_id)
        reason = np.asarray(INCLUSION_REASONS, dtype=object)[reasons]
        reason[not_sent] = "not_sent"
        age_ms = np.rint((t_ref - f.last_time_s) * 1000.0) if n else np.zeros(0)
        v = np.where(np.isfinite(f.v_mps), f.v_mps, np.nan)
        objects = [{"objectId": i, "xy_m": xy, "cov_m2": cov, "v_mps": None if math.isnan(vv[0]) else vv,
                    "sensorIdList": list(s), "class": c, "age_s": a, "measurementDeltaTime": 0,
                    "measurement_age_ms": int(ma), "quality": q, "segment": seg or None, "reason": r}
                   for i, xy, cov, vv, s, c, a, ma, q, seg, r in zip(
                       f.object_id.tolist(), f.xy_m.tolist(), f.cov_xy_m2.tolist(), v.tolist(), f.sensor_ids,
                       ev.classes, np.maximum(f.age_s, 0.0).tolist(), age_ms.tolist(), ev.columns.quality.tolist(),
                       segment.tolist(), reason.tolist(), strict=True)]
        frames = {k: v - self._frames_at_event.get(k, 0) for k, v in self.fusion.counts.items()}
        self._frames_at_event = dict(self.fusion.counts)
        counts = {"perceived": n, "included": int(np.count_nonzero(reasons > 0)),
                  "sent": int(np.count_nonzero(segment)), "not_sent": len(not_sent), "segments": len(out.payloads),
                  "bytes": [len(p) for p in out.payloads], "sdsm_objects": 0 if sdsm is None else len(sdsm["objects"]),
                  "sdsm_not_sent": int(sdsm_left), "frames_ok": frames["ok"], "late": frames["late"],
                  "dropped": frames["dropped_late"], "clock_backwards": frames["clock_backwards"]}
        c = self._counts
        c["events"] += 1
        c["cpms"] += len(out.payloads)
        c["cpm_bytes"] += sum(counts["bytes"])
        c["included"] += counts["included"]
        c["sent"] += counts["sent"]
        c["not_sent"] += counts["not_sent"]
        c["sdsm"] += sdsm is not None
        c["sdsm_objects"] += counts["sdsm_objects"]
        c["sdsm_not_sent"] += counts["sdsm_not_sent"]
        return {"time_s": t, "reference_time_ms": ref_ms, "event": self._events, "station_id": self.station_id,
                "sensor_information": bool(out.sensor_information), "objects": objects, "counts": counts}

    def counts(self) -> dict:
        """Running totals: events, CPMs (segments) and their bytes, objects included / sent / not sent (beyond 8
        segments, sent later), SDSMs and their objects / objects left out, frames by outcome (``ok``, ``late``,
        ``dropped_late``, ``clock_backwards``: :attr:`RsuFusion.counts`), frames fused after an event had passed
        their time (``late_after_event``), objects merged and pairs unstuck by the fusion."""
        return {**self._counts, **{f"frames_{k}": v for k, v in self.fusion.counts.items()},
                "merged": self.fusion.n_merged, "unstuck": self.fusion.n_unstuck, "live_objects": len(self.fusion)}


def _semi_major_95(cov_m2: np.ndarray) -> np.ndarray:
    """95 % semi-major axis (m) of ``(n, 2, 2)`` covariances (closed form; any rotation leaves it unchanged)."""
    a, b, d = cov_m2[:, 0, 0], 0.5 * (cov_m2[:, 0, 1] + cov_m2[:, 1, 0]), cov_m2[:, 1, 1]
    return K95_2D * np.sqrt(0.5 * (a + d) + np.hypot(0.5 * (a - d), b))
