"""The edge service's per-frame API, its messages and its drop policy (no broker: see test_service_mqtt.py).

* ``Service.process_frame`` gives the numbers of ``FrameProcessor`` and the V2X fields of
  ``footprint_uq.products.v2x`` for the centre covariance, in the output record and in the CPM / SDSM;
* the CPM's UPER bytes: a hand-derived bit string for a tiny message (pinned), the direct writer
  equal to asn1tools on seeded random messages, and asn1tools decoding back to the JSON;
* malformed frames give error records naming the field, never an exception;
* the one-pending-frame-per-camera queue drops and counts as documented.
"""

from __future__ import annotations

import json
import math
import threading
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import FrameProcessor, PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.products.footprints import V2X_FIELDS
from footprint_uq.products.v2x import J2735_POSITION_CONFIDENCE_NAMES, cpm_fields, j2735_fields
from footprint_uq.service import Service
from footprint_uq.service.messages.cpm import (
    build_cpm,
    decode_cpm_uper,
    encode_cpm_uper,
    perceived_object,
    timestamp_its_ms,
)
from footprint_uq.service.messages.uper_cpm import encode_cpm_uper_fast
from footprint_uq.service.runner import FrameQueue

pytest.importorskip("asn1tools")

T0 = 1714564800.0  # 2024-05-01 12:00:00 UTC
HEADING = 12.0


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


@pytest.fixture(scope="module")
def service(camera):
    return Service(camera, "basler1", heading_offset_deg=HEADING, uper_encoder="asn1tools")


def boxes3d(rng, n):
    return [{"object_id": i, "class": rng.choice(["car", "pedestrian", "truck", "bicycle"]),
             "x_m": float(rng.uniform(0, 40)), "y_m": float(rng.uniform(8, 70)), "z_m": 0.75,
             "length_m": float(rng.uniform(0.5, 6)), "width_m": float(rng.uniform(0.5, 2.5)), "height_m": 1.5,
             "yaw_rad": float(rng.uniform(-3, 3))} for i in range(n)]


# -- timestamps -------------------------------------------------------------------------------------
def test_timestamp_its_counts_tai_milliseconds_since_2004():
    assert timestamp_its_ms(1072915200.0) == 0  # 2004-01-01 00:00:00 UTC
    assert timestamp_its_ms(1072915200.001) == 1
    # 2024-05-01 12:00:00 UTC: 641,649,600 s of UTC since 2004 plus the 5 leap seconds of 2005-2016
    assert timestamp_its_ms(T0) == (641_649_600 + 5) * 1000
    with pytest.raises(ValueError, match="timestamp_s"):
        timestamp_its_ms(1e9)  # 2001


def _timestamp_by_lookup(unix_s: float) -> int:
    """TimestampIts by the leap-second look-up alone (the general branch of ``timestamp_its_ms``)."""
    import bisect

    from footprint_uq.service.messages import cpm

    leap = bisect.bisect_right(cpm._LEAP_SECONDS_UNIX_S, unix_s)
    return int(round((unix_s - cpm._UNIX_2004_S + leap) * 1000.0))


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.floats(1.0e9, 5.5e9), st.floats(1483228799.0, 1483228801.0), st.floats(3.9999e9, 4.0001e9),
                 st.sampled_from([1483228800.0, 1483228799.9995, 1483228800.0005, 4.0e9, 1072915200.0005, T0,
                                  1.7e9 + 1 / 30, 5470961706.1025, 5470961706.1035]),
                 st.integers(1_100_000_000, 5_000_000_000)))
def test_timestamp_its_shortcut_is_the_lookups(unix_s):
    """The shortcut for times after the last leap second (the usual frame's) gives the look-up's milliseconds, to
    the one: at and around the last leap second, the shortcut's end, half milliseconds, integers (not taken by the
    shortcut), and the range's ends and errors as before."""
    from footprint_uq.service.messages import cpm

    try:
        want = _timestamp_by_lookup(unix_s) if unix_s >= cpm._UNIX_2004_S else None
    except OverflowError:
        want = None
    if want is None or want > cpm.TIMESTAMP_ITS_MAX:
        with pytest.raises(ValueError, match="timestamp_s"):
            timestamp_its_ms(unix_s)
        return
    got = timestamp_its_ms(unix_s)
    assert type(got) is int and got == want


# -- UPER: hand-derived bits ----------------------------------------------------------------------------
def _bits(v: int, n: int) -> str:
    assert 0 <= v < 2 ** n
    return format(v, f"0{n}b")


def _octets(bits: str) -> bytes:
    bits += "0" * (-len(bits) % 8)
    return int(bits, 2).to_bytes(len(bits) // 8, "big")


PINNED_TINY_CPM_HEX = ("020e000000010000000000035a4e900eb49d200fffffff08eddd0f88808020b004028408001e0010"
                       "2690123ff900a030000091017200")  # 54 octets


@pytest.mark.parametrize("cdd", ["2.1.1", "2.2.1"])
def test_uper_of_a_tiny_cpm_is_the_hand_derived_bytes(cdd):
    """One perceived object; every field written out from X.691 (unaligned PER) by hand, in both CDD releases."""
    po = perceived_object(7, 1234, -56, 37, 81, 45, {"vehicleSubClass": 5}, 101, 0)
    cpm = build_cpm(1, 0, [po])  # reference time 0, reference position unavailable
    obj = "".join([
        "0",                                  # PerceivedObject extension bit
        "10000100000010",                     # presence: objectId, lowerTriangular..., classification
        _bits(7, 16),                         # objectId (0..65535)
        _bits(0 + 2048, 12),                  # measurementDeltaTime (-2048..2047)
        "0",                                  # position: zCoordinate absent
        _bits(1234 + 131072, 18), _bits(37 - 1, 12),   # x value (-131072..131071), confidence (1..4096)
        _bits(-56 + 131072, 18), _bits(81 - 1, 12),    # y
        "00",                                 # one correlation matrix (SIZE 1..4)
        "0" + "1100000000000",                # components: extension bit + 13 bits (xPosition, yPosition)
        "0" * (cdd == "2.2.1"),               # CDD V2.2.1: the columns' SIZE (1..13, ...) extension bit
        "0000",                               # one column (SIZE 1..13)
        "0" + "0000",                         # column: extension bit + one cell (SIZE 1..13, ...)
        _bits(45 + 100, 8),                   # CorrelationCellValue (-100..101)
        "000",                                # one class (SIZE 1..8)
        "0" + "00",                           # ObjectClass: extension bit + alternative 0 (vehicleSubClass)
        _bits(5, 4),                          # TrafficParticipantType passengerCar in (0..14)
        _bits(101 - 1, 7),                    # ConfidenceLevel (1..101)
    ])
    container = _octets("0" + _bits(1, 8) + "0" + _bits(1, 8) + obj)  # ext, numberOf..., list ext + count
    message = "".join([
        _bits(2, 8), _bits(14, 8), _bits(1, 32),              # ItsPduHeader
        "0",                                                  # CpmPayload extension bit
        "0" + "00",                                           # ManagementContainer: extension bit, 2 optionals
        _bits(0, 42),                                         # referenceTime
        _bits(900000001 + 900000000, 31),                     # latitude unavailable
        _bits(1800000001 + 1800000000, 32),                   # longitude unavailable
        _bits(4095, 12), _bits(4095, 12), _bits(3601, 12),    # confidence ellipse unavailable
        _bits(800001 + 100000, 20), _bits(15, 4),             # altitude unavailable
        "0" + _bits(2 - 1, 3),                                # two wrapped containers (SIZE 1..8, ...)
        _bits(2 - 1, 4), _bits(1, 8), _bits(0, 8),            # originatingRsuContainer: 1 octet 0x00
        _bits(5 - 1, 4), _bits(len(container), 8),            # perceivedObjectContainer, length < 128
        "".join(_bits(b, 8) for b in container),
    ])
    expected = _octets(message)
    if cdd == "2.1.1":
        assert expected.hex() == PINNED_TINY_CPM_HEX
    assert encode_cpm_uper(cpm, cdd) == expected            # asn1tools from the subset module
    assert encode_cpm_uper_fast(cpm, cdd=cdd) == expected   # the direct writer
    assert decode_cpm_uper(expected, cdd) == cpm


def _vru_classes(cdd):
    from footprint_uq.service.messages.asn1_cpm import VRU_SUBPROFILES

    return [{"vruSubClass": {alt: (name if cdd == "2.1.1" else k)}}
            for alt, names in VRU_SUBPROFILES.items() for k, name in enumerate(names)] + \
        [{"vruSubClass": {alt: "max" if cdd == "2.1.1" else 15}} for alt in VRU_SUBPROFILES]


@pytest.mark.parametrize("cdd", ["2.1.1", "2.2.1"])
def test_direct_writer_equals_asn1tools_on_random_messages(cdd):
    rng = np.random.default_rng(14)
    classes = [None, {"vehicleSubClass": 0}, {"vehicleSubClass": 14}, {"otherSubClass": 255}, *_vru_classes(cdd)]
    for n in (0, 1, 2, 17, 255):
        objs = [perceived_object(int(rng.integers(0, 65536)), int(rng.integers(-131072, 131072)),
                                 int(rng.integers(-131072, 131072)), int(rng.integers(1, 4097)),
                                 int(rng.integers(1, 4097)),
                                 int(rng.choice([101, -100, 100, 0, int(rng.integers(-99, 99))])),
                                 classes[int(rng.integers(len(classes)))], int(rng.integers(1, 102)),
                                 int(rng.integers(-2048, 2048))) for _ in range(n)]
        cpm = build_cpm(int(rng.integers(0, 2 ** 32)), int(rng.integers(0, 2 ** 42)), objs,
                        latitude=int(rng.integers(-900000000, 900000002)),
                        longitude=int(rng.integers(-1800000000, 1800000002)))
        ref = encode_cpm_uper(cpm, cdd)
        assert encode_cpm_uper_fast(cpm, cdd=cdd) == ref, n
        assert decode_cpm_uper(ref, cdd) == cpm, n
    with pytest.raises(ValueError, match="objectId"):
        encode_cpm_uper_fast(build_cpm(1, 0, [perceived_object(70000, 0, 0, 1, 1, 0, None)]))


# -- the per-frame API ------------------------------------------------------------------------------
def test_process_frame_matches_frame_processor_and_v2x(camera, service):
    rng = np.random.default_rng(3)
    dets = boxes3d(rng, 40)
    rec = service.process_frame({"camera_id": "cam1", "frame": 5, "timestamp_s": T0, "detections": dets})
    assert rec["type"] == "footprints" and rec["n_objects"] == 40
    ref = FrameProcessor(camera, "basler1", heading_offset_deg=HEADING).boxes3d(
        np.array([[d[k] for k in ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")] for d in dets]))
    objs = rec["objects"]
    valid = ref.centre_valid
    assert 0 < valid.sum() < 40  # some boxes reach outside the image: partial / error rows are exercised too
    xy = np.array([[np.nan if o["x_m"] is None else o["x_m"], np.nan if o["y_m"] is None else o["y_m"]]
                   for o in objs])
    np.testing.assert_allclose(xy[valid], ref.centre_xy_world_m[valid], rtol=1e-12)
    cov = np.array([[[np.nan if v is None else v for v in row] for row in o["cov_m2"]] for o in objs])
    np.testing.assert_allclose(cov[valid], ref.centre_cov_m2[valid], rtol=1e-12)
    # the V2X fields of the record are footprint_uq.products.v2x's of the centre covariance
    fields = {**cpm_fields(ref.centre_cov_m2, HEADING), **j2735_fields(ref.centre_cov_m2, HEADING)}
    for name in V2X_FIELDS:
        assert [o[name] for o in objs] == fields[name].tolist(), name
    a = np.array([np.nan if o["sigma_major_m"] is None else o["sigma_major_m"] for o in objs])
    k95 = math.sqrt(-2 * math.log(0.05))
    semi = np.array([np.nan if o["semi_major_m"] is None else o["semi_major_m"] for o in objs])
    np.testing.assert_allclose(semi[valid], k95 * a[valid], rtol=1e-12)
    assert [o["status"] for o in objs] == ["ok" if v else ("partial" if li >= 0 else "error")
                                          for v, li in zip(valid, ref.largest_index, strict=True)]
    # the CPM carries exactly the objects with a centre, with the same confidence codes
    pos = rec["cpm"]["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"]
    ok = [o for o in objs if o["status"] == "ok"]
    assert [p["objectId"] for p in pos] == [o["message_object_id"] for o in ok]
    for p, o in zip(pos, ok, strict=True):
        assert p["position"]["xCoordinate"]["confidence"] == o["cpm_x_confidence"]
        assert p["position"]["yCoordinate"]["confidence"] == o["cpm_y_confidence"]
        corr = p.get("lowerTriangularCorrelationMatrices")
        assert (corr[0]["matrix"][0][0] if corr else 101) == o["cpm_xy_correlation"]
    # east/north offsets: the world point rotated by the heading offset, in cm, as the CDD's
    # CartesianCoordinateLarge: (n - 1) x 0.01 m < v <= n x 0.01 m
    h = np.deg2rad(HEADING)
    for p, o in zip(pos, ok, strict=True):
        e = o["x_m"] * np.cos(h) + o["y_m"] * np.sin(h)
        n = -o["x_m"] * np.sin(h) + o["y_m"] * np.cos(h)
        assert p["position"]["xCoordinate"]["value"] == math.ceil(100 * e)
        assert p["position"]["yCoordinate"]["value"] == math.ceil(100 * n)
    sd = rec["sdsm"]["objects"]
    assert [s["detObjCommon"]["posConfidence"]["pos"] for s in sd] == \
        [J2735_POSITION_CONFIDENCE_NAMES[o["j2735_position_confidence"]] for o in ok]
    # the UPER bytes decode (asn1tools) to the CPM JSON, and the record is plain JSON
    assert decode_cpm_uper(rec["cpm_uper_hex"]) == rec["cpm"]
    assert json.loads(json.dumps(rec, allow_nan=False)) == rec


def test_2d_boxes_with_detector_covariance_and_classes(camera, service):
    det = {"object_id": "ped-3", "class": "pedestrian", "class_confidence": 0.87,
           "u_min_px": 900.0, "v_min_px": 600.0, "u_max_px": 1000.0, "v_max_px": 700.0}
    plain = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": [det]})
    noisy = service.process_frame({"frame": 2, "timestamp_s": T0, "detections": [
        {**det, "cov_uu_px2": 16.0, "cov_uv_px2": 0.0, "cov_vv_px2": 25.0}]})
    ref = FrameProcessor(camera, "basler1", heading_offset_deg=HEADING).boxes2d(
        np.array([[900.0, 600.0, 1000.0, 700.0]]), pixel_cov_px2=np.array([[[16.0, 0.0], [0.0, 25.0]]]))
    np.testing.assert_allclose(noisy["objects"][0]["cov_m2"], ref.centre_cov_m2[0], rtol=1e-12)
    assert noisy["objects"][0]["sigma_major_m"] > plain["objects"][0]["sigma_major_m"]
    po = noisy["cpm"]["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"][0]
    assert po["classification"] == [{"objectClass": {"vruSubClass": {"pedestrian": 1}},  # CDD V2.2.1: INTEGER
                                     "confidence": 87}]
    assert noisy["sdsm"]["objects"][0]["detObjCommon"]["objType"] == "vru"
    assert noisy["sdsm"]["objects"][0]["detObjCommon"]["objTypeCfd"] == 87


def test_geodetic_reference_position(camera):
    pytest.importorskip("pyproj")
    svc = Service(camera, "basler1", heading_offset_deg=HEADING, origin_lat_deg=42.2808, origin_lon_deg=-83.743)
    rec = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": [
        {"u_min_px": 900.0, "v_min_px": 600.0, "u_max_px": 1000.0, "v_max_px": 700.0}]})
    mc = rec["cpm"]["payload"]["managementContainer"]
    assert mc["referencePosition"]["latitude"] == 422808000 and mc["referencePosition"]["longitude"] == -837430000
    assert mc["referenceTime"] == timestamp_its_ms(T0)
    assert rec["sdsm"]["refPos"] == {"lat": 422808000, "long": -837430000}
    o = rec["objects"][0]
    assert 42.28 < o["lat_deg"] < 42.29 and -83.75 < o["lon_deg"] < -83.73


@pytest.mark.parametrize("frame, field, words", [
    ('{"frame": 1', None, "invalid JSON"),
    ("[1, 2]", None, "not a JSON object"),
    ({"timestamp_s": T0, "detections": []}, "frame", "missing field frame"),
    ({"frame": "7", "timestamp_s": T0, "detections": []}, "frame", "not an integer"),
    ({"frame": 1, "timestamp_s": None, "detections": []}, "frame.timestamp_s", "missing"),
    ({"frame": 1, "timestamp_s": 1e9, "detections": []}, "timestamp_s", "2004"),
    ({"frame": 1, "timestamp_s": T0, "detections": {}}, "detections", "not a list"),
    (b'\xff{"frame": 1}', None, "not UTF-8"),
    ('{"frame": 1, "timestamp_s": NaN, "detections": []}', None, "invalid JSON"),  # (strict JSON, as over MQTT)
])
def test_malformed_frames_give_error_records(service, frame, field, words):
    rec = service.process_frame(frame, source="test line 3")
    assert rec["type"] == "error", rec
    assert rec["field"] == field and words in rec["reason"] and rec["source"] == "test line 3"
    json.dumps(rec, allow_nan=False)


GOOD_BOX = {"u_min_px": 900.0, "v_min_px": 600.0, "u_max_px": 1000.0, "v_max_px": 700.0}


@pytest.mark.parametrize("bad, field, words", [
    ({"u_min_px": 1.0}, "detections[1]", "no complete box"),
    ({"u_min_px": 1.0, "v_min_px": "x", "u_max_px": 3.0, "v_max_px": 4.0}, "detections[1].v_min_px", "not a number"),
    ({"u_min_px": 1.0, "v_min_px": 2.0, "u_max_px": 3.0, "v_max_px": True}, "detections[1].v_max_px", "number"),
    ({"u_min_px": 1.0, "v_min_px": 2.0, "u_max_px": 3.0, "v_max_px": float("inf")}, "detections[1].v_max_px",
     "not finite"),
    ({"u_min_px": 5.0, "v_min_px": 2.0, "u_max_px": 3.0, "v_max_px": 4.0}, "detections[1]", "u_min <= u_max"),
    ({**GOOD_BOX, "cov_uu_px2": 1.0}, "detections[1].cov_uv_px2", "incomplete pixel covariance"),
    ({**GOOD_BOX, "cov_uu_px2": 1.0, "cov_uv_px2": 5.0, "cov_vv_px2": 1.0}, "detections[1]", "positive semi-definite"),
    ({**GOOD_BOX, "object_id": [1]}, "detections[1].object_id", "not a string or integer"),
    ({**GOOD_BOX, "class": 2}, "detections[1].class", "--class-names"),
    ({**GOOD_BOX, "class": 2.5}, "detections[1].class", "not a name or an integer class id"),
    ({**GOOD_BOX, "class": True}, "detections[1].class", "not a name or an integer class id"),
    ({**GOOD_BOX, "class_confidence": 1.5}, "detections[1].class_confidence", "not in [0, 1]"),
    ({"x_m": 1.0, "y_m": 20.0, "z_m": 0.0, "length_m": 4.0, "width_m": 2.0, "height_m": 1.5, "yaw_rad": 0.0},
     "detections[1]", "a 3d box in a frame of 2d boxes"),
    ("car", "detections[1]", "not a JSON object"),
])
def test_a_bad_detection_is_its_own_error_entry(service, bad, field, words):
    """The frame's other detections are processed and the record published; the bad one is named (index, field,
    reason) in ``detection_errors``, never the frame's error."""
    good = [dict(GOOD_BOX, object_id=f"g{k}", u_min_px=800.0 + 30 * k, u_max_px=900.0 + 30 * k) for k in range(3)]
    rec = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": [good[0], bad, good[1], good[2]]})
    assert rec["type"] == "footprints", rec
    (err,) = rec["detection_errors"]
    assert err["index"] == 1 and err["field"] == field and words in err["reason"], err
    assert rec["n_objects"] == 3 and [o["object_id"] for o in rec["objects"]] == ["g0", "g1", "g2"]
    alone = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": good})
    assert alone["detection_errors"] == [] and alone["objects"] == rec["objects"]  # the same numbers without it
    json.dumps(rec, allow_nan=False)


def test_one_bad_detection_among_ten_nine_processed_and_published(camera):
    """Issue 33: integer class ids named through the COCO map; one id the map does not name is that detection's
    error entry; the nine others are in the record, its CPM and its SDSM."""
    svc = Service(camera, "basler1", heading_offset_deg=HEADING, class_names="coco")
    dets = [dict(GOOD_BOX, u_min_px=700.0 + 40 * k, u_max_px=760.0 + 40 * k, **{"class": [2, 0, 7, 5][k % 4]})
            for k in range(10)]
    dets[6]["class"] = 80  # COCO has ids 0..79
    rec = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": dets})
    assert rec["type"] == "footprints" and rec["n_objects"] == 9 and len(rec["objects"]) == 9
    assert rec["detection_errors"] == [{"index": 6, "field": "detections[6].class",
                                        "reason": "class id 80 is not in the names map (coco, 80 names)"}]
    # object ids default to the detection's position in the frame: the bad one's position is skipped
    assert [o["object_id"] for o in rec["objects"]] == [0, 1, 2, 3, 4, 5, 7, 8, 9]
    assert [o["class"] for o in rec["objects"]] == ["car", "person", "truck", "bus", "car", "person", "bus", "car",
                                                    "person"]
    assert rec["cpm"]["payload"]["cpmContainers"][1]["containerData"]["numberOfPerceivedObjects"] == 9
    assert len(rec["sdsm"]["objects"]) == 9 and decode_cpm_uper(rec["cpm_uper_hex"]) == rec["cpm"]
    # the numbers are those of the nine alone (names given as text)
    named = [dict(d, **{"class": rec["objects"][j]["class"]}) for j, d in enumerate(dets[:6] + dets[7:])]
    alone = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": named})
    ids = ("object_id", "message_object_id")  # (the message ids follow the object ids)
    assert [{k: v for k, v in o.items() if k not in ids} for o in alone["objects"]] == \
        [{k: v for k, v in o.items() if k not in ids} for o in rec["objects"]]


def test_every_bad_detection_of_a_frame_is_named_once(service):
    """Several bad detections, several faults each: one entry per bad detection (its first fault), in order."""
    dets = [dict(GOOD_BOX, u_min_px=2000.0), dict(GOOD_BOX), dict(GOOD_BOX, cov_uu_px2=-1.0, cov_uv_px2=0.0,
            cov_vv_px2=1.0, u_max_px=1.0), {"v_min_px": 1.0}, dict(GOOD_BOX, cov_uu_px2=1e13, cov_uv_px2=0.0,
                                                                    cov_vv_px2=1.0)]
    rec = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": dets})
    assert [e["index"] for e in rec["detection_errors"]] == [0, 2, 3, 4] and rec["n_objects"] == 1
    assert "u_min <= u_max" in rec["detection_errors"][1]["reason"]  # (the box's fault first, then the covariance)
    assert rec["detection_errors"][3]["field"] == "detections[4].cov_uu_px2"
    none = service.process_frame({"frame": 1, "timestamp_s": T0, "detections": [dets[0], dets[3]]})
    assert none["type"] == "footprints" and none["n_objects"] == 0 and len(none["detection_errors"]) == 2
    assert none["sdsm"] is None


def test_class_names_files(tmp_path, camera):
    """The service names integer classes (ints and integral floats) through a names file; an id it does not name is
    that detection's error entry, or the class 'unknown' with unknown_class="unknown" (the loader's own tests:
    tests/test_class_names.py)."""
    (tmp_path / "data.yaml").write_text("path: x\nnames:\n  0: car\n  3: Pedestrian\n")
    svc = Service(camera, "basler1", class_names=tmp_path / "data.yaml", messages=False)
    rec = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": [
        dict(GOOD_BOX, **{"class": 3}), dict(GOOD_BOX, **{"class": 1}), dict(GOOD_BOX, **{"class": 0.0})]})
    assert [o["class"] for o in rec["objects"]] == ["Pedestrian", "car"]
    assert rec["detection_errors"][0]["index"] == 1 and "not in the names map" in rec["detection_errors"][0]["reason"]
    unk = Service(camera, "basler1", class_names=tmp_path / "data.yaml", unknown_class="unknown", messages=False)
    for second in (1, 1.0):  # ints only (the frame's fast path) and a float among them (detection by detection)
        rec = unk.process_frame({"frame": 1, "timestamp_s": T0, "detections": [
            dict(GOOD_BOX, **{"class": 3}), dict(GOOD_BOX, **{"class": second}), dict(GOOD_BOX, **{"class": 0})]})
        assert [o["class"] for o in rec["objects"]] == ["Pedestrian", "unknown", "car"], second
        assert rec["detection_errors"] == []
    with pytest.raises(InputError, match="^unknown_class"):
        Service(camera, "basler1", class_names="coco", unknown_class="skip", messages=False)
    with pytest.raises(InputError, match="^unknown_class"):
        Service(camera, "basler1", unknown_class="skip", messages=False)


def test_registry_routes_frames_by_camera_id(tmp_path, camera):
    from footprint_uq import save_camera

    save_camera(camera, tmp_path / "camA.yaml")
    save_camera(PanTiltCamera(focal_px=1000, image_size_px=(1280, 720), height_m=5.0, pan_deg=0.0, tilt_deg=15.0),
                tmp_path / "camB.yaml")
    (tmp_path / "reg.csv").write_text("camera_id,camera,budget,heading_offset_deg\ncamA,camA.yaml,basler1,\n"
                                      "camB,camB.yaml,bw-cube1,30\n")
    svc = Service(registry=tmp_path / "reg.csv")
    det = [{"u_min_px": 600.0, "v_min_px": 500.0, "u_max_px": 700.0, "v_max_px": 600.0}]
    a = svc.process_frame({"camera_id": "camA", "frame": 1, "timestamp_s": T0, "detections": det})
    b = svc.process_frame({"camera_id": "camB", "frame": 1, "timestamp_s": T0, "detections": det})
    assert a["heading_offset_deg"] == 0.0 and b["heading_offset_deg"] == 30.0
    assert a["station_id"] != b["station_id"] and a["objects"][0]["x_m"] != b["objects"][0]["x_m"]
    c = svc.process_frame({"camera_id": "camC", "frame": 1, "timestamp_s": T0, "detections": det})
    assert c["type"] == "error" and c["field"] == "camera_id" and "not in the registry" in c["reason"]


# -- the drop policy --------------------------------------------------------------------------------
def test_queue_keeps_the_newest_frame_per_camera_and_counts_drops():
    q = FrameQueue("newest")
    for i in range(5):
        q.put("a", i)
    q.put("b", 0)
    q.put("a", 5)
    assert len(q) == 2 and q.dropped == 5
    assert q.get(0) == 5 and q.get(0) == 0 and q.get(0.01) is None  # camera a first: it was waiting longer
    q.close()
    assert q.get() is None and not q.put("a", 6)


def test_queue_block_policy_waits_instead_of_dropping():
    q = FrameQueue("block")
    q.put("a", 1)
    got = []
    t = threading.Thread(target=lambda: got.append(q.put("a", 2)))
    t.start()
    time.sleep(0.2)
    assert t.is_alive() and len(q) == 1  # the second frame of camera a waits for the first
    assert q.get(0) == 1
    t.join(2)
    assert got == [True] and q.get(0) == 2 and q.dropped == 0


def test_queue_block_policy_serves_frames_in_the_order_they_were_read():
    # stdin replays a recording: the CP service must see the frames as recorded, whatever the reader's lead
    # (the fair cameras-in-turn order of ``newest`` would swap a late frame of one camera behind another's)
    q = FrameQueue("block", depth=3)
    for key, item in [("a", 1), ("b", 2), ("a", 3), ("a", 4), ("c", 5), ("b", 6)]:
        assert q.put(key, item)
    assert [q.get(0) for _ in range(6)] == [1, 2, 3, 4, 5, 6] and q.get(0.01) is None
    n = FrameQueue("newest", depth=3)
    for key, item in [("a", 1), ("b", 2), ("a", 3), ("a", 4), ("c", 5), ("b", 6)]:
        n.put(key, item)
    assert [n.get(0) for _ in range(6)] == [1, 2, 5, 3, 6, 4]  # cameras in turn


def _random_motion(rng, n):
    """Motion codes of n objects, each component present or not, over the whole value ranges."""
    from footprint_uq.service.messages.motion import MotionCodes

    def pick(lo, hi):
        return np.where(rng.random(n) < 0.2, rng.choice([lo, hi], n), rng.integers(lo, hi + 1, n))

    z = np.zeros(n, np.int64)
    return MotionCodes(rng.random(n) < 0.6, pick(-16383, 16383), pick(1, 127), pick(-16383, 16383), pick(1, 127),
                       rng.random(n) < 0.6, pick(0, 3601), pick(1, 127), rng.random(n) < 0.6, pick(0, 2047),
                       z, z, z, z)


def _motion_kwargs(mc, i):
    return dict(velocity=(mc.vx[i], mc.vx_conf[i], mc.vy[i], mc.vy_conf[i]) if mc.has_velocity[i] else None,
                yaw=(mc.yaw[i], mc.yaw_conf[i]) if mc.has_yaw[i] else None,
                age_ms=int(mc.age_ms[i]) if mc.has_age[i] else None)


@pytest.mark.parametrize("cdd", ["2.1.1", "2.2.1"])
def test_column_writer_equals_asn1tools(cdd):
    """The per-frame path writes the container from columns (motion included): the same bytes as asn1tools."""
    from footprint_uq.service.messages.cpm import _spec, cpm_to_asn1_value
    from footprint_uq.service.messages.uper_cpm import class_bits, perceived_object_container_uper

    rng = np.random.default_rng(41)
    classes = [None, {"vehicleSubClass": 0}, {"vehicleSubClass": 14}, {"otherSubClass": 255}, *_vru_classes(cdd)]
    for n in (0, 1, 9, 255):
        cols = dict(o=rng.integers(0, 65536, n).tolist(), x=rng.integers(-131072, 131072, n).tolist(),
                    y=rng.integers(-131072, 131072, n).tolist(), cx=rng.integers(1, 4097, n).tolist(),
                    cy=rng.integers(1, 4097, n).tolist(), r=rng.choice([101, -100, 100, 0, 37], n).tolist(),
                    c=[classes[k] for k in rng.integers(0, len(classes), n)], lv=rng.integers(1, 102, n).tolist())
        mc = _random_motion(rng, n)
        objs = [perceived_object(*row, **_motion_kwargs(mc, i))  # (id, x, y, cx, cy, r, c, lv)
                for i, row in enumerate(zip(*cols.values(), strict=True))]
        cpm = build_cpm(5, 0, objs)
        ref = cpm_to_asn1_value(cpm, cdd)["payload"]["cpmContainers"][1]["containerData"]
        got = perceived_object_container_uper(cols["o"], cols["x"], cols["cx"], cols["y"], cols["cy"], cols["r"],
                                              [None if c is None else (class_bits(c, cdd), lv)
                                               for c, lv in zip(cols["c"], cols["lv"], strict=True)], cdd=cdd,
                                              motion=mc)
        assert got == ref, n
        assert _spec(cdd).decode("PerceivedObjectContainer", got)["numberOfPerceivedObjects"] == n
        assert encode_cpm_uper_fast(cpm, cdd=cdd) == encode_cpm_uper(cpm, cdd)
    with pytest.raises(ValueError, match="xCoordinate.value"):
        perceived_object_container_uper([1], [131072], [1], [0], [1], [101], [None])


def test_more_than_255_objects_are_said_not_to_fit_in_the_messages(camera):
    svc = Service(camera, "basler1")
    dets = [{"object_id": i, "u_min_px": 900.0, "v_min_px": 600.0, "u_max_px": 1000.0, "v_max_px": 700.0}
            for i in range(260)]
    rec = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": dets})
    assert rec["n_objects"] == 260 and rec["objects_not_in_messages"] == 5
    assert [o["message_object_id"] for o in rec["objects"][255:]] == [None] * 5
    assert rec["cpm"]["payload"]["cpmContainers"][1]["containerData"]["numberOfPerceivedObjects"] == 255
    assert len(rec["sdsm"]["objects"]) == 255
    assert decode_cpm_uper(rec["cpm_uper_hex"]) == rec["cpm"]
    assert "objects_not_in_messages" not in svc.process_frame({"frame": 2, "timestamp_s": T0, "detections": dets[:3]})
    empty = svc.process_frame({"frame": 3, "timestamp_s": T0, "detections": []})
    assert empty["n_objects"] == 0 and empty["sdsm"] is None  # J3224: an object list has at least one entry
    assert decode_cpm_uper(empty["cpm_uper_hex"]) == empty["cpm"]


def test_bad_service_options_are_refused(camera):
    with pytest.raises(ValueError, match="contact"):
        Service(camera, "basler1", contact="2d", warm_up=False)
    with pytest.raises(ValueError, match="camera/registry"):
        Service(warm_up=False)
    with pytest.raises(ValueError, match="budget"):
        Service(camera, warm_up=False)
    with pytest.raises(ValueError, match="uper_encoder"):
        Service(camera, "basler1", uper_encoder="ber", warm_up=False)
    with pytest.raises(ValueError, match="cpm_cdd"):
        Service(camera, "basler1", cpm_cdd="1.3.1", warm_up=False)
    with pytest.raises(ValueError, match="v2x_policy"):
        Service(camera, "basler1", v2x_policy="optimistic", warm_up=False)
    with pytest.raises(ValueError, match="confidence"):
        Service(camera, "basler1", confidence=1.0, warm_up=False)


@pytest.mark.parametrize("args, words", [
    (["--budget", "basler1"], "--camera/--registry"),
    (["--camera", "cam.yaml", "--budget", "basler1", "--mqtt", "http://x"], "mqtt://HOST:PORT"),
    (["--camera", "nope.yaml", "--budget", "basler1", "--input", "-"], "nope.yaml"),
    (["--registry", "reg.csv", "--input", "-", "--workers", "2"], "--workers"),
    (["--camera", "cam.yaml", "--output", "mqtt"], "--mqtt"),
    (["--camera", "cam.yaml", "--input", "-"], "--budget"),
    (["--camera", "cam.yaml", "--budget", "basler1", "--cpm-cdd", "2.4.1"], "--cpm-cdd"),
    (["--camera", "cam.yaml", "--budget", "basler1", "--queue-depth", "0"], "--queue-depth"),
    (["--camera", "cam.yaml", "--budget", "basler1", "--class-names", "nope.names"], "nope.names"),
    (["--camera", "cam.yaml", "--budget", "basler1", "--unknown-class", "unknown"], "--unknown-class"),
    (["--camera", "cam.yaml", "--budget", "basler1", "--record", "compact"], "--record"),
])
def test_serve_bad_options_exit_2_with_one_line(tmp_path, monkeypatch, camera, args, words):
    from click.testing import CliRunner

    from footprint_uq import save_camera
    from footprint_uq.cli.main import main

    monkeypatch.chdir(tmp_path)
    save_camera(camera, "cam.yaml")
    (tmp_path / "reg.csv").write_text("camera_id,camera,budget\ncam1,cam.yaml,basler1\n")
    r = CliRunner().invoke(main, ["serve", *args])
    assert r.exit_code == 2, r.output
    lines = [ln for ln in r.output.splitlines() if ln.startswith("footprint-uq: error")]
    assert len(lines) == 1 and words in lines[0], r.output


_CDD = st.sampled_from(["2.1.1", "2.2.1"])
_CLASSES = st.one_of(st.none(), st.builds(lambda v: {"vehicleSubClass": v}, st.sampled_from([0, 5, 6, 7, 8, 9, 10,
                                                                                              11, 14])),
                     st.builds(lambda v: {"otherSubClass": v}, st.integers(0, 255)),
                     st.sampled_from(_vru_classes("2.1.1") + _vru_classes("2.2.1")))
_OBJECT = st.tuples(st.integers(0, 65535), st.integers(-131072, 131071), st.integers(-131072, 131071),
                    st.integers(1, 4096), st.integers(1, 4096), st.integers(-100, 101), _CLASSES,
                    st.integers(1, 101), st.one_of(st.just(0), st.integers(-2048, 2047)))
_MOTION = st.fixed_dictionaries({}, optional={
    "velocity": st.tuples(st.integers(-16383, 16383), st.integers(1, 127), st.integers(-16383, 16383),
                          st.integers(1, 127)),
    "yaw": st.tuples(st.integers(0, 3601), st.integers(1, 127)), "age_ms": st.integers(0, 2047)})


def _release_class(c, cdd):
    """A class of either release's JSON, as the release ``cdd`` writes it."""
    if c is None or "vruSubClass" not in c:
        return c
    from footprint_uq.service.messages.asn1_cpm import VRU_SUBPROFILES

    (alt, v), = c["vruSubClass"].items()
    names = (*VRU_SUBPROFILES[alt], "max")
    k = 15 if v == "max" else names.index(v) if isinstance(v, str) else v
    return {"vruSubClass": {alt: (names[-1] if k == 15 else names[k]) if cdd == "2.1.1" else k}}


@settings(max_examples=150, deadline=None)
@given(objs=st.lists(st.tuples(_OBJECT, _MOTION), max_size=4), station=st.integers(0, 2 ** 32 - 1),
       ref=st.integers(0, 2 ** 42 - 1), lat=st.integers(-900000000, 900000001),
       lon=st.integers(-1800000000, 1800000001), cdd=_CDD)
def test_uper_writers_equal_asn1tools_over_the_whole_value_ranges(objs, station, ref, lat, lon, cdd):
    """Every field at every value of its range (edges included), both releases, with and without motion: both
    writers give asn1tools' bytes."""
    from footprint_uq.service.messages.cpm import cpm_to_asn1_value
    from footprint_uq.service.messages.motion import MotionCodes
    from footprint_uq.service.messages.uper_cpm import CpmUperWriter, class_bits, perceived_object_container_uper

    objs = [((*o[:6], _release_class(o[6], cdd), *o[7:]), mo) for o, mo in objs]
    cpm = build_cpm(station, ref, [perceived_object(*o, **mo) for o, mo in objs], latitude=lat, longitude=lon)
    ref_bytes = encode_cpm_uper(cpm, cdd)
    assert encode_cpm_uper_fast(cpm, cdd=cdd) == ref_bytes
    assert decode_cpm_uper(ref_bytes, cdd) == cpm
    if all(o[8] == 0 for o, _ in objs):  # the column writer: objects measured at the reference time
        cols = list(zip(*[o for o, _ in objs], strict=True)) if objs else [()] * 9
        mos = [mo for _, mo in objs]
        vel = [mo.get("velocity", (0, 1, 0, 1)) for mo in mos]
        yaw = [mo.get("yaw", (0, 1)) for mo in mos]
        z = np.zeros(len(objs), np.int64)
        mc = MotionCodes(np.array(["velocity" in mo for mo in mos], bool), *np.array(vel, np.int64).reshape(-1, 4).T,
                         np.array(["yaw" in mo for mo in mos], bool), *np.array(yaw, np.int64).reshape(-1, 2).T,
                         np.array(["age_ms" in mo for mo in mos], bool),
                         np.array([mo.get("age_ms", 0) for mo in mos], np.int64), z, z, z, z)
        got = perceived_object_container_uper(cols[0], cols[1], cols[3], cols[2], cols[4], cols[5],
                                              [None if c is None else (class_bits(c, cdd), lv)
                                               for c, lv in zip(cols[6], cols[7], strict=True)], cdd=cdd, motion=mc)
        assert got == cpm_to_asn1_value(cpm, cdd)["payload"]["cpmContainers"][1]["containerData"]
        # the service's per-station writer: fixed part once, reference time and container per frame
        assert CpmUperWriter(station, latitude=lat, longitude=lon).encode(ref, got) == ref_bytes


def test_linearity_flag_is_the_librarys_nonlinearity(camera):
    from footprint_uq.uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD, nonlinearity

    svc = Service(camera, "basler1", linearity=True)
    boxes = [(900.0, 600.0, 1000.0, 700.0), (300.0, 200.0, 340.0, 260.0), (1500.0, 80.0, 1520.0, 105.0),
             (100.0, 10.0, 120.0, 20.0)]  # near, far, close to the horizon, above it
    rec = svc.process_frame({"frame": 1, "timestamp_s": T0, "detections": [
        {"u_min_px": a, "v_min_px": b, "u_max_px": c, "v_max_px": d, "cov_uu_px2": 4.0, "cov_uv_px2": 0.0,
         "cov_vv_px2": 9.0} for a, b, c, d in boxes]})
    uv = np.array([[(a + c) / 2, d] for a, b, c, d in boxes])
    ref = nonlinearity(camera, "basler1", uv, pixel_cov_px2=np.tile(np.diag([4.0, 9.0]), (4, 1, 1)))
    got = np.array([np.nan if o["nonlinearity"] is None else o["nonlinearity"] for o in rec["objects"]])
    np.testing.assert_allclose(got[:3], ref[:3], rtol=1e-12)
    assert np.isnan(got[3]) and rec["objects"][3]["linear_ok"] is False  # above the horizon: no flag to give
    assert [o["linear_ok"] for o in rec["objects"][:3]] == (ref[:3] <= DEFAULT_LINEAR_THRESHOLD).tolist()
    assert ref[0] < ref[1] < ref[2]  # grows towards the horizon
    # 3D boxes: the worst of the four corners
    rng = np.random.default_rng(8)
    dets = boxes3d(rng, 6)
    rec3 = svc.process_frame({"frame": 2, "timestamp_s": T0, "detections": dets})
    est = FrameProcessor(camera, "basler1").boxes3d(
        np.array([[d[k] for k in ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")] for d in dets]))
    nl = nonlinearity(camera, "basler1", est.corners_px.reshape(-1, 2)).reshape(-1, 4)
    for o, row, use in zip(rec3["objects"], nl, est.corner_usable, strict=True):
        if use.any():
            assert o["nonlinearity"] == pytest.approx(np.max(row[use]), rel=1e-12)
        else:
            assert o["nonlinearity"] is None and o["linear_ok"] is False
    assert "linear_ok" not in Service(camera, "basler1").process_frame(
        {"frame": 1, "timestamp_s": T0, "detections": dets})["objects"][0]  # off by default: absent, not guessed


# -- the column-wise JSON writer ------------------------------------------------------------------------
_TEXT = st.text(alphabet=st.sampled_from(list(',[]{}":\\ aZ\u00e9\u4e2d\n\t\x00\U0001f697')), max_size=6)
_FLOAT = st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.sampled_from([0.0, -0.0, 5e-324, 1e16, 1e-7]))


@settings(max_examples=150, deadline=None)
@given(n=st.integers(0, 12), data=st.data())
def test_table_writes_what_orjson_writes_for_the_dicts(n, data):
    """Every kind of column (floats with NaN/inf/-0.0, int32/int64, bools, strings with JSON's special
    characters, None, objects), optional groups and a column used twice: the same bytes as orjson.dumps
    of the list of dicts."""
    import orjson

    from footprint_uq.service.jsonrows import Table

    f = np.array(data.draw(st.lists(_FLOAT, min_size=n, max_size=n)), dtype=np.float64)
    i32 = np.array(data.draw(st.lists(st.integers(-2 ** 31, 2 ** 31 - 1), min_size=n, max_size=n)), dtype=np.int32)
    i64 = np.array(data.draw(st.lists(st.integers(-2 ** 63, 2 ** 63 - 1), min_size=n, max_size=n)), dtype=np.int64)
    ok = np.array(data.draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=bool)
    txt = data.draw(st.lists(st.one_of(st.none(), _TEXT, st.integers(-10 ** 6, 10 ** 6)), min_size=n, max_size=n))
    obj = data.draw(st.lists(st.one_of(st.none(), st.dictionaries(_TEXT, st.one_of(_TEXT, st.dictionaries(
        _TEXT, _TEXT, max_size=2)), max_size=2)), min_size=n, max_size=n))
    t = Table(n)
    cf, c32, c64, cb, ct, co = (t.column(f), *t.columns(np.array([i32, i64])), t.column(ok), t.column(txt),
                                t.column(obj))
    got = t.json([b'{"f":', cf, b',"t":', ct, t.when(ok, b',"i32":', c32, b',"again":', cf), t.when(~ok, b',"o":', co),
                  b',"i64":', c64, b',"b":', cb, b"}"])
    ref = []
    for k in range(n):
        d = {"f": f[k].item(), "t": txt[k]}
        d.update({"i32": int(i32[k]), "again": f[k].item()} if ok[k] else {"o": obj[k]})
        d.update({"i64": int(i64[k]), "b": bool(ok[k])})
        ref.append(d)
    assert got == orjson.dumps(ref)


def test_objects_and_messages_are_the_documented_layout(camera):
    """The record written column-wise equals the one built object by object from FrameProcessor,
    ellipse_axes and footprint_uq.v2x (the per-object dicts of the documented layout): every key, order
    and value, for a frame with valid, partial and failed centres, classes, class confidences and
    detector covariances."""
    from footprint_uq.products.geo import GeoReference
    from footprint_uq.service.messages.cpm import CPM_CLASSES, coordinate_cm
    from footprint_uq.service.messages.ids import MessageIdMap
    from footprint_uq.service.messages.sdsm import offset_dm, sdsm_object
    from footprint_uq.uncertainty.ellipse import ellipse_axes

    rng = np.random.default_rng(21)
    n = 60
    u, v, w = rng.uniform(-50, 1900, n), rng.uniform(0, 1100, n), rng.uniform(5, 150, n)
    classes = [None, "car", "Pedestrian", "truck", "bicycle", "dog", "thing", ""]
    dets = []
    for k in range(n):
        d = {"object_id": [k, f"id-{k}", 70000 + k, "123", None][k % 5], "class": classes[k % len(classes)],
             "u_min_px": float(u[k]), "v_min_px": float(v[k] - 0.8 * w[k]), "u_max_px": float(u[k] + w[k]),
             "v_max_px": float(v[k]), "cov_uu_px2": 4.0 + k, "cov_uv_px2": 0.5, "cov_vv_px2": 9.0}
        if k % 3:
            d["class_confidence"] = float(rng.uniform(0, 1))
        dets.append(d)
    svc = Service(camera, "basler1", heading_offset_deg=HEADING, confidence=0.9, linearity=True,
                  contact="bottom-corners")
    rec = svc.process_frame({"camera_id": "c", "frame": 3, "timestamp_s": T0, "detections": dets})
    X = np.array([[d[c] for c in ("u_min_px", "v_min_px", "u_max_px", "v_max_px")] for d in dets])
    P = np.array([[[d["cov_uu_px2"], d["cov_uv_px2"]], [d["cov_uv_px2"], d["cov_vv_px2"]]] for d in dets])
    est = FrameProcessor(camera, "basler1", heading_offset_deg=HEADING, joint_cov=False).boxes2d(
        X, contact="bottom-corners", pixel_cov_px2=P)
    a, b, ori = ellipse_axes(est.centre_cov_m2)
    k90 = math.sqrt(-2 * math.log(0.1))
    none = lambda x: None if not math.isfinite(x) else x  # noqa: E731
    reasons = est.centre_reason_text()
    objects, pos, sdsm = [], [], []
    en = GeoReference(heading_offset_deg=HEADING).world_to_enu(est.centre_xy_world_m)
    ok_rows = np.flatnonzero(est.centre_valid)
    msg_id = dict(zip(ok_rows.tolist(), MessageIdMap().assign([d["object_id"] for d in dets], ok_rows, T0).tolist(),
                      strict=True))
    v2x_cov = est.centre_cov_m2 if est.v2x_cov_m2 is None else est.v2x_cov_m2
    for k, d in enumerate(dets):
        ok = bool(est.centre_valid[k])
        li = int(est.largest_index[k])
        c = est.centre_cov_m2[k].tolist()
        o = {"object_id": d["object_id"], "class": d["class"], "status": "ok" if ok else ("partial" if li >= 0 else
             "error"), "reason": "ok" if ok else f"no centre: {reasons[k]}",
             "x_m": none(est.centre_xy_world_m[k, 0]), "y_m": none(est.centre_xy_world_m[k, 1]),
             "cov_m2": [[none(c[0][0]), none(c[0][1])], [none(c[0][1]), none(c[1][1])]],
             "sigma_major_m": none(a[k]), "sigma_minor_m": none(b[k]), "orientation_deg": none(ori[k]),
             "semi_major_m": none(k90 * a[k]), "semi_minor_m": none(k90 * b[k]), "largest_index": li,
             "largest_sigma_major_m": none(est.largest_semi_major_m[k]),
             "largest_x_m": none(est.largest_xy_world_m[k, 0]), "largest_y_m": none(est.largest_xy_world_m[k, 1]),
             **dict(zip(V2X_FIELDS, est.v2x_codes[k].tolist(), strict=True)),
             "v2x_source": ["linear", "sampled", "unavailable"][est.v2x_source[k]],
             "v2x_cov_m2": None if est.v2x_source[k] == 2 else [[v2x_cov[k, 0, 0], v2x_cov[k, 0, 1]],
                                                                [v2x_cov[k, 0, 1], v2x_cov[k, 1, 1]]],
             # (checked against the library by test_linearity_flag_is_the_librarys_nonlinearity)
             "nonlinearity": rec["objects"][k]["nonlinearity"], "linear_ok": rec["objects"][k]["linear_ok"],
             "message_object_id": msg_id[k] if ok else None}
        objects.append(o)
        if ok:
            p = d.get("class_confidence")
            cls = CPM_CLASSES.get(d["class"].lower()) if d["class"] else None
            level = 101 if p is None else max(1, math.ceil(100 * p - 1e-9))
            pos.append(perceived_object(o["message_object_id"], int(coordinate_cm(en[k, 0])),
                                        int(coordinate_cm(en[k, 1])), o["cpm_x_confidence"], o["cpm_y_confidence"],
                                        o["cpm_xy_correlation"], cls, level))
            sdsm.append(sdsm_object(o["message_object_id"], int(offset_dm(en[k, 0])), int(offset_dm(en[k, 1])),
                                    o["j2735_position_confidence"], d["class"], 0 if p is None else round(100 * p)))
    assert 0 < len(pos) < n and {o["status"] for o in objects} == {"ok", "partial", "error"}
    # the kernel's ellipse orientation and numpy's ellipse_axes may differ in the last bit (FMA contraction on some
    # CPUs): floats to 1e-12 relative, everything else exact, key order too
    assert _same_floats(rec["objects"], objects, 1e-12)
    assert [list(o) for o in rec["objects"]] == [list(o) for o in objects]
    assert rec["cpm"]["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"] == pos
    assert rec["sdsm"]["objects"] == sdsm
    assert decode_cpm_uper(rec["cpm_uper_hex"]) == rec["cpm"]


def _same_floats(a, b, rel: float) -> bool:
    """``a == b`` for JSON-like structures, floats (not ints, not bools) to ``rel`` relative."""
    if isinstance(a, dict):
        return isinstance(b, dict) and list(a) == list(b) and all(_same_floats(a[k], b[k], rel) for k in a)
    if isinstance(a, list):
        return isinstance(b, list) and len(a) == len(b) and all(_same_floats(x, y, rel)
                                                                for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float):
        return math.isclose(a, b, rel_tol=rel, abs_tol=0.0)
    return type(a) is type(b) and a == b


def test_message_coordinates_are_coordinate_cm_and_offset_dm():
    """The service's one-pass conversion gives cpm.coordinate_cm / sdsm.offset_dm exactly (halves, clamps, NaN)."""
    from footprint_uq.service.frame_kernels import cm_dm
    from footprint_uq.service.messages.cpm import coordinate_cm
    from footprint_uq.service.messages.sdsm import offset_dm

    rng = np.random.default_rng(5)
    en = np.concatenate([rng.standard_normal((2000, 2)) * s for s in (0.01, 1.0, 100.0, 1e3, 1e4, 1e6)] + [np.array(
        [[0.005, -0.005], [0.015, 0.025], [1310.715, -1310.725], [np.nan, np.inf], [-np.inf, 1e308],
         [3276.75, -3276.75], [-0.0, 0.0]])])
    rows = rng.permutation(len(en))
    with np.errstate(over="ignore"):
        ref = [coordinate_cm(en[rows, 0]), coordinate_cm(en[rows, 1]), offset_dm(en[rows, 0]), offset_dm(en[rows, 1])]
    for got, want in zip(cm_dm(en, rows), ref, strict=True):
        np.testing.assert_array_equal(got, want)


# -- lean records on the wire (record="compact") ---------------------------------------------------------------------
def _tracked_frames(n: int, k: int = 3):
    """``k`` frames of ``n`` 2-D boxes moving right, some reaching past the image (partial / error objects)."""
    rng = np.random.default_rng(5)
    u, v = rng.uniform(-60, 1800, n), rng.uniform(450, 1070, n)
    u[::17] = -400.0  # wholly left of the image
    for i in range(k):
        yield {"camera_id": "c", "frame": i, "timestamp_s": T0 + i / 30, "detections": [
            {"object_id": j, "class": ["car", "person", None][j % 3], "class_confidence": 0.8,
             "u_min_px": float(a + 3 * i), "v_min_px": float(b - 80), "u_max_px": float(a + 90 + 3 * i),
             "v_max_px": float(b), "cov_uu_px2": 4.0, "cov_uv_px2": 0.0, "cov_vv_px2": 4.0}
            for j, (a, b) in enumerate(zip(u, v, strict=True))]}


def test_compact_record_is_the_full_records_numbers_and_the_cpm_bytes(camera):
    """Every field of a compact record is the full record's (same bytes of the numbers); its CPM's UPER bytes are the
    full record's ``cpm_uper_hex`` and decode (asn1tools) to its CPM JSON; the compact record is the documented
    field list."""
    from footprint_uq.service.core import COMPACT_OBJECT_FIELDS

    kw = dict(heading_offset_deg=HEADING, tracks=True, linearity=True, contact="bottom-corners")
    full_svc, lean_svc = Service(camera, "basler1", **kw), Service(camera, "basler1", record="compact", **kw)
    for f in _tracked_frames(60):
        full, lean = full_svc.process_frame_json(f), lean_svc.process_frame_json(f)
    assert full.cpm_uper is None and lean.cpm_uper is not None
    rf, rl = json.loads(full.data), json.loads(lean.data)
    assert rl["record"] == "compact" and "cpm" not in rl and "sdsm" not in rl and "cpm_uper_hex" not in rl
    assert {o["status"] for o in rl["objects"]} == {"ok", "partial", "error"}  # (every status exercised)
    for key in ("camera_id", "frame", "timestamp_s", "station_id", "heading_offset_deg", "n_objects",
                "detection_errors", "cpm_cdd"):
        assert rl[key] == rf[key], key
    for of, ol in zip(rf["objects"], rl["objects"], strict=True):
        assert set(ol) <= set(COMPACT_OBJECT_FIELDS)
        assert ol == {k: of[k] for k in COMPACT_OBJECT_FIELDS if k in of and (k != "reason" or of["status"] != "ok")}
    assert lean.cpm_uper == bytes.fromhex(rf["cpm_uper_hex"]) and rl["cpm_uper_bytes"] == len(lean.cpm_uper)
    assert decode_cpm_uper(lean.cpm_uper.hex()) == rf["cpm"]


def test_compact_record_and_cpm_are_at_most_a_quarter_of_the_full_record(camera):
    """Issue 31: the bytes on the wire of a tracked 100-object frame (compact record + the CPM's UPER bytes) at most a
    quarter of the full record's (measured: ~42 kB of ~206 kB)."""
    full_svc = Service(camera, "basler1", tracks=True, linearity=True)
    lean_svc = Service(camera, "basler1", tracks=True, linearity=True, record="compact")
    for f in _tracked_frames(100):
        full, lean = full_svc.process_frame_json(f), lean_svc.process_frame_json(f)
    assert json.loads(lean.data)["n_objects"] == 100
    assert len(lean.data) + len(lean.cpm_uper) <= 0.25 * len(full.data), (len(lean.data), len(full.data))


def test_compact_record_without_messages_or_with_asn1tools(camera):
    svc = Service(camera, "basler1", record="compact", messages=False)
    out = svc.process_frame_json(next(_tracked_frames(5, 1)))
    rec = json.loads(out.data)
    assert out.cpm_uper is None and "cpm_uper_bytes" not in rec and rec["n_objects"] == 5
    a = Service(camera, "basler1", record="compact", uper_encoder="asn1tools").process_frame_json(
        next(_tracked_frames(5, 1)))
    b = Service(camera, "basler1", record="compact").process_frame_json(next(_tracked_frames(5, 1)))
    assert a.cpm_uper == b.cpm_uper and a.cpm_uper
    with pytest.raises(ValueError, match="record"):
        Service(camera, "basler1", record="lean", warm_up=False)


def test_mqtt_sink_publishes_the_record_then_the_cpm_bytes(camera):
    """The worker hands a compact frame's two outputs to the MQTT sink: the record on <prefix>/<camera_id>, the CPM's
    bytes on <prefix>/<camera_id>/cpm (a fake client: the broker tests run where Mosquitto is installed)."""
    from footprint_uq.service.runner import FrameQueue, Metrics, _MqttSink, _work

    class FakeClient:
        def __init__(self):
            self.sent = []

        def publish(self, topic, payload, qos):
            self.sent.append((topic, payload, qos))
            return type("Info", (), {"rc": 0, "is_published": lambda self: True})()

        def want_write(self):
            return False

    svc = Service(camera, "basler1", record="compact")
    q, client, metrics = FrameQueue("block"), FakeClient(), Metrics()
    f = next(_tracked_frames(5, 1))
    q.put("c", (json.dumps(f).encode(), "mqtt detections/c", time.monotonic(), "c"))
    q.close()
    _work(svc, q, _MqttSink(client, "fp", metrics), metrics, "mqtt", threading.Event())
    (t1, rec, q1), (t2, cpm, q2) = client.sent
    assert (t1, t2, q1, q2) == ("fp/c", "fp/c/cpm", 1, 1)
    assert json.loads(rec)["cpm_uper_bytes"] == len(cpm) and decode_cpm_uper(cpm.hex())
    assert metrics.frames_out == 1 and metrics.publish_failed == 0


def test_default_workers_is_min_of_cores_minus_one_and_cameras(monkeypatch):
    """``serve``'s default --workers with MQTT input and a registry: one core left to the broker and the detector,
    never more workers than cameras, at least one."""
    from footprint_uq.service import runner

    assert [runner.default_workers(8, cores=c) for c in (1, 2, 3, 4, 16)] == [1, 1, 2, 3, 8]
    assert runner.default_workers(2, cores=16) == 2 and runner.default_workers(1, cores=4) == 1
    monkeypatch.setattr(runner, "usable_cores", lambda: 5)
    assert runner.default_workers(8) == 4
