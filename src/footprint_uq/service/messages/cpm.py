"""ETSI Collective Perception Message (TS 103 324 Release 2) of one frame: JSON and UPER.

JSON layout
-----------
The JSON uses the standard's component names and units (the ASN.1 value, written as JSON):
a CHOICE is an object with one key (the alternative), a BIT STRING of named bits is the list
of the names of the bits that are set, and the open-type ``containerData`` holds the
container itself (its type follows from ``containerId``)::

    {"header": {"protocolVersion": 2, "messageId": 14, "stationId": 1},
     "payload": {
       "managementContainer": {
         "referenceTime": 660000000000,                    # TimestampIts: ms since 2004-01-01 UTC (TAI)
         "referencePosition": {"latitude": 422808000,     # 0.1 microdegree, 900000001 = unavailable
                               "longitude": -837430000,   # 0.1 microdegree, 1800000001 = unavailable
                               "positionConfidenceEllipse": {"semiMajorConfidence": 4095, ...},
                               "altitude": {"altitudeValue": 800001, "altitudeConfidence": "unavailable"}}},
       "cpmContainers": [
         {"containerId": 2, "containerData": {}},                        # OriginatingRsuContainer
         {"containerId": 5, "containerData": {                           # PerceivedObjectContainer
            "numberOfPerceivedObjects": 1,
            "perceivedObjects": [{
               "objectId": 7, "measurementDeltaTime": 0,                 # ms after referenceTime
               "position": {"xCoordinate": {"value": 1234, "confidence": 37},   # 0.01 m east; 0.01 m at 95 %
                            "yCoordinate": {"value": -56, "confidence": 81}},   # 0.01 m north
               "lowerTriangularCorrelationMatrices": [
                  {"componentsIncludedIntheMatrix": ["xPosition", "yPosition"], "matrix": [[45]]}],
               "classification": [{"objectClass": {"vehicleSubClass": 5}, "confidence": 101}]}]}}]}}

Positions are relative to the reference position, x east and y north (TS 103 324: for an
RSU the perceived objects are "in the coordinate system in which the y-axis corresponds to
the North direction, the x-axis to the East direction").  The confidences and the
correlation are :func:`footprint_uq.products.v2x.cpm_fields` of the centre covariance, unchanged.
Coordinates are ``ceil(v / 0.01 m)`` as the CDD defines ``CartesianCoordinateLarge`` (:func:`coordinate_cm`);
beyond -1310.72 / +1310.70 m they take the out-of-range values (-131072 / 131071).  With motion
(:mod:`.motion`) an object also carries ``velocity`` (``cartesianVelocity``: east, north with their
``SpeedConfidence``), ``angles.zAngle`` (its yaw) and ``objectAge``.

CDD releases: the JSON and the UPER follow the release given as ``cdd`` (:data:`~.asn1_cpm.CDD_RELEASES`;
:mod:`.asn1_cpm` says what differs).  A VRU sub-profile is a name in V2.1.1 and a number in V2.2.1.

UPER
----
:func:`encode_cpm_uper` encodes the JSON with asn1tools from the subset module
:data:`~footprint_uq.service.messages.asn1_cpm.CPM_ASN1_BY_CDD` (read its doc for how the subset keeps
the standard's bits); :func:`decode_cpm_uper` is its inverse and returns the same JSON.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from ...errors import InputError
from .asn1_cpm import (
    CDD_RELEASES,
    CONTAINER_ID_PERCEIVED_OBJECTS,
    CONTAINER_ID_RSU,
    CPM_ASN1_BY_CDD,
    CPM_PROTOCOL_VERSION,
    DEFAULT_CDD,
    MESSAGE_ID_CPM,
    VRU_SUBPROFILES,
)

__all__ = ["build_cpm", "encode_cpm_uper", "decode_cpm_uper", "cpm_to_asn1_value", "timestamp_its_ms",
           "perceived_object", "coordinate_cm", "LATITUDE_UNAVAILABLE", "LONGITUDE_UNAVAILABLE", "CPM_CLASSES",
           "MATRIX_COMPONENTS", "unavailable_reference_ellipse", "CPM_CLASS_OF", "CPM_CLASSES_BY_CDD",
           "object_class_json", "check_cdd"]

LATITUDE_UNAVAILABLE = 900000001
LONGITUDE_UNAVAILABLE = 1800000001
SEMI_AXIS_UNAVAILABLE = 4095
HEADING_UNAVAILABLE = 3601
ALTITUDE_UNAVAILABLE = 800001
COORD_MIN, COORD_MAX = -131072, 131071  # CartesianCoordinateLarge negative/positiveOutOfRange
CONFIDENCE_LEVEL_UNAVAILABLE = 101

#: MatrixIncludedComponents bit names, in bit order
MATRIX_COMPONENTS = ("xPosition", "yPosition", "zPosition", "xVelocityOrVelocityMagnitude",
                     "yVelocityOrVelocityDirection", "zSpeed", "xAccelOrAccelMagnitude", "yAccelOrAccelDirection",
                     "zAcceleration", "zAngle", "yAngle", "xAngle", "zAngularVelocity")

#: detector class (lower case) -> ObjectClass, release-neutral: ``("vehicleSubClass", TrafficParticipantType)`` or
#: ``("vruSubClass", VruProfileAndSubprofile alternative, sub-profile number)``.  ``vehicleSubClass`` is constrained
#: to ``unknown|passengerCar..tram|agricultural`` (0, 5..11, 14): two-wheelers and animals are VRU sub-classes
#: (CDD ``ObjectClass``, ``VruProfileAndSubprofile``).  Classes not listed get no classification (it is OPTIONAL).
_VEH, _VRU = "vehicleSubClass", "vruSubClass"
_PED, _BIKE, _MOTO, _ANIMAL = "pedestrian", "bicyclistAndLightVruVehicle", "motorcyclist", "animal"
CPM_CLASS_OF = {
    **dict.fromkeys(("car", "passengercar", "passenger_car"), (_VEH, 5)),
    "bus": (_VEH, 6),
    **dict.fromkeys(("van", "lighttruck", "light_truck"), (_VEH, 7)),
    **dict.fromkeys(("truck", "heavytruck", "heavy_truck"), (_VEH, 8)),
    "trailer": (_VEH, 9),
    **dict.fromkeys(("specialvehicle", "special_vehicle"), (_VEH, 10)),
    "tram": (_VEH, 11),
    **dict.fromkeys(("agricultural", "tractor"), (_VEH, 14)),
    **dict.fromkeys(("pedestrian", "person"), (_VRU, _PED, 1)),  # ordinary-pedestrian
    **dict.fromkeys(("road_worker", "road-worker"), (_VRU, _PED, 2)),
    **dict.fromkeys(("bicycle", "bicyclist", "cyclist", "bike"), (_VRU, _BIKE, 1)),  # bicyclist
    **dict.fromkeys(("wheelchair", "wheelchair_user", "wheelchair-user"), (_VRU, _BIKE, 2)),
    **dict.fromkeys(("e-scooter", "e_scooter", "escooter"), (_VRU, _BIKE, 5)),
    **dict.fromkeys(("moped",), (_VRU, _MOTO, 1)),
    **dict.fromkeys(("motorcycle", "motorcyclist", "motorbike"), (_VRU, _MOTO, 2)),
    **dict.fromkeys(("animal", "dog", "cat", "bird"), (_VRU, _ANIMAL, 0)),  # sub-profile unavailable
    **dict.fromkeys(("wild_animal", "wild-animal", "deer", "bear", "elephant", "zebra", "giraffe"),
                    (_VRU, _ANIMAL, 1)),
    **dict.fromkeys(("farm_animal", "farm-animal", "horse", "cow", "sheep"), (_VRU, _ANIMAL, 2)),
    **dict.fromkeys(("service_animal", "service-animal"), (_VRU, _ANIMAL, 3)),
}


def check_cdd(cdd: str) -> str:
    """The CDD release name, checked (:data:`~.asn1_cpm.CDD_RELEASES`)."""
    if cdd not in CDD_RELEASES:
        raise InputError("cpm_cdd", cdd, f"one of {', '.join(CDD_RELEASES)} (the ETSI-ITS-CDD release of the CPM)")
    return cdd


def object_class_json(spec: tuple, cdd: str = DEFAULT_CDD) -> dict:
    """The ``ObjectClass`` (JSON form) of a :data:`CPM_CLASS_OF` entry in the CDD release ``cdd``: a VRU sub-profile
    is its name in V2.1.1 (ENUMERATED) and its number in V2.2.1 (INTEGER (0..15))."""
    if spec[0] == _VEH:
        return {_VEH: spec[1]}
    _, alt, number = spec
    return {_VRU: {alt: VRU_SUBPROFILES[alt][number] if check_cdd(cdd) == "2.1.1" else number}}


#: per CDD release: detector class (lower case) -> ObjectClass (JSON form)
CPM_CLASSES_BY_CDD = {cdd: {k: object_class_json(v, cdd) for k, v in CPM_CLASS_OF.items()} for cdd in CDD_RELEASES}
#: detector class (lower case) -> ObjectClass (JSON form) of the default release
CPM_CLASSES = CPM_CLASSES_BY_CDD[DEFAULT_CDD]

_UNIX_2004_S = 1072915200.0
#: TAI - UTC leap seconds inserted after 2004-01-01 (Unix time at which each took effect)
_LEAP_SECONDS_UNIX_S = (1136073600.0, 1230768000.0, 1341100800.0, 1435708800.0, 1483228800.0)
TIMESTAMP_ITS_MAX = 4398046511103


def timestamp_its_ms(unix_s: float) -> int:
    """``TimestampIts`` of a Unix time (s, UTC): TAI milliseconds since 2004-01-01 00:00:00 UTC.

    Leap seconds inserted since 2004 (five, the last at the start of 2017) are added, as the
    CDD defines the count in TAI.
    """
    if not (isinstance(unix_s, (int, float)) and math.isfinite(unix_s)) or unix_s < _UNIX_2004_S:
        raise InputError("timestamp_s", unix_s, "Unix time in seconds (UTC) on or after 2004-01-01 (TimestampIts)")
    leap = sum(1 for t in _LEAP_SECONDS_UNIX_S if unix_s >= t)
    ms = int(round((unix_s - _UNIX_2004_S + leap) * 1000.0))
    if ms > TIMESTAMP_ITS_MAX:
        raise InputError("timestamp_s", unix_s, "a time TimestampIts can hold (before the year 2143)")
    return ms


def unavailable_reference_ellipse() -> dict:
    """PosConfidenceEllipse with every field 'unavailable' (the station's own position accuracy is not known)."""
    return {"semiMajorConfidence": SEMI_AXIS_UNAVAILABLE, "semiMinorConfidence": SEMI_AXIS_UNAVAILABLE,
            "semiMajorOrientation": HEADING_UNAVAILABLE}


#: absolute guard (in 0.01 m) against binary rounding pushing a coordinate exactly on a step (0.07 m) up
COORD_GUARD_CM = 1e-7


def coordinate_cm(v_m):
    """``CartesianCoordinateLarge`` (0.01 m) of metres -> int array.

    The CDD (TS 102 894-2 V2.1.1 and V2.2.1, DE ``CartesianCoordinateLarge``): ``n`` "if the longitudinal
    offset information is equal to or less than n x 0,01 metre and more than (n-1) x 0,01 metre", i.e.
    ``n = ceil(v / 0.01 m)`` (not the nearest centimetre); -131072 "less than or equal to -1 310,72 metres",
    131071 "greater than + 1 310,70 metres" (both follow from the ceiling and the clamp).  A value within
    1e-9 m of a step counts as on it (:data:`COORD_GUARD_CM`).  NaN gives 0 (such objects are not sent).
    """
    c = np.ceil(np.nan_to_num(np.asarray(v_m, dtype=np.float64), nan=0.0) * 100.0 - COORD_GUARD_CM)
    return np.clip(c, COORD_MIN, COORD_MAX).astype(np.int64)


def perceived_object(object_id: int, east_cm: int, north_cm: int, x_conf: int, y_conf: int, xy_corr: int,
                     object_class: dict | None, class_confidence: int = CONFIDENCE_LEVEL_UNAVAILABLE,
                     measurement_delta_ms: int = 0, *, velocity: tuple | None = None, yaw: tuple | None = None,
                     age_ms: int | None = None) -> dict:
    """One ``PerceivedObject`` (JSON form): position east/north of the reference position in 0.01 m
    (:func:`coordinate_cm`) with its CPM confidences (:func:`footprint_uq.products.v2x.cpm_fields`), the x/y
    correlation cell when available; with motion (:mod:`.motion` codes) ``velocity = (vx, vx_conf, vy, vy_conf)``
    (``cartesianVelocity``), ``yaw = (zAngle value, confidence)`` and ``age_ms`` (``objectAge``)."""
    po = {"objectId": int(object_id), "measurementDeltaTime": int(measurement_delta_ms),
          "position": {"xCoordinate": {"value": int(east_cm), "confidence": int(x_conf)},
                       "yCoordinate": {"value": int(north_cm), "confidence": int(y_conf)}}}
    if velocity is not None:
        vx, cx, vy, cy = map(int, velocity)
        po["velocity"] = {"cartesianVelocity": {"xVelocity": {"value": vx, "confidence": cx},
                                                "yVelocity": {"value": vy, "confidence": cy}}}
    if yaw is not None:
        po["angles"] = {"zAngle": {"value": int(yaw[0]), "confidence": int(yaw[1])}}
    if xy_corr != 101:  # CorrelationCellValue unavailable: the optional matrix is left out
        po["lowerTriangularCorrelationMatrices"] = [
            {"componentsIncludedIntheMatrix": ["xPosition", "yPosition"], "matrix": [[int(xy_corr)]]}]
    if age_ms is not None:
        po["objectAge"] = int(age_ms)
    if object_class is not None:
        po["classification"] = [{"objectClass": object_class, "confidence": int(class_confidence)}]
    return po


def build_cpm(station_id: int, reference_time_ms: int, perceived_objects: list[dict], *,
              latitude: int = LATITUDE_UNAVAILABLE, longitude: int = LONGITUDE_UNAVAILABLE) -> dict:
    """The CPM (JSON form, see the module doc) of one frame.

    Parameters
    ----------
    station_id : int        StationId of the roadside unit (0 .. 2^32 - 1)
    reference_time_ms : int TimestampIts of the frame (:func:`timestamp_its_ms`)
    perceived_objects : list of :func:`perceived_object` dicts (at most 255)
    latitude, longitude : int
        Reference position in 0.1 microdegree (unavailable by default: positions are then
        relative to an unknown point and only their confidences are meaningful).
    """
    if not 0 <= int(station_id) <= 4294967295:
        raise InputError("station_id", station_id, "an integer in 0..4294967295 (StationId)")
    if len(perceived_objects) > 255:
        raise InputError("perceived_objects", len(perceived_objects), "at most 255 objects per CPM")
    return {
        "header": {"protocolVersion": CPM_PROTOCOL_VERSION, "messageId": MESSAGE_ID_CPM, "stationId": int(station_id)},
        "payload": {
            "managementContainer": {
                "referenceTime": int(reference_time_ms),
                "referencePosition": {"latitude": int(latitude), "longitude": int(longitude),
                                      "positionConfidenceEllipse": unavailable_reference_ellipse(),
                                      "altitude": {"altitudeValue": ALTITUDE_UNAVAILABLE,
                                                   "altitudeConfidence": "unavailable"}}},
            "cpmContainers": [
                {"containerId": CONTAINER_ID_RSU, "containerData": {}},
                {"containerId": CONTAINER_ID_PERCEIVED_OBJECTS,
                 "containerData": {"numberOfPerceivedObjects": len(perceived_objects),
                                   "perceivedObjects": perceived_objects}}]}}


@functools.cache
def _spec(cdd: str = DEFAULT_CDD):
    import asn1tools

    return asn1tools.compile_string(CPM_ASN1_BY_CDD[check_cdd(cdd)], "uper")


def _bits_to_asn1(names: list[str]) -> tuple[bytes, int]:
    v = 0
    for n in names:
        v |= 1 << (15 - MATRIX_COMPONENTS.index(n))
    return v.to_bytes(2, "big"), len(MATRIX_COMPONENTS)


def _bits_from_asn1(value: tuple[bytes, int]) -> list[str]:
    data, n = value
    v = int.from_bytes(data, "big")
    nb = 8 * len(data)
    return [MATRIX_COMPONENTS[i] for i in range(min(n, len(MATRIX_COMPONENTS))) if v >> (nb - 1 - i) & 1]


def _choice_to_asn1(c: dict):
    (name, value), = c.items()
    return (name, _choice_to_asn1(value) if isinstance(value, dict) else value)


def _choice_from_asn1(c):
    name, value = c
    return {name: _choice_from_asn1(value) if isinstance(value, tuple) else value}


def _po_to_asn1(po: dict) -> dict:
    out = dict(po)
    if "velocity" in po:  # a CHOICE of SEQUENCEs
        out["velocity"], = po["velocity"].items()
    if "lowerTriangularCorrelationMatrices" in po:
        out["lowerTriangularCorrelationMatrices"] = [
            {"componentsIncludedIntheMatrix": _bits_to_asn1(m["componentsIncludedIntheMatrix"]), "matrix": m["matrix"]}
            for m in po["lowerTriangularCorrelationMatrices"]]
    if "classification" in po:
        out["classification"] = [{"objectClass": _choice_to_asn1(c["objectClass"]), "confidence": c["confidence"]}
                                 for c in po["classification"]]
    return out


def _po_from_asn1(po: dict) -> dict:
    out = dict(po)
    if "velocity" in po:
        out["velocity"] = dict([po["velocity"]])
    if "lowerTriangularCorrelationMatrices" in po:
        out["lowerTriangularCorrelationMatrices"] = [
            {"componentsIncludedIntheMatrix": _bits_from_asn1(m["componentsIncludedIntheMatrix"]),
             "matrix": [list(col) for col in m["matrix"]]}
            for m in po["lowerTriangularCorrelationMatrices"]]
    if "classification" in po:
        out["classification"] = [{"objectClass": _choice_from_asn1(c["objectClass"]), "confidence": c["confidence"]}
                                 for c in po["classification"]]
    return out


_CONTAINER_TYPES = {CONTAINER_ID_RSU: "OriginatingRsuContainer",
                    CONTAINER_ID_PERCEIVED_OBJECTS: "PerceivedObjectContainer"}


def cpm_to_asn1_value(cpm: dict, cdd: str = DEFAULT_CDD) -> dict:
    """The asn1tools value of a CPM JSON (containers encoded into their open-type octets) in CDD release ``cdd``."""
    spec = _spec(cdd)
    containers = []
    for w in cpm["payload"]["cpmContainers"]:
        cid = w["containerId"]
        if cid not in _CONTAINER_TYPES:
            raise InputError("cpmContainers.containerId", cid, f"one of {sorted(_CONTAINER_TYPES)} (the subset sent)")
        data = w["containerData"]
        if cid == CONTAINER_ID_PERCEIVED_OBJECTS:
            data = {**data, "perceivedObjects": [_po_to_asn1(p) for p in data["perceivedObjects"]]}
        containers.append({"containerId": cid, "containerData": spec.encode(_CONTAINER_TYPES[cid], data)})
    return {"header": cpm["header"],
            "payload": {"managementContainer": cpm["payload"]["managementContainer"], "cpmContainers": containers}}


def encode_cpm_uper(cpm: dict, cdd: str = DEFAULT_CDD) -> bytes:
    """UPER encoding (bytes) of a CPM given in its JSON form, with the subset module of CDD release ``cdd``."""
    return _spec(cdd).encode("CollectivePerceptionMessage", cpm_to_asn1_value(cpm, cdd))


def decode_cpm_uper(data: bytes | str, cdd: str = DEFAULT_CDD) -> dict:
    """Decode UPER bytes (or their hex) into the CPM JSON form (inverse of :func:`encode_cpm_uper`)."""
    spec = _spec(cdd)
    raw = bytes.fromhex(data) if isinstance(data, str) else bytes(data)
    msg = spec.decode("CollectivePerceptionMessage", raw)
    containers = []
    for w in msg["payload"]["cpmContainers"]:
        cid = w["containerId"]
        if cid not in _CONTAINER_TYPES:
            raise InputError("cpmContainers.containerId", cid,
                             f"one of {sorted(_CONTAINER_TYPES)} (the subset decoded)")
        data_ = spec.decode(_CONTAINER_TYPES[cid], w["containerData"])
        if cid == CONTAINER_ID_PERCEIVED_OBJECTS:
            data_ = {**data_, "perceivedObjects": [_po_from_asn1(p) for p in data_["perceivedObjects"]]}
        containers.append({"containerId": cid, "containerData": data_})
    return {"header": msg["header"], "payload": {"managementContainer": msg["payload"]["managementContainer"],
                                                 "cpmContainers": containers}}
