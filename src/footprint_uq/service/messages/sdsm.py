"""SAE J3224 Sensor Data Sharing Message (SDSM) of one frame, as JSON with J3224's field names.

Only JSON is produced (no UPER).  Layout (J3224 ``SensorDataSharingMessage``)::

    {"msgCnt": 17,                                   # MsgCount 0..127 (frame number mod 128)
     "sourceID": "00000001",                         # TemporaryID, 4 octets (hex) = the station id
     "equipmentType": "rsu",
     "sDSMTimeStamp": {"year": 2024, "month": 5, "day": 1, "hour": 12, "minute": 0, "second": 1500},  # second: ms
     "refPos": {"lat": 422808000, "long": -837430000},                # 1e-7 deg; 900000001 / 1800000001 unavailable
     "refPosXYConf": {"semiMajor": 255, "semiMinor": 255, "orientation": 65535},   # station's own: unavailable
     "objects": [{"detObjCommon": {
         "objType": "vehicle", "objTypeCfd": 0, "objectID": 7,
         "measurementTime": 0,                        # ms relative to sDSMTimeStamp
         "timeConfidence": "unavailable",
         "pos": {"offsetX": 123, "offsetY": -6},      # 0.1 m east / north of refPos
         "posConfidence": {"pos": "a50cm", "elevation": "unavailable"},   # J2735 PositionConfidence (95 %)
         "speed": 8191, "speedConfidence": "unavailable", "heading": 28800, "headingConf": "unavailable"}}]}

``posConfidence.pos`` is :func:`footprint_uq.products.v2x.j2735_position_confidence` of the centre
covariance (the per-object ``j2735`` fields of the service output carry the full J2735
``PositionalAccuracy`` too).  Speed and heading come from a tracker
(:class:`~.motion.ObjectMotion`, conversions in :mod:`.motion`); without one they are J3224's
"unavailable" values.  ``objTypeCfd`` is the detector's class confidence in percent
(``class_confidence`` in [0, 1] in the detection), 0 when the detector gives none.
Offsets beyond +-3276.7 m are clamped to +-32767.
"""

from __future__ import annotations

import datetime as _dt

import numpy as np

from ...products.v2x import J2735_POSITION_CONFIDENCE_NAMES
from .motion import HEADING_CONFIDENCE_NAMES, SPEED_CONFIDENCE_NAMES

__all__ = ["build_sdsm", "sdsm_object", "offset_dm", "SDSM_OBJECT_TYPES"]

SPEED_UNAVAILABLE = 8191
HEADING_UNAVAILABLE = 28800
OFFSET_MAX = 32767

#: detector class (lower case) -> J3224 ObjectType (others: "unknown")
SDSM_OBJECT_TYPES = {
    **dict.fromkeys(("car", "passengercar", "passenger_car", "bus", "van", "truck", "lighttruck", "light_truck",
                     "heavytruck", "heavy_truck", "trailer", "tram", "motorcycle", "motorcyclist", "motorbike", "moped",
                     "specialvehicle", "special_vehicle", "agricultural", "tractor", "vehicle"), "vehicle"),
    **dict.fromkeys(("pedestrian", "person", "road_worker", "road-worker", "cyclist", "bicycle", "bicyclist", "bike",
                     "wheelchair", "wheelchair_user", "wheelchair-user", "e-scooter", "e_scooter", "escooter", "vru"),
                    "vru"),
    **dict.fromkeys(("animal", "dog", "cat", "bird", "deer", "bear", "elephant", "zebra", "giraffe", "horse", "cow",
                     "sheep", "wild_animal", "wild-animal", "farm_animal", "farm-animal", "service_animal",
                     "service-animal"), "animal"),
}


def offset_dm(v_m):
    """``ObjectDistance`` (0.1 m, clamped to +-32767) of metres ``(...)`` -> int array."""

    d = np.rint(np.nan_to_num(np.asarray(v_m, dtype=np.float64), nan=0.0) * 10.0)
    return np.clip(d, -OFFSET_MAX, OFFSET_MAX).astype(np.int64)


def sdsm_object(object_id: int, east_dm: int, north_dm: int, position_confidence: int, object_class: str | None,
                class_confidence_pct: int = 0, measurement_time_ms: int = 0, *, speed: int = SPEED_UNAVAILABLE,
                speed_confidence: int = 0, heading: int = HEADING_UNAVAILABLE, heading_confidence: int = 0) -> dict:
    """One ``DetectedObjectData`` (JSON form) with the common data only; offsets from :func:`offset_dm`; speed,
    heading and their confidence codes from :func:`~.motion.motion_codes` (unavailable by default)."""
    return {"detObjCommon": {
        "objType": SDSM_OBJECT_TYPES.get((object_class or "").lower(), "unknown"),
        "objTypeCfd": int(class_confidence_pct), "objectID": int(object_id),
        "measurementTime": int(measurement_time_ms), "timeConfidence": "unavailable",
        "pos": {"offsetX": int(east_dm), "offsetY": int(north_dm)},
        "posConfidence": {"pos": J2735_POSITION_CONFIDENCE_NAMES[int(position_confidence)],
                          "elevation": "unavailable"},
        "speed": int(speed), "speedConfidence": SPEED_CONFIDENCE_NAMES[int(speed_confidence)],
        "heading": int(heading), "headingConf": HEADING_CONFIDENCE_NAMES[int(heading_confidence)]}}


def build_sdsm(station_id: int, frame: int, unix_s: float, objects: list[dict], *, lat_1e7deg: int = 900000001,
               lon_1e7deg: int = 1800000001) -> dict:
    """The SDSM (JSON form, see the module doc) of one frame; ``objects`` from :func:`sdsm_object`."""
    t = _dt.datetime.fromtimestamp(unix_s, tz=_dt.UTC)
    return {
        "msgCnt": int(frame) % 128,
        "sourceID": f"{int(station_id) & 0xFFFFFFFF:08x}",
        "equipmentType": "rsu",
        "sDSMTimeStamp": {"year": t.year, "month": t.month, "day": t.day, "hour": t.hour, "minute": t.minute,
                          "second": t.second * 1000 + t.microsecond // 1000},
        "refPos": {"lat": int(lat_1e7deg), "long": int(lon_1e7deg)},
        "refPosXYConf": {"semiMajor": 255, "semiMinor": 255, "orientation": 65535},
        "objects": objects,
    }
