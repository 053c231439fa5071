"""The Collective Perception basic service's rules, apart from any codec: when a CPM is generated, which objects it
includes, when the Sensor Information container goes with it, and how a large CPM is split into segments.

This module decides; it encodes nothing (the writers in :mod:`.messages` do), in the way vanetza and ms-van3t keep
a CP basic service apart from its ASN.1 codec.  Everything works on columns (one array entry per object).

Rules (ETSI TS 103 324 V2.1.1, clause 6.1 "CPM generation", and the thresholds the open implementations use:
ms-van3t's ``CPBasicService``, OpenCDA's ``CPservice``, Artery's ``CpService``):

=================================  ==================================================================================
generation event                   every ``t_gen_cpm_s`` (``T_GenCpm``, 0.1 to 1 s, default 0.1 s) from the first
                                   one; a CPM is sent at an event when it has objects to include, and at least every
                                   ``t_gen_cpm_max_s`` (``T_GenCpmMax``, default 1 s) even with none (then it
                                   carries the Sensor Information container and the perception regions: "I see
                                   nothing there" is information)
Sensor Information container       in the first CPM and then whenever ``sensor_info_interval_s`` (1 s) has passed
                                   since it was last sent
object inclusion (per object)      at an event, an object is included when any of:
                                   - it has never been included (new objects at once);
                                   - its position moved more than ``position_change_m`` (4 m) since it was last
                                     included;
                                   - its speed changed by more than ``speed_change_mps`` (0.5 m/s);
                                   - its heading (direction of motion) turned by more than ``heading_change_deg``
                                     (4 deg);
                                   - ``max_interval_s`` (1 s) has passed since it was last included, or
                                     ``vru_max_interval_s`` (0.5 s) for persons and animals (the VRU classes)
segmentation                       when the encoded CPM exceeds ``max_size_bytes`` (default 1,100 bytes of UPER),
                                   its objects are split into consecutive segments that each fit, every object in
                                   exactly one segment; ``MessageSegmentationInfo`` numbers them (1..8 segments:
                                   ``CardinalNumber3b``); objects that do not fit in 8 segments are counted as not
                                   sent at this event, never dropped silently (they stay due at the next event)
=================================  ==================================================================================

An unknown speed or heading (NaN) never triggers its rule by itself (NaN compares false); such an object is still
included by the position and time rules.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._checks import as_float, as_int
from ..errors import InputError

__all__ = ["CpRules", "GenerationClock", "InclusionMemory", "plan_segments", "MAX_SEGMENTS", "INCLUSION_REASONS"]

#: times closer than this are equal (s): unix times near 1.7e9 s resolve to ~2.4e-7 s, so a frame stamped on an
#: event's grid may compute a hair before it; far below any frame period
TIME_TOLERANCE_S = 1e-6
#: ``MessageSegmentationInfo.totalMsgNo`` is a ``CardinalNumber3b`` (1..8)
MAX_SEGMENTS = 8
#: why an event includes an object (:meth:`InclusionMemory.reasons`: the index; 0 = not due), the first rule that
#: holds in this order
INCLUSION_REASONS = ("not_due", "new", "interval", "position", "speed", "heading")


@dataclass(frozen=True)
class CpRules:
    """The generation and inclusion thresholds (see the module doc; the defaults are the usual ones)."""

    t_gen_cpm_s: float = 0.1
    t_gen_cpm_max_s: float = 1.0
    sensor_info_interval_s: float = 1.0
    position_change_m: float = 4.0
    speed_change_mps: float = 0.5
    heading_change_deg: float = 4.0
    max_interval_s: float = 1.0
    vru_max_interval_s: float = 0.5
    max_size_bytes: int = 1100

    def __post_init__(self):
        t = as_float("t_gen_cpm_s", self.t_gen_cpm_s)
        if not 0.1 <= t <= 1.0:
            raise InputError("t_gen_cpm_s", self.t_gen_cpm_s, "T_GenCpm between 0.1 and 1 s")
        if not as_float("t_gen_cpm_max_s", self.t_gen_cpm_max_s) >= t:
            raise InputError("t_gen_cpm_max_s", self.t_gen_cpm_max_s, f"T_GenCpmMax >= T_GenCpm ({t} s)")
        for name in ("sensor_info_interval_s", "position_change_m", "speed_change_mps", "heading_change_deg",
                     "max_interval_s", "vru_max_interval_s"):
            as_float(name, getattr(self, name), positive=True)
        as_int("max_size_bytes", self.max_size_bytes, minimum=64, expected="a CPM size limit of at least 64 bytes")


@dataclass
class GenerationClock:
    """When generation events fall, and what each event must carry (one per roadside unit).

    ``tick(t_s)`` is called with the service's clock; it answers whether ``t_s`` is a generation event (the first
    call is one; then every ``t_gen_cpm_s``, on a fixed grid so that late calls do not drift the rate).
    """

    rules: CpRules = field(default_factory=CpRules)
    _origin_s: float | None = None
    _next_k: int = 0
    _last_cpm_s: float | None = None
    _last_sensor_info_s: float | None = None

    @property
    def _next_s(self) -> float | None:
        """The next event's time: the first call's time + k T_GenCpm (computed, never accumulated)."""
        return None if self._origin_s is None else self._origin_s + self._next_k * self.rules.t_gen_cpm_s

    def tick(self, t_s: float) -> bool:
        t = as_float("t_s", t_s)
        if self._origin_s is None:
            self._origin_s = t
        if t + TIME_TOLERANCE_S < self._next_s:
            return False
        # the next event on the grid after t (a late call skips the events it missed: they are not made up)
        self._next_k = int(np.floor((t - self._origin_s + TIME_TOLERANCE_S) / self.rules.t_gen_cpm_s)) + 1
        return True

    def must_send(self, t_s: float) -> bool:
        """At an event: a CPM is owed even with no object (``T_GenCpmMax`` since the last one)."""
        return self._last_cpm_s is None or t_s - self._last_cpm_s >= self.rules.t_gen_cpm_max_s - TIME_TOLERANCE_S

    def sensor_info_due(self, t_s: float) -> bool:
        return (self._last_sensor_info_s is None
                or t_s - self._last_sensor_info_s >= self.rules.sensor_info_interval_s - TIME_TOLERANCE_S)

    def sent(self, t_s: float, *, sensor_info: bool) -> None:
        """Record a CPM sent at ``t_s`` (with the Sensor Information container or not)."""
        self._last_cpm_s = float(t_s)
        if sensor_info:
            self._last_sensor_info_s = float(t_s)


def _angle_diff_deg(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + 180.0) % 360.0 - 180.0)


@dataclass
class InclusionMemory:
    """What was sent of every object the last time it was included: the state the inclusion rules compare with.

    Keyed by the object's id (the ``objectId`` it keeps across CPMs), looked up on sorted columns (no per-object
    Python).  ``forget(ids)`` drops objects that ended.
    """

    rules: CpRules = field(default_factory=CpRules)
    _ids: np.ndarray = field(default_factory=lambda: np.empty(0, dtype=np.int64))   # sorted
    _t: np.ndarray = field(default_factory=lambda: np.empty(0))
    _xy: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    _speed: np.ndarray = field(default_factory=lambda: np.empty(0))
    _heading: np.ndarray = field(default_factory=lambda: np.empty(0))

    def _rows(self, ids: np.ndarray) -> np.ndarray:
        """Row of every id in the memory, -1 where it is not there."""
        pos = np.searchsorted(self._ids, ids)
        pos_c = np.minimum(pos, max(len(self._ids) - 1, 0))
        found = (pos < len(self._ids)) & (self._ids[pos_c] == ids) if len(self._ids) else np.zeros(len(ids), bool)
        return np.where(found, pos_c, -1)

    def select(self, t_s: float, ids, xy_m, speed_mps, heading_deg, is_vru) -> np.ndarray:
        """Which objects an event at ``t_s`` includes: bool ``(n,)`` (see the module doc's rules).

        Parameters
        ----------
        ids : array_like of int (n,)
        xy_m : array_like (n, 2)
            Positions (m, any fixed ground frame).
        speed_mps, heading_deg : array_like (n,)
            Speed (m/s) and direction of motion (deg); NaN = unknown.
        is_vru : array_like of bool (n,)
            Persons and animals (the 0.5 s rule).
        """
        return self.reasons(t_s, ids, xy_m, speed_mps, heading_deg, is_vru) > 0

    def reasons(self, t_s: float, ids, xy_m, speed_mps, heading_deg, is_vru) -> np.ndarray:
        """:meth:`select` with the reason: int ``(n,)``, the index in :data:`INCLUSION_REASONS` of the first rule
        that includes the object (new, interval, position, speed, heading), 0 where none does."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        rows = self._rows(ids)
        new = rows < 0
        out = np.where(new, 1, 0).astype(np.int64)
        if np.all(new):
            return out
        r = np.where(new, 0, rows)
        limit = np.where(np.asarray(is_vru, dtype=bool), self.rules.vru_max_interval_s, self.rules.max_interval_s)
        with np.errstate(invalid="ignore"):
            tests = (t_s - self._t[r] >= limit - TIME_TOLERANCE_S,
                     np.linalg.norm(xy - self._xy[r], axis=1) > self.rules.position_change_m,
                     np.abs(np.asarray(speed_mps, dtype=float) - self._speed[r]) > self.rules.speed_change_mps,
                     _angle_diff_deg(heading_deg, self._heading[r]) > self.rules.heading_change_deg)
        for code, hit in zip(range(len(tests) + 1, 1, -1), tests[::-1], strict=True):
            out = np.where(~new & hit, code, out)
        return out

    def last_included_s(self, ids) -> np.ndarray:
        """When each object was last included (s; -inf where never): the order in which an event fills its
        segments (the longest-waiting first, so that objects left over by a full event are sent first next)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        rows = self._rows(ids)
        return np.where(rows >= 0, self._t[np.maximum(rows, 0)] if len(self._t) else -np.inf, -np.inf)

    def included(self, t_s: float, ids, xy_m, speed_mps, heading_deg) -> None:
        """Record the objects a CPM sent at ``t_s`` actually carried (ids unique)."""
        ids = np.asarray(ids, dtype=np.int64).reshape(-1)
        fresh = np.unique(ids[self._rows(ids) < 0])
        if len(fresh):
            keep = np.concatenate([self._ids, fresh])
            order = np.argsort(keep, kind="stable")
            self._ids = keep[order]
            grow = len(fresh)
            self._t = np.concatenate([self._t, np.zeros(grow)])[order]
            self._xy = np.concatenate([self._xy, np.zeros((grow, 2))])[order]
            self._speed = np.concatenate([self._speed, np.full(grow, np.nan)])[order]
            self._heading = np.concatenate([self._heading, np.full(grow, np.nan)])[order]
        rows = self._rows(ids)
        self._t[rows] = t_s
        self._xy[rows] = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
        # an unknown value keeps the last known one (so that it cannot trigger the change rules)
        for col, v in ((self._speed, speed_mps), (self._heading, heading_deg)):
            v = np.asarray(v, dtype=np.float64).reshape(-1)
            ok = np.isfinite(v)
            col[rows[ok]] = v[ok]

    def forget(self, ids) -> None:
        self._keep(~np.isin(self._ids, np.asarray(ids, dtype=np.int64)))

    def retain(self, ids) -> None:
        """Forget every object but ``ids`` (the live ones: an ended object's id may be handed out again)."""
        self._keep(np.isin(self._ids, np.asarray(ids, dtype=np.int64)))

    def _keep(self, keep: np.ndarray) -> None:
        self._ids, self._t, self._xy = self._ids[keep], self._t[keep], self._xy[keep]
        self._speed, self._heading = self._speed[keep], self._heading[keep]

    def __len__(self) -> int:
        return len(self._ids)


def plan_segments(object_bytes, *, header_bytes, max_size_bytes: int = 1100,
                  max_segments: int = MAX_SEGMENTS) -> tuple[list[np.ndarray], np.ndarray]:
    """Split objects into CPM segments of at most ``max_size_bytes`` each, in their order.

    Parameters
    ----------
    object_bytes : array_like of int (n,)
        The encoded size of every object (bytes, upper bound: its bits rounded up).
    header_bytes : int or sequence of int
        The size of a segment without objects (header, management container, the containers the segment carries;
        upper bound): one value for every segment, or one per segment (segment ``k`` uses ``header_bytes[k]``, the
        segments beyond the sequence its last value) -- the segments that carry the cameras' containers have larger
        headers than the others.

    Returns
    -------
    segments : list of int arrays
        The object indices of each segment (consecutive, each object in exactly one), at most ``max_segments``;
        one empty segment when there are no objects.  An object that does not fit the room left in a segment
        starts the next one (a segment with a large header may stay without objects).
    not_sent : int array
        The indices of objects beyond ``max_segments`` full segments (counted by the caller, sent at the next
        event).  An object larger than the room of an empty segment raises :class:`InputError`.
    """
    sizes = np.asarray(object_bytes, dtype=np.int64).reshape(-1)
    heads = np.atleast_1d(np.asarray(header_bytes, dtype=np.int64)).tolist()
    rooms = [int(max_size_bytes) - h for h in heads]
    room_last = rooms[-1]
    if np.any(sizes > max(rooms)):
        i = int(np.argmax(sizes > max(rooms)))
        raise InputError(f"object_bytes[{i}]", int(sizes[i]), f"an object that fits a segment ({max(rooms)} bytes)")
    segments, start, used = [], 0, 0
    for i, s in enumerate(sizes.tolist()):
        while used + s > (rooms[len(segments)] if len(segments) < len(rooms) else room_last):
            if used == 0 and len(segments) >= len(rooms) - 1:
                raise InputError(f"object_bytes[{i}]", s, f"an object that fits a segment ({room_last} bytes)")
            segments.append(np.arange(start, i))
            if len(segments) == max_segments:
                return segments, np.arange(i, len(sizes))
            start, used = i, 0
        used += s
    segments.append(np.arange(start, len(sizes)))
    return segments, np.arange(0)
