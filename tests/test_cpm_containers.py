"""The CPM's Sensor Information and Perception Region containers, its segmentation and the per-object quality fields,
checked as a receiver would: with the official ETSI modules (asn1tools and pycrate, ``tests/test_cpm_official.py``
compiles them), for each CDD release.

* a seeded Hypothesis sweep over polygons (3..16 vertices, near and beyond +-327 m: a shapeReferencePoint),
  sensor lists, segment numbers, objects with measurementDeltaTime, objectAge, objectPerceptionQuality and
  sensorIdList: the JSON builder's asn1tools bytes == the fast writer's (JSON path and compiled column path), and
  both official decoders return exactly the JSON the builder was given;
* one generation event of 300 objects from three cameras' perception regions: several segments, each <= 1,100
  bytes and a valid CPM, every object once, the sensor containers in the first segment when due;
* mutation: a flipped bit in a sensor container fails or changes the decode; the polygon's count bits are pinned.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.products.perception_region import perception_region, polygon_east_north_cm
from footprint_uq.service.cp_rules import CpRules, GenerationClock
from footprint_uq.service.cp_segments import (
    CpmObjectColumns,
    SensorRegion,
    event_segments,
    object_perception_quality,
    sensor_region,
)
from footprint_uq.service.messages.cpm import (
    build_cpm,
    decode_cpm_uper,
    encode_cpm_uper,
    perceived_object,
    perception_region_entry,
    polygonal_shape,
    sensor_information,
)
from footprint_uq.service.messages.motion import MotionCodes
from footprint_uq.service.messages.uper_cpm import (
    class_bits,
    encode_cpm_uper_fast,
    object_bits,
    perceived_object_container_uper_arrays,
)
from test_cpm_official import OFFICIAL, decode_official, official  # noqa: F401 - the fixture

pytest.importorskip("asn1tools")
REF_MS = 660000000000
SWEEP = settings(max_examples=14, deadline=None, derandomize=True,
                 suppress_health_check=[HealthCheck.function_scoped_fixture])


def _polygon(rng, far: bool) -> np.ndarray:
    """A star-shaped polygon of 3..16 vertices (0.01 m); ``far``: centred up to ~300 m away, vertices up to ~600 m
    (sent with a reference point)."""
    m = int(rng.integers(3, 17))
    ang = np.sort(rng.uniform(0, 2 * np.pi, m))
    r = rng.uniform(500, 30000, m)
    c = rng.uniform(-30000, 30000, 2) if far else rng.uniform(-1000, 1000, 2)
    return np.rint(np.column_stack([c[0] + r * np.cos(ang), c[1] + r * np.sin(ang)])).astype(np.int64)


def _objects(rng, n: int, cdd: str, n_sensors: int) -> tuple[list[dict], dict]:
    """n perceived objects as JSON and as the columns of the compiled writer."""
    cols = {"id": rng.integers(0, 65536, n), "x": rng.integers(-131072, 131072, n),
            "y": rng.integers(-131072, 131072, n), "cx": rng.integers(1, 4097, n), "cy": rng.integers(1, 4097, n),
            "r": np.where(rng.random(n) < 0.3, 101, rng.integers(-100, 101, n)),
            "mdt": rng.integers(-2048, 2048, n), "q": rng.integers(-1, 16, n), "age": rng.integers(-1, 2048, n)}
    sids = [None if rng.random() < 0.3 else sorted(rng.choice(n_sensors, int(rng.integers(1, n_sensors + 1)),
                                                              replace=False).tolist()) for _ in range(n)]
    cls = [None if rng.random() < 0.3 else {"vehicleSubClass": 5} for _ in range(n)]
    lvl = rng.integers(1, 102, n)
    pos = [perceived_object(int(cols["id"][i]), int(cols["x"][i]), int(cols["y"][i]), int(cols["cx"][i]),
                            int(cols["cy"][i]), int(cols["r"][i]), cls[i], int(lvl[i]), int(cols["mdt"][i]),
                            age_ms=None if cols["age"][i] < 0 else int(cols["age"][i]),
                            quality=None if cols["q"][i] < 0 else int(cols["q"][i]), sensor_ids=sids[i])
           for i in range(n)]
    cb = [class_bits(c, cdd) if c is not None else (0, 0) for c in cls]
    cols.update(cv=np.array([v for v, _ in cb], dtype=np.int64), cw=np.array([w for _, w in cb], dtype=np.int64),
                lvl=lvl, sids=sids)
    return pos, cols


def _motion_ages(age: np.ndarray) -> MotionCodes:
    n = len(age)
    z, one = np.zeros(n, np.int64), np.ones(n, np.int64)
    return MotionCodes(z, z, one, z, one, z, z, one, (age >= 0).astype(np.int64), np.maximum(age, 0), z, z, z, z)


def _check_official(payload: bytes, cpm: dict, cdd: str, official) -> None:  # noqa: F811
    for folder in OFFICIAL[cdd]:
        for decoded in decode_official(payload, *official(folder)):
            assert decoded == cpm


@SWEEP
@given(cdd=st.sampled_from(["2.1.1", "2.2.1"]), n_sensors=st.integers(1, 5), n=st.integers(0, 30),
       seg=st.one_of(st.none(), st.integers(1, 8).flatmap(lambda t: st.tuples(st.integers(1, t), st.just(t)))),
       far=st.booleans(), with_pr=st.booleans(), seed=st.integers(0, 2 ** 32 - 1))
@example(cdd="2.1.1", n_sensors=5, n=30, seg=(3, 8), far=True, with_pr=True, seed=1)
@example(cdd="2.2.1", n_sensors=1, n=0, seg=(1, 1), far=False, with_pr=True, seed=2)
def test_new_containers_decode_with_the_official_modules(official, cdd, n_sensors, n, seg, far,  # noqa: F811
                                                         with_pr, seed):
    rng = np.random.default_rng(seed)
    ids = rng.choice(256, n_sensors, replace=False).tolist()
    shapes = [polygonal_shape(_polygon(rng, far and k == 0)) for k in range(n_sensors)]
    info = [sensor_information(i, s if rng.random() < 0.8 else None,
                               int(rng.integers(1, 102)) if rng.random() < 0.8 else None, bool(rng.random() < 0.5))
            for i, s in zip(ids, shapes, strict=True)]
    pr = [perception_region_entry(s, int(rng.integers(1, 102)), bool(rng.random() < 0.5),
                                  measurement_delta_ms=int(rng.integers(-2048, 2048)),
                                  sensor_ids=[i] if rng.random() < 0.7 else None,
                                  number_of_objects=int(rng.integers(0, 256)) if rng.random() < 0.5 else None,
                                  object_ids=rng.integers(0, 65536, int(rng.integers(0, 20))).tolist()
                                  if rng.random() < 0.5 else None)
          for i, s in zip(ids, shapes, strict=True)] if with_pr else None
    pos, cols = _objects(rng, n, cdd, n_sensors)
    total = n + int(rng.integers(0, 400))
    cpm = build_cpm(int(rng.integers(0, 2 ** 32)), REF_MS, pos, segmentation=seg, sensor_information=info,
                    perception_regions=pr, number_of_perceived_objects=total)
    ref = encode_cpm_uper(cpm, cdd)
    assert decode_cpm_uper(ref, cdd) == cpm
    assert encode_cpm_uper_fast(cpm, cdd=cdd) == ref
    poc = perceived_object_container_uper_arrays(
        cols["id"], cols["x"], cols["cx"], cols["y"], cols["cy"], cols["r"], cols["cv"], cols["cw"], cols["lvl"],
        cdd=cdd, motion=_motion_ages(cols["age"]), measurement_delta_ms=cols["mdt"], quality=cols["q"],
        sensor_ids=cols["sids"], number_of_perceived_objects=total)
    assert encode_cpm_uper_fast(cpm, cdd=cdd, perceived_objects_uper=poc) == ref
    bits = object_bits(cols["r"], cols["cw"], cdd=cdd, motion=_motion_ages(cols["age"]), quality=cols["q"],
                       sensor_ids=cols["sids"])
    assert len(poc) == (18 + int(bits.sum()) + 7) // 8
    _check_official(ref, cpm, cdd, official)


def test_polygon_count_bits_are_pinned():
    """X.691 by hand: Shape = extension 0, index 2 (3 bits); PolygonalShape: no reference point, no height (00);
    the polygon: extension 0 and n - 3 in 4 bits (the effective SIZE(3..16,...)); a vertex: no z (0), x + 32768
    and y + 32768 in 16 bits each."""
    shape = polygonal_shape(np.array([[0, 0], [100, 0], [0, -100]]))
    info = sensor_information(7, shape, 95, True)
    cpm = build_cpm(1, REF_MS, [], sensor_information=[info])
    data = next(c for c in cpm["payload"]["cpmContainers"] if c["containerId"] == 3)
    assert data["containerData"] == [info]
    from footprint_uq.service.messages.uper_cpm import _sensor_information_bytes

    got = _sensor_information_bytes([info])
    bits = ("0" "0000000"          # container: extension 0, one entry (n - 1 in 7 bits)
            "0" "11"               # SensorInformation: extension 0, shape and confidence present
            "00000111" "00011"     # sensorId 7, sensorType monovideo (3) in 5 bits
            "0" "010" "00"         # Shape: extension 0, polygonal (2); no reference point, no height
            "0" "0000"             # polygon: extension 0, 3 vertices (3 - 3)
            + "".join("0" + format(x + 32768, "016b") + format(y + 32768, "016b")
                      for x, y in ((0, 0), (100, 0), (0, -100)))
            + format(95 - 1, "07b") + "1")  # perceptionRegionConfidence 95, shadowingApplies
    want = int(bits, 2) << (-len(bits) % 8)
    assert got == want.to_bytes((len(bits) + 7) // 8, "big")
    assert got == __import__("footprint_uq.service.messages.cpm", fromlist=["_spec"])._spec().encode(
        "SensorInformationContainer", [{**info, "perceptionRegionShape": ("polygonal", shape["polygonal"])}])


def test_a_far_polygon_goes_with_a_reference_point(official):  # noqa: F811
    """Vertices beyond +-327.67 m: sent relative to the bounding box's centre; the decoded polygon + the point is the
    given polygon (official decoders)."""
    verts = np.array([[5000, 20000], [55000, 21000], [54000, 40000], [6000, 39000]])
    shape = polygonal_shape(verts)
    ref = shape["polygonal"]["shapeReferencePoint"]
    assert ref == {"xCoordinate": 30000, "yCoordinate": 30000}
    cpm = build_cpm(5, REF_MS, [], sensor_information=[sensor_information(1, shape, 95, False)])
    payload = encode_cpm_uper(cpm, "2.1.1")
    assert encode_cpm_uper_fast(cpm, cdd="2.1.1") == payload
    _check_official(payload, cpm, "2.1.1", official)
    got = decode_cpm_uper(payload, "2.1.1")["payload"]["cpmContainers"][1]["containerData"][0]
    poly = got["perceptionRegionShape"]["polygonal"]
    back = [[v["xCoordinate"] + poly["shapeReferencePoint"]["xCoordinate"],
             v["yCoordinate"] + poly["shapeReferencePoint"]["yCoordinate"]] for v in poly["polygon"]]
    assert back == verts.tolist()
    assert "shapeReferencePoint" not in polygonal_shape(verts // 10)["polygonal"]  # within range: none


def test_a_flipped_bit_in_a_sensor_container_fails_or_changes_the_decode(official):  # noqa: F811
    rng = np.random.default_rng(3)
    shapes = [polygonal_shape(_polygon(rng, False)) for _ in range(2)]
    cpm = build_cpm(9, REF_MS, [], segmentation=(1, 2),
                    sensor_information=[sensor_information(k, s, 95, True) for k, s in enumerate(shapes)],
                    perception_regions=[perception_region_entry(s, 95, True, sensor_ids=[k])
                                        for k, s in enumerate(shapes)])
    payload = encode_cpm_uper(cpm, "2.2.1")
    spec, pyc = official("cdd-v2.2.1")
    _check_official(payload, cpm, "2.2.1", official)
    # the Sensor Information container starts after header 48, management container 173 + 6 (segmentation), the
    # container count 4, the RSU container (4 + 8 + 8), its id 4 and its length (16 bits: >= 128 octets, else 8)
    octets = spec.decode("CollectivePerceptionMessage", payload)["payload"]["cpmContainers"][1]["containerData"]
    start = 48 + 179 + 4 + 20 + 4 + (16 if len(octets) >= 128 else 8)
    failures = 0
    for b in range(start, start + 8 * len(octets), 7):  # every 7th bit of the container
        raw = bytearray(payload)
        raw[b // 8] ^= 0x80 >> (b % 8)
        try:
            decoded = decode_official(bytes(raw), spec, pyc)
        except Exception:  # noqa: BLE001 - a decode error is a detected mutation
            failures += 1
            continue
        assert all(d != cpm for d in decoded), f"bit {b} flipped and still decodes to the same CPM"
    assert failures >= 1


# -- one generation event --------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def regions():
    """Three cameras around an intersection, their perception regions (1 m limit), as the CPM's SensorRegions
    relative to the reference position (0, 0)."""
    out = []
    for k, (x, y, pan) in enumerate(((-20.0, -20.0, 45.0), (20.0, -20.0, -45.0), (0.0, 25.0, 180.0))):
        cam = PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=pan, tilt_deg=20.0,
                            position_m=(x, y))
        reg = perception_region(cam, "basler1@deg", max_cells=120)
        assert reg is not None
        out.append((reg, sensor_region(10 + k, reg, (0.0, 0.0))))
    return out


def _event_objects(rng, n: int, cdd: str) -> CpmObjectColumns:
    _, cols = _objects(rng, n, cdd, 3)
    cols["id"] = rng.permutation(65536)[:n]  # unique ids within the event
    sids = [None if s is None else [10 + i for i in s] for s in cols["sids"]]
    return CpmObjectColumns(cols["id"], cols["x"], cols["y"], cols["cx"], cols["cy"], cols["r"], cols["cv"],
                            cols["cw"], cols["lvl"], motion=_motion_ages(cols["age"]), measurement_delta_ms=cols["mdt"],
                            quality=cols["q"], sensor_ids=sids)


@pytest.mark.parametrize("cdd", ["2.1.1", "2.2.1"])
def test_an_event_of_300_objects_is_several_valid_segments(official, regions, cdd):  # noqa: F811
    rng = np.random.default_rng(11)
    objs = _event_objects(rng, 300, cdd)
    srs = [sr for _, sr in regions]
    clock = GenerationClock(CpRules())
    ev = event_segments(77, REF_MS, objs, srs, clock, 0.0, cdd=cdd, number_of_perceived_objects=300)
    assert ev.sensor_information and len(ev.payloads) >= 3 and len(ev.not_sent) == 0
    assert np.array_equal(np.concatenate(ev.segments), np.arange(300))  # every object once, in order
    seen = []
    for k, (payload, idx) in enumerate(zip(ev.payloads, ev.segments, strict=True)):
        assert len(payload) <= 1100
        cpm = decode_cpm_uper(payload, cdd)
        _check_official(payload, cpm, cdd, official)
        mc = cpm["payload"]["managementContainer"]
        assert mc["segmentationInfo"] == {"totalMsgNo": len(ev.payloads), "thisMsgNo": k + 1}
        assert mc["referenceTime"] == REF_MS
        cont = {c["containerId"]: c["containerData"] for c in cpm["payload"]["cpmContainers"]}
        assert set(cont) == ({2, 3, 4, 5} if k == 0 else {2, 5})
        if k == 0:
            for (reg, sr), si, pr in zip(regions, cont[3], cont[4], strict=True):
                verts = si["perceptionRegionShape"]["polygonal"]["polygon"]
                poly = [[v["xCoordinate"], v["yCoordinate"]] for v in verts]
                assert poly == polygon_east_north_cm(reg.polygon_xy_world_m, (0.0, 0.0)).tolist()
                assert si["sensorId"] == sr.sensor_id and si["sensorType"] == 3
                assert si["perceptionRegionConfidence"] == 95 and si["shadowingApplies"] is True
                assert pr["perceptionRegionShape"] == si["perceptionRegionShape"]
                assert pr["sensorIdList"] == [si["sensorId"]]
        poc = cont[5]
        assert poc["numberOfPerceivedObjects"] == 255  # 300 perceived, sent as the field's maximum
        for p, i in zip(poc["perceivedObjects"], idx, strict=True):
            ptr, val = objs.sensor_ids
            assert p["objectId"] == objs.object_id[i] and p["measurementDeltaTime"] == objs.measurement_delta_ms[i]
            assert p["position"]["xCoordinate"]["value"] == objs.x_cm[i]
            assert p.get("objectPerceptionQuality", -1) == objs.quality[i]
            assert p.get("sensorIdList", []) == val[ptr[i]:ptr[i + 1]].tolist()
            assert p.get("objectAge", -1) == (objs.motion.age_ms[i] if objs.motion.has_age[i] else -1)
            seen.append(p["objectId"])
    assert sorted(seen) == sorted(objs.object_id.tolist())
    # 0.1 s later: no sensor containers (due once a second), one segment without segmentationInfo
    ev2 = event_segments(77, REF_MS + 100, objs.take(np.arange(10)), srs, clock, 0.1, cdd=cdd)
    cpm2 = decode_cpm_uper(ev2.payloads[0], cdd)
    assert not ev2.sensor_information and len(ev2.payloads) == 1
    assert "segmentationInfo" not in cpm2["payload"]["managementContainer"]
    assert [c["containerId"] for c in cpm2["payload"]["cpmContainers"]] == [2, 5]
    # no objects before T_GenCpmMax: no CPM; at 1.1 s: one CPM with the sensor containers again
    empty = objs.take(np.arange(0))
    assert event_segments(77, REF_MS + 500, empty, srs, clock, 0.5, cdd=cdd).payloads == []
    ev3 = event_segments(77, REF_MS + 1100, empty, srs, clock, 1.1, cdd=cdd)
    assert ev3.sensor_information and len(ev3.payloads) == 1
    _check_official(ev3.payloads[0], decode_cpm_uper(ev3.payloads[0], cdd), cdd, official)


def test_objects_beyond_eight_segments_are_returned_not_dropped():
    rng = np.random.default_rng(4)
    objs = _event_objects(rng, 255, "2.2.1")
    srs = [SensorRegion(1, np.array([[0, 0], [100, 0], [0, 100]]))]
    ev = event_segments(1, REF_MS, objs, srs, GenerationClock(CpRules(max_size_bytes=400)), 0.0)
    assert len(ev.payloads) == 8 and len(ev.not_sent) > 0
    assert np.array_equal(np.concatenate([*ev.segments, ev.not_sent]), np.arange(255))
    assert all(len(p) <= 400 for p in ev.payloads)


# -- objectPerceptionQuality -----------------------------------------------------------------------------------
def test_quality_pinned_values():
    q = object_perception_quality([1.0, 1.0, 0.8, np.nan, 0.0, 1.0, 1.0], [2.0, 2.0, 0.75, 3.0, 5.0, np.nan, 0.0],
                                  [1.0, 1.0, 0.9, 1.0, 1.0, 1.0, 1.0], [True, False, True, True, True, True, True])
    # 15; 14 (not linear_ok); floor(15*0.8*0.75*0.9) = floor(8.1) = 8; floor(15*0.5) = 7; 0; floor(15*0.5) = 7;
    # a new object: floor(15*0.5) = 7
    assert q.tolist() == [15, 14, 8, 7, 0, 7, 7]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(c=st.floats(0, 1), age=st.floats(0, 100), r=st.floats(0, 1), lin=st.booleans(),
       dc=st.floats(0, 1), dage=st.floats(0, 5), dr=st.floats(0, 1))
def test_quality_is_monotone_and_never_15_for_a_nonlinear_centre(c, age, r, lin, dc, dage, dr):
    q0 = object_perception_quality([c], [age], [r], [lin])[0]
    q1 = object_perception_quality([min(c + dc, 1.0)], [age + dage], [min(r + dr, 1.0)], [lin])[0]
    assert 0 <= q0 <= q1 <= 15
    assert lin or q1 <= 14


def test_bad_inputs_name_the_field():
    with pytest.raises(InputError, match="detection_rate"):
        object_perception_quality([0.5], [1.0], [1.5], [True])
    with pytest.raises(InputError, match="measurementDeltaTime"):
        perceived_object(1, 0, 0, 1, 1, 101, None, measurement_delta_ms=2048)
    with pytest.raises(InputError, match="polygon"):
        polygonal_shape(np.array([[0, 0], [1, 1]]))
    with pytest.raises(InputError, match="polygon"):
        polygonal_shape(np.array([[0, 0], [70000, 0], [0, 10]]))  # 700 m across: beyond a reference point too
    with pytest.raises(InputError, match="thisMsgNo"):
        build_cpm(1, REF_MS, [], segmentation=(3, 2))
    with pytest.raises(InputError, match="sensorIdList"):
        perceived_object_container_uper_arrays([1], [0], [1], [0], [1], [101], [0], [0], [1], sensor_ids=[[256]])
    with pytest.raises(InputError, match="measurementDeltaTime"):
        perceived_object_container_uper_arrays([1], [0], [1], [0], [1], [101], [0], [0], [1],
                                               measurement_delta_ms=[-2049])


@settings(max_examples=20, deadline=None, derandomize=True)
@given(n=st.integers(0, 400), max_size=st.integers(300, 1500), due=st.booleans(), seed=st.integers(0, 2 ** 32 - 1),
       n_cams=st.integers(1, 8))
def test_segments_hold_every_object_once_within_the_size(n, max_size, due, seed, n_cams):
    """Over object counts and size limits: every segment <= the limit and a CPM that decodes (the subset) to its
    objects, in order; objects beyond 8 segments returned; the sensor containers, when due, spread over the first
    segments camera by camera (each camera once), and only there."""
    rng = np.random.default_rng(seed)
    objs = _event_objects(rng, n, "2.2.1")
    srs = [SensorRegion(k, _polygon(rng, False)) for k in range(n_cams)]
    clock = GenerationClock(CpRules(max_size_bytes=max_size))
    if not due:
        clock.sent(-0.5, sensor_info=True)
    ev = event_segments(3, REF_MS, objs, srs, clock, 0.0, number_of_perceived_objects=n)
    assert ev.sensor_information == due
    # when due, every camera's entries once over the segments (in camera order); the first segment has some
    assert np.array_equal(np.concatenate([np.zeros(0, np.int64), *ev.sensor_segments]),
                          np.arange(n_cams if due else 0))
    assert not due or len(ev.sensor_segments[0]) > 0
    assert np.array_equal(np.concatenate([*ev.segments, ev.not_sent]), np.arange(n))
    assert len(ev.payloads) <= 8 and (len(ev.not_sent) == 0 or len(ev.payloads) == 8)
    for k, (payload, idx) in enumerate(zip(ev.payloads, ev.segments, strict=True)):
        assert len(payload) <= max_size
        cpm = decode_cpm_uper(payload, "2.2.1")
        ids = [c["containerId"] for c in cpm["payload"]["cpmContainers"]]
        cams = ev.sensor_segments[k].tolist()
        assert ids == ([2, 3, 4, 5] if cams else [2, 5])
        if cams:
            assert [e["sensorId"] for e in cpm["payload"]["cpmContainers"][1]["containerData"]] == cams
        pos = cpm["payload"]["cpmContainers"][-1]["containerData"]["perceivedObjects"]
        assert [p["objectId"] for p in pos] == objs.object_id[idx].tolist()
        seg = cpm["payload"]["managementContainer"].get("segmentationInfo")
        assert seg == (None if len(ev.payloads) == 1 else {"totalMsgNo": len(ev.payloads), "thisMsgNo": k + 1})


def test_sensor_containers_that_cannot_fit_are_refused_in_one_line():
    """Twelve cameras at 300 bytes spread over the segments (no error); one camera's entries and an object that do
    not fit one segment, or cameras that need more than 8 segments, are refused in one line naming the limit."""
    rng = np.random.default_rng(6)
    srs = [SensorRegion(k, _polygon(rng, False)) for k in range(12)]
    objs = _event_objects(rng, 5, "2.2.1")
    ev = event_segments(1, REF_MS, objs, srs, GenerationClock(CpRules(max_size_bytes=300)), 0.0)
    assert len([g for g in ev.sensor_segments if len(g)]) > 1 and all(len(p) <= 300 for p in ev.payloads)
    big = [SensorRegion(k, np.array([[30000 * np.cos(a), 30000 * np.sin(a)] for a in np.arange(16) * np.pi / 8],
                                    dtype=np.int64)) for k in range(40)]
    not_due = GenerationClock(CpRules(max_size_bytes=64))  # containers not due: a header and a 120-sensor object
    not_due.sent(-0.5, sensor_info=True)
    wide = dataclasses.replace(objs.take(np.arange(1)), sensor_ids=[list(range(120))])
    for regions, clock, words in ((big[:1], GenerationClock(CpRules(max_size_bytes=120)),
                                   "entries of sensor 0 and an object"),
                                  (big, GenerationClock(CpRules(max_size_bytes=300)), "in 8 segments"),
                                  (big, not_due, r"header \(\d+ bytes\) and its largest object")):
        with pytest.raises(InputError, match=f"max_size_bytes.*{words}") as e:
            event_segments(1, REF_MS, objs if clock is not not_due else wide, regions, clock, 0.0)
        assert "\n" not in str(e.value)
