"""The untracked compact record and its CPM written from the columns (issue 31 part 1) are the general writers' bytes.

* :func:`footprint_uq.service.jsonrows.compact_objects_json` (one compiled pass: the integers formatted in compiled
  code, the classes and statuses by index, every float of the frame in one ``orjson.dumps``) writes what
  :class:`~footprint_uq.service.jsonrows.Table` writes for the same layout (Hypothesis over the whole int64 range,
  every float including NaN / inf / subnormals, any text);
* a :class:`~footprint_uq.service.Service` (``record="compact"``) writes the same record and UPER CPM bytes as the
  same service with ``_columnar = False`` (the general writers, main's code path): seeded frames with bad
  detections, partial and no-centre objects, > 255 objects, NaN / missing class confidences, several classes,
  an origin or none, ``linearity`` on or off, messages on or off; string and > int64 object ids (the fallback),
  through the scanned bytes and the dict API;
* the same for tracked compact frames (the record's motion fields ``track_id`` / ``v_east_mps`` / ``v_north_mps`` /
  ``cov_v_m2ps2`` written by the same compiled pass): births, a missed frame, no-centre objects, > 255 objects,
  several classes, and the UPER CPM with its motion codes.
"""

from __future__ import annotations

import json
import zlib

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.service import Service
from footprint_uq.service.core import _motion_object_layout
from footprint_uq.service.jsonrows import Table, compact_objects_json
from footprint_uq.service.messages import ids as ids_mod
from footprint_uq.service.messages.uper_cpm import CpmUperWriter
from footprint_uq.tracking.motion import ObjectMotion

T0 = 1714564800.0
_INT64 = st.integers(-(2 ** 63), 2 ** 63 - 1)
_FLOAT = st.floats(allow_nan=True, allow_infinity=True, allow_subnormal=True)


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


def _table_text(ids, classes, statuses, reasons, values, mid, tid=None) -> bytes:
    """The general writer's text of the compact layout (as ``Service._objects_json`` lays it out; with ``tid``
    the motion fields by the service's own ``_motion_object_layout`` of ``values[5:]``)."""
    n = len(ids)
    t = Table(n)
    valid = np.array([s == "ok" for s in statuses], bool)
    x, y, cxx, cxy, cyy = t.columns(values[:5])
    layout = [b'{"object_id":', t.column(ids), b',"class":', t.column(classes), b',"status":', t.column(statuses),
              t.when(~valid, b',"reason":', t.column(reasons)), b',"x_m":', x, b',"y_m":', y, b',"cov_m2":[[', cxx,
              b",", cxy, b"],[", cxy, b",", cyy, b"]]"]
    if tid is not None:
        ve, vn, c00, c01, c11 = values[5:]
        cov_v = np.stack([np.stack([c00, c01], -1), np.stack([c01, c11], -1)], -2)
        nan = np.full(n, np.nan)
        layout += _motion_object_layout(t, (tid, ObjectMotion(ve.copy(), vn.copy(), cov_v, *[nan] * 7)), True)
    if mid is not None:
        sent = mid >= 0
        layout += [b',"message_object_id":', t.when(sent, t.column(np.where(sent, mid, 0))), t.when(~sent, b"null")]
    layout.append(b"}")
    return bytes(t.json_buffer(layout))


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 12).flatmap(lambda n: st.tuples(
    st.lists(_INT64, min_size=n, max_size=n),
    st.lists(st.none() | st.text(max_size=6), min_size=n, max_size=n),
    st.lists(st.tuples(st.sampled_from(["ok", "partial", "error"]), st.text(max_size=8)), min_size=n, max_size=n),
    st.lists(st.lists(_FLOAT, min_size=10, max_size=10), min_size=n, max_size=n),
    st.none() | st.lists(st.integers(-1, 65535), min_size=n, max_size=n),
    st.none() | st.lists(st.integers(-1, 2 ** 63 - 1), min_size=n, max_size=n))))
def test_compact_writer_is_the_table_writers_bytes(case):
    """Untracked (5 floats per object) and tracked (``tid``: 10 floats, a track id or -1: null)."""
    ids, classes, status, values, mid, tid = case
    statuses = [s for s, _ in status]
    reasons = ["" if s == "ok" else f"no centre: {r}" for s, r in status]
    vals = np.array(values, dtype=np.float64).T.copy()[:5 if tid is None else 10]
    mid_arr = None if mid is None else np.array(mid, np.int64)
    tid_arr = None if tid is None else np.array(tid, np.int64)
    want = _table_text(ids, classes, statuses, reasons, vals, mid_arr, tid_arr)
    cls: dict = {}
    cidx = np.array([cls.setdefault(c, len(cls)) for c in classes], np.int64)
    texts: dict = {}
    pieces = [b',"status":' + orjson.dumps(s) + (b"" if s == "ok" else b',"reason":' + orjson.dumps(r))
              for s, r in zip(statuses, reasons, strict=True)]
    sidx = np.array([texts.setdefault(p, len(texts)) for p in pieces], np.int64)
    got = compact_objects_json(np.array(ids, np.int64), cidx, [orjson.dumps(c) for c in cls], sidx, list(texts), vals,
                               mid_arr, tid_arr)
    assert bytes(got) == want
    assert json.loads(bytes(got))[0]["object_id"] == ids[0]


_EDGE_INTS = st.sampled_from([0, 7, -1, 9, 10, 99999999, 10 ** 8, -(10 ** 8), 2 ** 63 - 1, -(2 ** 63)])
#: floats at the edges of orjson's text: -0.0, subnormals, the longest texts (24 bytes), huge and tiny, non-finite
_EDGE_FLOATS = st.sampled_from([-0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308,
                                -1.2345678901234567e-300, 1e16, 1e-7, np.nan, np.inf, -np.inf])


@settings(max_examples=40, deadline=None)
@given(st.sampled_from([1, 2, 37, 300]).flatmap(lambda n: st.tuples(
    st.lists(_INT64 | _EDGE_INTS, min_size=n, max_size=n),
    st.lists(st.none() | st.text(max_size=40), min_size=n, max_size=n).map(lambda c: c[:1] * len(c) if len(c) > 3
                                                                          else c) | st.lists(
        st.sampled_from([None, "car", 'a"b\\c\n', "vélo \u2603"]), min_size=n, max_size=n),
    st.lists(st.tuples(st.sampled_from(["ok", "partial", "error"]), st.text(max_size=80)), min_size=n, max_size=n),
    st.lists(st.lists(_FLOAT | _EDGE_FLOATS, min_size=10, max_size=10), min_size=n, max_size=n),
    st.none() | st.lists(st.integers(-1, 65535) | _EDGE_INTS.filter(lambda v: v >= -1), min_size=n, max_size=n),
    st.none() | st.lists(st.integers(-1, 2 ** 63 - 1) | _EDGE_INTS.filter(lambda v: v >= -1), min_size=n,
                         max_size=n))))
def test_compact_writer_many_rows_long_texts_and_edge_numbers(case):
    """The writer's bytes are the Table writer's for 1, 2, 37 and 300 rows (its 32-byte copies at every offset
    and across the ends of its buffers), class texts with escapes and UTF-8 (one class per frame or several),
    status texts longer than 32 bytes (a reason up to 80 characters), the integers where their formatting
    changes (10 ** 8, the int64 ends, -1: null) and the floats of the longest texts (24 bytes), -0.0, subnormals,
    huge values and non-finite ones (null)."""
    test_compact_writer_is_the_table_writers_bytes.hypothesis.inner_test(case)


def test_compact_writer_pins_a_hand_written_row():
    got = compact_objects_json(np.array([-12, 7], np.int64), np.array([0, 1]), [b'"car"', b"null"],
                               np.array([0, 0]), [b',"status":"ok"'],
                               np.array([[1.5, 2.0], [-0.25, np.nan], [1e-7, 4.0], [0.5, 0.0], [3.0, 1e20]]),
                               np.array([65535, -1]))
    assert bytes(got) == (b'[{"object_id":-12,"class":"car","status":"ok","x_m":1.5,"y_m":-0.25,'
                          b'"cov_m2":[[1e-7,0.5],[0.5,3.0]],"message_object_id":65535},'
                          b'{"object_id":7,"class":null,"status":"ok","x_m":2.0,"y_m":null,'
                          b'"cov_m2":[[4.0,0.0],[0.0,1e+20]],"message_object_id":null}]')
    assert compact_objects_json(np.zeros(0, np.int64), np.zeros(0, np.int64), [], np.zeros(0, np.int64), [],
                                np.zeros((5, 0))) == b"[]"


def test_compact_writer_pins_a_hand_written_tracked_row():
    """The motion fields: a track id or null, -0.0, NaN / inf as null, huge and tiny values as orjson writes them."""
    got = compact_objects_json(np.array([-12, 7], np.int64), np.array([0, 1]), [b'"car"', b"null"],
                               np.array([0, 0]), [b',"status":"ok"'],
                               np.array([[1.5, 2.0], [-0.25, np.nan], [1e-7, 4.0], [0.5, 0.0], [3.0, 1e20],
                                         [-0.0, np.nan], [1.0, np.inf], [0.1, 2.0], [0.0, -1e-300], [5e300, 1.0]]),
                               np.array([65535, -1]), np.array([-1, 2 ** 62]))
    assert bytes(got) == (b'[{"object_id":-12,"class":"car","status":"ok","x_m":1.5,"y_m":-0.25,'
                          b'"cov_m2":[[1e-7,0.5],[0.5,3.0]],"track_id":null,"v_east_mps":-0.0,"v_north_mps":1.0,'
                          b'"cov_v_m2ps2":[[0.1,0.0],[0.0,5e+300]],"message_object_id":65535},'
                          b'{"object_id":7,"class":null,"status":"ok","x_m":2.0,"y_m":null,'
                          b'"cov_m2":[[4.0,0.0],[0.0,1e+20]],"track_id":4611686018427387904,"v_east_mps":null,'
                          b'"v_north_mps":null,"cov_v_m2ps2":[[2.0,-1e-300],[-1e-300,1.0]],'
                          b'"message_object_id":null}]')
    with pytest.raises(ValueError, match="10 x 2"):  # (tracked: 10 values per object)
        compact_objects_json(np.array([1, 2]), np.zeros(2, np.int64), [b"null"], np.zeros(2, np.int64), [b""],
                             np.zeros((5, 2)), None, np.array([1, 2]))


@pytest.mark.parametrize("tracked, n, position_n, motion_n", [
    (False, 2, 2, 0), (False, 2, 1, 0), (False, 2, 3, 0), (False, 1, 0, 0), (True, 2, 2, 2), (True, 2, 2, 1),
    (True, 2, 2, 3), (True, 2, 1, 2), (True, 2, 3, 3), (True, 1, 1, 0)])
def test_compact_kernel_refuses_columns_of_another_length(tracked, n, position_n, motion_n):
    """orjson's text of float columns of another length than the ids (a value short or one too many in every
    column, only in the motion's five, empty columns) is refused (empty), not woven out of step; right lengths
    are written."""
    from footprint_uq.service import jsonrows

    rows = [[1.5] * position_n] * 5 + ([[2.5] * motion_n] * 5 if tracked else [])
    ftext = orjson.dumps(rows)  # (bytes, as compact_objects_json hands them to the kernel)
    ids = np.arange(n, dtype=np.int64)
    zeros = np.zeros(n, np.int64)
    args = jsonrows._compact_args(ids, zeros, [b"null"], zeros, [b""], np.ones((10 if tracked else 5, n)), None,
                                  ids if tracked else None)
    size = jsonrows._compact_rows(ftext, *args[1:-1], np.empty(4096, np.uint8))
    right = position_n == n and (motion_n == n or not tracked)
    assert (size > 0) == right and (size == -1) == (not right)
    if not tracked and not right:
        with pytest.raises(ValueError, match=f"not 5 x {n} numbers"):
            compact_objects_json(ids, zeros, [b"null"], zeros, [b""], np.ones((5, position_n)))


_CLASSES = ("car", "pedestrian", "truck", "Bicycle", "unknown")


def _frame(rng, n: int, k: int, *, variant: str) -> dict:
    """Frame ``k`` of a seeded sequence: boxes across the image and beyond, some above the horizon (no ground point)
    and some reversed (a bad detection), ids persisting across frames."""
    u = rng.uniform(-150, 1950, n)
    v = rng.uniform(-40, 1150, n)
    w = rng.uniform(10, 150, n)
    dets = []
    for i in range(n):
        d = {"object_id": int(i + 3 * k // 2), "u_min_px": round(float(u[i]), 2),
             "v_min_px": round(float(v[i] - 0.8 * w[i]), 2), "u_max_px": round(float(u[i] + w[i]), 2),
             "v_max_px": round(float(v[i]), 2)}
        if variant != "no-class":
            d["class"] = "car" if variant == "one-class" else _CLASSES[i % len(_CLASSES)]
        if variant == "confidence":
            d["class_confidence"] = round(float(rng.uniform(0, 1)), 3)
        if variant == "some-confidence" and i % 3:
            d["class_confidence"] = round(float(rng.uniform(0, 1)), 3)
        if variant == "string-ids":
            d["object_id"] = f"t{d['object_id']}"
        if variant == "huge-ids" and i == 0:
            d["object_id"] = 2 ** 64 - 1
        if variant == "covariance":
            d.update(cov_uu_px2=4.0, cov_uv_px2=0.5, cov_vv_px2=9.0)
        if i % 17 == 5:  # a reversed box: that detection's error entry
            d["u_min_px"], d["u_max_px"] = d["u_max_px"], d["u_min_px"] - 1.0
        dets.append(d)
    return {"camera_id": "cam0", "frame": k, "timestamp_s": T0 + k / 30.0, "detections": dets}


def _record(out) -> bytes:
    """The record without its timings (``processing_us``, the last field)."""
    return out.data[:out.data.rindex(b',"processing_us":')]


_OPTIONS = {
    "plain": {},
    "linearity": {"linearity": True},
    "origin": {"origin_lat_deg": 48.1, "origin_lon_deg": 11.6, "heading_offset_deg": 12.0},
    "corners": {"contact": "bottom-corners", "linearity": True},
    "no-messages": {"messages": False},
    "cdd-2.1.1": {"cpm_cdd": "2.1.1", "v2x_policy": "unavailable"},
}


@pytest.mark.parametrize("variant", ["one-class", "classes", "no-class", "confidence", "some-confidence",
                                     "string-ids", "huge-ids", "covariance"])
@pytest.mark.parametrize("option", list(_OPTIONS))
def test_untracked_compact_frames_are_the_general_writers_bytes(camera, option, variant):
    kw = dict(record="compact", **_OPTIONS[option])
    fast, ref = Service(camera, "basler1", **kw), Service(camera, "basler1", **kw)
    ref._columnar = False
    rng = np.random.default_rng(zlib.crc32(f"{option}/{variant}".encode()))
    statuses: set = set()
    for k in range(4):
        frame = _frame(rng, 40 if k < 3 else 700, k, variant=variant)  # (the last: > 255 with a centre)
        for a, b in ((fast.process_frame_json(orjson.dumps(frame)), ref.process_frame_json(orjson.dumps(frame))),
                     (fast.process_frame_json(frame), ref.process_frame_json(frame))):
            assert a.type == b.type == "footprints"
            assert _record(a) == _record(b)
            assert a.cpm_uper == b.cpm_uper
            assert (a.cpm_uper is None) == (option == "no-messages")
        rec = json.loads(a.data)
        statuses |= {o["status"] for o in rec["objects"]}
        assert rec["detection_errors"]  # (the reversed boxes)
    assert {"ok", "error"} <= statuses
    if option == "corners":
        assert "partial" in statuses
    if option != "no-messages":
        assert rec["objects_not_in_messages"] > 0  # (the 700-object frame)


def _tracked_frame(k: int, *, variant: str) -> dict:
    """Frame ``k`` (0..5) of a tracked sequence: objects moving across the image (a few above the horizon: no
    centre), new ids every frame (births), a quarter of them missed in frame 3, the last frame 700 objects (> 255
    with a centre), a reversed box now and then (a detection error)."""
    base = np.random.default_rng(31)
    u0, v0, w = base.uniform(-150, 1950, 700), base.uniform(-40, 1150, 700), base.uniform(10, 150, 700)
    du, dv = base.uniform(-20, 20, 700), base.uniform(-10, 10, 700)
    n = 700 if k == 5 else 40 + 8 * k
    dets = []
    for i in range(n):
        if k == 3 and i % 4 == 1:  # missed this frame, seen again in the next
            continue
        u, v = u0[i] + k * du[i], v0[i] + k * dv[i]
        d = {"object_id": f"t{i}" if variant == "string-ids" else i, "u_min_px": round(float(u), 2),
             "v_min_px": round(float(v - 0.8 * w[i]), 2), "u_max_px": round(float(u + w[i]), 2),
             "v_max_px": round(float(v), 2)}
        if variant != "no-class":
            d["class"] = "car" if variant == "one-class" else _CLASSES[i % len(_CLASSES)]
        if variant == "confidence":
            d["class_confidence"] = round(float(0.1 + 0.8 * ((i * 7) % 10) / 10), 3)
        if (i + k) % 17 == 5:
            d["u_min_px"], d["u_max_px"] = d["u_max_px"], d["u_min_px"] - 1.0
        dets.append(d)
    return {"camera_id": "cam0", "frame": k, "timestamp_s": T0 + k / 10.0, "detections": dets}


@pytest.mark.parametrize("variant", ["one-class", "classes", "no-class", "confidence", "string-ids"])
@pytest.mark.parametrize("option", ["plain", "origin", "no-messages", "cdd-2.1.1"])
def test_tracked_compact_frames_are_the_general_writers_bytes(camera, option, variant):
    """A tracked compact frame's record (the motion fields from the compiled pass) and UPER CPM (with the motion
    codes) are the general writers' bytes, frame after frame (the even frames as bytes, the odd ones as dicts)."""
    kw = dict(record="compact", tracks=True, **_OPTIONS[option])
    fast, ref = Service(camera, "basler1", **kw), Service(camera, "basler1", **kw)
    ref._columnar = False
    seen = {"null": 0, "id": 0, "v": 0, "no-v": 0}
    for k in range(6):
        frame = _tracked_frame(k, variant=variant)
        payload = orjson.dumps(frame) if k % 2 == 0 else frame
        a, b = fast.process_frame_json(payload), ref.process_frame_json(payload)
        assert a.type == b.type == "footprints"
        assert _record(a) == _record(b)
        assert a.cpm_uper == b.cpm_uper
        assert (a.cpm_uper is None) == (option == "no-messages")
        for o in json.loads(a.data)["objects"]:
            seen["null" if o["track_id"] is None else "id"] += 1
            seen["no-v" if o["v_east_mps"] is None else "v"] += 1
    assert all(seen.values()), seen  # (untracked no-centre objects, tracks with and without a velocity yet)


def test_the_tracked_columnar_path_is_the_one_taken(camera, monkeypatch):
    """A tracked compact frame's objects come from the compiled writer: a broken motion field there changes the
    record."""
    from footprint_uq.service import jsonrows

    frames = [orjson.dumps(_tracked_frame(k, variant="classes")) for k in range(3)]
    before = [_record(Service(camera, "basler1", record="compact", tracks=True).process_frame_json(f))
              for f in frames][-1]
    real = jsonrows._compact_rows

    def broken(ftext, ids, cls_idx, st_idx, mid, tid, *rest):  # (the track ids one off: the record's track_id differs)
        return real(ftext, ids, cls_idx, st_idx, mid, tid + 1, *rest)

    monkeypatch.setattr(jsonrows, "_compact_rows", broken)
    svc = Service(camera, "basler1", record="compact", tracks=True)
    after = [_record(svc.process_frame_json(f)) for f in frames][-1]
    assert before != after and b'"track_id":' in after


def test_the_tracked_cpm_takes_the_columnar_writer(camera, monkeypatch):
    """A tracked compact frame's UPER CPM comes from ``lean_cpm_uper`` (``service/frame_kernels.py``; or, where the
    camera has no packed constants, ``plain_cpm_uper``) with the motion (not silently the general writer): its
    message replaced, the CPM changes; and the motion reaches it (velocity present)."""
    from footprint_uq.service import core

    frames = [orjson.dumps(_tracked_frame(k, variant="classes")) for k in range(3)]
    seen = []
    svc = Service(camera, "basler1", record="compact", tracks=True)
    lean = next(iter(svc.cameras.values())).lean_cpm is not None
    name = "lean_cpm_uper" if lean else "plain_cpm_uper"
    real = getattr(core, name)

    def spy(*a, **k):
        out = real(*a, **k)
        seen.append((a[9] if lean else k.get("motion"), out))
        return out

    monkeypatch.setattr(core, name, spy)
    before = [svc.process_frame_json(f).cpm_uper for f in frames][-1]
    motion, container = seen[-1]
    assert motion is not None and motion.shape[0] == 14 and motion[0].any()  # (motion_rows: row 0 velocity present)
    assert container is not None  # (its bytes, not None: the general writer's fallback)
    monkeypatch.setattr(core, name, lambda *a, **k: b"")
    svc = Service(camera, "basler1", record="compact", tracks=True)
    assert [svc.process_frame_json(f).cpm_uper for f in frames][-1] != before


def test_the_columnar_path_is_the_one_taken(camera, monkeypatch):
    """The compact untracked frame goes through the compiled writers (not silently the general ones): a broken
    compiled writer changes the record."""
    from footprint_uq.service import core

    svc = Service(camera, "basler1", record="compact")
    frame = orjson.dumps(_frame(np.random.default_rng(3), 20, 0, variant="one-class"))
    before = _record(svc.process_frame_json(frame))
    monkeypatch.setattr(core, "compact_objects_json", lambda *a, **k: b"[]")
    cpm = svc.process_frame_json(frame).cpm_uper
    monkeypatch.setattr(core, "lean_cpm_uper", lambda *a, **k: b"")
    monkeypatch.setattr(core, "plain_cpm_uper", lambda *a, **k: b"")
    out = svc.process_frame_json(frame)
    assert b'"objects":[]' in _record(out) and before != _record(out)
    assert cpm and out.cpm_uper == b""


@pytest.mark.parametrize("variant", ["one-class", "classes", "no-class", "some-without-class"])
@pytest.mark.parametrize("tracks", [False, True])
def test_scanned_frames_take_the_scanners_class_columns(camera, variant, tracks, monkeypatch):
    """A frame the scanner reads whole (no bad detection: its ``ScannedFrame`` goes to the lean path as it is) is
    written from the scanner's class columns -- the distinct classes and each detection's entry, no list of
    classes made -- to the general writers' bytes, record and CPM, frame after frame, untracked and tracked (one
    class, several, none, some detections without one); and the frames leave the shared rows (``_kept_rows``: the
    uniform frame's class and status entries, the messages' rows) as they were."""
    from footprint_uq.service import core

    kw = dict(record="compact", tracks=tracks)
    fast, ref = Service(camera, "basler1", **kw), Service(camera, "basler1", **kw)
    ref._columnar = False
    taken = []
    real = Service._compact_text
    monkeypatch.setattr(Service, "_compact_text", lambda *a: taken.append(a[3]) or real(*a))  # (a[3]: class_idx)
    monkeypatch.setattr(core, "_class_index", lambda *a: pytest.fail("a list of classes indexed"))
    for k in range(4):
        frame = _frame(np.random.default_rng(40 + k), 30 if k < 3 else 300, k,
                       variant="classes" if variant == "some-without-class" else variant)
        for i, d in enumerate(frame["detections"]):
            if d["u_min_px"] > d["u_max_px"]:  # (no reversed box: the scanner's frame goes to the lean path whole)
                d["u_min_px"], d["u_max_px"] = d["u_max_px"], d["u_min_px"]
            if variant == "some-without-class" and i % 4 == 1:
                del d["class"]
        a, b = fast.process_frame_json(orjson.dumps(frame)), ref.process_frame_json(orjson.dumps(frame))
        assert a.type == b.type == "footprints" and not json.loads(a.data)["detection_errors"]
        assert _record(a) == _record(b) and a.cpm_uper == b.cpm_uper
    assert len(taken) == 4 and all(t is None for t in taken) == (variant in ("one-class", "no-class"))
    for n, (zeros, rows) in core._KEPT_ROWS.items():
        assert zeros.tolist() == [0] * n and rows.tolist() == list(range(min(n, 255)))


_IDS = st.tuples(st.lists(st.integers(0, 70), unique=True, max_size=24),
                 st.sampled_from([None, None, None, None, "a", "7", 2 ** 40, -3, 5])).map(
    lambda c: c[0] if c[1] is None else c[0] + [c[1]])  # (mostly distinct ints: the path by array)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.tuples(_IDS, st.floats(-0.5, 2.0), st.integers(0, 2 ** 25)), max_size=25),
       st.sampled_from([0.0, 0.7, 3.0]))
def test_message_ids_by_array_are_the_general_paths(frames, hold_s):
    """``MessageIdMap.assign(..., int_ids=...)`` (integer ids by array) gives the numbers of the general path and
    leaves the same tables (keys, numbers, last-seen times, their order), frame after frame: new and known ids,
    repeated ids, nulls and texts (the general path), time going back, numbers released after ``hold_s``, and every
    number held (a table of 64 numbers here: the longest-unseen id released early)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(ids_mod, "_N", 64)
        _same_ids(ids_mod.MessageIdMap(hold_s), ids_mod.MessageIdMap(hold_s), frames)
        _same_ids(ids_mod.MessageIdMap(hold_s), ids_mod.MessageIdMap(hold_s), frames, lazy=True)


def _same_ids(fast, ref, frames, lazy: bool = False) -> None:
    """``lazy``: the integer ids' frames given to ``fast`` as the array alone (``ids`` None: the list made only
    where the array path declines them -- an id twice, or beyond the table)."""
    t = T0
    for ids, dt, pick in frames:
        t += dt
        rows = np.array([i for i in range(len(ids)) if (pick >> i) & 1], np.int64)
        ints = None if set(map(type, ids)) - {int} else np.array(ids, np.int64)
        given = None if lazy and ints is not None else ids
        assert fast.assign(given, rows, t, int_ids=ints).tolist() == ref.assign(ids, rows, t).tolist()
    fast._sync()
    assert fast._num == ref._num and fast._owner == ref._owner
    assert list(fast._seen.items()) == list(ref._seen.items())


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 30), st.integers(0, 2 ** 32 - 1), st.sampled_from(["bottom-centre", "bottom-corners"]))
def test_checked_boxes_give_the_same_estimate(camera_proc, n, seed, contact):
    """``FrameProcessor.boxes2d(..., boxes_checked=True)`` (the service's boxes, checked by its value checks: the
    contact pixels formed without the checks) is the estimate of the checked call, array for array, bit for bit
    (boxes across the image, beyond it and above the horizon, degenerate ones)."""
    rng = np.random.default_rng(seed)
    u, v = rng.uniform(-300, 2200, n), rng.uniform(-100, 1300, n)
    w, h = rng.uniform(0, 200, n) * (rng.random(n) > 0.1), rng.uniform(0, 150, n)
    boxes = np.column_stack([u, v - h, u + w, v])
    cov = np.tile(np.diag([4.0, 9.0]), (n, 1, 1)) if seed % 2 else None
    a = camera_proc.boxes2d(boxes, contact=contact, pixel_cov_px2=cov)
    b = camera_proc.boxes2d(boxes, contact=contact, pixel_cov_px2=cov, boxes_checked=True)
    for name in ("corners_px", "centre_xy_world_m", "centre_cov_m2", "largest_xy_world_m", "v2x_codes",
                 "centre_reason", "object_rows"):
        x, y = np.asarray(getattr(a, name)), np.asarray(getattr(b, name))
        assert x.shape == y.shape and x.tobytes() == y.tobytes(), name


@pytest.fixture(scope="module")
def camera_proc(camera):
    from footprint_uq import FrameProcessor

    return FrameProcessor(camera, "basler1", joint_cov=False)


_P_VALUES = st.one_of(st.floats(0.0, 1.0), st.just(float("nan")), st.sampled_from([0.0, 0.01, 0.015, 0.29, 0.5, 1.0]))


@settings(max_examples=120, deadline=None)
@given(st.integers(0, 300), st.integers(0, 2 ** 32 - 1), st.booleans(), st.sampled_from(["2.1.1", "2.2.1"]),
       st.data())
def test_plain_cpm_container_is_the_composed_writers(n, seed, with_p, cdd, data):
    """``frame_kernels.plain_cpm_container`` (cm, confidence levels and container in one compiled call) gives the
    bytes of what the service composed before: ``cm_dm`` + ``_confidence_levels`` + ``plain_container_uper``, and
    ``plain_cpm_uper`` (the message too) ``CpmUperWriter.encode``'s --
    over positions on and beyond the coordinate range (NaN, the cm rounding's edges), class confidences (NaN,
    the level's edges, none given), subsets of rows (> 255 objects), several classes, CDD releases, and values
    out of range (None from both)."""
    from footprint_uq.service import core
    from footprint_uq.service.frame_kernels import cm_dm, plain_cpm_container, plain_cpm_uper
    from footprint_uq.service.messages.uper_cpm import plain_container_uper

    rng = np.random.default_rng(seed)
    en = rng.choice([1.0, 100.0, 1500.0], (n, 2)) * rng.uniform(-1, 1, (n, 2))
    en[rng.random((n, 2)) < 0.05] = np.nan
    en[rng.random((n, 2)) < 0.05] = 0.125  # (an exact cm edge)
    rows = np.flatnonzero(rng.random(n) < 0.8)
    class_p = np.array(data.draw(st.lists(_P_VALUES, min_size=n, max_size=n)), dtype=np.float64) if with_p else None
    msg_ids = rng.integers(0, 65536, len(rows)).astype(np.int64)
    if len(rows) and rng.random() < 0.1:
        msg_ids[0] = 70000  # (out of range: None)
    v2x = np.ascontiguousarray(rng.integers(1, 4096, (7, n)).astype(np.int32))
    v2x[core._CPM_INDEX + 2] = rng.integers(-100, 101, n)
    class_idx = rng.integers(0, 3, n).astype(np.int64)
    class_row = core._class_rows_of(["car", None, "pedestrian"])
    cls = core._class_tables(cdd)
    got = plain_cpm_container(en, rows, class_p, msg_ids, v2x, core._CPM_INDEX, class_idx, class_row, cls.bits_value,
                              cls.bits_width, cdd=cdd)
    level, _ = core._confidence_levels(class_p, rows)
    want = plain_container_uper(msg_ids, cm_dm(en, rows), v2x, rows, core._CPM_INDEX, class_idx, class_row,
                                cls.bits_value, cls.bits_width, level, cdd=cdd)
    assert got == want
    # the whole message by bits (plain_cpm_uper) == the writer's Python integers, short and long containers
    writer = CpmUperWriter(int(rng.integers(0, 2 ** 32)), latitude=int(rng.integers(-900000000, 900000001)),
                           longitude=int(rng.integers(-1800000000, 1800000001)))
    ref_ms = data.draw(st.one_of(st.integers(0, 4398046511103), st.sampled_from([0, 4398046511103])))
    msg = plain_cpm_uper(writer, ref_ms, en, rows, class_p, msg_ids, v2x, core._CPM_INDEX, class_idx, class_row,
                         cls.bits_value, cls.bits_width, cdd=cdd)
    assert msg == (None if want is None else writer.encode(ref_ms, want))


def test_plain_cpm_uper_names_a_reference_time_out_of_range():
    """A reference time beyond TimestampIts: the writer's error, as ``CpmUperWriter.encode`` raises it."""
    from footprint_uq.errors import InputError
    from footprint_uq.service import core
    from footprint_uq.service.frame_kernels import plain_cpm_uper

    cls = core._class_tables("2.2.1")
    one = np.ones(1, np.int64)
    for ref_ms in (-1, 4398046511104):
        with pytest.raises(InputError, match="referenceTime"):
            plain_cpm_uper(CpmUperWriter(7), ref_ms, np.zeros((1, 2)), 0 * one, None, one, np.ones((7, 1), np.int32),
                           core._CPM_INDEX, 0 * one, 0 * one, cls.bits_value, cls.bits_width)
