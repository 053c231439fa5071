"""JSON text of per-object records written column-wise: the service's output without per-object dicts.

A frame's record holds three lists of ~100 small objects (the per-object record, the CPM's perceived
objects, the SDSM's detected objects).  Building them as Python dicts and serialising those costs
~20 us per object.  Here every column is formatted by one ``orjson.dumps`` call (on the numpy array
or the list of values: the same text orjson writes for each value inside a dict), and one compiled
kernel cuts those texts into values and interleaves them with the constant text of the row layout
(:class:`Table`).  The result is byte for byte what ``orjson.dumps`` writes for the list of dicts with
the same keys in the same order (the tests compare the two), so the records parse back to the same
values.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import orjson
from llvmlite import ir as llvm_ir
from numba import njit, types
from numba.core import cgutils
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import intrinsic

from .bytewords import store8

__all__ = ["Table", "compact_objects_json"]

_NUMPY = orjson.OPT_SERIALIZE_NUMPY
_COMMA, _LBRACKET, _RBRACKET, _QUOTE, _BACKSLASH, _LBRACE, _RBRACE = b",[]\"\\{}"


@njit(cache=True, nogil=True, inline="always")
def _skip_string(buf, i):  # pragma: no cover - compiled
    """``buf[i]`` is a string's opening quote: the index just after its closing quote (escapes honoured)."""
    one, two = np.uint64(1), np.uint64(2)
    i += one
    while buf[i] != _QUOTE:
        i += two if buf[i] == _BACKSLASH else one
    return i + one


@njit(cache=True, nogil=True)
def _scan(buf, seg_len, plain, starts, ends):  # pragma: no cover - compiled
    """Start and end of every value of the JSON arrays in ``buf``: orjson's compact texts of the columns, one after
    the other (``seg_len`` bytes each; arrays of arrays allowed).  A ``plain`` text holds only numbers and literals
    (a numpy array's: no strings, no objects), and its values end at the next ``,`` or ``]``: one comparison loop
    per byte.  Any other text: strings (escapes honoured) and objects too.  Indices are unsigned (no negative-index
    wrap-around test per byte).  Returns how many values were found."""
    cap = starts.shape[0]
    one = np.uint64(1)
    t = 0
    i = np.uint64(0)
    for g in range(seg_len.shape[0]):
        end = i + np.uint64(seg_len[g])
        fast = plain[g]
        while i < end:
            c = buf[i]
            if c == _LBRACKET or c == _RBRACKET or c == _COMMA:
                i += one
                continue
            s = i
            if fast or (c != _QUOTE and c != _LBRACE):  # a number or a literal: up to the next , or ]
                i += one
                c = buf[i]
                while c != _COMMA and c != _RBRACKET:
                    i += one
                    c = buf[i]
            elif c == _QUOTE:
                i = _skip_string(buf, i)
            else:  # an object: to its matching brace (braces inside strings skipped)
                depth = 0
                while True:
                    c = buf[i]
                    if c == _QUOTE:
                        i = _skip_string(buf, i)
                        continue
                    if c == _LBRACE:
                        depth += 1
                    elif c == _RBRACE:
                        depth -= 1
                        if depth == 0:
                            i += one
                            break
                    i += one
            if t < cap:
                starts[t] = s
                ends[t] = i
            t += 1
    return t


@intrinsic
def _copy_bytes(typingctx, dst, dst_at, src, src_at, n):
    """``dst[dst_at:dst_at + n] = src[src_at:src_at + n]`` for C-contiguous uint8 arrays, as one ``memcpy``
    (the callers guarantee the bounds; a byte loop costs ~1 ns per byte, most of the weaving)."""
    for a in (dst, src):
        if not (isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and a.dtype == types.uint8):
            return None  # (no typing: only C-contiguous byte arrays, whose data pointer is the first byte)

    def codegen(context, builder, signature, args):
        d, d_at, s_, s_at, count = args
        da = context.make_array(signature.args[0])(context, builder, d)
        sa = context.make_array(signature.args[2])(context, builder, s_)
        cgutils.raw_memcpy(builder, builder.gep(da.data, [d_at]), builder.gep(sa.data, [s_at]), count, 1)
        return context.get_dummy_value()

    return types.void(dst, types.intp, src, types.intp, types.intp), codegen


@njit(cache=True, nogil=True)
def _weave(buf, starts, ends, n, lit, ops, masks, size):  # pragma: no cover - compiled
    """``[row,row,...]``: per row the ops -- (0, offset, length): constant text ``lit[offset:offset+length]``;
    (1, column, 0): value ``row`` of that column; (2, mask, count): skip the next ``count`` ops unless
    ``masks[mask, row]``."""
    out = np.empty(size, np.uint8)
    p = 0
    out[p] = _LBRACKET
    p += 1
    nops = ops.shape[0]
    for r in range(n):
        if r:
            out[p] = _COMMA
            p += 1
        k = 0
        while k < nops:
            kind, a, b = ops[k, 0], ops[k, 1], ops[k, 2]
            k += 1
            if kind == 0:
                _copy_bytes(out, p, lit, a, b)
                p += b
            elif kind == 1:
                t = a * n + r
                s = starts[t]
                _copy_bytes(out, p, buf, s, ends[t] - s)
                p += ends[t] - s
            elif not masks[a, r]:
                k += b
    out[p] = _RBRACKET
    p += 1
    return out[:p]


class Table:
    """Rows of JSON objects built from columns: ``Table(n).column(values)`` adds a column (a numpy array,
    or a list of JSON-able values, ``n`` of them; :meth:`columns` adds the rows of a ``(k, n)`` array at
    once) and returns its handle; :meth:`json` writes ``[{...},{...},...]`` following a layout of
    constant texts (bytes), column handles and :meth:`when` groups (included where a mask is True).

    ``Table(3)`` with ``x = t.column(np.array([1.5, 2.0, np.nan]))`` and
    ``t.json([b'{"x":', x, b'}'])`` gives ``[{"x":1.5},{"x":2.0},{"x":null}]``.
    """

    __slots__ = ("n", "_texts", "_plain", "_ncols", "_masks")

    def __init__(self, n: int):
        self.n = int(n)
        self._texts: list[bytes] = []
        self._plain: list[bool] = []  # per text: numbers and literals only (a numeric or boolean array's)
        self._ncols = 0
        self._masks: list[np.ndarray] = []

    def column(self, values) -> int:
        if isinstance(values, np.ndarray):
            text = orjson.dumps(np.ascontiguousarray(values), option=_NUMPY)
            self._plain.append(values.dtype.kind in _PLAIN_KINDS)
        else:
            text = orjson.dumps(values)
            self._plain.append(False)
        self._texts.append(text)
        self._ncols += 1
        return self._ncols - 1

    def columns(self, matrix: np.ndarray) -> list[int]:
        m = np.ascontiguousarray(matrix)
        self._texts.append(orjson.dumps(m, option=_NUMPY))
        self._plain.append(m.dtype.kind in _PLAIN_KINDS)
        first = self._ncols
        self._ncols += m.shape[0]
        return list(range(first, self._ncols))

    def when(self, mask, *parts) -> tuple:
        """A group of layout parts written only in the rows where ``mask`` is True."""
        self._masks.append(np.asarray(mask, dtype=bool))
        return (len(self._masks) - 1, parts)

    def json(self, layout) -> bytes:
        """The rows as JSON text (``bytes``); :meth:`json_buffer` without the copy into ``bytes``."""
        out = self.json_buffer(layout)
        return out if isinstance(out, bytes) else out.tobytes()

    def json_buffer(self, layout):
        """:meth:`json`'s text as a 1-D uint8 array (or ``b"[]"``): a bytes-like object that ``bytes.join``, file
        writes and MQTT publishes take as it is (a record of ~200 kB is then copied once, by the final join)."""
        n = self.n
        if n == 0:
            return b"[]"
        key = tuple(layout)
        compiled = _LAYOUTS.get(key)
        if compiled is None:
            compiled = _compile(key)
            if len(_LAYOUTS) < 256:
                _LAYOUTS[key] = compiled
        lit, ops, per_row, reuse = compiled
        buf = np.frombuffer(b"".join(self._texts), dtype=np.uint8)
        want = self._ncols * n
        starts = np.empty(want, np.int64)
        ends = np.empty(want, np.int64)
        got = _scan(buf, np.fromiter(map(len, self._texts), np.int64, len(self._texts)),
                    np.array(self._plain, dtype=np.bool_), starts, ends)
        if got != want:
            raise ValueError(f"columns hold {got} values, expected {want} ({self._ncols} columns x {n} rows)")
        masks = np.array(self._masks) if self._masks else _NO_MASKS
        size = 2 + n * (per_row + 1) + reuse * buf.shape[0]  # an upper bound (a column may be written twice)
        return _weave(buf, starts, ends, n, lit, ops, masks, size)


_LAYOUTS: dict = {}
#: numpy dtype kinds whose orjson text holds only numbers and literals (bool, int, uint, float)
_PLAIN_KINDS = frozenset("biuf")
_NO_MASKS = np.zeros((1, 1), dtype=bool)


def _compile(layout: tuple):
    """A layout -> (constant texts, ops of :func:`_weave`, constant bytes per row, most uses of one column in a row)."""
    lit = bytearray()
    ops: list[tuple[int, int, int]] = []

    def emit(parts):
        for p in parts:
            if isinstance(p, bytes):
                if ops and ops[-1][0] == 0 and ops[-1][1] + ops[-1][2] == len(lit):  # merge with the last text
                    ops[-1] = (0, ops[-1][1], ops[-1][2] + len(p))
                else:
                    ops.append((0, len(lit), len(p)))
                lit.extend(p)
            elif isinstance(p, tuple):
                k = len(ops)
                ops.append((2, p[0], 0))
                emit(p[1])
                ops[k] = (2, p[0], len(ops) - k - 1)
                ops.append((0, len(lit), 0))  # a boundary: text after the group is not merged into it
            else:
                ops.append((1, p, 0))

    emit(layout)
    cols = [o[1] for o in ops if o[0] == 1]
    reuse = max((cols.count(c) for c in set(cols)), default=1)
    return np.frombuffer(bytes(lit), np.uint8), np.array(ops, dtype=np.int64), len(lit), reuse


# -- the compact record's objects: one compiled pass ---------------------------------------------------------
#: bytes per vector step of the compact writer (one 256-bit load, compare or store)
_VEC = 32
_VEC_TYPE = llvm_ir.VectorType(llvm_ir.IntType(8), _VEC)


def _vector_pointer(context, builder, array_type, array, at):
    data = context.make_array(array_type)(context, builder, array).data
    return builder.bitcast(builder.gep(data, [at]), _VEC_TYPE.as_pointer())


@intrinsic
def _copy32(typingctx, dst, dst_at, src, src_at):
    """``dst[dst_at:dst_at + 32] = src[src_at:src_at + 32]`` (C-contiguous uint8 arrays; the caller guarantees the
    bounds): one unaligned vector load, then one store (so ``src`` may be ``dst``, the ranges overlapping)."""
    if not (_bytes1d(dst) and _bytes1d(src)):
        return None

    def codegen(context, builder, signature, args):
        word = builder.load(_vector_pointer(context, builder, signature.args[2], args[2], args[3]), align=1)
        builder.store(word, _vector_pointer(context, builder, signature.args[0], args[0], args[1]), align=1)
        return context.get_dummy_value()

    return types.void(dst, types.intp, src, types.intp), codegen


def _bytes1d(a) -> bool:
    """A C-contiguous 1-D uint8 array or ``bytes`` (its data pointer is the first byte)."""
    return isinstance(a, types.Buffer) and a.ndim == 1 and a.layout == "C" and a.dtype == types.uint8


def _byte_mask(*wanted: int):
    """An intrinsic ``mask(buf, at)``: bit ``i`` of the uint64 result set where ``buf[at + i]`` (``i`` < 32) is one of
    the ``wanted`` bytes (one vector load and compare; the caller guarantees ``at + 32`` within ``buf``)."""

    @intrinsic
    def mask(typingctx, buf, at):
        if not _bytes1d(buf):
            return None

        def codegen(context, builder, signature, args):
            word = builder.load(_vector_pointer(context, builder, signature.args[0], args[0], args[1]), align=1)
            return _mask_of(builder, word, wanted)

        return types.uint64(buf, types.intp), codegen

    return mask


def _mask_of(builder, word, wanted):
    """The uint64 whose bit ``i`` says that byte ``i`` of the 32-byte vector ``word`` is one of ``wanted``."""
    hit = None
    for b in wanted:
        eq = builder.icmp_unsigned("==", word, llvm_ir.Constant(_VEC_TYPE, [b] * _VEC))
        hit = eq if hit is None else builder.or_(hit, eq)
    return builder.zext(builder.bitcast(hit, llvm_ir.IntType(_VEC)), llvm_ir.IntType(64))


_closes32 = _byte_mask(_RBRACKET)  # where an inner array ends


@intrinsic
def _copy32_ends(typingctx, dst, dst_at, src, src_at):
    """:func:`_copy32` that also returns where the 32 bytes copied hold a ``,`` or a ``]`` (bit ``i``: byte ``i``;
    uint64), from the same vector load: where a value of a numeric array's text ends."""
    if not (_bytes1d(dst) and _bytes1d(src)):
        return None

    def codegen(context, builder, signature, args):
        word = builder.load(_vector_pointer(context, builder, signature.args[2], args[2], args[3]), align=1)
        builder.store(word, _vector_pointer(context, builder, signature.args[0], args[0], args[1]), align=1)
        return _mask_of(builder, word, (_COMMA, _RBRACKET))

    return types.uint64(dst, types.intp, src, types.intp), codegen


@njit(cache=True, nogil=True, inline="always")
def _first_bit(mask):  # pragma: no cover - compiled
    """The index (int64) of the lowest set bit of a non-zero uint64."""
    return np.int64(trailing_zeros(mask))


@njit(cache=True, nogil=True, inline="always")
def _put_int(out, p, v):  # pragma: no cover - compiled
    """The decimal text of ``v`` (int64) at ``out[p]``; the index after it (``out`` keeps 8 bytes of room).  Below
    10 ** 8 the digits are gathered in a word, stored at once; larger and negative numbers digit by digit.
    (Measured: one digit per division by 10 is faster here than two per division by 100 from a table of digit
    pairs, which also made the row loop's code larger.)"""
    if v >= 0 and v < 100000000:
        w = np.uint64(0)
        n = 0
        t = np.uint64(v)
        while True:  # (the last digit found is the first written: the lowest byte)
            w = (w << np.uint64(8)) | (np.uint64(48) + t % np.uint64(10))
            t //= np.uint64(10)
            n += 1
            if t == np.uint64(0):
                break
        store8(out, p, w)
        return p + n
    if v < 0:
        out[p] = 45
        p += 1
        m = np.uint64(-(v + 1)) + np.uint64(1)
    else:
        m = np.uint64(v)
    n = 1
    t = m
    while t >= np.uint64(10):
        t //= np.uint64(10)
        n += 1
    for q in range(p + n - 1, p - 1, -1):
        out[q] = np.uint8(48) + np.uint8(m % np.uint64(10))
        m //= np.uint64(10)
    return p + n


@njit(cache=True, nogil=True, inline="always")
def _put_text(out, p, src, a, b):  # pragma: no cover - compiled
    """``src[a:b]`` at ``out[p]``, 32 bytes at a time (``src`` readable up to ``b + 31``, ``out`` 32 bytes of room
    past the text: the extra bytes are overwritten next); the index after it.  ``src`` may be ``out`` itself for a
    text before ``p`` (each load precedes its store, and no store reaches below ``p``)."""
    k = a
    while k < b:
        _copy32(out, p + (k - a), src, k)
        k += _VEC
    return p + b - a


@njit(cache=True, nogil=True, inline="always")
def _put_piece(out, p, src, a, b):  # pragma: no cover - compiled
    """:func:`_put_text` of a text of at most 32 bytes (a constant piece, a float's value): one vector copy."""
    _copy32(out, p, src, a)
    return p + b - a


@njit(cache=True, nogil=True, inline="always")
def _put_id(out, p, v):  # pragma: no cover - compiled
    """An id at ``out[p]``: ``v`` as an integer, or ``null`` where ``v`` < 0 (none); the position after it.  (The
    four bytes stored one by one: a copy of the text from a table here made the whole row loop ~30 % slower.)"""
    if v < 0:
        out[p] = 110
        out[p + 1] = 117
        out[p + 2] = 108
        out[p + 3] = 108
        return p + 4
    return _put_int(out, p, v)


@njit(cache=True, nogil=True)
def _column_bounds(ftext, nf):  # pragma: no cover - compiled
    """Where the ``nf`` inner arrays of orjson's text of a float array ``(nf, n)`` (numbers and ``null`` only)
    begin and end: ``(first (nf,), close (nf,), ok)`` -- per column the index of its first value and of its
    ``]``; ``ok`` False: the text is not ``nf`` non-empty arrays in one.  The ``]`` is searched 32 bytes at a
    time."""
    first = np.zeros(nf, np.int64)
    close = np.zeros(nf, np.int64)
    L = len(ftext)
    i = 1
    if L < 2 or ftext[0] != 91:
        return first, close, False
    for k in range(nf):
        if i + 1 >= L or ftext[i] != 91 or ftext[i + 1] == 93:
            return first, close, False
        i += 1
        first[k] = i
        while i + _VEC <= L:
            m = _closes32(ftext, i)
            if m != np.uint64(0):
                i += _first_bit(m)
                break
            i += _VEC
        while i < L and ftext[i] != 93:
            i += 1
        if i >= L:
            return first, close, False
        close[k] = i
        i += 1
        if k + 1 < nf:
            if i >= L or ftext[i] != 44:
                return first, close, False
            i += 1
    return first, close, i == L - 1 and ftext[i] == 93


@njit(cache=True, nogil=True, inline="always")
def _put_value(out, p, ftext, c):  # pragma: no cover - compiled
    """The value at ``ftext[c]`` (up to the next ``,`` or ``]``) at ``out[p]``, searched and copied 32 bytes at a
    time (``out`` keeps 32 bytes of room: the bytes past the value are overwritten next): ``(p, c)`` after it --
    ``ftext[c]`` is then its ``,`` or ``]``."""
    L = len(ftext)
    while c + _VEC <= L:
        m = _copy32_ends(out, p, ftext, c)
        if m != np.uint64(0):
            f = _first_bit(m)
            return p + f, c + f
        p += _VEC
        c += _VEC
    while ftext[c] != 44 and ftext[c] != 93:  # (the text's last bytes: it ends with "]]")
        out[p] = ftext[c]
        p += 1
        c += 1
    return p, c


@njit(cache=True, nogil=True)
def _compact_rows(ftext, ids, cls_idx, st_idx, mid, tid, texts, at, st_base, out):  # pragma: no cover - compiled
    """The compact record's ``objects`` text (see :func:`compact_objects_json`) written into ``out`` (uint8, at
    least the text's length and 32 bytes more), from the texts ``texts[at[k]:at[k + 1]]`` of :func:`_row_texts`
    (:func:`_pieces`, then the class texts from entry 16 and the status texts from ``st_base``; 32 bytes of room
    past the last): per row the id, the row's class text (entry ``16 + cls_idx[r]``) and status text (entry
    ``st_base + st_idx[r]``), the five float values (``ftext``: orjson's text of the (5, n) array, or (10, n) with
    the motion: the ``bytes`` as they are), the motion (``tid`` not empty: the track id, negative: null, and the
    five motion values) and the message id (``mid`` not empty; negative: null).  Returns the text's length;
    -1: ``ftext`` does not hold 5 n (10 n) values (the caller's ``out`` of no use then).

    One pass: a cursor per column of ``ftext`` (:func:`_column_bounds`) copies the row's value of that column
    straight into place (:func:`_put_value`); the column's ``n``-th value must end at its ``]``, the others
    before it.  Texts are copied 32 bytes at a time (:func:`_put_text`).  (The loops over the groups and their
    values are kept as loops: the same code written out straight, or with more copies of the value's or the
    id's code, measured up to 2x slower -- probably the loop's code no longer fitting the CPU's decoded-instruction
    cache.)"""
    n = ids.shape[0]
    with_mid, with_motion = mid.shape[0] != 0, tid.shape[0] != 0
    cur, close, ok = _column_bounds(ftext, 10 if with_motion else 5)
    if not ok:
        return -1
    out[0] = 91
    p = 1
    s_xy = e_xy = 0
    for r in range(n):
        j = 1 if r else 0  # ('{"object_id":', after the first row '},{"object_id":')
        p = _put_piece(out, p, texts, at[j], at[j + 1])
        p = _put_int(out, p, ids[r])
        j = 16 + cls_idx[r]
        p = _put_text(out, p, texts, at[j], at[j + 1])
        j = st_base + st_idx[r]
        p = _put_text(out, p, texts, at[j], at[j + 1])
        last = r == n - 1
        for g in range(2 if with_motion else 1):  # the position (x, y, cov), then the motion (v, cov_v)
            if g:
                p = _put_id(out, p, tid[r])
            t0 = 2 + 7 * g
            for k in range(6):  # x, y, cxx, cxy, cxy, cyy (v_east, v_north, cvv_ee, cvv_en, cvv_en, cvv_nn)
                p = _put_piece(out, p, texts, at[t0 + k], at[t0 + 1 + k])
                if k == 4:  # the off-diagonal once more: the text just written (out[s_xy:e_xy], <= 32 bytes)
                    p = _put_piece(out, p, out, s_xy, e_xy)
                    continue
                q = 5 * g + (k if k < 4 else k - 1)
                s_xy = p
                p, c = _put_value(out, p, ftext, cur[q])
                e_xy = p
                if (c == close[q]) != last or e_xy - s_xy > _VEC:  # (a column with more or fewer than n values;
                    # a value longer than orjson writes for a float64, at most 24 bytes: not this kernel's text)
                    return -1
                cur[q] = c + 1
            p = _put_piece(out, p, texts, at[t0 + 6], at[t0 + 7])  # (with the next field's name)
        if with_mid:
            p = _put_id(out, p, mid[r])
    out[p] = 125
    out[p + 1] = 93
    return p + 2


def _pieces(with_mid: bool, with_motion: bool) -> tuple:
    """The constant texts of a compact record's objects (:func:`_compact_rows`' ``at`` entries 0..15): a row's
    opening (the first, then the others with the previous row's close); the texts before ``x`` (none: the status
    text ends with the name), ``y``, ``xx``, ``xy``, ``xy``, ``yy`` of the position and the text after it (with the
    next field's name: the track id, else the message id); the same seven of the motion."""
    mid = b',"message_object_id":' if with_mid else b""
    return (b'{"object_id":', b'},{"object_id":', b"", b',"y_m":', b',"cov_m2":[[', b",", b"],[", b",",
            b']],"track_id":' if with_motion else b"]]" + mid, b',"v_east_mps":', b',"v_north_mps":',
            b',"cov_v_m2ps2":[[', b",", b"],[", b",", b"]]" + mid)


#: bytes of a row beside its floats and its class and status texts: the constant texts, 3 integers of at most
#: 20 digits and a sign
_ROW_BYTES = sum(map(len, _pieces(True, True))) + 3 * 21


class _RowTexts(NamedTuple):
    """:func:`_compact_rows`' texts of a frame's distinct classes and statuses: ``texts`` the constant pieces
    (:func:`_pieces`), the class texts (after ``,"class":``), the status texts (before ``,"x_m":``) and 32 bytes
    of room; ``at`` (16 + classes + statuses + 1,) their offsets; ``st_base`` the status texts' first entry in
    ``at``; ``row_bytes`` a bound on a row's bytes beside its floats."""

    texts: np.ndarray
    at: np.ndarray
    st_base: int
    row_bytes: int


def _row_texts(class_texts: list, status_texts: list, with_mid: bool, with_motion: bool) -> _RowTexts:
    """The :class:`_RowTexts` of a frame's class and status texts (bytes); a frame's few texts repeat from frame
    to frame: up to 256 tables are kept (then forgotten at once; the kernel only reads them)."""
    key = (*class_texts, None, *status_texts, with_mid, with_motion)  # (None: between the texts, which are bytes)
    table = _ROW_TEXTS.get(key)
    if table is None:
        const = _pieces(with_mid, with_motion)
        pieces = (*const, *(b',"class":' + t for t in class_texts), *(t + b',"x_m":' for t in status_texts))
        at = np.zeros(len(pieces) + 1, np.int64)
        np.cumsum([len(t) for t in pieces], out=at[1:])
        table = _RowTexts(np.frombuffer(b"".join(pieces) + bytes(_VEC), np.uint8), at,
                          len(const) + len(class_texts),
                          _ROW_BYTES + max(map(len, pieces[len(const):len(const) + len(class_texts)])) +
                          max(map(len, pieces[len(const) + len(class_texts):])))
        if len(_ROW_TEXTS) >= 256:
            _ROW_TEXTS.clear()
        _ROW_TEXTS[key] = table
    return table


_ROW_TEXTS: dict = {}


def _compact_args(ids: np.ndarray, class_idx: np.ndarray, class_texts: list, status_idx: np.ndarray,
                  status_texts: list, values: np.ndarray, message_ids: np.ndarray | None = None,
                  track_ids: np.ndarray | None = None) -> tuple:
    """:func:`_compact_rows`' arguments for :func:`compact_objects_json`'s (``n`` > 0), its output buffer last
    (uninitialised: a bound on the text's length and 32 bytes of room)."""
    ftext = orjson.dumps(np.ascontiguousarray(values, dtype=np.float64), option=_NUMPY)  # (the kernel reads bytes)
    with_mid, with_motion = message_ids is not None, track_ids is not None
    texts, at, st_base, row_bytes = _row_texts(class_texts, status_texts, with_mid, with_motion)
    # (the bound: the off-diagonals are written twice)
    out = np.empty(2 + len(ids) * row_bytes + 2 * len(ftext) + _VEC, np.uint8)
    return (ftext, ids, class_idx, status_idx, message_ids if with_mid else _NO_IDS,
            track_ids if with_motion else _NO_IDS, texts, at, st_base, out)


_NO_IDS = np.zeros(0, np.int64)  # (no message ids, no track ids: only its length is read)


def compact_objects_json(ids: np.ndarray, class_idx: np.ndarray, class_texts: list, status_idx: np.ndarray,
                         status_texts: list, values: np.ndarray, message_ids: np.ndarray | None = None,
                         track_ids: np.ndarray | None = None):
    """The ``objects`` list of a compact record in one compiled pass: per object
    ``{"object_id":<id>,"class":<class><status>,"x_m":..,"y_m":..,"cov_m2":[[xx,xy],[xy,yy]]``, with tracks
    ``,"track_id":<id or null>,"v_east_mps":..,"v_north_mps":..,"cov_v_m2ps2":[[ee,en],[en,nn]]``, (and
    ``,"message_object_id":<id or null>``) ``}`` -- the bytes :class:`Table` writes for that layout.

    Parameters
    ----------
    ids : ndarray (n,) int64
        The detector's integer object ids (written by the kernel).
    class_idx, class_texts : ndarray (n,) int64, list of bytes
        Each object's entry in the frame's distinct class texts (their JSON: ``"car"``, ``null``).
    status_idx, status_texts : ndarray (n,) int64, list of bytes
        Each object's entry in the frame's distinct status texts (``,"status":"ok"``, or with a ``reason``).
    values : ndarray (5, n) float64, or (10, n) with ``track_ids``
        ``x_m, y_m, cov_xx, cov_xy, cov_yy`` (m, m^2), then with tracks ``v_east_mps, v_north_mps, cov_v_ee,
        cov_v_en, cov_v_nn`` (m/s, m^2/s^2): one ``orjson.dumps``, non-finite values ``null``.
    message_ids : ndarray (n,) int64, optional
        The messages' object ids (negative: not in the messages, ``null``); None: no such field.
    track_ids : ndarray (n,) int64, optional
        The objects' track ids (negative: not tracked, ``null``); None: no motion fields.

    Returns
    -------
    The text as a uint8 array (``b"[]"`` without objects), as :meth:`Table.json_buffer`.
    """
    n = len(ids)
    if n == 0:
        return b"[]"
    args = _compact_args(ids, class_idx, class_texts, status_idx, status_texts, values, message_ids, track_ids)
    size = _compact_rows(*args)
    if size < 0:
        raise ValueError(f"values hold {len(args[0])} bytes of text, not {10 if track_ids is not None else 5} x {n} "
                         "numbers")
    return args[-1][:size]
