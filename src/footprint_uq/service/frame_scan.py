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
  operation, the double ``orjson`` reads); any other number (more digits, a larger exponent) -> ``None``,
  except ``timestamp_s``, whose text (``json.dumps(time.time())`` writes 17 digits) Python's correctly rounded
  ``float`` reads.  Detections' values of full precision (16-17 digits) take the general path.

So a frame this pass reads gives the same values as the general path, bit for bit
(``tests/test_service_scan.py`` compares the two on random and hostile texts).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ..products.detection_columns import MAX_PIXEL_VAR_PX2
from .bytewords import digits_value, first_of, leading_digits, load8, string_stop

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
def _string_end(buf, i):  # pragma: no cover - compiled
    """From ``buf[i]`` inside a plain string (no escape, no control character): the index of its closing quote,
    or -1."""
    n = buf.shape[0]
    while i < n:
        c = buf[i]
        if c == 34:
            return i
        if c == 92 or c < 32:
            return -1
        i += 1
    return -1


@njit(cache=True, nogil=True, inline="always")
def _string(buf, i):  # pragma: no cover - compiled
    """``buf[i]`` should open a plain string: the index of its closing quote, or -1."""
    if i >= buf.shape[0] or buf[i] != 34:
        return -1
    return _string_end(buf, i + 1)


@njit(cache=True, nogil=True, inline="always")
def _same(buf, i, s, n):  # pragma: no cover - compiled
    """``buf[i:i + n] == buf[s:s + n]`` (no early exit: a loop LLVM vectorises)."""
    if i + n > buf.shape[0]:
        return False
    d = 0
    for j in range(n):
        d |= buf[i + j] ^ buf[s + j]
    return d == 0


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
def _number_end(buf, i):  # pragma: no cover - compiled
    """The end of the JSON number at ``buf[i]`` (its grammar only, any length), or -1."""
    n = buf.shape[0]
    if i < n and buf[i] == 45:
        i += 1
    s = i
    while i < n and 48 <= buf[i] <= 57:
        i += 1
    if i == s or (i - s > 1 and buf[s] == 48):
        return -1
    if i < n and buf[i] == 46:
        i += 1
        s = i
        while i < n and 48 <= buf[i] <= 57:
            i += 1
        if i == s:
            return -1
    if i < n and (buf[i] == 101 or buf[i] == 69):
        i += 1
        if i < n and (buf[i] == 43 or buf[i] == 45):
            i += 1
        s = i
        while i < n and 48 <= buf[i] <= 57:
            i += 1
        if i == s:
            return -1
    return i


@njit(cache=True, nogil=True)
def _value(buf, i, r, k, fv, iv, pow10):  # pragma: no cover - compiled
    """The value of key ``k`` at ``buf[i]`` (a class: just after its opening quote) into row ``r``: the index just
    after it (a class: its closing quote), or -1."""
    if k == _K_CLASS:
        e = _string_end(buf, i)
        if e >= 0:
            iv[r, 1], iv[r, 2] = i, e
        return e
    i, is_int, ival, fval, ok = _number(buf, i, pow10)
    if not ok or (k == _K_OBJECT_ID and not is_int):
        return -1
    if k == _K_OBJECT_ID:
        iv[r, 0] = ival
    else:
        fv[r, k] = float(ival) if is_int else fval
    return i


@njit(cache=True, nogil=True)
def _detection(buf, i, r, fv, iv, pow10, dk, dk_at, tpl):  # pragma: no cover - compiled
    """The detection object opening at ``buf[i]`` into row ``r`` of ``fv (cap, 8)`` and ``iv (cap, 4)`` (object id,
    class start, class end, seen-keys mask): the index after its ``}``, or -1 (not in the subset).  Its text as a
    template into ``tpl``: per value the constant text before it (start, end in ``buf``) and its key, then
    the text after the last value (start, end, -1); ``tpl[10, 2]``: the number of values (``tpl (11, 4)``: its
    last column is :func:`_template_words`')."""
    if buf[i] != 123:
        return -1
    lit = i
    i = _ws(buf, i + 1)
    seen = 0
    iv[r, 1], iv[r, 2] = -1, -1
    fv[r, 7] = np.nan
    j = 0
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
            if i >= buf.shape[0] or buf[i] != 34:
                return -1
            i += 1  # (the opening quote belongs to the constant text)
        tpl[j, 0], tpl[j, 1], tpl[j, 2] = lit, i, k
        j += 1
        i = _value(buf, i, r, k, fv, iv, pow10)
        if i < 0:
            return -1
        lit = i
        if k == _K_CLASS:
            i += 1
        i = _ws(buf, i)
        if i >= buf.shape[0]:
            return -1
        if buf[i] == 125:
            iv[r, 3] = seen
            tpl[j, 0], tpl[j, 1], tpl[j, 2] = lit, i + 1, -1
            tpl[10, 2] = j
            return i + 1
        if buf[i] != 44:
            return -1
        i = _ws(buf, i + 1)


@njit(cache=True, nogil=True)
def _number_chars_end(buf, i):  # pragma: no cover - compiled
    """The end of the run of bytes from ``buf[i]`` that a number's text can hold (digits, signs, point,
    exponent): the span :func:`_read_numbers` reads or declines."""
    n = buf.shape[0]
    while i < n and (48 <= buf[i] <= 57 or buf[i] == 45 or buf[i] == 43 or buf[i] == 46 or buf[i] == 101
                     or buf[i] == 69):
        i += 1
    return i


@njit(cache=True, nogil=True)
def _template_words(buf, tpl, tw):  # pragma: no cover - compiled
    """The words the constant pieces of the template ``tpl`` (its ``tpl[10, 2] + 1`` pieces) are compared by, into
    ``tw (11, 5)`` uint64: per piece its first 8 bytes, the 8 bytes from ``tpl[j, 3]`` (its last 8; a piece under
    8 bytes: 0, its first again), the masks of the piece's bytes in each, and its first byte in all 8 places (the
    byte that ends the value before it).  ``tpl[j, 3]`` -1: a piece over 16 bytes or near the end, compared 8
    bytes at a time by a loop."""
    n = buf.shape[0]
    for j in range(tpl[10, 2] + 1):
        s, L = tpl[j, 0], tpl[j, 1] - tpl[j, 0]
        tw[j, 4] = np.uint64(buf[s]) * np.uint64(0x0101010101010101)
        if L > 16 or s + 16 > n:
            tpl[j, 3] = -1
            continue
        off = max(L - 8, 0)
        mask = np.uint64(0xFFFFFFFFFFFFFFFF) if L >= 8 else (np.uint64(1) << np.uint64(8 * L)) - np.uint64(1)
        tw[j, 0], tw[j, 1], tw[j, 2], tw[j, 3] = load8(buf, s), load8(buf, s + off), mask, mask
        tpl[j, 3] = off


@njit(cache=True, nogil=True)
def _number_slow(buf, i, r, k, fv, iv, spans, ns, pow10):  # pragma: no cover - compiled
    """A number at ``buf[i]`` that :func:`_templated_run`'s word reading did not take, read byte by byte into row
    ``r``: ``(end, ns)``.  At most 18 digits, no exponent, and the next byte not one a number can hold: an
    integer, or ``m / 10^f`` with ``m <= 2^53`` and ``f <= 22`` fraction digits (Clinger's exact case, one
    correctly rounded division by an exact power of ten); any other (an exponent, more digits, not JSON) goes
    by its span to :func:`_read_numbers` (``spans[ns]``: start, end, row, key), which reads it or declines."""
    n = buf.shape[0]
    e = i
    neg = e < n and buf[e] == 45
    e += 1 if neg else 0
    st = e
    m = 0
    while e < n and 48 <= buf[e] <= 57 and e - st < 18:  # (18 digits: m < 10^18, no int64 wrap)
        m = m * 10 + (np.int64(buf[e]) - 48)
        e += 1
    n_int, n_frac = e - st, -1  # (n_frac -1: no point)
    if e < n and buf[e] == 46:
        e += 1
        fs = e
        while e < n and 48 <= buf[e] <= 57 and e - fs + n_int < 18:
            m = m * 10 + (np.int64(buf[e]) - 48)
            e += 1
        n_frac = e - fs
    c = buf[e] if e < n else np.uint8(32)
    fast = (1 <= n_int and (n_int == 1 or buf[st] != 48) and n_frac != 0 and n_int + max(n_frac, 0) <= 18
            and not (48 <= c <= 57 or c == 46 or c == 101 or c == 69 or c == 43 or c == 45))
    if fast and n_frac < 0:  # an integer
        if k == _K_OBJECT_ID:
            iv[r, 0] = -m if neg else m
        else:
            fv[r, k] = float(-m if neg else m)
    elif fast and k != _K_OBJECT_ID and m <= 9007199254740992 and n_frac <= 22:
        v = float(m) / pow10[n_frac]
        fv[r, k] = -v if neg else v
    else:  # the number's extent (its grammar and value: _read_numbers)
        e = _number_chars_end(buf, i)
        spans[ns, 0], spans[ns, 1], spans[ns, 2], spans[ns, 3] = i, e, r, k
        ns += 1
    return e, ns


@njit(cache=True, nogil=True)
def _templated_run(buf, i, r, fv, iv, tpl, seen, spans, ns, pow10):  # pragma: no cover - compiled
    """Detections from ``buf[i]`` (row ``r`` on) read as the first one's template ``tpl`` (the same constant text
    byte for byte: the same keys in the same order, the same spacing), as long as they follow it: ``(i, r, ns,
    stopped)`` -- the index after the last one read (and its separator), the next row, the spans of the numbers
    left to :func:`_read_numbers` (``spans (ns, 4)``: start, end, row, key) and whether a detection did not
    follow the template (it opens at ``i``: read it in full).  One loop; its helpers take words, not the text (a
    compiled call per value, or per inlined helper taking the text, costs ~10 ns in reference counting).

    The constant text is compared by two words (:func:`_template_words`).  A value ends at the first byte of the
    next constant piece (a comma, ``}``, a space; a class: its closing quote), found in one word; a number of at
    most 7 bytes there (sign apart) is then checked and read from that word alone: digits, or digits, a point and
    digits (its value ``m / 10^f``, one correctly rounded division by an exact power of ten, the double
    :func:`_number_slow` and :func:`_read_numbers` give), which keeps the next value's position off the digits'
    arithmetic.  Any other number goes to :func:`_number_slow`."""
    n = buf.shape[0]
    nv = tpl[10, 2]
    tw = np.empty((11, 5), np.uint64)
    _template_words(buf, tpl, tw)
    while r < iv.shape[0]:
        start, ns0 = i, ns
        iv[r, 1], iv[r, 2] = -1, -1
        good = True
        for j in range(nv + 1):
            s, L, off = tpl[j, 0], tpl[j, 1] - tpl[j, 0], tpl[j, 3]
            if off >= 0 and i + 16 <= n:
                d = ((load8(buf, i) ^ tw[j, 0]) & tw[j, 2]) | ((load8(buf, i + off) ^ tw[j, 1]) & tw[j, 3])
            elif i + L <= n:  # (a long piece, or near the end: 8 bytes at a time, the tail's last 8 overlapping)
                d, q = np.uint64(0), 0
                while q + 8 <= L:
                    d |= load8(buf, i + q) ^ load8(buf, s + q)
                    q += 8
                d |= load8(buf, i + L - 8) ^ load8(buf, s + L - 8) if L >= 8 else np.uint64(0)
                for t in range(L if L < 8 else 0):
                    d |= np.uint64(buf[i + t] ^ buf[s + t])
            else:
                d = np.uint64(1)  # (the text ends before the piece)
            if d != 0:
                good = False
                break
            i += L
            if j == nv:
                break
            k, end = tpl[j, 2], tw[j + 1, 4]
            if k == _K_CLASS:  # a plain string up to its closing quote (the next piece's first byte)
                e = i
                while e + 8 <= n:
                    w = load8(buf, e)
                    z = first_of(w, end)
                    if string_stop(w) != z:  # (an escape or a control character before the quote)
                        break
                    e += z
                    if z < 8:
                        break
                while e < n and buf[e] != 34 and buf[e] != 92 and buf[e] >= 32:
                    e += 1
                if e >= n or buf[e] != 34:
                    good = False
                    break
                iv[r, 1], iv[r, 2] = i, e
                i = e
                continue
            if i + 8 <= n:
                w = load8(buf, i)
                e = i + first_of(w, end)  # (the number's end, its sign included: the next value's position)
                neg = (w & np.uint64(0xFF)) == np.uint64(45)
                w = w >> np.uint64(8) if neg else w
                p, k1 = e - i - (1 if neg else 0), leading_digits(w)  # (its length, sign apart; integer digits)
                if 1 <= k1 and e - i <= 7 and (k1 == 1 or (w & np.uint64(0xFF)) != np.uint64(48)):
                    if k1 == p:  # an integer
                        m = digits_value(w, k1)
                        if k == _K_OBJECT_ID:
                            iv[r, 0] = -m if neg else m
                        else:
                            fv[r, k] = float(-m if neg else m)
                        i = e
                        continue
                    low = (np.uint64(1) << np.uint64(8 * k1)) - np.uint64(1)
                    w2 = (w & low) | ((w >> np.uint64(8)) & ~low)  # (the point taken out: the mantissa's digits)
                    if (k != _K_OBJECT_ID and ((w >> np.uint64(8 * k1)) & np.uint64(0xFF)) == np.uint64(46)
                            and k1 + 1 < p and leading_digits(w2) == p - 1):
                        v = float(digits_value(w2, p - 1)) / pow10[p - 1 - k1]
                        fv[r, k] = -v if neg else v
                        i = e
                        continue
            i, ns = _number_slow(buf, i, r, k, fv, iv, spans, ns, pow10)
        if not good:
            return start, r, ns0, True
        iv[r, 3], r = seen, r + 1
        i = _ws(buf, i)
        if i >= n or buf[i] != 44:
            return i, r, ns, False
        i = _ws(buf, i + 1)
    return i, r, ns, True


@njit(cache=True, nogil=True)
def _read_numbers(buf, spans, fv, iv, pow10):  # pragma: no cover - compiled
    """The numbers at ``spans (ns, 4)`` (start, end, row, key) into their rows, each read as :func:`_number` does
    (JSON's grammar, the same exact subset, the same doubles) and filling its span: False at the first that is
    not."""
    for t in range(spans.shape[0]):
        i, end, r, k = spans[t, 0], spans[t, 1], spans[t, 2], spans[t, 3]
        neg = i < end and buf[i] == 45
        i += 1 if neg else 0
        st, m, nd, e10, ex, nexp, pt, ep, eneg = i, 0, 0, 0, 0, 0, -1, -1, False
        while i < end:
            c = buf[i]
            if 48 <= c <= 57:
                if ep >= 0:
                    ex = min(ex * 10 + np.int64(c) - 48, 100000)
                    nexp += 1
                else:
                    if m > 0 or c != 48:  # (leading zeros are no digits of the mantissa: as _number)
                        nd += 1
                        if nd > 18:  # declined before ``m`` could overflow (a 19th digit wraps int64)
                            return False
                    m = m * 10 + np.int64(c) - 48
                    e10 -= 1 if pt >= 0 else 0  # a fraction digit moves the point
            elif c == 46 and pt < 0 and ep < 0:
                pt = i
            elif (c == 101 or c == 69) and ep < 0:
                ep = i
                if i + 1 < end and (buf[i + 1] == 43 or buf[i + 1] == 45):
                    eneg = buf[i + 1] == 45
                    i += 1
            else:
                return False
            i += 1
        n_int = (pt if pt >= 0 else (ep if ep >= 0 else end)) - st
        if n_int < 1 or (n_int > 1 and buf[st] == 48) or nd > 18 or (ep >= 0 and not 1 <= nexp <= 4):
            return False
        if pt >= 0 and (ep if ep >= 0 else end) - pt < 2:  # a point needs a digit after it
            return False
        integer = pt < 0 and ep < 0
        e10 += -ex if eneg else ex
        if k == _K_OBJECT_ID:
            if not integer:
                return False
            iv[r, 0] = -m if neg else m
        elif integer:
            fv[r, k] = float(-m if neg else m)
        else:
            if m > 9007199254740992 or e10 > 22 or e10 < -22:
                return False
            v = float(m)
            v = v * pow10[e10] if e10 >= 0 else v / pow10[-e10]
            fv[r, k] = -v if neg else v
    return True


@njit(cache=True, nogil=True)
def _detections(buf, i, fv, iv, pow10, dk, dk_at):  # pragma: no cover - compiled
    """The detections list opening at ``buf[i]``: ``(index after its ]``, count)``; index -1: not in the subset.
    The first detection is read in full and sets the template of the others (:func:`_templated_run`); one that
    does not follow it is read in full."""
    if buf[i] != 91:
        return -1, 0
    i = _ws(buf, i + 1)
    if i < buf.shape[0] and buf[i] == 93:
        return i + 1, 0
    tpl = np.zeros((11, 4), np.int64)
    scratch = np.zeros((11, 4), np.int64)
    # (every number left to _read_numbers follows its key: >= 12 bytes each, '"u_min_px":0')
    spans = np.empty((buf.shape[0] // 12 + 1, 4), np.int64)
    fv[:, 7] = np.nan  # (class_confidence: NaN where absent)
    r = ns = 0
    while True:
        if r >= fv.shape[0]:
            return -1, 0
        i = _detection(buf, i, r, fv, iv, pow10, dk, dk_at, tpl if r == 0 else scratch)
        if i < 0:
            return -1, 0
        r += 1
        i = _ws(buf, i)
        if i < buf.shape[0] and buf[i] == 44:
            i, r, ns, stopped = _templated_run(buf, _ws(buf, i + 1), r, fv, iv, tpl, iv[0, 3], spans, ns,
                                                 pow10)
            if stopped:
                continue  # (a detection that does not follow the template, or no room: read in full)
        if i >= buf.shape[0] or buf[i] != 93 or not _read_numbers(buf, spans[:ns], fv, iv, pow10):
            return -1, 0
        return i + 1, r


@njit(cache=True, nogil=True)
def _scan(buf, pow10, fk, fk_at, dk, dk_at):  # pragma: no cover - compiled
    """The frame in ``buf``: ``(ok, head (6,) int64, timestamp_s, fv (n, 8), iv (n, 4), class_first (n,))``; head:
    count, camera_id start and end (-1: absent), frame number, keys seen (bits of _FRAME_KEYS); ``class_first``:
    per detection the first detection with the same class text (-1: no class)."""
    # rows: a detection the columns take holds the four box keys, >= 53 bytes ({"u_min_px":0,...,"v_max_px":0});
    # a frame with more detections than this has a shorter one, which the columns refuse anyway
    cap = buf.shape[0] // 53 + 1
    fv = np.empty((cap, N_VALUES))
    iv = np.empty((cap, 4), np.int64)
    head = np.zeros(7, np.int64)
    head[1], head[2], head[5], head[6] = -1, -1, -1, -1
    ts = 0.0
    bad = (False, head, ts, fv[:0], iv[:0], head[:0])
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
            st = i
            i, is_int, ival, fval, ok = _number(buf, i, pow10)
            if k == 2 and not ok:  # a time stamp of full precision (17 digits): its text, for Python's float
                i = _number_end(buf, st)
                if i < 0:
                    return bad
                head[5], head[6] = st, i
                ok, is_int = True, False
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


#: :func:`_scan_columns`' head: ok, n, camera_id start and end, frame, timestamp_s text start and end (-1: read by
#: the pass), has_cov, has_conf, one_class, values_ok, the first detection's class start and end (-1: none)
_H = 13


@njit(cache=True, nogil=True)
def _columns(ok, head, ts, fv, iv, first, max_var):  # pragma: no cover - compiled
    """The detections' columns as the service takes them, in two blocks (two arrays handed back, not eight):
    ``ib`` int64 = the head (``_H``) | ids (n) | ``first`` (n) | class starts (n) | class ends (n), and ``fb``
    float64 = boxes (n, 4) | pixel covariances (n, 2, 2) | class confidences (n,) | ``timestamp_s``.  The head's
    ok is False also for a detection without a complete 2-D box, some with a covariance and some without (or one
    incomplete), a confidence outside [0, 1] -- cases whose error entries the general path writes.  Absent object
    ids: the detection's index.  ``one_class``: every detection's class text the first one's, or none has one
    (``first`` (n,): :func:`_class_first`); ``values_ok``: every box's corners in order and every pixel covariance
    entry within ``max_var`` (px^2) -- :func:`.detections.boxes2d_detections`' value checks, nothing for them to
    mark."""
    n = fv.shape[0]
    ib = np.empty(_H + 4 * n, np.int64)
    fb = np.empty(9 * n + 1)
    n_cov = 0
    has_conf = False
    one_class = values_ok = True
    for r in range(n):
        mask = iv[r, 3]
        ok &= (mask & _ALL_BOX) == _ALL_BOX
        c = mask & _ALL_COV
        ok &= (c == 0) | (c == _ALL_COV)
        n_cov += c == _ALL_COV
        if (mask >> 7) & 1:
            has_conf = True
            ok &= (fv[r, 7] >= 0.0) & (fv[r, 7] <= 1.0)
        ib[_H + r] = iv[r, 0] if (mask >> _K_OBJECT_ID) & 1 else r
        ib[_H + n + r], ib[_H + 2 * n + r], ib[_H + 3 * n + r] = first[r], iv[r, 1], iv[r, 2]
        for q in range(4):
            fb[4 * r + q] = fv[r, q]
        a = 4 * (n + r)
        fb[a], fb[a + 1], fb[a + 2], fb[a + 3] = fv[r, 4], fv[r, 5], fv[r, 5], fv[r, 6]
        fb[8 * n + r] = fv[r, 7]
        one_class &= first[r] == first[0]
        values_ok &= (fv[r, 0] <= fv[r, 2]) & (fv[r, 1] <= fv[r, 3])
    ok &= (n_cov == 0) | (n_cov == n)
    if n_cov > 0:
        for r in range(n):
            for q in range(4, 7):
                values_ok &= abs(fv[r, q]) <= max_var
    fb[9 * n] = ts
    ib[0], ib[1], ib[2], ib[3], ib[4], ib[5], ib[6] = ok, n, head[1], head[2], head[3], head[5], head[6]
    ib[7], ib[8], ib[9], ib[10] = n_cov > 0, has_conf, one_class, values_ok
    ib[11], ib[12] = (iv[0, 1], iv[0, 2]) if n > 0 else (-1, -1)
    return ib, fb


@njit(cache=True, nogil=True)
def _scan_columns(buf):  # pragma: no cover - compiled
    """:func:`_scan` and :func:`_columns` in one call (one dispatch of one argument -- the key tables and the
    limit are the module's constants --, the rows not boxed in between): ``(ib, fb)`` as :func:`_columns` says;
    the head's ok False: not in the subset, a frame field missing or not the common layout (:func:`scan_frame`
    then declines)."""
    ok, head, ts, fv, iv, first = _scan(buf, _POW10, _FK, _FK_AT, _DK, _DK_AT)
    return _columns(ok and head[4] == 0b1111, head, ts, fv, iv, first, MAX_PIXEL_VAR_PX2)


@njit(cache=True, nogil=True)
def _class_first(buf, iv):  # pragma: no cover - compiled
    """Per detection, the first detection whose class text is the same bytes (-1: no class).  A text is compared
    with the previous detection's first (a frame's detections come in runs of one class; texts of up to 8 bytes
    as one masked word), then with each distinct text before it."""
    n, nb = iv.shape[0], buf.shape[0]
    first = np.full(n, -1, np.int64)
    uniq = np.empty(n, np.int64)
    u = 0
    for r in range(n):
        s, e = iv[r, 1], iv[r, 2]
        if s < 0:
            continue
        if r > 0 and iv[r - 1, 1] >= 0 and iv[r - 1, 2] - iv[r - 1, 1] == e - s and e - s <= 8 and s + 8 <= nb \
                and iv[r - 1, 1] + 8 <= nb:
            mask = np.uint64(0xFFFFFFFFFFFFFFFF) >> np.uint64(64 - 8 * (e - s)) if e > s else np.uint64(0)
            if ((load8(buf, s) ^ load8(buf, iv[r - 1, 1])) & mask) == np.uint64(0):
                first[r] = first[r - 1]
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


class _ScannedColumns(NamedTuple):
    """:class:`ScannedFrame`'s fields (every frame field present; the detections' columns hold ``n`` rows)."""

    camera_id: str
    frame: int
    timestamp_s: float
    boxes: np.ndarray           # (n, 4) u_min, v_min, u_max, v_max (px)
    pixel_cov_px2: np.ndarray | None  # (n, 2, 2); None: no detection has one
    class_confidence: np.ndarray | None  # (n,), NaN where absent; None: no detection has one
    int_ids: np.ndarray         # (n,) int64: the object ids (absent: the detection's index)
    values_checked: bool        # every box in order, every covariance in range (nothing for the value checks)
    distinct_classes: list      # the frame's distinct classes (str or None), in order of first appearance
    class_index: np.ndarray | None  # (n,) int64 each detection's entry in ``distinct_classes``; None: one class


class ScannedFrame(_ScannedColumns):
    """A frame read by :func:`scan_frame`.  Its ids and classes are kept as columns (``int_ids``;
    ``distinct_classes`` and ``class_index``, what the lean frame's writers take); :attr:`object_ids` and
    :attr:`classes` are their lists, made when asked for (each time: read them once)."""

    __slots__ = ()

    @property
    def object_ids(self) -> list:
        """The n object ids as Python ints."""
        return self.int_ids.tolist()

    @property
    def classes(self) -> list:
        """The n detections' classes (str or None)."""
        if self.class_index is None:
            return self.distinct_classes * len(self.int_ids)
        return np.array(self.distinct_classes, dtype=object)[self.class_index].tolist()


def scan_frame(text) -> ScannedFrame | None:
    """One frame's JSON text (bytes-like) read into columns, or None when it is not in the subset this pass reads
    (see the module doc): then parse it in full (orjson) and read its detections with
    :func:`.detections.parse_detections`.  The columns are views of the pass's two new arrays (nothing shared
    with another frame)."""
    buf = np.frombuffer(text, np.uint8)
    if buf.size == 0:
        return None
    ib, fb = _scan_columns(buf)
    h = ib[:_H].tolist()
    if not h[0]:
        return None
    n = h[1]
    raw = text if type(text) is bytes else bytes(buf)  # (decoded only where a string is)
    try:
        camera = raw[h[2]:h[3]].decode("utf-8")
        if h[9]:  # one class for all (or none): one text decoded, no per-detection work
            distinct, class_index = [None if h[11] < 0 else raw[h[11]:h[12]].decode("utf-8")], None
        else:
            distinct, class_index = _classes(raw, ib, n)
    except UnicodeDecodeError:
        return None
    if h[6] >= 0:  # a time stamp beyond the exact subset: Python's correctly rounded float of its JSON text
        ts = float(raw[h[5]:h[6]])
        if not math.isfinite(ts):
            return None
    else:
        ts = fb.item(9 * n)
    # (every field in order, without the NamedTuple's Python-level __new__: ~0.15 us a frame)
    return tuple.__new__(ScannedFrame, (
        camera, h[4], ts, fb[:4 * n].reshape(n, 4), fb[4 * n:8 * n].reshape(n, 2, 2) if h[7] else None,
        fb[8 * n:9 * n] if h[8] else None, ib[_H:_H + n], h[10] == 1, distinct, class_index))


def _classes(raw: bytes, ib: np.ndarray, n: int) -> tuple[list, np.ndarray]:
    """The detections' classes of a frame of several class texts (``ib``: :func:`_columns`' int block): the
    distinct classes (str or None; each text decoded once) in order of first appearance, and each detection's
    entry among them (int64)."""
    first = ib[_H + n:_H + 2 * n]  # (each detection's first detection of the same text; -1: no class)
    starts, ends = ib[_H + 2 * n:_H + 3 * n], ib[_H + 3 * n:_H + 4 * n]
    none = first < 0
    if none.any():  # (the detections without a class: one more class, None, first seen at the first of them)
        first = np.where(none, np.argmax(none), first)
    heads = np.flatnonzero(first == np.arange(n))  # (each class's first detection, in order)
    entry = np.empty(n, np.int64)
    entry[heads] = np.arange(len(heads))
    distinct = [None if s < 0 else raw[s:e].decode("utf-8")
                for s, e in zip(starts[heads].tolist(), ends[heads].tolist(), strict=True)]
    return distinct, entry[first]
