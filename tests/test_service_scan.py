"""The compiled frame reader (service/frame_scan.py) against the general path (orjson -> dicts -> parse_detections).

* numbers: every text the reader accepts gives orjson's double bit for bit (Hypothesis over floats written
  in several ways, and pinned cases at the edges of the exact subset);
* hostile and unusual texts: the reader declines (None) and the service's record is the general path's;
* whole frames: ``Service.process_frame_json`` of the bytes (the reader) and of the parsed dict (the general
  path) give the same record, byte for byte but the timing, for good frames, bad detections, tracks and both
  record layouts.
"""

from __future__ import annotations

import json
import math
import re

import numpy as np
import orjson
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from footprint_uq import PanTiltCamera
from footprint_uq.service import Service
from footprint_uq.service.frame_scan import scan_frame

T0 = 1714564800.0
_TIMING = re.compile(rb',"processing_us":\{[^}]*\}')


@pytest.fixture(scope="module")
def camera():
    return PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)


def _frame(dets, frame=3, ts=T0 + 0.033333, camera="cam0") -> bytes:
    return b'{"camera_id":%s,"frame":%d,"timestamp_s":%r,"detections":%s}' % (
        json.dumps(camera).encode(), frame, ts, json.dumps(dets, ensure_ascii=False).encode())


def _dets(rng, n, cov=False, conf=False):
    out = []
    for k in range(n):
        u, v, w = rng.uniform(50, 1800), rng.uniform(420, 1070), rng.uniform(20, 120)
        d = {"object_id": k, "class": str(rng.choice(["car", "pedestrian", "truck", "Fahrrad-ü"])),
             "u_min_px": round(u, 2), "v_min_px": round(v - 0.8 * w, 3), "u_max_px": round(u + w, 1),
             "v_max_px": int(v)}
        if cov:
            d.update(cov_uu_px2=4.0, cov_uv_px2=-0.5, cov_vv_px2=9)
        if conf and k % 3:
            d["class_confidence"] = round(rng.uniform(0, 1), 4)
        out.append(d)
    return out


def _record(out) -> bytes:
    return _TIMING.sub(b"", out.data)


def _scan_number(text: bytes):
    """``text`` as a detection's value, read by the reader's two paths: in the first detection (read in full) and
    in the second (read by the first one's template); they must agree (None: declined)."""
    det = b'{"u_min_px":0,"v_min_px":0,"u_max_px":1,"v_max_px":%s}'
    got = []
    for dets in (det % text + b"," + det % b"2", det % b"2" + b"," + det % text):
        s = scan_frame(b'{"camera_id":"c","frame":1,"timestamp_s":0,"detections":[%s]}' % dets)
        got.append(None if s is None else s.boxes[0 if dets.startswith(det % text) else 1, 3])
    assert got[0] == got[1] or got[0] is got[1] is None, (text, got)
    return got[0]


@settings(max_examples=300, deadline=None)
@given(st.floats(allow_nan=False, allow_infinity=False, min_value=-1e30, max_value=1e30),
       st.sampled_from(["%r", "%.17g", "%.3f", "%.6e", "%.1E", "%.0f", "%.15g"]))
def test_numbers_are_orjson_doubles(x, fmt):
    text = (fmt % x).encode()
    if b"inf" in text or b"nan" in text:
        return
    want = orjson.loads(text)
    got = _scan_number(text)
    if got is not None:  # (declined: the general path reads it)
        assert got == float(want) and math.copysign(1.0, got) == math.copysign(1.0, float(want)), text


@pytest.mark.parametrize("text, value", [
    (b"0", 0.0), (b"-0.0", -0.0), (b"1714564800.033333", 1714564800.033333), (b"9007199254740992", 2.0 ** 53),
    (b"1e22", 1e22), (b"1.5e-21", 1.5e-21), (b"1.5e-22", None), (b"0.000001", 1e-6),
    (b"123456789012345678", 123456789012345678.0), (b"0.0003911144233402361", 0.0003911144233402361),
    (b"1e23", None), (b"1e-23", None), (b"9007199254740993.5", None), (b"1234567890123456789", None),
    (b"01", None), (b"1.", None), (b".5", None), (b"1e", None), (b"+1", None), (b"-", None), (b"NaN", None),
    (b"Infinity", None), (b"true", None), (b"null", None), (b'"1"', None),
    # 19 digits whose mantissa wraps int64 (found by Hypothesis: the template path read -9223372036854776.0)
    (b"9223372036854776.000", None), (b"-9300000000000000.000", None), (b"0.00092233720368547760", None)])
def test_numbers_pinned(text, value):
    got = _scan_number(text)
    if value is None:
        assert got is None
    else:
        assert got == value and math.copysign(1.0, got) == math.copysign(1.0, value)


_JSON_NUMBER = re.compile(rb"-?(0|[1-9][0-9]*)(\.([0-9]+))?([eE]([+-]?)([0-9]+))?")


def _exact_subset(text: bytes):
    """What the reader must give for a detection's number: its double where the text is in the exact subset
    (module doc: JSON's grammar, at most 18 significant digits; with a point or an exponent, a mantissa up to
    2^53 scaled by at most 10^22), None (declined) elsewhere -- written from the doc, not from the reader."""
    g = _JSON_NUMBER.fullmatch(text)
    if g is None:
        return None
    whole, frac, exp = g[1], g[3] or b"", g[6]
    if len((whole + frac).lstrip(b"0")) > 18:
        return None
    if g[2] is None and g[4] is None:
        return float(int(text))
    e10 = (int(exp) if g[5] != b"-" else -int(exp)) if g[4] else 0
    if int(whole + frac) > 2 ** 53 or abs(e10 - len(frac)) > 22:
        return None
    return float(text)  # (Python's correctly rounded double: the exact subset's one operation gives it)


def _scan_number_at(text: bytes, key: bytes):
    """``text`` as the value of ``key`` (followed by ``,`` or ``}``) in the first detection (read in full) and in
    the second (by the first one's template); both readings must agree."""
    keys = (b"u_min_px", b"v_min_px", b"u_max_px", b"v_max_px")
    det = b"{" + b",".join(b'"%s":%s' % (k, b"%s" if k == key else b"2") for k in keys) + b"}"
    col = keys.index(key)
    got = []
    for row, dets in ((0, det % text + b"," + det % b"7"), (1, det % b"7" + b"," + det % text)):
        s = scan_frame(b'{"camera_id":"c","frame":1,"timestamp_s":0,"detections":[%s]}' % dets)
        got.append(None if s is None else s.boxes[row, col])
    assert got[0] is got[1] is None or (None not in got and np.float64(got[0]).tobytes() ==
                                        np.float64(got[1]).tobytes()), (text, got)  # (bit for bit: -0.0 too)
    return got[0]


_DIGITS = st.text("0123456789", max_size=22)


@settings(max_examples=500, deadline=None)
@given(st.sampled_from([b"", b"-"]), st.text("0123456789", min_size=1, max_size=22), st.none() | _DIGITS,
       st.none() | st.tuples(st.sampled_from([b"e", b"E"]), st.sampled_from([b"", b"+", b"-"]),
                             st.text("0123456789", max_size=4)),
       st.sampled_from([b"u_min_px", b"v_max_px"]))
def test_decimal_texts_of_every_length(sign, whole, frac, exp, key):
    """Digit strings across the reader's limits (18 digits, 2^53, 22 places, leading zeros, a point or an exponent
    without digits): read exactly where the exact subset holds them (orjson's double), declined elsewhere."""
    text = sign + whole.encode() + (b"" if frac is None else b"." + frac.encode())
    if exp is not None:
        text += exp[0] + exp[1] + exp[2].encode()
    want = _exact_subset(text)
    got = _scan_number_at(text, key)
    if want is None:
        assert got is None, text
    else:
        assert got == want == float(orjson.loads(text)), text
        assert math.copysign(1.0, got) == math.copysign(1.0, want), text


@pytest.mark.parametrize("text", [
    b"123456789012345678", b"1234567890123456789", b"12345678901234567.8", b"1234567890123456.78",
    b"0.000000000000000000001234567890123456", b"0.00000000000000000000001", b"-0", b"-0.0", b"0.5e1", b"5.",
    b"9007199254740993.0", b"9007199254740992.0", b"-1.25-", b"1.2.3", b"1e+", b"12e3", b"00.5", b"4.500000"])
def test_decimal_texts_pinned(text):
    """The fast reading's edges in both places of a detection: as the exact subset says (see above)."""
    for key in (b"u_min_px", b"v_max_px"):
        want, got = _exact_subset(text), _scan_number_at(text, key)
        assert (got is None) if want is None else (got == want and math.copysign(1.0, got) ==
                                                   math.copysign(1.0, want)), (text, got, want)


@pytest.mark.parametrize("indent", [b"", b"\n      "])
def test_every_byte_of_a_templated_detections_constant_text_is_compared(indent):
    """A later detection read by the first one's template (its keys, quotes, colons, commas, spacing compared
    by words: two per piece up to 16 bytes, a loop of words beyond -- ``indent``: pretty-printed pieces): any one
    byte of that text changed (to ``Q``: an unknown key or not JSON) is not read as the template -- the frame is
    declined, never read with the first detection's keys."""
    det = (b'{"object_id": %d, "class":"car","u_min_px":1.5, "v_min_px" :2,"u_max_px":30.25,"v_max_px":40,'
           b'"cov_uu_px2":4.0,"cov_uv_px2":0.5,"cov_vv_px2":9.0,"class_confidence":0.75}')
    det = det.replace(b',"', b"," + indent + b'"')
    head = b'{"camera_id":"c","frame":1,"timestamp_s":0,"detections":['
    second = det % 2
    assert scan_frame(head + det % 1 + b"," + second + b"," + det % 3 + b"]}") is not None
    values = {m.start() + k for m in re.finditer(rb"[0-9.]+|car", second) for k in range(m.end() - m.start())}
    for p in sorted(set(range(len(second))) - values):
        bad = second[:p] + b"Q" + second[p + 1:]
        assert scan_frame(head + det % 1 + b"," + bad + b"," + det % 3 + b"]}") is None, bad


@pytest.mark.parametrize("text", [b"1714564800.0333333", b"1764329048.1234567", b"1e23", b"1.5", b"-2", b"1e-400"])
def test_timestamp_of_full_precision(text):
    """The time stamp (17 digits from ``json.dumps(time.time())``) beyond the exact subset: Python's float of its
    text, orjson's double; not finite: declined."""
    frame = b'{"camera_id":"c","frame":1,"timestamp_s":%s,"detections":[]}' % text
    s = scan_frame(frame)
    assert s is not None and s.timestamp_s == orjson.loads(frame)["timestamp_s"]
    assert scan_frame(frame.replace(text, b"1e400")) is None
    assert scan_frame(frame.replace(text, b"01.5")) is None


def test_reads_the_common_layout():
    rng = np.random.default_rng(1)
    dets = _dets(rng, 40, cov=True, conf=True)
    del dets[7]["object_id"]
    text = _frame(dets).replace(b",", b" ,\n\t ").replace(b":", b" :  ")  # JSON whitespace anywhere
    s = scan_frame(text)
    f = orjson.loads(text)
    assert s is not None and (s.camera_id, s.frame, s.timestamp_s) == ("cam0", 3, f["timestamp_s"])
    cols = ("u_min_px", "v_min_px", "u_max_px", "v_max_px")
    np.testing.assert_array_equal(s.boxes, [[d[c] for c in cols] for d in f["detections"]])
    assert s.object_ids == [d.get("object_id", i) for i, d in enumerate(f["detections"])]
    assert s.classes == [d["class"] for d in f["detections"]]
    np.testing.assert_array_equal(s.class_confidence, [d.get("class_confidence", np.nan) for d in f["detections"]])
    np.testing.assert_array_equal(s.pixel_cov_px2, np.broadcast_to([[4.0, -0.5], [-0.5, 9.0]], (40, 2, 2)))


_GOOD = _frame(_dets(np.random.default_rng(2), 5, cov=True, conf=True))
_HOSTILE = {
    "escape in a class": _GOOD.replace(b'"car"', b'"c\\u0061r"', 1).replace(b'"truck"', b'"tr\\"uck"', 1),
    "string object_id": _GOOD.replace(b'"object_id": 1', b'"object_id": "1"'),
    "float object_id": _GOOD.replace(b'"object_id": 1', b'"object_id": 1.0'),
    "null class": _GOOD.replace(b'"class": "', b'"class": null, "x": "', 1),
    "unknown key": _GOOD.replace(b'"object_id": 1', b'"object_id": 1, "score": 0.5'),
    "duplicate key": _GOOD.replace(b'"object_id": 1', b'"object_id": 1, "object_id": 2'),
    "frame as float": _GOOD.replace(b'"frame":3', b'"frame":3.0'),
    "missing frame": _GOOD.replace(b'"frame":3,', b""),
    "trailing text": _GOOD + b" x",
    "truncated": _GOOD[:-3],
    "confidence out of range": re.sub(rb'"class_confidence": [0-9.]+', b'"class_confidence": 1.5', _GOOD, count=1),
    "missing box column": _GOOD.replace(b'"u_min_px": ', b'"uu_min_px": ', 1),
    "one detection without covariance": re.sub(rb', "cov_uu_px2": 4.0, "cov_uv_px2": -0.5, "cov_vv_px2": 9', b"",
                                               _GOOD, count=1),
    "detection not an object": _GOOD.replace(b'"detections":[', b'"detections":[7, '),
    "leading zero": _GOOD.replace(b'"cov_vv_px2": 9', b'"cov_vv_px2": 09', 1),
    "huge number": _GOOD.replace(b'"cov_vv_px2": 9', b'"cov_vv_px2": 1e400', 1),
    "bad utf-8": _GOOD.replace(b'"cam0"', b'"cam\xff"'),
    "control character": _GOOD.replace(b'"cam0"', b'"cam\x010"'),
    "a 3-D box frame": _frame([{"object_id": 1, "x_m": 1, "y_m": 20, "z_m": 0, "length_m": 4, "width_m": 2,
                                "height_m": 1.5, "yaw_rad": 0}]),
    "not an object": b"[1, 2]",
    "empty": b"",
}


@pytest.mark.parametrize("name", sorted(_HOSTILE))
def test_hostile_texts_take_the_general_path(camera, name):
    """Each text the reader declines (None); the service's record for it is the general path's (an error record
    or a record with that detection's error entry), whether given as bytes or as the parsed frame."""
    text = _HOSTILE[name]
    assert scan_frame(text) is None
    a, b = (Service(camera, "basler1", camera_id="cam0", record="full") for _ in range(2))
    out = a.process_frame_json(text)
    try:
        frame = orjson.loads(text)
    except orjson.JSONDecodeError:
        assert out.type == "error"
        return
    assert _record(out) == _record(b.process_frame_json(frame))


@pytest.mark.parametrize("record, tracks, cov, conf", [
    ("full", False, False, False), ("full", False, True, True), ("compact", False, True, False),
    ("compact", True, False, True), ("full", True, True, False)])
def test_frames_read_either_way_give_the_same_record(camera, record, tracks, cov, conf):
    """Bytes through the compiled reader == the parsed dict through parse_detections, frame after frame (message
    ids and tracks carried on), bad detections (boxes upside down, covariances out of range) included."""
    rng = np.random.default_rng(3)
    a, b = (Service(camera, "basler1", camera_id="cam0", record=record, tracks=tracks, linearity=True)
            for _ in range(2))
    for k in range(4):
        dets = _dets(rng, 30, cov=cov, conf=conf)
        dets[4]["u_min_px"], dets[4]["u_max_px"] = 900.0, 800.0  # upside down: its error entry
        if cov:
            dets[9]["cov_uu_px2"] = 1e13  # out of range: its error entry
        text = _frame(dets, frame=k, ts=round(T0 + k / 30, 6))
        assert scan_frame(text) is not None
        out_a = a.process_frame_json(text)
        out_b = b.process_frame_json(orjson.loads(text))
        assert out_a.type == "footprints" and out_a.n_detection_errors == (2 if cov else 1)
        assert _record(out_a) == _record(out_b)
        assert out_a.cpm_uper == out_b.cpm_uper


def test_frame_level_errors_as_the_general_path(camera):
    """Errors after the reading (camera not this service's, too many detections) are the same records."""
    dets = _dets(np.random.default_rng(4), 6)
    for kwargs, text in [({}, _frame(dets, camera="cam9")), ({"max_frame_detections": 5}, _frame(dets))]:
        a, b = (Service(camera, "basler1", camera_id="cam0", **kwargs) for _ in range(2))
        assert scan_frame(text) is not None
        out = a.process_frame_json(text, source="t")
        assert out.type == "error" and out.record == b.process_frame_json(orjson.loads(text), source="t").record


@settings(max_examples=80, deadline=None)
@given(st.integers(1, 12), st.integers(0, 2 ** 32 - 1), st.booleans(), st.booleans())
def test_scanned_flags_are_the_numpy_checks(n, seed, cov, one_class):
    """The reader's compiled flags: ``values_checked`` -- every box in order and every covariance entry within
    ``MAX_PIXEL_VAR_PX2`` (the value checks would mark nothing: ``boxes2d_detections`` then skips them) -- and the
    one-class shortcut of the classes, against numpy on the same columns: boxes flat, flipped or equal, covariances
    at, below and beyond the limit (negative ones too)."""
    from footprint_uq.products.detection_columns import MAX_PIXEL_VAR_PX2

    rng = np.random.default_rng(seed)
    dets = _dets(rng, n, cov=cov)
    for d in dets:
        if one_class:
            d["class"] = "car"
        pick = rng.integers(0, 6)
        if pick == 0:  # upside down
            d["v_min_px"], d["v_max_px"] = d["v_max_px"] + 1, d["v_min_px"]
        elif pick == 1:  # flat (in order)
            d["u_max_px"] = d["u_min_px"]
        elif pick == 2 and cov:
            d["cov_uv_px2"] = float(rng.choice([MAX_PIXEL_VAR_PX2, -MAX_PIXEL_VAR_PX2, 1.0000001e12, -2e12]))
    s = scan_frame(_frame(dets))
    assert s is not None
    X = s.boxes
    in_order = not ((X[:, 0] > X[:, 2]) | (X[:, 1] > X[:, 3])).any()
    in_range = s.pixel_cov_px2 is None or not (np.abs(s.pixel_cov_px2) > MAX_PIXEL_VAR_PX2).any()
    assert s.values_checked == (in_order and in_range)
    assert s.int_ids.tolist() == s.object_ids and s.int_ids.dtype == np.int64
    assert s.classes == [d["class"] for d in dets]  # (a wrong one-class flag: every class the first one's)


def _word(b: bytes) -> np.uint64:
    return np.uint64(int.from_bytes(b, "little"))


_WORD_BYTES = st.lists(st.sampled_from(list(b'0123456789.-+eE,}] "\\\x00\x1f\x7f\x80\xc3\xfa\xff:a/')), min_size=8,
                       max_size=8).map(bytes)


@settings(max_examples=400, deadline=None)
@given(st.one_of(_WORD_BYTES, st.binary(min_size=8, max_size=8)))
def test_word_helpers_are_the_bytewise_readings(b):
    """The reader's word helpers (service/bytewords.py) against the same questions asked byte by byte: the
    leading digits and their value for every count, the first quote / backslash / control character, the first
    byte of a pattern (bytes >= 0xFA, whose carry crosses into the next byte, included)."""
    from footprint_uq.service.bytewords import digits_value, first_of, leading_digits, string_stop

    w = _word(b)
    k = next((i for i, c in enumerate(b) if not 48 <= c <= 57), 8)
    assert leading_digits(w) == k
    for count in range(1, k + 1):
        assert digits_value(w, count) == int(b[:count])
    assert string_stop(w) == next((i for i, c in enumerate(b) if c in b'"\\' or c < 32), 8)
    for c in (44, 125, 32, 34, b[3]):
        at = b.find(bytes([c]))
        assert first_of(w, np.uint64(c * 0x0101010101010101)) == (at if at >= 0 else 8)


_BOX_KEYS = [b"u_min_px", b"v_min_px", b"u_max_px", b"v_max_px"]


@settings(max_examples=500, deadline=None)
@given(st.sampled_from([b"", b"-"]), st.text("0123456789", min_size=1, max_size=9), st.none() | st.text(
    "0123456789", max_size=8), st.sampled_from(_BOX_KEYS + [b"object_id"]),
    st.sampled_from([b",", b" ,", b"\n,", b"}"]), st.integers(0, 20))
def test_numbers_in_the_template_read_by_words(sign, whole, frac, key, after, pad):
    """A later detection's number read a word at a time: its end found at the next constant text's first byte (a
    comma, a space, a newline, ``}``), near the text's end or not (``pad`` spaces before ``]``): the double of the
    exact subset or declined, as ``_exact_subset`` says and as the same detection read first (in full) gives; an
    ``object_id`` only as an integer."""
    text = sign + whole.encode() + (b"" if frac is None else b"." + frac.encode())
    keys = [b"object_id"] + _BOX_KEYS
    if after == b"}":  # (the key last: its value ends the detection)
        keys.remove(key)
        keys.append(key)
    gap = b"" if after == b"}" else after[:-1]

    def det(v):
        return b"{" + b",".join(b'"%s":%s' % (k, v + gap if k == key else b"7") for k in keys) + b"}"

    head = b'{"camera_id":"c","frame":1,"timestamp_s":0,"detections":['
    s = scan_frame(head + det(b"7") + b"," + det(text) + b" " * pad + b"]}")
    want = _exact_subset(text)
    if key == b"object_id" and want is not None and not re.fullmatch(rb"-?[0-9]+", text):
        want = None
    if want is None:
        assert s is None, text
        return
    assert s is not None, text
    got = s.int_ids[1] if key == b"object_id" else s.boxes[1, _BOX_KEYS.index(key)]
    assert np.float64(got).tobytes() == np.float64(want).tobytes(), (text, got, want)
    alone = scan_frame(head + det(text) + b"]}")  # (read in full: the first detection's reading)
    assert alone is not None and alone.boxes.tobytes() == s.boxes[1:].tobytes() and alone.object_ids == s.object_ids[1:]


_CLASS_TEXTS = ["car", "cars", "ca", "", "truck", "bus", "pedestrian", "Fahrrad-ü", "carX", "Xcar", "12345678",
                "123456789", "12345679"]


@settings(max_examples=150, deadline=None)
@given(st.lists(st.sampled_from(_CLASS_TEXTS + [None]), min_size=1, max_size=30), st.integers(0, 2 ** 32 - 1))
def test_class_texts_in_runs_and_mixed(names, seed):
    """The classes as orjson reads them, in runs of one text (compared with the previous detection's, as one
    word) and mixed: texts that share a prefix, differ in their last byte, are empty, longer than a word, UTF-8,
    and detections without a class (None); the one-class shortcut only where every text is the first one's.  The
    columns the lean frame takes instead of the list -- the distinct classes in order of first appearance and each
    detection's entry among them (None: one class) -- are the service's ``_class_index`` of that list."""
    from footprint_uq.service.core import _class_index

    dets = _dets(np.random.default_rng(seed), len(names))
    for d, name in zip(dets, names, strict=True):
        if name is None:
            del d["class"]
        else:
            d["class"] = name
    text = _frame(dets)
    s = scan_frame(text)
    assert s is not None
    want = [d.get("class") for d in orjson.loads(text)["detections"]]
    assert s.classes == want
    index, distinct = _class_index(want)
    assert s.distinct_classes == distinct
    if s.class_index is None:
        assert index is None and len(distinct) == 1
    else:
        assert s.class_index.dtype == np.int64 and s.class_index.tolist() == index.tolist() and len(distinct) > 1


def test_the_smallest_detections_fit_the_rows():
    """The rows are sized from the text's length (a detection the columns take is >= 53 bytes): a frame of the
    smallest such detections is read; more detections than that bound in the same text have a shorter one, which
    the general path names (declined: None)."""
    det = b'{"u_min_px":0,"v_min_px":0,"u_max_px":0,"v_max_px":0}'
    assert len(det) == 53
    head = b'{"camera_id":"c","frame":1,"timestamp_s":0,"detections":['
    for n in (1, 2, 300):
        s = scan_frame(head + b",".join([det] * n) + b"]}")
        assert s is not None and s.boxes.shape == (n, 4) and s.object_ids == list(range(n))
    assert scan_frame(head + b",".join([det] * 299 + [b'{"u_min_px":0}'] * 50) + b"]}") is None


def test_each_frame_gets_its_own_columns():
    """The columns are new arrays per frame (views of the pass's two blocks): reading the next frame leaves the
    last frame's values as they were; their types as the service takes them."""
    rng = np.random.default_rng(5)
    a_text, b_text = _frame(_dets(rng, 20, cov=True, conf=True)), _frame(_dets(rng, 30, cov=True, conf=True))
    a = scan_frame(a_text)
    kept = [a.boxes.copy(), a.pixel_cov_px2.copy(), a.class_confidence.copy(), a.int_ids.copy()]
    b = scan_frame(b_text)
    for got, want in zip([a.boxes, a.pixel_cov_px2, a.class_confidence, a.int_ids], kept, strict=True):
        assert got.tobytes() == want.tobytes()
    assert not np.shares_memory(a.boxes, b.boxes) and not np.shares_memory(a.int_ids, b.int_ids)
    assert (type(b.frame), type(b.timestamp_s), type(b.values_checked)) == (int, float, bool)
    for arr, shape, dtype in [(b.boxes, (30, 4), np.float64), (b.pixel_cov_px2, (30, 2, 2), np.float64),
                              (b.class_confidence, (30,), np.float64), (b.int_ids, (30,), np.int64)]:
        assert arr.shape == shape and arr.dtype == dtype and arr.flags.c_contiguous
