"""The fused SAE J3224 Sensor Data Sharing Message of one generation event, written from columns.

:class:`~footprint_uq.service.cp_service.CpBasicService` sends, beside the event's CPMs, one SDSM of the same fused
objects with the same time handling (J3224 has no segmentation and no inclusion rules: the SDSM is the unit's whole
object list at the event's time).  The layout, the field names and every code are those of
:mod:`.messages.sdsm` (:func:`~.messages.sdsm.sdsm_object`, :func:`~.messages.sdsm.build_sdsm`,
:func:`~.messages.sdsm.offset_dm`, :data:`~.messages.sdsm.SDSM_OBJECT_TYPES`); this module only builds the
objects from columns (one array per field) instead of one call per object, and bounds the list:

* at most :data:`MAX_SDSM_OBJECTS` (255) objects, in the given order; the rest are counted (returned), never
  dropped silently;
* ``measurementTime`` (``MeasurementTimeOffset``, ms relative to ``sDSMTimeStamp``, -1500..1500) is checked;
* no object: no SDSM (J3224's ``DetectedObjectList`` has at least one entry).
"""

from __future__ import annotations

import numpy as np

from ..errors import InputError
from ..products.v2x import J2735_POSITION_CONFIDENCE_NAMES
from .messages.motion import HEADING_CONFIDENCE_NAMES, SPEED_CONFIDENCE_NAMES, MotionCodes
from .messages.sdsm import HEADING_UNAVAILABLE, SDSM_OBJECT_TYPES, SPEED_UNAVAILABLE, build_sdsm

__all__ = ["fused_sdsm", "MAX_SDSM_OBJECTS", "MEASUREMENT_TIME_RANGE_MS", "sdsm_object_type"]

#: the most objects one fused SDSM carries (the rest are counted)
MAX_SDSM_OBJECTS = 255
#: J3224 ``MeasurementTimeOffset`` (ms)
MEASUREMENT_TIME_RANGE_MS = (-1500, 1500)


def sdsm_object_type(object_class) -> str:
    """J3224 ``ObjectType`` of a detector class name (:data:`~.messages.sdsm.SDSM_OBJECT_TYPES`; others
    ``"unknown"``)."""
    return SDSM_OBJECT_TYPES.get(str(object_class).lower() if object_class is not None else "", "unknown")


def _int_column(name: str, a, n: int) -> np.ndarray:
    arr = np.asarray(a)
    if arr.shape != (n,) or not np.issubdtype(arr.dtype, np.integer):
        raise InputError(name, f"{arr.dtype} {arr.shape}", f"integer codes of shape ({n},)")
    return arr.astype(np.int64)


def fused_sdsm(station_id: int, msg_count: int, unix_s: float, object_id, east_dm, north_dm, position_confidence,
               object_class, measurement_time_ms, motion: MotionCodes | None = None, *, class_confidence_pct=None,
               lat_1e7deg: int | None = None, lon_1e7deg: int | None = None) -> tuple[dict | None, int]:
    """The SDSM (JSON form of :mod:`.messages.sdsm`) of n objects given as columns, and how many were left out.

    Parameters
    ----------
    station_id : int
        ``sourceID`` (the roadside unit's station id).
    msg_count : int
        The event's number (``msgCnt`` = it mod 128).
    unix_s : float
        ``sDSMTimeStamp`` (Unix s, UTC): the event's reference time.
    object_id : int (n,)
        ``objectID`` (0..65535: the fused objects' CPM ``objectId``).
    east_dm, north_dm : int (n,)
        ``pos.offsetX`` / ``offsetY`` (0.1 m east / north of ``refPos``, :func:`~.messages.sdsm.offset_dm`).
    position_confidence : int (n,)
        J2735 ``PositionConfidence`` codes (0..15, :func:`footprint_uq.products.v2x.j2735_position_confidence`).
    object_class : sequence of n class names (or None)
        Mapped to ``objType`` (:func:`sdsm_object_type`).
    measurement_time_ms : int (n,)
        ``measurementTime`` (ms relative to ``sDSMTimeStamp``, -1500..1500).
    motion : MotionCodes, optional
        Speed, heading and their confidence codes (:func:`~.messages.motion.motion_codes`); None: unavailable.
    class_confidence_pct : int (n,), optional
        ``objTypeCfd`` (percent; 0 by default: none given).
    lat_1e7deg, lon_1e7deg : int, optional
        ``refPos`` (0.1 microdegree); unavailable when not given.

    Returns
    -------
    sdsm : dict or None
        None when there is no object.
    not_sent : int
        Objects beyond :data:`MAX_SDSM_OBJECTS` (the last ones given).
    """
    oid = _int_column("objectID", object_id, len(np.asarray(object_id).reshape(-1)))
    n = len(oid)
    cols = [oid] + [_int_column(name, a, n) for name, a in (
        ("pos.offsetX", east_dm), ("pos.offsetY", north_dm), ("posConfidence.pos", position_confidence),
        ("measurementTime", measurement_time_ms))]
    classes = list(object_class)
    if len(classes) != n:
        raise InputError("objType", len(classes), f"{n} classes, one per object")
    lo, hi = MEASUREMENT_TIME_RANGE_MS
    bad = np.flatnonzero((cols[4] < lo) | (cols[4] > hi))
    if len(bad):
        raise InputError(f"measurementTime[{bad[0]}]", int(cols[4][bad[0]]), f"ms in {lo}..{hi}")
    cfd = np.zeros(n, np.int64) if class_confidence_pct is None else _int_column("objTypeCfd", class_confidence_pct, n)
    if motion is None:
        sp, spc = np.full(n, SPEED_UNAVAILABLE), np.zeros(n, np.int64)
        hd, hdc = np.full(n, HEADING_UNAVAILABLE), np.zeros(n, np.int64)
    else:
        sp, spc, hd, hdc = motion.sdsm_speed, motion.sdsm_speed_conf, motion.sdsm_heading, motion.sdsm_heading_conf
    m = min(n, MAX_SDSM_OBJECTS)
    if m == 0:
        return None, 0
    rows = zip([sdsm_object_type(c) for c in classes[:m]], *(a[:m].tolist() for a in (cfd, *cols, sp, spc, hd, hdc)),
               strict=True)
    objects = [{"detObjCommon": {
        "objType": ty, "objTypeCfd": cf, "objectID": i, "measurementTime": mt, "timeConfidence": "unavailable",
        "pos": {"offsetX": x, "offsetY": y},
        "posConfidence": {"pos": J2735_POSITION_CONFIDENCE_NAMES[pc], "elevation": "unavailable"},
        "speed": s, "speedConfidence": SPEED_CONFIDENCE_NAMES[sc], "heading": h,
        "headingConf": HEADING_CONFIDENCE_NAMES[hc]}}
        for ty, cf, i, x, y, pc, mt, s, sc, h, hc in rows]
    ref = {} if lat_1e7deg is None else {"lat_1e7deg": int(lat_1e7deg), "lon_1e7deg": int(lon_1e7deg)}
    return build_sdsm(station_id, msg_count, unix_s, objects, **ref), n - m
