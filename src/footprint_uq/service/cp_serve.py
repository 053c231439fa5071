"""``serve --cp-service``: the roadside unit's Collective Perception basic service deployed in the edge service.

:class:`CpServe` sits between :class:`~footprint_uq.service.core.Service` and the transports.  The service tracks
each camera's frame as before (``--tracks``); :meth:`CpServe.on_tracked` (the service's ``on_tracked`` hook, in the
worker thread) hands the frame's tracks to ONE :class:`~footprint_uq.service.cp_service.CpBasicService` for all the
cameras, then asks it for the generation event due at the frame's time.  What the CP service produces -- the event's
CPM segments (UPER), its SDSM and its JSON record, and a frame's one-line error (a clock going backwards, a frame too
late) -- waits in :class:`CpServe` and is written right after the frame's own record by the sink wrapper
(:meth:`CpServe.wrap`): on MQTT ``<prefix>/rsu/cpm`` (each segment its own message), ``<prefix>/rsu/sdsm`` and
``<prefix>/rsu/events``; on stdout one JSON line of ``"type": "cp_event"`` per event (the segments as hex beside the
record).  The health record gets the CP service's counts (``cp_service``).  docs/service.md, "The roadside unit's
CP service".

The cameras (:func:`cp_cameras`): each registry entry's ``sensor_id`` (default: its index in the sorted camera ids
+ 1), clock sigmas, and its perception region computed once here from the camera and its budget
(:func:`~footprint_uq.products.perception_region.perception_region`, the 95 % semi-major axis <= ``--region-max-
semi-major-m``).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import orjson

from .._checks import as_float, as_int
from ..errors import ConfigError, FootprintUQError, InputError
from ..products.perception_region import perception_region
from .core import RECORD_ERROR, RECORD_FOOTPRINTS, Service, error_record, station_id_of
from .cp_rules import MAX_SEGMENTS, CpRules
from .cp_segments import sensor_groups
from .cp_service import CpBasicService, CpCamera, CpEvent
from .frame_kernels import worst_usable
from .messages.cpm import CPM_CLASS_OF, build_cpm, object_class_json
from .messages.motion import MotionCodes
from .messages.uper_cpm import class_bits, object_bits

__all__ = ["CpServeOptions", "CpServe", "cp_cameras", "cp_workers", "start_cp_service", "largest_object_bytes",
           "unit_station_id", "RECORD_CP_EVENT", "CP_TOPIC"]

#: the record kind of a generation event on stdout (and on ``<prefix>/rsu/events``)
RECORD_CP_EVENT = "cp_event"
#: the CP service's MQTT topics: ``<output-prefix>/<CP_TOPIC>/cpm``, ``.../sdsm``, ``.../events``
CP_TOPIC = "rsu"


@dataclass(frozen=True)
class CpServeOptions:
    """The options of ``serve --cp-service`` (docs/service.md).

    t_gen_cpm_ms : int                 ``T_GenCpm``, the generation event period (100..1000 ms)
    cpm_max_bytes : int                a CPM larger than this (UPER bytes) is split into segments
    region_max_semi_major_m : float    the perception regions' limit on the 95 % ellipse's semi-major axis (m)
    per_camera_output : bool           write every camera frame's record too (a debugging output)
    """

    t_gen_cpm_ms: int = 100
    cpm_max_bytes: int = 1100
    region_max_semi_major_m: float = 1.0
    per_camera_output: bool = True

    def __post_init__(self):
        t = as_int("--t-gen-cpm-ms", self.t_gen_cpm_ms, minimum=100, expected="an integer number of ms in 100..1000")
        if t > 1000:
            raise InputError("--t-gen-cpm-ms", self.t_gen_cpm_ms, "an integer number of ms in 100..1000")
        as_int("--cpm-max-bytes", self.cpm_max_bytes, minimum=64, expected="an integer >= 64 (bytes of UPER)")
        as_float("--region-max-semi-major-m", self.region_max_semi_major_m, positive=True)

    def rules(self) -> CpRules:
        return CpRules(t_gen_cpm_s=self.t_gen_cpm_ms / 1000.0, max_size_bytes=int(self.cpm_max_bytes))


def cp_cameras(entries: dict, *, max_semi_major_m: float = 1.0, log=None) -> list[CpCamera]:
    """The unit's cameras for :class:`~.cp_service.CpBasicService` from registry entries
    (:class:`~footprint_uq.io.registry.RegistryEntry` by camera id, or ``(camera, budget)`` pairs for one camera).

    ``sensor_id``: the entry's, else the camera's index in the sorted camera ids + 1 (one line naming both cameras
    where two end with the same id, or one beyond 255); the perception region computed from the camera and its
    budget (None, logged, where no point meets ``max_semi_major_m``: the camera's objects are sent, its region not).
    """
    cams, used = [], {}
    for k, cid in enumerate(sorted(entries, key=str)):
        e = entries[cid]
        camera, budget = (e.camera, e.budget) if hasattr(e, "camera") else e
        sid = getattr(e, "sensor_id", None)
        sid = k + 1 if sid is None else int(sid)
        if sid > 255:
            raise ConfigError(f"registry: {cid}: sensor_id", sid, "a sensor id in 0..255 (give sensor_id in the "
                              "registry: the default, the camera's index + 1, passes 255 beyond 255 cameras)")
        if sid in used:
            raise ConfigError(f"registry: {cid}: sensor_id", sid, f"a sensor id of its own (camera {used[sid]!r} "
                              "has it; explicit ids and the defaults, index + 1, must not meet)")
        used[sid] = cid
        region = perception_region(camera, budget, max_semi_major_m=max_semi_major_m)
        if region is None and log is not None:
            log(f"camera {cid}: no point of its image has a 95 % semi-major axis <= {max_semi_major_m} m: its "
                "CPMs' Sensor Information carries no perception region for it")
        cams.append(CpCamera(str(cid), sid, region, float(getattr(e, "clock_offset_sigma_s", 0.0)),
                             float(getattr(e, "clock_jitter_sigma_s", 0.0))))
    return cams


def unit_station_id(camera_ids) -> int:
    """The unit's default StationId: CRC-32 of its sorted camera ids joined by commas (stable, documented)."""
    return station_id_of(",".join(sorted(str(c) for c in camera_ids)))


class _Out(NamedTuple):
    """One output waiting for the sink: an error record (``event`` None) or a generation event."""

    record: dict | None
    event: CpEvent | None


class CpServe:
    """The CP basic service of one roadside unit inside ``serve`` (module doc).

    Parameters
    ----------
    service : Service
        With ``tracks=True``; its ``on_tracked`` hook is set to :meth:`on_tracked`.
    cameras : list of CpCamera
        :func:`cp_cameras`.
    options : CpServeOptions
    station_id : int
        The unit's StationId.
    cdd, heading_offset_deg, origin_lat_deg, origin_lon_deg
        As :class:`~.cp_service.CpBasicService` (the unit's map tie: one for all its cameras).
    camera_alias : str, optional
        One camera (``serve --camera``): every frame is that camera's, whatever its ``camera_id``.
    """

    def __init__(self, service: Service, cameras: list, options: CpServeOptions, *, station_id: int,
                 cdd: str, heading_offset_deg: float = 0.0, origin_lat_deg: float | None = None,
                 origin_lon_deg: float | None = None, camera_alias: str | None = None):
        if not service.tracks:
            raise InputError("--cp-service", "without --tracks", "--tracks too (the CP service fuses the cameras' "
                                                                 "tracks)")
        self.options = options
        self.cp = CpBasicService(cameras, station_id=int(station_id), rules=options.rules(), cdd=cdd,
                                 heading_offset_deg=heading_offset_deg, origin_lat_deg=origin_lat_deg,
                                 origin_lon_deg=origin_lon_deg)
        self._linearity = (service.linear_threshold if service.linearity else None)
        self._alias = camera_alias
        self._lock = threading.Lock()
        self._pending: list[_Out] = []
        self._own = {"frames_ingested": 0, "frame_errors": 0, "cpm_messages_published": 0, "internal_errors": 0}
        service.on_tracked = self.on_tracked

    # -- the worker thread: one tracked camera frame ------------------------------------------------------------
    def on_tracked(self, camera_id, frame, time_s: float, tracks, est, found) -> None:
        """The service's hook (:attr:`Service.on_tracked`): the frame's tracks into the CP service, then the
        generation event due at ``time_s``; both outputs wait for :meth:`drain`.  Never raises: an error of the
        CP service is the frame's error record (the frame's own record goes out all the same)."""
        src = "cp-service"
        try:
            linear_ok = None
            if self._linearity is not None and est.corners_nonlinearity is not None and len(est):
                worst, linear_ok = np.empty(len(est)), np.empty(len(est), np.bool_)
                worst_usable(est.corners_nonlinearity, est.corner_usable, self._linearity, worst, linear_ok)
            with self._lock:
                self._own["frames_ingested"] += 1
                cid = camera_id if self._alias is None else self._alias
                fused = self.cp.ingest(cid, time_s, tracks, class_id=found.classes, linear_ok=linear_ok,
                                       detection_confidence=found.class_confidence)
                if fused.error is not None:
                    self._own["frame_errors"] += 1
                    self._pending.append(_Out(error_record(fused.error, field="timestamp_s", camera_id=camera_id,
                                                           frame=frame, source=src), None))
                event = self.cp.poll(time_s)
                if event is not None:
                    self._pending.append(_Out(None, event))
        except (FootprintUQError, ValueError) as e:
            self._error(camera_id, frame, f"CP service: {e}", src)
        except Exception as e:  # noqa: BLE001 - a bug met by one frame is its error record, never fatal
            self._error(camera_id, frame, f"CP service internal error (please report): {type(e).__name__}: {e}",
                        src)

    def _error(self, camera_id, frame, reason: str, src: str) -> None:
        with self._lock:
            self._own["internal_errors"] += 1
            self._pending.append(_Out(error_record(reason, camera_id=camera_id, frame=frame, source=src), None))

    def count(self, key: str, n: int = 1) -> None:
        """Add ``n`` to this layer's count ``key`` (thread-safe; the health record reads it)."""
        with self._lock:
            self._own[key] += n

    def counts(self) -> dict:
        """The health record's ``cp_service``: :meth:`~.cp_service.CpBasicService.counts` and this layer's own
        (frames ingested, frame errors, CPM messages published, internal errors)."""
        with self._lock:
            return {**self.cp.counts(), **self._own}

    # -- the outputs ----------------------------------------------------------------------------------------
    def wrap(self, sink, *, mqtt: bool) -> _CpSink:
        """The transport's sink with the CP service's outputs written after each frame's record (and the frame's
        record left out with ``per_camera_output=False``)."""
        return _CpSink(sink, self, mqtt)

    def take(self) -> list[_Out]:
        with self._lock:
            out, self._pending = self._pending, []
            return out

    def event_record(self, ev: CpEvent, *, with_payloads: bool) -> dict:
        """The JSON record of a generation event: ``type`` ``cp_event``, then the CP service's own record
        (:class:`~.cp_service.CpEvent`: time, referenceTime, objects, counts) and, on stdout, the segments' UPER as
        hex (``cpm_uper_hex``, one string per segment) and the SDSM (``sdsm``, null without objects)."""
        rec = {"type": RECORD_CP_EVENT, **ev.record}
        if with_payloads:
            rec["cpm_uper_hex"] = [s.hex() for s in ev.segments]
            rec["sdsm"] = ev.sdsm
        return rec


class _CpSink:
    """A transport's sink (runner's stdout / MQTT / bag sinks) with the CP service's outputs (:meth:`CpServe.wrap`).

    After each frame's record: every pending error record (as the transport writes errors) and every generation
    event -- MQTT: each segment's bytes on ``<prefix>/rsu/cpm``, the SDSM on ``<prefix>/rsu/sdsm``, the record on
    ``<prefix>/rsu/events``; otherwise one ``cp_event`` JSON line."""

    def __init__(self, sink, cp: CpServe, mqtt: bool):
        self._sink = sink
        self._cp = cp
        self._mqtt = mqtt
        self._keep_frames = cp.options.per_camera_output

    def write(self, record: dict) -> None:
        self._sink.write(record)

    def write_json(self, kind, camera_id, data: bytes) -> None:
        if kind != RECORD_FOOTPRINTS or self._keep_frames:
            self._sink.write_json(kind, camera_id, data)
        self._drain()

    def write_cpm(self, camera_id, cpm_uper: bytes) -> None:
        if self._keep_frames:
            self._sink.write_cpm(camera_id, cpm_uper)

    def _drain(self) -> None:
        for out in self._cp.take():
            if out.event is None:
                self._sink.write_json(RECORD_ERROR, out.record.get("camera_id"), orjson.dumps(out.record))
                continue
            ev = out.event
            rec = self._cp.event_record(ev, with_payloads=not self._mqtt)
            if self._mqtt:
                for seg in ev.segments:
                    self._sink.publish(f"{CP_TOPIC}/cpm", seg)
                if ev.sdsm is not None:
                    self._sink.publish(f"{CP_TOPIC}/sdsm", orjson.dumps(ev.sdsm))
                self._sink.publish(f"{CP_TOPIC}/events", orjson.dumps(rec))
                self._cp.count("cpm_messages_published", len(ev.segments))
            else:
                self._sink.write_json(RECORD_CP_EVENT, None, orjson.dumps(rec))

    def close(self, timeout_s: float) -> None:
        self._drain()
        self._sink.close(timeout_s)


def cp_workers(workers: int | None, mqtt_registry: bool, log) -> int:
    """``--workers`` with ``--cp-service``: 1.  The fusion keeps one object list from every camera's tracks, in
    the frames' time order, so every camera runs in the one process that holds it: an explicit ``--workers N > 1``
    is refused in one line; the default (which would split a registry's cameras over processes) is 1, logged."""
    if workers is not None and workers > 1:
        raise InputError("--workers", workers, "1 with --cp-service (the fusion needs every camera's tracks in one "
                                               "process; docs/service.md, \"Workers\")")
    if workers is None and mqtt_registry:
        log("--workers 1: --cp-service fuses every camera in one process")
    return 1


def start_cp_service(service: Service, options: CpServeOptions, *, registry: dict | None, camera: tuple,
                     station_id: int | None, cdd: str, heading_offset_deg: float = 0.0,
                     origin_lat_deg: float | None = None, origin_lon_deg: float | None = None, log=None) -> CpServe:
    """The :class:`CpServe` of ``serve --cp-service`` (:func:`~.runner.run`): the cameras of ``registry`` (entries by
    id) or the one ``camera`` (``(camera_id or None, Camera)``, with the service's budget), their perception regions
    computed now; the unit's StationId ``station_id`` (default :func:`unit_station_id`); the unit's map tie
    (``heading_offset_deg``, origin) -- a registry entry with another one is refused (the fused list has one
    frame)."""
    if not service.tracks:
        raise InputError("--cp-service", "without --tracks", "--tracks too (the CP service fuses the cameras' tracks)")
    if registry is not None:
        entries = registry
        for cid, e in entries.items():
            for key, unit in (("heading_offset_deg", heading_offset_deg), ("origin_lat_deg", origin_lat_deg),
                              ("origin_lon_deg", origin_lon_deg)):
                own = getattr(e, key, None)
                if own is not None and own != unit:
                    raise ConfigError(f"registry: {cid}: {key}", own, f"the unit's value ({unit}, from the command "
                                      "line): --cp-service fuses every camera into one list, in one map tie")
    else:
        cid, cam = camera
        entries = {cid if cid is not None else "camera": (cam, service.cameras[cid].processor.budget)}
    if CP_TOPIC in entries:
        raise ConfigError("camera_id", CP_TOPIC, f"another camera id with --cp-service (the unit's topics are "
                                                 f"<prefix>/{CP_TOPIC}/...)")
    if log is not None:
        log(f"CP service: {len(entries)} camera(s), perception regions (95 % semi-major <= "
            f"{options.region_max_semi_major_m} m), T_GenCpm {options.t_gen_cpm_ms} ms, CPM segments <= "
            f"{options.cpm_max_bytes} bytes")
    cams = cp_cameras(entries, max_semi_major_m=options.region_max_semi_major_m, log=log)
    sid = unit_station_id(entries) if station_id is None else int(station_id)
    _check_room(cams, options, sid, cdd, heading_offset_deg)
    alias = None if registry is not None else cams[0].camera_id
    return CpServe(service, cams, options, station_id=sid, cdd=cdd, heading_offset_deg=heading_offset_deg,
                   origin_lat_deg=origin_lat_deg, origin_lon_deg=origin_lon_deg, camera_alias=alias)


def _check_room(cams: list, options: CpServeOptions, station_id: int, cdd: str, heading_offset_deg: float) -> None:
    """Refuse at start, in one line, a ``--cpm-max-bytes`` that cannot work for these cameras: a segment too small
    for one camera's Sensor Information and Perception Region entries and the largest object
    (:func:`largest_object_bytes`), or cameras whose entries need more than 8 segments
    (:func:`~.cp_segments.sensor_groups`; the sizes from real encodings of the cameras' entries).  A limit that holds
    every camera's entries only over several segments works: an event spreads them over its segments."""
    probe = CpBasicService(cams, station_id=station_id, rules=options.rules(), cdd=cdd,
                           heading_offset_deg=heading_offset_deg)

    def skeleton(k: int, info, regions) -> dict:
        return build_cpm(station_id, 0, [], segmentation=(k + 1, MAX_SEGMENTS), sensor_information=info,
                         perception_regions=regions)

    try:
        sensor_groups(probe.regions, skeleton, cdd=cdd, max_size_bytes=options.cpm_max_bytes,
                      reserve_bits=8 * largest_object_bytes(len(cams), cdd))
    except InputError as e:
        raise InputError("--cpm-max-bytes", options.cpm_max_bytes, f"{e.expected} ({len(cams)} camera(s))") from None


def largest_object_bytes(n_cameras: int, cdd: str) -> int:
    """The most bytes one PerceivedObject takes (:func:`~.messages.uper_cpm.object_bits`): velocity, angle, age,
    correlation, quality, the widest class of the release and a ``sensorIdList`` of every camera."""
    one = np.ones(1, np.int64)
    motion = MotionCodes(*(one for _ in MotionCodes._fields))
    width = max(class_bits(object_class_json(spec, cdd), cdd)[1] for spec in set(CPM_CLASS_OF.values()))
    bits = object_bits(np.zeros(1, np.int64), np.array([width]), cdd=cdd, motion=motion, quality=np.array([15]),
                       sensor_ids=[list(range(max(int(n_cameras), 1)))])
    return -(-int(bits[0]) // 8)
