"""A detector frame's JSON text read straight into columns by one compiled pass, for the common layout.

:func:`scan_frame` reads the bytes of one frame as the detectors (and ``bench/bench_service.py``) write it::

    {"camera_id":"cam1","frame":42,"timestamp_s":1714564800.033,
     "detections":[{"object_id":7,"class":"car","class_confidence":0.9,
                    "u_min_px":900,"v_min_px":600,"u_max_px":1000,"v_max_px":700,
                    "cov_uu_px2":4.0,"cov_uv_px2":0.0,"cov_vv_px2":9.0}, ...]}

(keys in any order, JSON whitespace anywhere) into the frame's fields and the detections' columns, without
building a dict per detection.  It accepts only a strict subset of JSON and says "not mine" (``None``) for
everything else, which then takes the general path (``orjson`` -> dicts -> :func:`.detections.parse_detections`)
with its error entries and messages unchanged:

* the frame's keys are ``camera_id`` (a string), ``frame`` (an integer), ``timestamp_s`` (a number) and
  ``detections`` (a list of objects); the detections' keys are ``object_id`` (an integer), ``class`` (a string),
  ``class_confidence`` and the 2-D box's four columns (numbers), and the three pixel-covariance columns
  (numbers; all three in every detection or in none); no other key, no key twice, no ``null``, no
  ``true`` / ``false``;
* strings hold no escape and no control character (anything else, UTF-8 included, is copied as it is and
  decoded by Python);
* numbers follow JSON's grammar, integers of at most 18 digits, and every float is read exactly: a decimal
  mantissa below 2^53 scaled by a power of ten up to 10^22 (Clinger's exact case: one correctly rounded
  operation, the double ``orjson`` reads); any other number (more digits, a larger exponent) -> ``None``.

So a frame this pass reads gives the same values as the general path, bit for bit
(``tests/test_service_scan.py`` compares the two on random and hostile texts).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

__all__ = ["ScannedFrame", "scan_frame"]

# the keys (as bytes) this pass knows; detections' keys are numbered for their bit in the seen mask
_FRAME_KEYS = (b"camera_id", b"frame", b"timestamp_s", b"detections")
_DET_KEYS = (b"u_min_px", b"v_min_px", b"u_max_px", b"v_max_px", b"cov_uu_px2", b"cov_uv_px2", b"cov_vv_px2",
             b"class_confidence", b"object_id", b"class")
#: f64 columns of a detection (4 box, 3 covariance, class confidence): the first 8 keys of _DET_KEYS
N_VALUES = 8
_K_OBJECT_ID, _K_CLASS = 8, 9
_ALL_BOX = 0b1111
_ALL_COV = 0b1110000


def _key_table(keys) -> tuple[np.ndarray, np.ndarray]:
    """The keys as one byte array and their start offsets ``(len + 1,)``."""
    starts = np.zeros(len(keys) + 1, np.int64)
    starts[1:] = np.cumsum([len(k) for k in keys])
    return np.frombuffer(b"".join(keys), np.uint8).copy(), starts


_FK, _FK_AT = _key_table(_FRAME_KEYS)
_DK, _DK_AT = _key_table(_DET_KEYS)
_POW10 = np.array([10.0 ** k for k in range(23)])


@njit(cache=True, nogil=True, inline="always")
def _ws(buf, i):  # pragma: no cover - compiled
    """The index of the first byte at or after ``i`` that is not JSON whitespace (``len(buf)`` at the end)."""
    n = buf.shape[0]
    while i < n and (buf[i] == 32 or buf[i] == 10 or buf[i] == 13 or buf[i] == 9):
        i += 1
    return i


@njit(cache=True, nogil=True, inline="always")
def _string(buf, i):  # pragma: no cover - compiled
    """``buf[i]`` should open a plain string (no escape, no control character): the index of its closing quote,
    or -1."""
    n = buf.shape[0]
    if i >= n or buf[i] != 34:
        return -1
    i += 1
    while i < n:
        c = buf[i]
        if c == 34:
            return i
        if c == 92 or c < 32:
            return -1
        i += 1
    return -1


@njit(cache=True, nogil=True, inline="always")
def _key_index(buf, s, e, table, at):  # pragma: no cover - compiled
    """Which key of ``table`` the bytes ``buf[s:e]`` are (-1: none)."""
    for k in range(at.shape[0] - 1):
        a, b = at[k], at[k + 1]
        if b - a != e - s:
            continue
        same = True
        for j in range(b - a):
            if buf[s + j] != table[a + j]:
                same = False
                break
        if same:
            return k
    return -1


@njit(cache=True, nogil=True)
def _number(buf, i, pow10):  # pragma: no cover - compiled
    """A JSON number at ``buf[i]``: ``(end, is_integer, integer value, float value, ok)``; ``ok`` False for text that
    is not a JSON number or a number outside the exact subset (see the module doc)."""
    n = buf.shape[0]
    neg = False
    if i < n and buf[i] == 45:
        neg = True
        i += 1
    if i >= n or buf[i] < 48 or buf[i] > 57:
        return i, False, 0, 0.0, False
    m = 0
    digits = 0
    if buf[i] == 48:  # a leading zero stands alone
        i += 1
        if i < n and 48 <= buf[i] <= 57:
            return i, False, 0, 0.0, False
    else:
        while i < n and 48 <= buf[i] <= 57:
            m = m * 10 + (np.int64(buf[i]) - 48)
            digits += 1
            i += 1
            if digits > 18:
                return i, False, 0, 0.0, False
    integer = True
    e10 = 0
    if i < n and buf[i] == 46:  # fraction
        integer = False
        i += 1
        if i >= n or buf[i] < 48 or buf[i] > 57:
            return i, False, 0, 0.0, False
        while i < n and 48 <= buf[i] <= 57:
            if m == 0 and buf[i] == 48:  # leading zeros of the fraction: only the exponent moves
                e10 -= 1
            else:
                m = m * 10 + (np.int64(buf[i]) - 48)
                digits += 1
                e10 -= 1
                if digits > 18:
                    return i, False, 0, 0.0, False
            i += 1
    if i < n and (buf[i] == 101 or buf[i] == 69):  # exponent
        integer = False
        i += 1
        eneg = False
        if i < n and (buf[i] == 43 or buf[i] == 45):
            eneg = buf[i] == 45
            i += 1
        if i >= n or buf[i] < 48 or buf[i] > 57:
            return i, False, 0, 0.0, False
        ex = 0
        while i < n and 48 <= buf[i] <= 57:
            ex = ex * 10 + (np.int64(buf[i]) - 48)
            i += 1
            if ex > 1000:
                return i, False, 0, 0.0, False
        e10 += -ex if eneg else ex
    if integer:
        return i, True, -m if neg else m, 0.0, True
    if m > 9007199254740992 or e10 > 22 or e10 < -22:  # beyond Clinger's exact case
        return i, False, 0, 0.0, False
    v = float(m)
    v = v * pow10[e10] if e10 >= 0 else v / pow10[-e10]
    return i, False, 0, -v if neg else v, True


@njit(cache=True, nogil=True)
def _detection(buf, i, r, fv, iv, pow10, dk, dk_at):  # pragma: no cover - compiled
    """The detection object opening at ``buf[i]`` into row ``r`` of ``fv (cap, 8)`` and ``iv (cap, 4)`` (object id,
    class start, class end, seen-keys mask): the index after its ``}``, or -1 (not in the subset)."""
    if buf[i] != 123:
        return -1
    i = _ws(buf, i + 1)
    seen = 0
    iv[r, 1], iv[r, 2] = -1, -1
    fv[r, 7] = np.nan
    if i < buf.shape[0] and buf[i] == 125:
        return -1  # an empty detection: the general path names it
    while True:
        e = _string(buf, i)
        if e < 0:
            return -1
        k = _key_index(buf, i + 1, e, dk, dk_at)
        if k < 0 or (seen >> k) & 1:
            return -1
        seen |= 1 << k
        i = _ws(buf, e + 1)
        if i >= buf.shape[0] or buf[i] != 58:
            return -1
        i = _ws(buf, i + 1)
        if k == _K_CLASS:
            e = _string(buf, i)
            if e < 0:
                return -1
            iv[r, 1], iv[r, 2] = i + 1, e
            i = e + 1
        else:
            i, is_int, ival, fval, ok = _number(buf, i, pow10)
            if not ok:
                return -1
            if k == _K_OBJECT_ID:
                if not is_int:
                    return -1
                iv[r, 0] = ival
            else:
                fv[r, k] = float(ival) if is_int else fval
        i = _ws(buf, i)
        if i >= buf.shape[0]:
            return -1
        if buf[i] == 125:
            iv[r, 3] = seen
            return i + 1
        if buf[i] != 44:
            return -1
        i = _ws(buf, i + 1)


@njit(cache=True, nogil=True)
def _detections(buf, i, fv, iv, pow10, dk, dk_at):  # pragma: no cover - compiled
    """The detections list opening at ``buf[i]``: ``(index after its ]``, count)``; index -1: not in the subset."""
    if buf[i] != 91:
        return -1, 0
    i = _ws(buf, i + 1)
    r = 0
    if i < buf.shape[0] and buf[i] == 93:
        return i + 1, 0
    while True:
        if r >= fv.shape[0]:
            return -1, 0
        i = _detection(buf, i, r, fv, iv, pow10, dk, dk_at)
        if i < 0:
            return -1, 0
        r += 1
        i = _ws(buf, i)
        if i >= buf.shape[0]:
            return -1, 0
        if buf[i] == 93:
            return i + 1, r
        if buf[i] != 44:
            return -1, 0
        i = _ws(buf, i + 1)


@njit(cache=True, nogil=True)
def _scan(buf, pow10, fk, fk_at, dk, dk_at):  # pragma: no cover - compiled
    """The frame in ``buf``: ``(ok, head (6,) int64, timestamp_s, fv (n, 8), iv (n, 4), class_first (n,))``; head:
    count, camera_id start and end (-1: absent), frame number, keys seen (bits of _FRAME_KEYS); ``class_first``:
    per detection the first detection with the same class text (-1: no class)."""
    cap = 0
    for c in buf:
        cap += c == 123
    fv = np.empty((cap, N_VALUES))
    iv = np.zeros((cap, 4), np.int64)
    head = np.zeros(6, np.int64)
    head[1], head[2] = -1, -1
    ts = 0.0
    bad = (False, head, ts, fv[:0], iv[:0], np.zeros(0, np.int64))
    i = _ws(buf, 0)
    if i >= buf.shape[0] or buf[i] != 123:
        return bad
    i = _ws(buf, i + 1)
    seen = 0
    n = 0
    while True:
        e = _string(buf, i)
        if e < 0:
            return bad
        k = _key_index(buf, i + 1, e, fk, fk_at)
        if k < 0 or (seen >> k) & 1:
            return bad
        seen |= 1 << k
        i = _ws(buf, e + 1)
        if i >= buf.shape[0] or buf[i] != 58:
            return bad
        i = _ws(buf, i + 1)
        if i >= buf.shape[0]:
            return bad
        if k == 0:  # camera_id
            e = _string(buf, i)
            if e < 0:
                return bad
            head[1], head[2] = i + 1, e
            i = e + 1
        elif k == 3:  # detections
            i, n = _detections(buf, i, fv, iv, pow10, dk, dk_at)
            if i < 0:
                return bad
        else:
            i, is_int, ival, fval, ok = _number(buf, i, pow10)
            if not ok or (k == 1 and not is_int):
                return bad
            if k == 1:
                head[3] = ival
            else:
                ts = float(ival) if is_int else fval
        i = _ws(buf, i)
        if i >= buf.shape[0]:
            return bad
        if buf[i] == 125:
            break
        if buf[i] != 44:
            return bad
        i = _ws(buf, i + 1)
    if _ws(buf, i + 1) != buf.shape[0]:
        return bad
    head[0], head[4] = n, seen
    return True, head, ts, fv[:n], iv[:n], _class_first(buf, iv[:n])


@njit(cache=True, nogil=True)
def _class_first(buf, iv):  # pragma: no cover - compiled
    """Per detection, the first detection whose class text is the same bytes (-1: no class)."""
    n = iv.shape[0]
    first = np.full(n, -1, np.int64)
    uniq = np.empty(n, np.int64)
    u = 0
    for r in range(n):
        s, e = iv[r, 1], iv[r, 2]
        if s < 0:
            continue
        for q in range(u):
            j = uniq[q]
            s2, e2 = iv[j, 1], iv[j, 2]
            if e2 - s2 != e - s:
                continue
            same = True
            for t in range(e - s):
                if buf[s + t] != buf[s2 + t]:
                    same = False
                    break
            if same:
                first[r] = j
                break
        if first[r] < 0:
            first[r] = r
            uniq[u] = r
            u += 1
    return first


class ScannedFrame(NamedTuple):
    """A frame read by :func:`scan_frame` (every frame field present); the detections' columns hold ``n`` rows."""

    camera_id: str
    frame: int
    timestamp_s: float
    boxes: np.ndarray           # (n, 4) u_min, v_min, u_max, v_max (px)
    pixel_cov_px2: np.ndarray | None  # (n, 2, 2); None: no detection has one
    object_ids: list            # n ints (absent: the detection's index)
    classes: list               # n str or None
    class_confidence: np.ndarray | None  # (n,), NaN where absent; None: no detection has one


def scan_frame(text) -> ScannedFrame | None:
    """One frame's JSON text (bytes-like) read into columns, or None when it is not in the subset this pass reads
    (see the module doc): then parse it in full (orjson) and read its detections with
    :func:`.detections.parse_detections`."""
    buf = np.frombuffer(text, np.uint8)
    if buf.size == 0:
        return None
    ok, head, ts, fv, iv, first = _scan(buf, _POW10, _FK, _FK_AT, _DK, _DK_AT)
    if not ok:
        return None
    n, seen = int(head[0]), int(head[4])
    if seen != 0b1111:
        return None  # a frame field missing: the general path's frame error
    masks = iv[:, 3]
    if n and not ((masks & _ALL_BOX) == _ALL_BOX).all():
        return None  # a detection without a complete 2-D box: the general path names it
    cov = masks & _ALL_COV
    has_cov = cov == _ALL_COV
    if has_cov.any() and not has_cov.all() or ((cov != 0) & ~has_cov).any():
        return None  # some detections without a covariance, or one incomplete: the general path
    raw = bytes(buf)  # (the text's own bytes: decoded only where a string is)
    try:
        camera = raw[head[1]:head[2]].decode("utf-8") if head[1] >= 0 else None
        classes = _classes(raw, iv, first)
    except UnicodeDecodeError:
        return None
    ids = np.where((masks >> _K_OBJECT_ID) & 1 == 1, iv[:, 0], np.arange(n)).tolist()
    P = fv[:, [4, 5, 5, 6]].reshape(n, 2, 2) if n and has_cov.all() else None
    conf = fv[:, 7] if ((masks >> 7) & 1).any() else None
    if conf is not None and ((conf < 0.0) | (conf > 1.0)).any():
        return None  # (NaN where absent compares False) a confidence out of range: the general path names it
    return ScannedFrame(camera, int(head[3]), ts, np.ascontiguousarray(fv[:, :4]), P, ids, classes, conf)


def _classes(raw: bytes, iv: np.ndarray, first: np.ndarray) -> list:
    """The detections' class strings: each distinct text decoded once."""
    n = len(first)
    if n == 0:
        return []
    rows = np.flatnonzero(first == np.arange(n))
    if rows.size == 0:
        return [None] * n
    names = np.empty(n + 1, dtype=object)  # (the last entry: None, for -1)
    for r in rows.tolist():
        names[r] = raw[iv[r, 1]:iv[r, 2]].decode("utf-8")
    return names[first].tolist()
