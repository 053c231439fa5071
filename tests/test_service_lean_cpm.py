"""The lean frame's CPM in one compiled call of few arguments (wave 10 c) and its record head from constant texts.

* :func:`footprint_uq.service.frame_kernels.enu_columns` under :func:`~footprint_uq.service.frame_kernels.enu_modes`
  gives numpy's world -> ENU product (``CameraSetup.world_to_enu``) to the bit, one point and many, both layouts
  (Hypothesis: headings, origins, magnitudes, NaN / inf);
* :func:`~footprint_uq.service.frame_kernels.lean_cpm_uper` (the camera's constants packed once, the ENU transform
  and the message's writing inside) gives :func:`~footprint_uq.service.frame_kernels.plain_cpm_uper`'s octets on
  numpy's ENU columns, and declines (None) exactly where that call declines or raises (Hypothesis: positions on and
  beyond the coordinate range and on cm edges, class confidences, rows, motion codes in and out of range, > 255
  objects, both CDD releases, reference times);
* ``core._lean_head`` is ``orjson.dumps`` of the head dict to the byte (Hypothesis: any camera id, 64-bit and
  larger frame numbers, any finite time, error entries, with and without messages), cached or not;
* a service's lean frame takes the call (a spy), equals the general writers' record and CPM, and finds its
  kernel warm.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.errors import InputError
from footprint_uq.service import Service, core
from footprint_uq.service import frame_kernels as fk
from footprint_uq.service.detections import DetectionError
from footprint_uq.service.messages.uper_cpm import CpmUperWriter

T0 = 1714564800.0
_P_VALUES = st.one_of(st.floats(0.0, 1.0), st.just(float("nan")), st.sampled_from([0.0, 0.01, 0.015, 0.5, 1.0]))


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


def _tie(heading_deg: float, origin):
    """A map tie as ``CameraSetup`` holds it: origin and ``R_enu_world.T`` (a transposed view)."""
    h = math.radians(heading_deg)
    c, s = math.cos(h), math.sin(h)
    rt = np.array([[c, s], [-s, c]]).T
    origin = np.asarray(origin, np.float64)
    return origin, rt, np.array([origin[0], origin[1], rt[0, 0], rt[0, 1], rt[1, 0], rt[1, 1]])


_MODES = fk.enu_modes()
needs_modes = pytest.mark.skipif(_MODES is None, reason="numpy's product not matched on this machine")


def test_enu_modes_tell_the_roundings_apart():
    """The modes found are distinct roundings: on a point where they differ, only the mode found gives numpy's
    bits (so a probe that matched by chance would not pass)."""
    if _MODES is None:
        pytest.skip("numpy's product not matched on this machine")
    origin, rt, tie = _tie(33.0, (5.0, -7.0))
    rng = np.random.default_rng(3)
    for n, mode in ((1, _MODES[0]), (50, _MODES[1])):
        xy = rng.normal(size=(n, 2)) * 300
        want = ((xy - origin) @ rt).T
        others = [m for m in (fk.ENU_PLAIN, fk.ENU_FMA_LAST, fk.ENU_FMA_FIRST) if m != mode]
        seen_other = []
        for _ in range(200 if n == 1 else 1):
            xy = rng.normal(size=(n, 2)) * 300
            want = ((xy - origin) @ rt).T
            assert np.array_equal(fk.enu_columns(np.ascontiguousarray(xy.T), tie, mode), want)
            seen_other.append([np.array_equal(fk.enu_columns(np.ascontiguousarray(xy.T), tie, m), want)
                               for m in others])
        assert not all(all(s) for s in seen_other)  # (another mode differs somewhere)
    # ENU_GIVEN: the values as they are
    xy = rng.normal(size=(2, 7))
    assert np.array_equal(fk.enu_columns(xy, tie, fk.ENU_GIVEN), xy)


_COORD = st.one_of(st.floats(-2e3, 2e3), st.floats(-1e7, 1e7), st.sampled_from([0.0, -0.0, 0.125, 0.07, 1310.72]),
                   st.just(float("nan")), st.sampled_from([float("inf"), -float("inf")]))


@needs_modes
@settings(max_examples=200, deadline=None)
@given(st.floats(-360, 360), st.tuples(st.floats(-1e4, 1e4), st.floats(-1e4, 1e4)),
       st.lists(st.tuples(_COORD, _COORD), min_size=1, max_size=40), st.booleans())
def test_enu_columns_are_numpys_product(heading, origin, points, fortran):
    """``enu_columns`` under the mode found == ``CameraSetup.world_to_enu`` (numpy's BLAS product), every bit but
    the sign of a zero (which no cm, level or text reads), NaN where numpy has NaN."""
    origin, rt, tie = _tie(heading, origin)
    xy = np.array(points, np.float64)
    if fortran:
        xy = np.asfortranarray(xy)
    with np.errstate(invalid="ignore"):  # (inf - inf, inf * 0: NaN, as numpy writes it)
        want = ((xy - origin) @ rt).T
    got = fk.enu_columns(np.ascontiguousarray(xy.T), tie, _MODES[0] if len(xy) == 1 else _MODES[1])
    assert np.array_equal(got, want, equal_nan=True)


def _motion_codes(rng, m: int, bad: bool) -> np.ndarray:
    """(14, m) int64 motion code rows as ``motion_rows`` makes them (the container reads the first ten)."""
    rows = np.zeros((14, m), np.int64)
    rows[0], rows[5], rows[8] = rng.integers(0, 2, (3, m))
    rows[1], rows[3] = rng.integers(-16383, 16384, (2, m))
    rows[2], rows[4], rows[7] = rng.integers(1, 128, (3, m))
    rows[6], rows[9] = rng.integers(0, 3602, m), rng.integers(0, 2048, m)
    if bad and m:
        rows[int(rng.integers(0, 10)), int(rng.integers(0, m))] = 99999
    return rows


@needs_modes
@settings(max_examples=150, deadline=None)
@given(st.integers(0, 300), st.integers(0, 2 ** 32 - 1), st.booleans(), st.sampled_from(["2.1.1", "2.2.1"]),
       st.floats(-360, 360), st.sampled_from(["none", "ok", "bad"]), st.data())
def test_lean_cpm_uper_is_plain_cpm_uper(n, seed, with_p, cdd, heading, motion, data):
    """``lean_cpm_uper`` == ``plain_cpm_uper`` on numpy's ENU columns of the same world points, to the octet; it
    declines (None) exactly where that call returns None or raises (then that call answers, as before)."""
    rng = np.random.default_rng(seed)
    values = np.empty((int(rng.choice([5, 10])), n))
    values[:2] = rng.choice([1.0, 100.0, 1500.0], (2, n)) * rng.uniform(-1, 1, (2, n))
    values[:2][rng.random((2, n)) < 0.05] = np.nan
    values[:2][rng.random((2, n)) < 0.05] = 0.125  # (an exact cm edge before the transform)
    rows = np.flatnonzero(rng.random(n) < 0.8) if rng.random() < 0.7 else np.arange(min(n, 255))
    m = len(rows)
    class_p = np.array(data.draw(st.lists(_P_VALUES, min_size=n, max_size=n)), dtype=np.float64) if with_p else None
    msg_ids = rng.integers(0, 65536, m).astype(np.int64)
    if m and rng.random() < 0.1:
        msg_ids[0] = 70000  # (out of range: declined)
    v2x = np.ascontiguousarray(rng.integers(1, 4096, (7, n)).astype(np.int32))
    v2x[core._CPM_INDEX + 2] = rng.integers(-100, 101, n)
    class_idx = rng.integers(0, 3, n).astype(np.int64)
    class_row = core._class_rows_of(["car", None, "pedestrian"])
    cls = core._class_tables(cdd)
    writer = CpmUperWriter(int(rng.integers(0, 2 ** 32)), latitude=int(rng.integers(-900000000, 900000001)),
                           longitude=int(rng.integers(-1800000000, 1800000001)))
    origin, rt, _ = _tie(heading, rng.uniform(-500, 500, 2))
    consts = fk.lean_cpm_constants(writer, cdd, origin, rt, core._CPM_INDEX, cls.bits_value, cls.bits_width)
    mc = None if motion == "none" else _motion_codes(rng, m, motion == "bad")
    ref_ms = data.draw(st.one_of(st.integers(0, 4398046511103), st.sampled_from([0, 4398046511103, -1,
                                                                                   4398046511104])))
    got = fk.lean_cpm_uper(consts, ref_ms, values, rows, class_p, msg_ids, v2x, class_idx, class_row, mc)
    en = (values[:2].T - origin) @ rt
    try:
        want = fk.plain_cpm_uper(writer, ref_ms, en, rows, class_p, msg_ids, v2x, core._CPM_INDEX, class_idx,
                                 class_row, cls.bits_value, cls.bits_width, cdd=cdd, motion=mc)
    except InputError:
        want = None
    assert got == want
    if m <= 255 and 0 <= ref_ms <= 4398046511103 and motion != "bad" and (m == 0 or msg_ids[0] != 70000) and \
            np.all(np.abs(en[rows]) < 1310.0):
        assert got is not None  # (nothing out of range: the lean call takes it)


def _edge_points(heading_deg: float, origin, one: bool) -> np.ndarray:
    """World points (k, 2) whose east or north lies within an ulp of a cm step (``ceil(100 v - 1e-7)``), where
    numpy's product and another rounding (:data:`~footprint_uq.service.frame_kernels.ENU_PLAIN` ...) give
    different cm: a CPM written with the wrong rounding differs there.  ``one``: points for one-object frames."""
    origin, rt, tie = _tie(heading_deg, origin)
    r = rt.T
    rng = np.random.default_rng(int(heading_deg * 1000) % 2 ** 32)
    found = []
    steps = np.arange(-24, 25)
    for _ in range(40):
        t = (rng.integers(-90000, 90000, 2) + 1e-7) / 100.0  # (east, north on a cm step)
        x0, y0 = origin + t @ r
        xs = x0 + steps * np.spacing(x0)
        ys = y0 + steps * np.spacing(y0)
        xy = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
        if one:
            want = np.concatenate([((p[None] - origin) @ rt) for p in xy])
        else:
            want = (xy - origin) @ rt
        cm = np.ceil(want * 100.0 - 1e-7)
        for mode in (fk.ENU_PLAIN, fk.ENU_FMA_LAST, fk.ENU_FMA_FIRST):
            other = np.ceil(fk.enu_columns(np.ascontiguousarray(xy.T), tie, mode).T * 100.0 - 1e-7)
            found += [xy[k] for k in np.flatnonzero((other != cm).any(axis=1))[:2]]
        if len(found) >= 6:
            break
    return np.array(found)


@needs_modes
@pytest.mark.parametrize("heading", [17.3, 123.0, -71.5])
def test_lean_cpm_uper_rounds_like_numpy_on_cm_edges(heading):
    """On points where a rounding other than numpy's changes a cm (an ulp from a step), ``lean_cpm_uper``'s message
    is still ``plain_cpm_uper``'s on numpy's columns: one-object frames (numpy's vector product) and frames of many
    (its matrix product).  A mode taken wrong fails here, not only in :func:`enu_columns`' test."""
    writer = CpmUperWriter(5)
    cls = core._class_tables("2.2.1")
    origin = (37.5, -12.25)
    o, rt, _ = _tie(heading, origin)
    consts = fk.lean_cpm_constants(writer, "2.2.1", o, rt, core._CPM_INDEX, cls.bits_value, cls.bits_width)
    for one in (True, False):
        pts = _edge_points(heading, origin, one)
        assert len(pts) >= 2  # (the edges exist for this heading: the test can fail)
        frames = [pts[k:k + 1] for k in range(len(pts))] if one else [pts]
        for xy in frames:
            n = len(xy)
            values = np.zeros((5, n))
            values[:2] = xy.T
            ids = np.arange(n, dtype=np.int64)
            v2x = np.full((7, n), 9, np.int32)
            args = (np.arange(n), None, ids, v2x)
            zero = np.zeros(n, np.int64)
            got = fk.lean_cpm_uper(consts, 1, values, *args, zero, core._class_rows_of([None]))
            want = fk.plain_cpm_uper(writer, 1, (xy - o) @ rt, *args, core._CPM_INDEX, zero,
                                     core._class_rows_of([None]), cls.bits_value, cls.bits_width)
            assert got == want is not None


def test_lean_cpm_uper_declines_motion_rows_of_another_shape():
    """Motion rows that are not (>= 10, m): declined (None), and ``plain_cpm_uper`` names them."""
    writer = CpmUperWriter(7)
    cls = core._class_tables("2.2.1")
    consts = fk.lean_cpm_constants(writer, "2.2.1", np.zeros(2), np.eye(2), core._CPM_INDEX, cls.bits_value,
                                   cls.bits_width)
    if consts is None:
        pytest.skip("numpy's product not matched on this machine")
    one = np.ones(2, np.int64)
    args = (consts, 0, np.zeros((5, 2)), np.arange(2), None, one, np.ones((7, 2), np.int32), 0 * one, 0 * one)
    assert fk.lean_cpm_uper(*args, np.ones((14, 2), np.int64)) is not None
    assert fk.lean_cpm_uper(*args, np.ones((14, 3), np.int64)) is None
    assert fk.lean_cpm_uper(*args, np.ones((9, 2), np.int64)) is None
    with pytest.raises(InputError, match="motion"):
        fk.plain_cpm_uper(writer, 0, np.zeros((2, 2)), np.arange(2), None, one, np.ones((7, 2), np.int32),
                          core._CPM_INDEX, 0 * one, 0 * one, cls.bits_value, cls.bits_width,
                          motion=np.ones((14, 3), np.int64))


def test_lean_cpm_uper_pins_a_hand_checked_message():
    """One object 1.234 m east and 5.678 m north of the origin (heading offset 90 deg: world +y points east), its
    message decoded: x 124 cm, y 568 cm (the next cm up), objectId 7, the level of confidence 0.42."""
    pytest.importorskip("asn1tools")
    from footprint_uq.service.messages.cpm import decode_cpm_uper

    writer = CpmUperWriter(99)
    cls = core._class_tables("2.2.1")
    origin, rt, _ = _tie(90.0, (10.0, 20.0))
    consts = fk.lean_cpm_constants(writer, "2.2.1", origin, rt, core._CPM_INDEX, cls.bits_value, cls.bits_width)
    if consts is None:
        pytest.skip("numpy's product not matched on this machine")
    values = np.zeros((5, 1))
    values[0, 0], values[1, 0] = 10.0 - 5.678, 20.0 + 1.234  # world x = -north, world y = east
    v2x = np.full((7, 1), 50, np.int32)
    v2x[core._CPM_INDEX + 2] = 101
    one = np.ones(1, np.int64)
    octets = fk.lean_cpm_uper(consts, 1000, values, 0 * one, np.array([0.42]), 7 * one, v2x, 0 * one,
                              core._class_rows_of(["car"]))
    msg = decode_cpm_uper(octets, "2.2.1")
    assert msg["header"]["stationId"] == 99 and msg["payload"]["managementContainer"]["referenceTime"] == 1000
    (po,) = msg["payload"]["cpmContainers"][1]["containerData"]["perceivedObjects"]
    assert po["objectId"] == 7
    assert po["position"]["xCoordinate"]["value"] == 124 and po["position"]["yCoordinate"]["value"] == 568
    assert po["classification"][0]["confidence"] == 42


_TEXT = st.text(max_size=12)
_ERRORS = st.lists(st.builds(DetectionError, st.integers(0, 10 ** 4), _TEXT, _TEXT), max_size=3)


@settings(max_examples=300, deadline=None)
@given(st.one_of(st.none(), _TEXT), st.one_of(st.integers(-(2 ** 63), 2 ** 64 - 1), st.integers()),
       st.floats(allow_nan=False, allow_infinity=False), st.integers(0, 10 ** 4), _ERRORS,
       st.sampled_from([None, "2.1.1", "2.2.1"]), st.integers(0, 2 ** 32 - 1),
       st.floats(-360, 360, allow_subnormal=True), st.booleans())
def test_lean_head_is_orjsons_text_of_the_dict(camera_id, fno, ts, n, errors, cdd, station_id, heading, cached):
    """``_lean_head`` == ``orjson.dumps(head dict)[:-1]`` (the record before this change), to the byte, whether its
    camera's texts are kept already or not; where orjson refuses (a frame number beyond 64 bits, text it cannot
    write) it raises orjson's error, as before."""
    setup = SimpleNamespace(head_texts={}, station_id=station_id, georef=SimpleNamespace(heading_offset_deg=heading))
    head = {"type": "footprints", "record": "compact", "camera_id": camera_id, "frame": fno, "timestamp_s": ts,
            "station_id": station_id, "heading_offset_deg": heading, "n_objects": n,
            "detection_errors": [e.as_dict() for e in errors]}
    if cdd is not None:
        head["cpm_cdd"] = cdd
    try:
        want = orjson.dumps(head)[:-1]
    except orjson.JSONEncodeError:
        with pytest.raises(orjson.JSONEncodeError):
            core._lean_head(setup, camera_id, fno, ts, n, errors, cdd)
        return
    if cached:
        core._lean_head(setup, camera_id, 0, 1.0, 0, [], cdd)
    assert core._lean_head(setup, camera_id, fno, ts, n, errors, cdd) == want
    assert core._lean_head(setup, camera_id, fno, ts, n, errors, cdd) == want  # (from the kept texts)


def test_lean_head_keeps_a_few_camera_ids():
    """A single camera answers to any id: its kept head texts stay few (64)."""
    setup = SimpleNamespace(head_texts={}, station_id=1, georef=SimpleNamespace(heading_offset_deg=0.0))
    for k in range(200):
        assert core._lean_head(setup, f"cam{k}", k, 1.5, 0, [], None).startswith(
            b'{"type":"footprints","record":"compact","camera_id":"cam%d","frame":%d,' % (k, k))
    assert 0 < len(setup.head_texts) <= 64


def _frames(rng, n_frames: int, n: int):
    for f in range(n_frames):
        dets = []
        for k in range(n):
            u, v = rng.uniform(100, 1800), rng.uniform(560, 1000)
            d = {"object_id": k, "class": ["car", "pedestrian", "truck"][k % 3], "u_min_px": u - 30,
                 "v_min_px": v - 40, "u_max_px": u + 30, "v_max_px": v}
            if k % 2:
                d["class_confidence"] = float(rng.uniform(0, 1))
            dets.append(d)
        yield json.dumps({"camera_id": "cam", "frame": f, "timestamp_s": T0 + f / 10, "detections": dets}).encode()


@pytest.mark.parametrize("tracks", [False, True])
def test_the_lean_frame_takes_the_one_call(camera, tracks, monkeypatch):
    """A lean frame's CPM is ``lean_cpm_uper``'s (``plain_cpm_uper`` never called), and its record and CPM are the
    general writers' (``_columnar = False``) byte for byte; without the packed constants (a machine where numpy's
    product is not matched) the numpy path gives the same bytes."""
    kw = dict(record="compact", tracks=tracks, heading_offset_deg=23.0, origin_lat_deg=48.0, origin_lon_deg=11.0)
    lean, ref, fallback = (Service(camera, "basler1", **kw) for _ in range(3))
    ref._columnar = False
    (setup,) = fallback.cameras.values()
    setup.lean_cpm = None
    if next(iter(lean.cameras.values())).lean_cpm is None:
        pytest.skip("numpy's product not matched on this machine")
    calls = []
    real_plain = core.plain_cpm_uper

    def spy(*a, **k):
        calls.append(1)
        return real_plain(*a, **k)

    monkeypatch.setattr(core, "plain_cpm_uper", spy)
    for p in _frames(np.random.default_rng(5), 4, 40):
        calls.clear()
        a = lean.process_frame_json(p)
        assert not calls
        b, c = ref.process_frame_json(p), fallback.process_frame_json(p)
        assert calls  # (the fallback's numpy path)
        head = [o.data.split(b',"processing_us"')[0] for o in (a, b, c)]
        assert head[0] == head[1] == head[2]
        assert a.cpm_uper == b.cpm_uper == c.cpm_uper is not None


def test_the_lean_cpm_kernel_is_warm(camera):
    """A compact service's warm-up leaves nothing of the lean CPM call to compile for its frames, untracked and
    tracked (one signature for both)."""
    services = [Service(camera, "basler1", record="compact", tracks=t) for t in (False, True)]
    before = set(fk._lean_cpm_kernel.signatures)
    assert before
    for svc in services:
        for p in _frames(np.random.default_rng(6), 2, 5):
            assert svc.process_frame_json(p).type == "footprints"
    assert set(fk._lean_cpm_kernel.signatures) == before


@settings(max_examples=500, deadline=None)
@given(st.one_of(st.floats(0.0, 1e6), st.floats(0.0, 1e14), st.integers(0, 10 ** 7).map(lambda k: k / 20 + 0.05)))
def test_a_total_read_back_from_its_text_is_the_rounded_total(us):
    """The lean record writes ``processing_us.total`` as ``"%.1f"`` of the time and hands ``float`` of that text as
    ``FrameOutput.processing_us``: the same float as ``round(us, 1)`` (the value before), and the same text as
    ``"%.1f"`` of that rounded value (ties included)."""
    text = b"%.1f" % us
    assert float(text) == round(us, 1)
    assert b"%.1f" % round(us, 1) == text


def test_each_camera_of_a_registry_has_its_own_constants(camera, monkeypatch):
    """A registry's cameras (each its own heading offset, origin and station): each one's lean CPM is the general
    writers' (``_columnar = False``), through the one call (``plain_cpm_uper`` not called), frames interleaved."""
    from footprint_uq.io.registry import RegistryEntry

    reg = {"east": RegistryEntry("east", camera, "basler1", 95.0, 48.1, 11.5),
           "west": RegistryEntry("west", camera, "basler1", -140.0, -33.9, 151.2),
           "plain": RegistryEntry("plain", camera, "basler1")}
    lean, ref = Service(registry=reg, record="compact"), Service(registry=reg, record="compact")
    ref._columnar = False
    if any(s.lean_cpm is None for s in lean.cameras.values()):
        pytest.skip("numpy's product not matched on this machine")
    ties = {cid: s.lean_cpm.tie.tobytes() for cid, s in lean.cameras.items()}
    assert len(set(ties.values())) == 3
    calls = []
    real_plain = core.plain_cpm_uper
    monkeypatch.setattr(core, "plain_cpm_uper", lambda *a, **k: calls.append(1) or real_plain(*a, **k))
    for k, p in enumerate(_frames(np.random.default_rng(8), 6, 30)):
        cid = ("east", "west", "plain")[k % 3]
        p = p.replace(b'"camera_id": "cam"', b'"camera_id": "%s"' % cid.encode())
        calls.clear()
        a = lean.process_frame_json(p)
        assert not calls and a.type == "footprints"
        b = ref.process_frame_json(p)
        assert a.data.split(b',"processing_us"')[0] == b.data.split(b',"processing_us"')[0]
        assert a.cpm_uper == b.cpm_uper is not None
