"""One generation event of the CP basic service as its CPM segments (ETSI TS 103 324 V2.1.1), and the objects'
``objectPerceptionQuality``.

:func:`event_segments` takes the objects an event includes (already selected by
:class:`~footprint_uq.service.cp_rules.InclusionMemory`, as columns of message codes: :class:`CpmObjectColumns`)
and the cameras' perception regions (:class:`SensorRegion`), and writes the event's CPMs:

* the sizes come from the real encoding: every object's bits (:func:`~.messages.uper_cpm.object_bits`, the bits
  the writer emits) and the bits of a segment without objects (the encoded message), split by
  :func:`~footprint_uq.service.cp_rules.plan_segments` into segments of at most ``max_size_bytes``; every written
  segment is checked against the limit;
* every segment is a complete CPM (header, management container, the originating RSU container, a Perceived Object
  Container); with more than one segment each carries ``segmentationInfo`` (``thisMsgNo`` / ``totalMsgNo``);
  every object is in exactly one segment, in the given order; objects beyond 8 full segments are returned as
  ``not_sent`` (the caller counts them; they stay due at the next event);
* the Sensor Information container (one ``SensorInformation`` per camera: ``sensorType`` monovideo, the region's
  polygon, ``perceptionRegionConfidence``, ``shadowingApplies``) and the Perception Region container (the same
  polygons, ``sensorIdList`` = the camera) go with an event when the
  :class:`~footprint_uq.service.cp_rules.GenerationClock` says they are due (at least once a second): whole in the
  **first** segment when every camera's entries fit there with room for the event's largest object; otherwise
  spread over the first segments, camera by camera (:func:`sensor_groups`: a camera's two entries always in the
  same segment, each segment's two containers listing the cameras of that segment), the objects filling the room
  left.  The polygons are never cut for size: each is the region's own (<= 16 vertices, already conservative);
* at an event with no objects a CPM is written only when ``T_GenCpmMax`` has passed since the last one
  (:meth:`~footprint_uq.service.cp_rules.GenerationClock.must_send`); the event is recorded on the clock.

``objectPerceptionQuality`` (:func:`object_perception_quality`) is **the project's rule**: TS 103 324 clause
7.1.8.6 names its inputs (detection confidence, object age, detection success rate) but the clause's text was not
available to us, so the rule is ours and is documented in docs/service.md ("The CPM's containers").
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..errors import InputError
from ..products.perception_region import PerceptionRegion, polygon_east_north_cm
from .cp_rules import MAX_SEGMENTS, CpRules, GenerationClock, plan_segments
from .messages.asn1_cpm import DEFAULT_CDD, SENSOR_TYPE_MONOVIDEO
from .messages.cpm import (
    LATITUDE_UNAVAILABLE,
    LONGITUDE_UNAVAILABLE,
    build_cpm,
    check_cdd,
    perception_region_entry,
    polygonal_shape,
    sensor_information,
)
from .messages.motion import MotionCodes
from .messages.uper_cpm import (
    encode_cpm_uper_fast,
    object_bits,
    perceived_object_container_uper_arrays,
    sensor_id_columns,
)

__all__ = ["object_perception_quality", "QUALITY_AGE_FULL_S", "CpmObjectColumns", "SensorRegion", "sensor_region",
           "EventSegments", "event_segments", "sensor_groups"]

#: the age (s) from which an object's age no longer lowers its quality (the CDD's ``objectAge`` note: "1500
#: indicates that the object has been observed for more than 1.5 s")
QUALITY_AGE_FULL_S = 1.5
#: the factor an unknown input (NaN) stands for
QUALITY_UNKNOWN_FACTOR = 0.5
#: the highest quality of an object whose centre is not ``linear_ok``
QUALITY_MAX_NONLINEAR = 14


def object_perception_quality(detection_confidence, age_s, detection_rate, linear_ok) -> np.ndarray:
    """``objectPerceptionQuality`` (0..15, int ``(n,)``) by the project's rule (see the module doc).

    ``q = floor(15 * c * a * r)`` with

    * ``c`` the detection confidence (0..1; unknown: 0.5);
    * ``a = 0.5 + 0.5 * min(age_s / 1.5 s, 1)`` (a new object counts half; from 1.5 s on, fully; unknown: 0.5);
    * ``r`` the detection success rate (0..1: the share of the track's frames in which a camera detected the
      object; unknown: 0.5);

    then at most 14 where the centre is not ``linear_ok`` (its covariance is a linearisation that cannot be
    trusted).  15 ("full confidence") needs all three at 1 and a linear centre; 0 ("no confidence") is what a
    zero confidence or a never-detected track gives.

    Parameters
    ----------
    detection_confidence, age_s, detection_rate : array_like (n,)
        Floats, NaN = unknown; confidence and rate in [0, 1], age >= 0 (s).
    linear_ok : array_like of bool (n,)
    """
    c = np.asarray(detection_confidence, dtype=np.float64).reshape(-1)
    n = len(c)
    age = np.asarray(age_s, dtype=np.float64).reshape(-1)
    r = np.asarray(detection_rate, dtype=np.float64).reshape(-1)
    lin = np.asarray(linear_ok, dtype=bool).reshape(-1)
    for name, a, hi in (("detection_confidence", c, 1.0), ("age_s", age, np.inf), ("detection_rate", r, 1.0)):
        if a.shape != (n,):
            raise InputError(name, a.shape, f"one value per object ({n})")
        bad = np.flatnonzero(~np.isnan(a) & ~((a >= 0.0) & (a <= hi)))
        if len(bad):
            raise InputError(f"{name}[{bad[0]}]", float(a[bad[0]]), f"a number in [0, {hi}] or NaN (unknown)")
    if lin.shape != (n,):
        raise InputError("linear_ok", lin.shape, f"one value per object ({n})")
    u = QUALITY_UNKNOWN_FACTOR
    a = np.where(np.isnan(age), u, 0.5 + 0.5 * np.minimum(np.nan_to_num(age) / QUALITY_AGE_FULL_S, 1.0))
    q = np.floor(15.0 * np.where(np.isnan(c), u, c) * a * np.where(np.isnan(r), u, r) + 1e-9)
    q = np.where(lin, q, np.minimum(q, QUALITY_MAX_NONLINEAR))
    return np.clip(q, 0, 15).astype(np.int64)


@dataclass(frozen=True)
class CpmObjectColumns:
    """The message codes of the objects of one event (int arrays ``(n,)``, one entry per object).

    ``object_id`` (0..65535), ``x_cm`` / ``y_cm`` (east / north of the reference position,
    :func:`~.messages.cpm.coordinate_cm`), ``x_conf`` / ``y_conf`` / ``xy_corr``
    (:func:`footprint_uq.products.v2x.cpm_fields`), ``class_value`` / ``class_width`` / ``class_level``
    (:func:`~.messages.uper_cpm.class_bits` and the ConfidenceLevel; width 0: no classification); optional
    ``motion`` (:class:`~.messages.motion.MotionCodes`), ``measurement_delta_ms`` (default 0), ``quality``
    (:func:`object_perception_quality`; -1: not sent) and ``sensor_ids`` (one list per object, or the
    (pointers, ids) pair of :func:`~.messages.uper_cpm.sensor_id_columns`).
    """

    object_id: np.ndarray
    x_cm: np.ndarray
    y_cm: np.ndarray
    x_conf: np.ndarray
    y_conf: np.ndarray
    xy_corr: np.ndarray
    class_value: np.ndarray
    class_width: np.ndarray
    class_level: np.ndarray
    motion: MotionCodes | None = None
    measurement_delta_ms: np.ndarray | None = None
    quality: np.ndarray | None = None
    sensor_ids: object = None

    def __post_init__(self):
        n = len(np.asarray(self.object_id).reshape(-1))
        for name in ("object_id", "x_cm", "y_cm", "x_conf", "y_conf", "xy_corr", "class_value", "class_width",
                     "class_level", "measurement_delta_ms", "quality"):
            v = getattr(self, name)
            if v is None:
                continue
            a = np.asarray(v)
            if a.shape != (n,) or not (np.issubdtype(a.dtype, np.integer) or np.issubdtype(a.dtype, np.bool_)):
                raise InputError(name, f"{a.dtype} {a.shape}", f"integer codes of shape ({n},)")
            object.__setattr__(self, name, a.astype(np.int64))
        object.__setattr__(self, "sensor_ids", sensor_id_columns(self.sensor_ids, n))
        if self.motion is not None and any(len(a) != n for a in self.motion):
            raise InputError("motion", [len(a) for a in self.motion], f"MotionCodes of {n} objects")

    def __len__(self) -> int:
        return len(self.object_id)

    def take(self, index) -> CpmObjectColumns:
        """The objects ``index`` (int array), in that order."""
        idx = np.asarray(index, dtype=np.int64)
        ptr, val = self.sensor_ids
        starts = ptr[idx]
        lens = ptr[idx + 1] - starts
        new_ptr = np.concatenate([[0], np.cumsum(lens)]).astype(np.int64)
        sub_val = val[np.repeat(starts - new_ptr[:-1], lens) + np.arange(new_ptr[-1])]
        pick = {name: None if getattr(self, name) is None else getattr(self, name)[idx]
                for name in ("object_id", "x_cm", "y_cm", "x_conf", "y_conf", "xy_corr", "class_value",
                             "class_width", "class_level", "measurement_delta_ms", "quality")}
        motion = None if self.motion is None else MotionCodes(*(a[idx] for a in self.motion))
        return replace(self, **pick, motion=motion, sensor_ids=(new_ptr, sub_val.astype(np.int64)))

    def container_uper(self, cdd: str, number_of_perceived_objects: int) -> bytes:
        """The Perceived Object Container of these objects (the compiled writer)."""
        return perceived_object_container_uper_arrays(
            self.object_id, self.x_cm, self.x_conf, self.y_cm, self.y_conf, self.xy_corr, self.class_value,
            self.class_width, self.class_level, cdd=cdd, motion=self.motion,
            measurement_delta_ms=self.measurement_delta_ms, quality=self.quality, sensor_ids=self.sensor_ids,
            number_of_perceived_objects=number_of_perceived_objects)

    def bits(self, cdd: str) -> np.ndarray:
        """Every object's encoded bits (:func:`~.messages.uper_cpm.object_bits`)."""
        return object_bits(self.xy_corr, self.class_width, cdd=cdd, motion=self.motion, quality=self.quality,
                           sensor_ids=self.sensor_ids)


@dataclass(frozen=True)
class SensorRegion:
    """A camera as the CPM describes it: its ``sensorId`` (0..255), its perception region's polygon as east/north
    offsets from the CPM's reference position (0.01 m, ``(M, 2)``, 3 <= M <= 16), the region's confidence
    (``ConfidenceLevel``, percent) and ``shadowingApplies`` (a camera does not see behind what it sees: True by
    default).  ``polygon_east_north_cm`` None: a camera without a region (no pixel meets the limit, or none was
    computed): its ``SensorInformation`` carries no shape and no confidence, and it has no Perception Region
    entry."""

    sensor_id: int
    polygon_east_north_cm: np.ndarray | None
    confidence_pct: int = 95
    shadowing_applies: bool = True
    sensor_type: int = SENSOR_TYPE_MONOVIDEO

    def shape(self) -> dict | None:
        if self.polygon_east_north_cm is None:
            return None
        return polygonal_shape(np.asarray(self.polygon_east_north_cm))


def sensor_region(sensor_id: int, region: PerceptionRegion, reference_xy_world_m, heading_offset_deg: float = 0.0,
                  *, shadowing_applies: bool = True) -> SensorRegion:
    """A camera's :class:`SensorRegion` from its :func:`~footprint_uq.products.perception_region.perception_region`:
    the polygon in the CPM's east/north offsets from the reference position (``reference_xy_world_m``, W; the
    compass bearing of W's +y axis ``heading_offset_deg``), the confidence the region was computed for (95 %)."""
    poly = polygon_east_north_cm(region.polygon_xy_world_m, reference_xy_world_m, heading_offset_deg)
    return SensorRegion(int(sensor_id), poly, int(round(100.0 * region.confidence)), bool(shadowing_applies))


@dataclass(frozen=True)
class EventSegments:
    """The CPMs of one generation event.

    Attributes
    ----------
    payloads : list of bytes
        The UPER of every segment (empty: no CPM at this event).
    segments : list of int arrays
        The objects (indices into the event's columns) of each segment.
    not_sent : int array
        Objects beyond 8 full segments (not sent at this event).
    sensor_information : bool
        Whether the event carries the Sensor Information and Perception Region containers.
    sensor_segments : list of int arrays
        The cameras (indices into the event's regions) whose Sensor Information and Perception Region entries each
        segment carries (:func:`sensor_groups`; empty arrays when the containers are not due).
    """

    payloads: list
    segments: list
    not_sent: np.ndarray
    sensor_information: bool
    sensor_segments: list = field(default_factory=list)


def _sensor_containers(regions: list[SensorRegion]) -> tuple[list[dict], list[dict | None]]:
    """The Sensor Information entry of every camera and its Perception Region entry (None for a camera without a
    region: it has none)."""
    if not regions:
        raise InputError("regions", 0, "at least one camera (the Sensor Information container needs one)")
    if len({r.sensor_id for r in regions}) != len(regions):
        raise InputError("regions.sensor_id", [r.sensor_id for r in regions], "unique sensor ids")
    shapes = [r.shape() for r in regions]
    info = [sensor_information(r.sensor_id, sh, None if sh is None else r.confidence_pct, r.shadowing_applies,
                               r.sensor_type) for r, sh in zip(regions, shapes, strict=True)]
    pr = [None if sh is None else perception_region_entry(sh, r.confidence_pct, r.shadowing_applies,
                                                          sensor_ids=[r.sensor_id])
          for r, sh in zip(regions, shapes, strict=True)]
    return info, pr


def _group_containers(info: list[dict], pr: list[dict | None], group) -> tuple[list[dict] | None, list[dict] | None]:
    """The two containers' entries of the cameras ``group`` (None: the container is left out)."""
    if group is None or len(group) == 0:
        return None, None
    regions = [pr[i] for i in group if pr[i] is not None]
    return [info[i] for i in group], (regions or None)


def _head_bits(skeleton: dict, cdd: str) -> int:
    """A segment's bits without objects, as an upper bound: the message with an empty object container
    (3 octets: 18 bits), less those 3 octets, plus the container's 18 bits, its padding (<= 7) and a longer
    length determinant (<= 8)."""
    return 8 * len(encode_cpm_uper_fast(skeleton, cdd=cdd)) - 24 + 18 + 7 + 8


def sensor_groups(regions: list[SensorRegion], skeleton, *, cdd: str, max_size_bytes: int,
                  reserve_bits: int = 0) -> list[np.ndarray]:
    """Which cameras' Sensor Information and Perception Region entries go into which of an event's segments.

    The cameras, in their order, fill consecutive segments: a segment takes cameras while its encoded size
    without objects (``skeleton(k, info, regions)``: the CPM of segment ``k`` with those containers, segmentation
    info included) plus ``reserve_bits`` (room kept for an object: the event's largest) stays within
    ``max_size_bytes``.  Every camera's two entries go into the same segment, so a receiver that gets one segment
    has the whole description of its cameras.  When they all fit, that is one group: the first segment carries
    both containers whole.

    Returns
    -------
    list of int arrays
        The camera indices of segment 0, 1, ... (at most :data:`~.cp_rules.MAX_SEGMENTS` groups).

    Raises
    ------
    InputError
        ``max_size_bytes``: one camera's entries and the reserved object do not fit a segment, or the groups need
        more than 8 segments (the limit cannot work for these cameras).
    """
    info, pr = _sensor_containers(regions)
    limit_bits = 8 * int(max_size_bytes)
    groups, start = [], 0
    while start < len(regions):
        if len(groups) == MAX_SEGMENTS:
            raise InputError("max_size_bytes", max_size_bytes,
                             f"room for the Sensor Information and Perception Region entries of {len(regions)} "
                             f"cameras in {MAX_SEGMENTS} segments (with an object of {-(-reserve_bits // 8)} bytes)")
        stop = start
        while stop < len(regions):
            bits = _head_bits(skeleton(len(groups), *_group_containers(info, pr, range(start, stop + 1))), cdd)
            if bits + reserve_bits > limit_bits:
                break
            stop += 1
        if stop == start:
            need = -(-(bits + reserve_bits) // 8)
            raise InputError("max_size_bytes", max_size_bytes,
                             f"at least {need} bytes: a segment with the Sensor Information and Perception Region "
                             f"entries of sensor {regions[start].sensor_id} and an object of "
                             f"{-(-reserve_bits // 8)} bytes")
        groups.append(np.arange(start, stop))
        start = stop
    return groups


def _plan(bits: np.ndarray, heads: list[int], max_size_bytes: int, n_groups: int):
    """:func:`~.cp_rules.plan_segments` in bits: segment ``k`` with header ``heads[k]`` (the last value for the
    segments beyond), then empty segments up to ``n_groups`` (every group of cameras gets its segment, with or
    without objects)."""
    largest = int(np.max(bits, initial=0))
    if heads[-1] + largest > 8 * max_size_bytes:
        raise InputError("max_size_bytes", max_size_bytes,
                         f"room for a segment's header ({-(-heads[-1] // 8)} bytes) and its largest object "
                         f"({-(-largest // 8)} bytes)")
    segments, not_sent = plan_segments(bits, header_bytes=heads, max_size_bytes=8 * max_size_bytes,
                                       max_segments=MAX_SEGMENTS)
    if not len(bits):
        segments = []
    segments += [np.zeros(0, np.int64) for _ in range(max(n_groups, 1) - len(segments))]
    return segments, not_sent


def event_segments(station_id: int, reference_time_ms: int, objects: CpmObjectColumns,
                   regions: list[SensorRegion], clock: GenerationClock, t_s: float, *, cdd: str = DEFAULT_CDD,
                   rules: CpRules | None = None, latitude: int = LATITUDE_UNAVAILABLE,
                   longitude: int = LONGITUDE_UNAVAILABLE,
                   number_of_perceived_objects: int | None = None) -> EventSegments:
    """The CPM segments of the generation event at ``t_s`` (s, the clock's time; ``reference_time_ms`` its
    ``TimestampIts``) with the selected ``objects`` and the cameras' ``regions`` (see the module doc).

    ``rules.max_size_bytes`` bounds every segment (default :class:`~.cp_rules.CpRules`: 1,100 bytes);
    ``number_of_perceived_objects``: the objects perceived at the event (default: those given).  The event is
    recorded on ``clock`` (:meth:`~.cp_rules.GenerationClock.sent`) when a CPM is written.
    """
    cdd = check_cdd(cdd)
    rules = clock.rules if rules is None else rules
    n = len(objects)
    if n == 0 and not clock.must_send(t_s):
        return EventSegments([], [], np.zeros(0, np.int64), False)
    due = clock.sensor_info_due(t_s)
    total = n if number_of_perceived_objects is None else int(number_of_perceived_objects)

    def skeleton(k: int, count: int, info=None, pr=None) -> dict:
        return build_cpm(station_id, reference_time_ms, [], latitude=latitude, longitude=longitude,
                         segmentation=None if count == 1 else (k + 1, count), sensor_information=info,
                         perception_regions=pr, number_of_perceived_objects=total)

    bits = objects.bits(cdd)
    groups, info, pr = [], None, None
    if due:
        info, pr = _sensor_containers(regions)
        groups = sensor_groups(regions, lambda k, i, r: skeleton(k, MAX_SEGMENTS, i, r), cdd=cdd,
                               max_size_bytes=rules.max_size_bytes, reserve_bits=int(np.max(bits, initial=0)))
    containers = [_group_containers(info, pr, g) for g in groups]
    heads = [_head_bits(skeleton(k, MAX_SEGMENTS, *c), cdd) for k, c in enumerate(containers)]
    heads.append(_head_bits(skeleton(min(len(groups), MAX_SEGMENTS - 1), MAX_SEGMENTS), cdd))
    segments, not_sent = _plan(bits, heads, rules.max_size_bytes, len(groups))
    payloads = []
    for k, idx in enumerate(segments):
        poc = objects.take(idx).container_uper(cdd, total)
        cont = containers[k] if k < len(containers) else (None, None)
        payload = encode_cpm_uper_fast(skeleton(k, len(segments), *cont), cdd=cdd, perceived_objects_uper=poc)
        if len(payload) > rules.max_size_bytes:  # the bound above is an upper bound: this is a bug if it fires
            raise RuntimeError(f"segment {k + 1} has {len(payload)} bytes > {rules.max_size_bytes}")
        payloads.append(payload)
    clock.sent(t_s, sensor_info=due)
    return EventSegments(payloads, segments, not_sent, due,
                         groups + [np.zeros(0, np.int64)] * (len(segments) - len(groups)))
