"""The service's CPMs checked as an independent receiver would: with the official ETSI ASN.1 modules.

The modules (TS 103 324 V2.1.1 with ETSI-ITS-CDD V2.1.1; the same CPM with CDD V2.2.1 and V2.4.1) are
the test data folder ``etsi-its-asn1`` (``shared_data``; skipped with a message where it is missing).
Two independent decoders compile them -- asn1tools and pycrate -- with their known limits worked
around **in memory** (never in the files; ``SOURCE.txt`` there names them):

* asn1tools and pycrate read ``ObjectClass.vehicleSubClass``'s union constraint
  ``(unknown|passengerCar..tram|agricultural)`` wrongly: written as its PER effective constraint
  ``(0..14)`` (X.691 clause 10.3; the encoding of every permitted value is unchanged);
* pycrate cannot parse unions of ``WITH COMPONENT(S)`` inner subtypes (not PER-visible, X.691 B.2.2):
  removed;
* ``PolygonalShape.polygon`` is ``SequenceOfCartesianPosition3d (SIZE(3..16,...))``, a SIZE constraint applied
  serially to a type with its own ``SIZE(1..16,...)``: pycrate fails on it and asn1tools ignores the second
  constraint (it writes the vertex count as ``n - 1``); both get the effective constraint (X.680, serial
  application: ``SIZE(3..16,...)``, the count written as ``n - 3``), as the project's subset writes it
  (``footprint_uq.service.messages.asn1_cpm``; ``tests/test_cpm_containers.py`` pins those bits).

Every payload of a seeded Hypothesis sweep -- classes, 0 to 255 objects, near and far objects, ids of
every kind, with and without origin and motion, both releases -- decodes with both decoders to exactly
the record's CPM JSON, and every field equals the record's numbers: the confidences and correlation are
``footprint_uq.products.v2x.cpm_fields`` of the covariance the record says they encode (``cov_m2``, or
``v2x_cov_m2`` where the V2X policy sampled or withheld it), positions follow the CDD's
``CartesianCoordinateLarge`` rule, classes the documented mapping, motion the CDD conversions.  A writer
with a wrong extension bit makes the check fail (mutation test).
"""

from __future__ import annotations

import copy
import importlib.util
import math
import re
import uuid

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.products.v2x import cpm_fields
from footprint_uq.service import Service
from footprint_uq.service.messages import uper_cpm
from footprint_uq.service.messages.cpm import CPM_CLASS_OF, MATRIX_COMPONENTS, object_class_json
from footprint_uq.service.messages.motion import ObjectMotion, motion_codes

asn1tools = pytest.importorskip("asn1tools")

#: CDD release -> folder of official modules; V2.4.1 is checked with the V2.2.1 payloads (same wire format)
OFFICIAL = {"2.1.1": ("cpm-v2.1.1",), "2.2.1": ("cdd-v2.2.1", "cdd-v2.4.1")}
T0 = 1714564800.0
HEADING = 12.0
CLASSES = ["car", "bus", "truck", "van", "tram", "Pedestrian", "person", "bicycle", "cyclist", "motorcycle", "moped",
           "e-scooter", "wheelchair", "dog", "deer", "cow", "service_animal", "thing", "", None]


# -- the official modules, compiled once per session ------------------------------------------------------------
def _strip_component_unions(text: str) -> str:
    """Remove every ``((WITH COMPONENT(S) ...) | (...))`` constraint (balanced parentheses)."""
    out, i = [], 0
    pat = re.compile(r"\(\s*\(\s*WITH\s+COMPONENT")
    while (m := pat.search(text, i)) is not None:
        out.append(text[i:m.start()])
        depth, j = 0, m.start()
        while True:
            depth += {"(": 1, ")": -1}.get(text[j], 0)
            if depth == 0:
                break
            j += 1
        i = j + 1
    out.append(text[i:])
    return "".join(out)


def _texts(folder, for_pycrate: bool) -> list[str]:
    texts = []
    for f in sorted(folder.glob("*.asn")):
        t = f.read_bytes().decode("utf-8", errors="replace").replace(  # V2.4.1 has a Latin-1 octet in a comment
            "TrafficParticipantType (unknown|passengerCar..tram|agricultural)",
                                                  "TrafficParticipantType (0..14)")
        # the polygon's serial SIZE constraint as its effective constraint (both decoders, see the module doc)
        t = t.replace("SequenceOfCartesianPosition3d (SIZE(3..16,...))",
                      "SEQUENCE (SIZE(3..16,...)) OF CartesianPosition3d")
        if for_pycrate:
            t = _strip_component_unions(t)
        texts.append(t)
    assert texts, folder
    return texts


@pytest.fixture(scope="session")
def official(shared_data, tmp_path_factory):
    """``official(folder_name)`` -> (asn1tools specification, pycrate CollectivePerceptionMessage or None)."""
    root = shared_data("etsi-its-asn1")
    cache = {}

    def get(name: str):
        if name not in cache:
            folder = root / name
            if not folder.is_dir():
                pytest.skip(f"official ASN.1 folder {folder} is missing")
            spec = asn1tools.compile_string("\n".join(_texts(folder, False)), "uper")
            cache[name] = (spec, _pycrate(folder, tmp_path_factory.mktemp("pycrate") / f"{name.replace('.', '_')}.py"))
        return cache[name]
    return get


def _pycrate(folder, dest):
    try:
        from pycrate_asn1c.asnproc import GLOBAL, PycrateGenerator, compile_text, generate_modules
    except ImportError:
        return None
    GLOBAL.clear()
    compile_text(_texts(folder, True))
    generate_modules(PycrateGenerator, str(dest))
    spec = importlib.util.spec_from_file_location(dest.stem, dest)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod.CPM_PDU_Descriptions.CollectivePerceptionMessage


# -- decoded values -> the record's CPM JSON form ---------------------------------------------------------------
def _bits(value) -> list[str]:
    data, n = value
    v = int.from_bytes(data, "big") >> (8 * len(data) - n) if isinstance(data, bytes) else data
    return [MATRIX_COMPONENTS[i] for i in range(n) if v >> (n - 1 - i) & 1]


def _json(v):
    if isinstance(v, dict):
        return {k: _bits(x) if k == "componentsIncludedIntheMatrix" else _json(x) for k, x in v.items()}
    if isinstance(v, tuple) and len(v) == 2 and isinstance(v[0], str):  # CHOICE
        return {v[0]: _json(v[1])}
    if isinstance(v, list):
        return [_json(x) for x in v]
    return v


_CONTAINER_TYPES = {2: "OriginatingRsuContainer", 3: "SensorInformationContainer", 4: "PerceptionRegionContainer",
                    5: "PerceivedObjectContainer"}


def decode_official(payload: bytes, spec, pycrate_cpm) -> list[dict]:
    """The CPM JSON of ``payload`` by each decoder (asn1tools, and pycrate when installed)."""
    msg = spec.decode("CollectivePerceptionMessage", payload)
    for w in msg["payload"]["cpmContainers"]:
        w["containerData"] = spec.decode(_CONTAINER_TYPES[w["containerId"]], w["containerData"])
    out = [_json(msg)]
    if pycrate_cpm is not None:
        pycrate_cpm.from_uper(payload)
        assert pycrate_cpm.to_uper() == payload  # pycrate's own encoding of what it decoded: the same bytes
        val = copy.deepcopy(pycrate_cpm.get_val())
        for w in val["payload"]["cpmContainers"]:
            w["containerData"] = w["containerData"][1]  # (type name, value) of the open type
        out.append(_json(val))
    return out


# -- the frame sweep ----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


_SERVICES: dict = {}


def _service(camera, cdd: str, origin: bool, policy: str = "sampled") -> Service:
    key = (cdd, origin, policy)
    if key not in _SERVICES:
        _SERVICES[key] = Service(camera, "basler1@deg", heading_offset_deg=HEADING, cpm_cdd=cdd, v2x_policy=policy,
                                 **(dict(origin_lat_deg=42.2808, origin_lon_deg=-83.7430) if origin else {}))
    return _SERVICES[key]


def _frame(rng, n: int, far_share: float) -> list[dict]:
    """2D boxes of n objects: far ones within ~30 rows of the horizon (v ~ 30 here: km away), near ones below."""
    far = rng.random(n) < far_share
    v = np.where(far, rng.uniform(31.0, 60.0, n), rng.uniform(200.0, 1079.0, n))
    u = rng.uniform(0.0, 1800.0, n)
    h = np.where(far, 3.0, rng.uniform(20.0, 150.0, n))
    kinds = rng.integers(0, 6, n)
    dets = []
    for k in range(n):
        oid = [int(rng.integers(0, 70000)), str(uuid.UUID(int=int(rng.integers(0, 2 ** 62)))), f"{k}", None,
               k, int(rng.integers(-5, 5))][kinds[k]]
        d = {"object_id": oid, "class": CLASSES[int(rng.integers(len(CLASSES)))], "u_min_px": float(u[k]),
             "v_min_px": float(v[k] - h[k]), "u_max_px": float(u[k] + h[k]), "v_max_px": float(v[k])}
        if rng.random() < 0.5:
            d["class_confidence"] = float(rng.uniform(0, 1))
        dets.append(d)
    return dets


def _motion(rng, n: int) -> ObjectMotion:
    """Synthetic motion over the whole value ranges (out-of-range values and NaN = unknown included)."""
    def nan_some(a):
        return np.where(rng.random(n) < 0.25, np.nan, a)

    sv = nan_some(rng.choice([0.0, 0.01, 0.3, 0.64, 2.0], n) * rng.uniform(0, 1.5, n))
    cov = np.zeros((n, 2, 2))
    cov[:, 0, 0], cov[:, 1, 1] = sv ** 2, (0.7 * sv) ** 2
    cov[:, 0, 1] = cov[:, 1, 0] = 0.3 * sv * 0.7 * sv
    return ObjectMotion(nan_some(rng.uniform(-200, 200, n)), nan_some(rng.uniform(-30, 30, n)), cov,
                        nan_some(rng.uniform(0, 200, n)), nan_some(rng.uniform(0, 60, n)),
                        nan_some(rng.uniform(-720, 720, n)), nan_some(rng.uniform(0, 8, n)),
                        nan_some(rng.uniform(0, 360, n)), nan_some(rng.uniform(0, 10, n)),
                        nan_some(rng.uniform(0, 3, n)))


def _cm_ok(got: int, v_m: float) -> bool:
    """``CartesianCoordinateLarge`` (CDD: n if (n-1) x 0.01 < v <= n x 0.01, clamped); a value within 1e-6 cm of a
    step may go either way (its last bit depends on the order of the rotation's operations)."""
    c = 100.0 * v_m
    lo, hi = math.ceil(c - 1e-6), math.ceil(c + 1e-6)
    return min(max(lo, -131072), 131071) <= got <= min(max(hi, -131072), 131071)


def check_record(rec: dict, cdd: str, spec, pycrate_cpm, motion: ObjectMotion | None = None,
                 dets: list | None = None) -> None:
    """Every check of the module doc on one footprints record (AssertionError on the first mismatch)."""
    assert rec["type"] == "footprints" and rec["cpm_cdd"] == cdd
    for decoded in decode_official(bytes.fromhex(rec["cpm_uper_hex"]), spec, pycrate_cpm):
        assert decoded == rec["cpm"]
    pos = rec["cpm"]["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"]
    sent = [(k, o) for k, o in enumerate(rec["objects"]) if o["message_object_id"] is not None]
    assert [p["objectId"] for p in pos] == [o["message_object_id"] for _, o in sent]
    assert len({p["objectId"] for p in pos}) == len(pos)  # unique within the message
    h = math.radians(rec["heading_offset_deg"])
    mc = None if motion is None else motion_codes(motion, len(rec["objects"]))
    v2x = np.array([o["v2x_cov_m2"] if o["v2x_cov_m2"] is not None else np.full((2, 2), np.nan) for _, o in sent],
                   dtype=float).reshape(-1, 2, 2)
    fields = cpm_fields(v2x, rec["heading_offset_deg"])
    for j, (p, (k, o)) in enumerate(zip(pos, sent, strict=True)):
        f = {name: int(v[j]) for name, v in fields.items()}
        if o["v2x_source"] == "linear":
            assert o["v2x_cov_m2"] == o["cov_m2"]
        assert p["position"]["xCoordinate"]["confidence"] == f["cpm_x_confidence"] == o["cpm_x_confidence"]
        assert p["position"]["yCoordinate"]["confidence"] == f["cpm_y_confidence"] == o["cpm_y_confidence"]
        corr = p.get("lowerTriangularCorrelationMatrices")
        assert (corr[0]["matrix"][0][0] if corr else 101) == f["cpm_xy_correlation"] == o["cpm_xy_correlation"]
        e = o["x_m"] * math.cos(h) + o["y_m"] * math.sin(h)
        n = -o["x_m"] * math.sin(h) + o["y_m"] * math.cos(h)
        assert _cm_ok(p["position"]["xCoordinate"]["value"], e) and _cm_ok(p["position"]["yCoordinate"]["value"], n)
        cls = (o["class"] or "").lower()
        if cls in CPM_CLASS_OF:
            assert p["classification"][0]["objectClass"] == object_class_json(CPM_CLASS_OF[cls], cdd)
            conf = None if dets is None else dets[k].get("class_confidence")
            assert p["classification"][0]["confidence"] == (101 if conf is None else max(1, math.ceil(100 * conf
                                                                                                   - 1e-9)))
        else:
            assert "classification" not in p
        if mc is None:
            assert not {"velocity", "angles", "objectAge"} & set(p)
            continue
        if mc.has_velocity[k]:
            cv = p["velocity"]["cartesianVelocity"]
            assert [cv["xVelocity"]["value"], cv["xVelocity"]["confidence"], cv["yVelocity"]["value"],
                    cv["yVelocity"]["confidence"]] == [mc.vx[k], mc.vx_conf[k], mc.vy[k], mc.vy_conf[k]]
        else:
            assert "velocity" not in p
        assert (p["angles"]["zAngle"]["value"], p["angles"]["zAngle"]["confidence"]) == (mc.yaw[k], mc.yaw_conf[k]) \
            if mc.has_yaw[k] else "angles" not in p
        assert p["objectAge"] == mc.age_ms[k] if mc.has_age[k] else "objectAge" not in p
    if mc is not None and sent:  # the SDSM's speed and heading with their J2735 confidences
        from footprint_uq.service.messages.motion import HEADING_CONFIDENCE_NAMES, SPEED_CONFIDENCE_NAMES

        rows = [k for k, _ in sent]
        assert [(o["detObjCommon"]["speed"], o["detObjCommon"]["speedConfidence"], o["detObjCommon"]["heading"],
                 o["detObjCommon"]["headingConf"]) for o in rec["sdsm"]["objects"]] == \
            [(mc.sdsm_speed[k], SPEED_CONFIDENCE_NAMES[mc.sdsm_speed_conf[k]], mc.sdsm_heading[k],
              HEADING_CONFIDENCE_NAMES[mc.sdsm_heading_conf[k]]) for k in rows]


def _run(camera, cdd, origin, dets, motion=None, monkeypatch=None, policy="sampled"):
    svc = _service(camera, cdd, origin, policy)
    if motion is not None:
        orig = Service._messages_json
        monkeypatch.setattr(Service, "_messages_json", lambda self, *a, **k: orig(self, *a, **{**k, "motion": motion}))
    try:
        return svc.process_frame({"camera_id": "cam", "frame": 1, "timestamp_s": T0, "detections": dets})
    finally:
        if motion is not None:
            monkeypatch.undo()


@settings(max_examples=16, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cdd=st.sampled_from(["2.1.1", "2.2.1"]),
       n=st.one_of(st.integers(0, 8), st.integers(9, 64), st.integers(200, 255)),
       far=st.sampled_from([0.0, 0.3, 1.0]), origin=st.booleans(), with_motion=st.booleans(),
       seed=st.integers(0, 2 ** 32 - 1))
@example(cdd="2.1.1", n=255, far=0.3, origin=True, with_motion=True, seed=1)  # the corners of the sweep, always
@example(cdd="2.2.1", n=255, far=0.3, origin=False, with_motion=True, seed=2)
@example(cdd="2.2.1", n=0, far=0.0, origin=True, with_motion=False, seed=3)
def test_every_payload_decodes_with_the_official_modules_to_the_records_numbers(camera, official, monkeypatch, cdd, n,
                                                                              far, origin, with_motion, seed):
    rng = np.random.default_rng(seed)
    dets = _frame(rng, n, far)
    motion = _motion(rng, n) if with_motion else None
    rec = _run(camera, cdd, origin, dets, motion, monkeypatch)
    for folder in OFFICIAL[cdd]:
        check_record(rec, cdd, *official(folder), motion=motion, dets=dets)


def test_far_objects_carry_the_fields_of_the_covariance_the_record_names(camera, official):
    """Objects 0.5-20 km away: the V2X policy (docs/uncertainty-model.md) encodes a sampled covariance or
    'unavailable' where the linear one cannot be trusted, and the record names that covariance; with
    ``v2x_policy="linear"`` the CPM carries ``cpm_fields(cov_m2)`` for every object, near or far."""
    rng = np.random.default_rng(5)
    dets = _frame(rng, 60, 0.7)
    rec = _run(camera, "2.2.1", True, dets)
    sources = {o["v2x_source"] for o in rec["objects"] if o["message_object_id"] is not None}
    assert sources == {"linear", "sampled", "unavailable"}
    check_record(rec, "2.2.1", *official("cdd-v2.2.1"), dets=dets)
    lin = _run(camera, "2.1.1", True, dets, policy="linear")
    check_record(lin, "2.1.1", *official("cpm-v2.1.1"), dets=dets)
    far = 0
    for o in lin["objects"]:
        if o["message_object_id"] is None:
            continue
        f = cpm_fields(np.array(o["cov_m2"], dtype=float), HEADING)
        assert (o["cpm_x_confidence"], o["cpm_y_confidence"], o["cpm_xy_correlation"]) == \
            (f["cpm_x_confidence"], f["cpm_y_confidence"], f["cpm_xy_correlation"])
        far += o["sigma_major_m"] > 500.0
    assert far >= 10


def test_a_wrong_extension_bit_fails_the_check(camera, official, monkeypatch):
    """Mutation check: the V2.2.1 writer without the correlation columns' extension bit (a 2.1.1 payload sent
    as 2.2.1), and a flipped PerceivedObject extension bit, are caught."""
    rng = np.random.default_rng(8)
    dets = _frame(rng, 5, 0.0)
    rec = _run(camera, "2.2.1", False, dets)
    spec, pyc = official("cdd-v2.2.1")
    check_record(rec, "2.2.1", spec, pyc, dets=dets)
    monkeypatch.setitem(uper_cpm._CORR_PREFIX, "2.2.1", uper_cpm._CORR_PREFIX["2.1.1"])
    bad = _run(camera, "2.2.1", False, dets)
    assert bad["cpm_uper_hex"] != rec["cpm_uper_hex"]
    with pytest.raises(Exception):  # noqa: B017 - any failure: a decode error or a mismatch
        check_record(bad, "2.2.1", spec, pyc, dets=dets)
    monkeypatch.undo()
    # the first PerceivedObject's extension bit: bit 18 of the container (after its 18-bit head); the container
    # starts at bit 253 of the message (header 48, management container 173, container count 4, the RSU container
    # 4 + 8 + 8, the object container's id 4 and its one-octet length: it is shorter than 128 octets)
    raw = bytearray(bytes.fromhex(rec["cpm_uper_hex"]))
    assert len(raw) < 33 + 128
    b = 253 + 18
    raw[b // 8] ^= 0x80 >> (b % 8)
    with pytest.raises(Exception):  # noqa: B017
        check_record({**rec, "cpm_uper_hex": raw.hex()}, "2.2.1", spec, pyc, dets=dets)


def test_releases_do_not_decode_each_other(camera, official):
    """What the CDD change breaks on the wire: a V2.1.1 payload with a correlation matrix fails (or differs)
    under the V2.2.1 modules and the other way round -- the reason ``--cpm-cdd`` exists."""
    rng = np.random.default_rng(9)
    dets = _frame(rng, 3, 0.0)
    for cdd, other in (("2.1.1", "cdd-v2.2.1"), ("2.2.1", "cpm-v2.1.1")):
        rec = _run(camera, cdd, False, dets)
        assert "lowerTriangularCorrelationMatrices" in str(rec["cpm"])
        with pytest.raises(Exception):  # noqa: B017
            check_record(rec, cdd, *official(other), dets=dets)


@pytest.mark.parametrize("cdd", ["2.1.1", "2.2.1"])
def test_tracked_motion_reaches_the_official_decoders(camera, official, cdd):
    """serve --tracks end to end: the tracker's motion of each object (the record's fields) is what the CPM and the
    SDSM carry, decoded by the official modules (velocity with confidences, yaw, objectAge; speed and heading)."""
    svc = Service(camera, "basler1@deg", heading_offset_deg=HEADING, cpm_cdd=cdd, tracks=True)
    rng = np.random.default_rng(5)
    xy0 = np.array([[2.0, 30.0], [12.0, 45.0], [10.0, 25.0]])  # pan 30 deg: all three in view
    v = np.array([[0.0, 8.0], [3.0, -1.0], [-1.5, 0.0]])
    rec = None
    for k in range(12):  # 12 frames at 10 Hz: every track has a velocity
        xy = xy0 + 0.1 * k * v + rng.normal(0, 0.02, (3, 2))
        dets = [{"object_id": f"o{j}", "class": "car", "x_m": float(xy[j, 0]), "y_m": float(xy[j, 1]), "z_m": 0.75,
                 "length_m": 4.5, "width_m": 1.8, "height_m": 1.5, "yaw_rad": float(np.arctan2(v[j, 1], v[j, 0]))}
                for j in range(3)]
        rec = svc.process_frame({"camera_id": "cam", "frame": k, "timestamp_s": T0 + 0.1 * k, "detections": dets})
    objs = rec["objects"]

    def col(key):
        return np.array([np.nan if o[key] is None else o[key] for o in objs], dtype=float)

    cov = np.array([[[np.nan if c is None else c for c in row] for row in o["cov_v_m2ps2"]] for o in objs])
    motion = ObjectMotion(col("v_east_mps"), col("v_north_mps"), cov, col("speed_mps"), col("sigma_speed_mps"),
                          col("heading_deg"), col("sigma_heading_deg"), col("yaw_deg"), col("sigma_yaw_deg"),
                          col("age_s"))
    assert np.isfinite(motion.v_east_mps).all() and (motion.age_s > 1.0).all()
    for folder in OFFICIAL[cdd]:
        check_record(rec, cdd, *official(folder), motion=motion, dets=None)
    pos = rec["cpm"]["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"]
    assert all("velocity" in p and "objectAge" in p for p in pos)
