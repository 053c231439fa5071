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

The CP service's parts (:mod:`footprint_uq.service.cp_segments`): ``managementContainer.segmentationInfo``
(``{"totalMsgNo": t, "thisMsgNo": k}``), the Sensor Information container (``containerId`` 3, a list of
:func:`sensor_information`), the Perception Region container (4, a list of :func:`perception_region_entry`), a
``Shape`` as ``{"polygonal": {"polygon": [{"xCoordinate": .., "yCoordinate": ..}, ...]}}`` (0.01 m east / north,
:func:`polygonal_shape`), and per object ``objectPerceptionQuality`` and ``sensorIdList`` (docs/service.md, "The
CPM's containers").

CDD releases: the JSON and the UPER follow the release given as ``cdd`` (:data:`~.asn1_cpm.CDD_RELEASES`;
:mod:`.asn1_cpm` says what differs).  A VRU sub-profile is a name in V2.1.1 and a number in V2.2.1.

UPER
----
:func:`encode_cpm_uper` encodes the JSON with asn1tools from the subset module
:data:`~footprint_uq.service.messages.asn1_cpm.CPM_ASN1_BY_CDD` (read its doc for how the subset keeps
the standard's bits); :func:`decode_cpm_uper` is its inverse and returns the same JSON.
"""

from __future__ import annotations

import bisect
import functools
import math

import numpy as np

from ...errors import InputError
from .asn1_cpm import (
    CDD_RELEASES,
    CONTAINER_ID_PERCEIVED_OBJECTS,
    CONTAINER_ID_PERCEPTION_REGION,
    CONTAINER_ID_RSU,
    CONTAINER_ID_SENSOR_INFORMATION,
    CPM_ASN1_BY_CDD,
    CPM_PROTOCOL_VERSION,
    DEFAULT_CDD,
    MESSAGE_ID_CPM,
    SENSOR_TYPE_MONOVIDEO,
    VRU_SUBPROFILES,
)

__all__ = ["build_cpm", "encode_cpm_uper", "decode_cpm_uper", "cpm_to_asn1_value", "timestamp_its_ms",
           "perceived_object", "coordinate_cm", "LATITUDE_UNAVAILABLE", "LONGITUDE_UNAVAILABLE", "CPM_CLASSES",
           "MATRIX_COMPONENTS", "unavailable_reference_ellipse", "CPM_CLASS_OF", "CPM_CLASSES_BY_CDD",
           "object_class_json", "check_cdd", "polygonal_shape", "sensor_information", "perception_region_entry"]

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
_N_LEAP_SECONDS = len(_LEAP_SECONDS_UNIX_S)
#: the end of :func:`timestamp_its_ms`' shortcut (2096-10-02 UTC; far below TimestampIts' range)
_ITS_AFTER_LAST_LEAP_END_S = 4.0e9


def timestamp_its_ms(unix_s: float) -> int:
    """``TimestampIts`` of a Unix time (s, UTC): TAI milliseconds since 2004-01-01 00:00:00 UTC.

    Leap seconds inserted since 2004 (five, the last at the start of 2017) are added, as the
    CDD defines the count in TAI.
    """
    if type(unix_s) is float and _LEAP_SECONDS_UNIX_S[-1] <= unix_s < _ITS_AFTER_LAST_LEAP_END_S:
        # (the usual frame's time: after the last leap second known here; the look-up's count, the same bits)
        return round((unix_s - _UNIX_2004_S + _N_LEAP_SECONDS) * 1000.0)
    if not (isinstance(unix_s, (int, float)) and math.isfinite(unix_s)) or unix_s < _UNIX_2004_S:
        raise InputError("timestamp_s", unix_s, "Unix time in seconds (UTC) on or after 2004-01-01 (TimestampIts)")
    leap = bisect.bisect_right(_LEAP_SECONDS_UNIX_S, unix_s)  # (the leap seconds at or before it: sorted)
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
                     age_ms: int | None = None, quality: int | None = None,
                     sensor_ids: list[int] | None = None) -> dict:
    """One ``PerceivedObject`` (JSON form): position east/north of the reference position in 0.01 m
    (:func:`coordinate_cm`) with its CPM confidences (:func:`footprint_uq.products.v2x.cpm_fields`), the x/y
    correlation cell when available; with motion (:mod:`.motion` codes) ``velocity = (vx, vx_conf, vy, vy_conf)``
    (``cartesianVelocity``), ``yaw = (zAngle value, confidence)`` and ``age_ms`` (``objectAge``).

    ``measurement_delta_ms``: the object's measurement time minus the CPM's ``referenceTime`` (ms,
    ``DeltaTimeMilliSecondSigned``: -2048..2047, checked); ``quality``: ``objectPerceptionQuality`` (0..15,
    :func:`footprint_uq.service.cp_segments.object_perception_quality`); ``sensor_ids``: ``sensorIdList``
    (the ``sensorId`` of every camera that contributed, 1..128 ids of 0..255)."""
    _int_in("measurementDeltaTime", measurement_delta_ms, -2048, 2047, "ms after referenceTime")
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
    if quality is not None:
        po["objectPerceptionQuality"] = _int_in("objectPerceptionQuality", quality, 0, 15, "ObjectPerceptionQuality")
    if sensor_ids is not None:
        po["sensorIdList"] = _sensor_id_list("sensorIdList", sensor_ids)
    if object_class is not None:
        po["classification"] = [{"objectClass": object_class, "confidence": int(class_confidence)}]
    return po


def _int_in(name: str, v, lo: int, hi: int, what: str) -> int:
    if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or not lo <= int(v) <= hi:
        raise InputError(name, v, f"an integer in {lo}..{hi} ({what})")
    return int(v)


def _sensor_id_list(name: str, ids) -> list[int]:
    ids = [_int_in(f"{name}[{k}]", v, 0, 255, "Identifier1B") for k, v in enumerate(ids)]
    if not 1 <= len(ids) <= 128:
        raise InputError(name, len(ids), "1..128 sensor ids (SequenceOfIdentifier1B)")
    return ids


#: CDD ``CartesianCoordinate`` (0.01 m) of a polygon vertex / shape reference point
SHAPE_COORD_MIN, SHAPE_COORD_MAX = -32768, 32767


def polygonal_shape(vertices_cm) -> dict:
    """The ``Shape`` (JSON form, ``polygonal``) of a polygon given as east/north offsets (0.01 m, ``(M, 2)`` int,
    3 <= M <= 16) from the CPM's reference position
    (:func:`footprint_uq.products.perception_region.polygon_east_north_cm`).

    ``CartesianCoordinate`` holds +-327.67 m: a polygon with a vertex beyond that is sent relative to a
    ``shapeReferencePoint`` (the centre of its bounding box, rounded to 0.01 m; the CDD's vertices are relative to
    it); a polygon that does not fit even then is refused (:class:`InputError`).
    """
    v = np.asarray(vertices_cm)
    if v.ndim != 2 or v.shape[1] != 2 or not 3 <= v.shape[0] <= 16:
        raise InputError("perceptionRegionShape.polygon", f"shape {v.shape}", "3..16 vertices (M, 2) (PolygonalShape)")
    if not np.issubdtype(v.dtype, np.integer):
        raise InputError("perceptionRegionShape.polygon", v.dtype, "integer offsets in 0.01 m")
    v = v.astype(np.int64)
    shape: dict = {}
    if v.min() < SHAPE_COORD_MIN or v.max() > SHAPE_COORD_MAX:
        ref = (v.min(axis=0) + v.max(axis=0)) // 2
        v = v - ref
        if (np.abs(ref).max() > SHAPE_COORD_MAX or v.min() < SHAPE_COORD_MIN or v.max() > SHAPE_COORD_MAX):
            raise InputError("perceptionRegionShape.polygon", f"extent {np.ptp(v, axis=0).tolist()} cm",
                             "a polygon within +-327 m of its reference point (CartesianCoordinate)")
        shape["shapeReferencePoint"] = {"xCoordinate": int(ref[0]), "yCoordinate": int(ref[1])}
    shape["polygon"] = [{"xCoordinate": int(x), "yCoordinate": int(y)} for x, y in v.tolist()]
    return {"polygonal": shape}


def sensor_information(sensor_id: int, shape: dict | None, confidence: int | None, shadowing_applies: bool,
                       sensor_type: int = SENSOR_TYPE_MONOVIDEO) -> dict:
    """One ``SensorInformation`` (JSON form): ``sensorId`` (0..255), ``sensorType`` (monovideo = 3 for a camera),
    the perception region's ``Shape`` (:func:`polygonal_shape`) and its ``perceptionRegionConfidence``
    (``ConfidenceLevel`` 1..101, percent; the region's ellipse probability), ``shadowingApplies``."""
    out = {"sensorId": _int_in("sensorId", sensor_id, 0, 255, "Identifier1B"),
           "sensorType": _int_in("sensorType", sensor_type, 0, 31, "SensorType")}
    if shape is not None:
        out["perceptionRegionShape"] = shape
    if confidence is not None:
        out["perceptionRegionConfidence"] = _int_in("perceptionRegionConfidence", confidence, 1, 101,
                                                    "ConfidenceLevel")
    out["shadowingApplies"] = bool(shadowing_applies)
    return out


def perception_region_entry(shape: dict, confidence: int, shadowing_applies: bool, *, measurement_delta_ms: int = 0,
                            sensor_ids=None, object_ids=None, number_of_objects: int | None = None) -> dict:
    """One ``PerceptionRegion`` (JSON form): ``measurementDeltaTime`` (ms after ``referenceTime``, -2048..2047),
    ``perceptionRegionConfidence`` (1..101), the ``Shape``, ``shadowingApplies``, and where given
    ``sensorIdList``, ``numberOfPerceivedObjects`` (0..255) and ``perceivedObjectIds`` (at most 255)."""
    out = {"measurementDeltaTime": _int_in("measurementDeltaTime", measurement_delta_ms, -2048, 2047,
                                           "ms after referenceTime"),
           "perceptionRegionConfidence": _int_in("perceptionRegionConfidence", confidence, 1, 101, "ConfidenceLevel"),
           "perceptionRegionShape": shape, "shadowingApplies": bool(shadowing_applies)}
    if sensor_ids is not None:
        out["sensorIdList"] = _sensor_id_list("sensorIdList", sensor_ids)
    if number_of_objects is not None:
        out["numberOfPerceivedObjects"] = _int_in("numberOfPerceivedObjects", number_of_objects, 0, 255,
                                                  "CardinalNumber1B")
    if object_ids is not None:
        ids = [_int_in(f"perceivedObjectIds[{k}]", v, 0, 65535, "Identifier2B") for k, v in enumerate(object_ids)]
        if len(ids) > 255:
            raise InputError("perceivedObjectIds", len(ids), "at most 255 ids (PerceivedObjectIds)")
        out["perceivedObjectIds"] = ids
    return out


def build_cpm(station_id: int, reference_time_ms: int, perceived_objects: list[dict], *,
              latitude: int = LATITUDE_UNAVAILABLE, longitude: int = LONGITUDE_UNAVAILABLE,
              segmentation: tuple[int, int] | None = None, sensor_information: list[dict] | None = None,
              perception_regions: list[dict] | None = None, number_of_perceived_objects: int | None = None) -> dict:
    """The CPM (JSON form, see the module doc) of one frame or one segment of a generation event.

    Parameters
    ----------
    station_id : int        StationId of the roadside unit (0 .. 2^32 - 1)
    reference_time_ms : int TimestampIts of the frame (:func:`timestamp_its_ms`)
    perceived_objects : list of :func:`perceived_object` dicts (at most 255)
    latitude, longitude : int
        Reference position in 0.1 microdegree (unavailable by default: positions are then
        relative to an unknown point and only their confidences are meaningful).
    segmentation : (thisMsgNo, totalMsgNo), optional
        ``managementContainer.segmentationInfo`` (both 1..8, this <= total).
    sensor_information : list of :func:`sensor_information` dicts (1..128), optional
        The Sensor Information container (``containerId`` 3).
    perception_regions : list of :func:`perception_region_entry` dicts (1..256), optional
        The Perception Region container (``containerId`` 4).
    number_of_perceived_objects : int, optional
        ``numberOfPerceivedObjects``: the total number of objects perceived at the time of generation (0..255,
        larger counts are sent as 255); default: the objects of this CPM.
    """
    if isinstance(station_id, bool) or not 0 <= int(station_id) <= 4294967295:
        raise InputError("station_id", station_id, "an integer in 0..4294967295 (StationId)")
    if len(perceived_objects) > 255:
        raise InputError("perceived_objects", len(perceived_objects), "at most 255 objects per CPM")
    mc = {"referenceTime": int(reference_time_ms),
          "referencePosition": {"latitude": int(latitude), "longitude": int(longitude),
                                "positionConfidenceEllipse": unavailable_reference_ellipse(),
                                "altitude": {"altitudeValue": ALTITUDE_UNAVAILABLE,
                                             "altitudeConfidence": "unavailable"}}}
    if segmentation is not None:
        this, total = segmentation
        _int_in("segmentationInfo.totalMsgNo", total, 1, 8, "CardinalNumber3b")
        mc["segmentationInfo"] = {"totalMsgNo": int(total),
                                  "thisMsgNo": _int_in("segmentationInfo.thisMsgNo", this, 1, int(total),
                                                       "OrdinalNumber3b, at most totalMsgNo")}
    containers = [{"containerId": CONTAINER_ID_RSU, "containerData": {}}]
    for cid, items, hi in ((CONTAINER_ID_SENSOR_INFORMATION, sensor_information, 128),
                           (CONTAINER_ID_PERCEPTION_REGION, perception_regions, 256)):
        if items is not None:
            if not 1 <= len(items) <= hi:
                raise InputError(_CONTAINER_TYPES[cid], len(items), f"1..{hi} entries")
            containers.append({"containerId": cid, "containerData": list(items)})
    n_total = len(perceived_objects) if number_of_perceived_objects is None else number_of_perceived_objects
    if isinstance(n_total, bool) or not isinstance(n_total, (int, np.integer)) or n_total < 0:
        raise InputError("number_of_perceived_objects", n_total, "a count >= 0")
    containers.append({"containerId": CONTAINER_ID_PERCEIVED_OBJECTS,
                       "containerData": {"numberOfPerceivedObjects": min(int(n_total), 255),
                                         "perceivedObjects": perceived_objects}})
    return {
        "header": {"protocolVersion": CPM_PROTOCOL_VERSION, "messageId": MESSAGE_ID_CPM, "stationId": int(station_id)},
        "payload": {"managementContainer": mc, "cpmContainers": containers}}


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


def _shaped_to_asn1(items: list[dict]) -> list[dict]:
    """SensorInformation / PerceptionRegion entries with their ``Shape`` CHOICE as asn1tools' (name, value)."""
    return [{**e, "perceptionRegionShape": next(iter(e["perceptionRegionShape"].items()))}
            if "perceptionRegionShape" in e else e for e in items]


def _shaped_from_asn1(items: list[dict]) -> list[dict]:
    return [{**e, "perceptionRegionShape": dict([e["perceptionRegionShape"]])}
            if "perceptionRegionShape" in e else e for e in items]


_CONTAINER_TYPES = {CONTAINER_ID_RSU: "OriginatingRsuContainer",
                    CONTAINER_ID_SENSOR_INFORMATION: "SensorInformationContainer",
                    CONTAINER_ID_PERCEPTION_REGION: "PerceptionRegionContainer",
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
        elif cid != CONTAINER_ID_RSU:
            data = _shaped_to_asn1(data)
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
        elif cid != CONTAINER_ID_RSU:
            data_ = _shaped_from_asn1(data_)
        containers.append({"containerId": cid, "containerData": data_})
    return {"header": msg["header"], "payload": {"managementContainer": msg["payload"]["managementContainer"],
                                                 "cpmContainers": containers}}
