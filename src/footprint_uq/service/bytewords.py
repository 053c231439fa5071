"""Bytes a machine word at a time inside compiled kernels: unaligned 8-byte loads and stores, the search for a
byte in a word, and decimal digits read a word at a time (the service's text readers and writers, ``frame_scan``
and ``jsonrows``).

Each helper trusts its caller with the bounds (a load or store of 8 bytes at ``at`` needs ``at + 8`` within the
array): the callers check them once per span instead of once per byte.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir as llvm_ir
from numba import njit, types
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import intrinsic

__all__ = ["digits_value", "first_of", "first_of_two", "leading_digits", "load8", "store8", "string_stop"]

_ONES = np.uint64(0x0101010101010101)
_HIGHS = np.uint64(0x8080808080808080)
_LOW7 = np.uint64(0x7F7F7F7F7F7F7F7F)
_HIGH_NIBBLES = np.uint64(0xF0F0F0F0F0F0F0F0)
_SIXES = np.uint64(0x0606060606060606)
_THREES = np.uint64(0x3333333333333333)
_LOW_NIBBLES = np.uint64(0x0F0F0F0F0F0F0F0F)
_BYTE_PAIRS = np.uint64(0x00FF00FF00FF00FF)
_HALF_PAIRS = np.uint64(0x0000FFFF0000FFFF)
_QUOTES = np.uint64(0x2222222222222222)
_BACKSLASHES = np.uint64(0x5C5C5C5C5C5C5C5C)
_SPACES = np.uint64(0x2020202020202020)


def _byte_array(a) -> bool:
    return isinstance(a, types.Array) and a.ndim == 1 and a.layout == "C" and a.dtype == types.uint8


def _word_pointer(context, builder, array_type, array, at):
    data = context.make_array(array_type)(context, builder, array).data
    return builder.bitcast(builder.gep(data, [at]), llvm_ir.IntType(64).as_pointer())


@intrinsic
def load8(typingctx, buf, at):
    """The 8 bytes ``buf[at:at + 8]`` of a C-contiguous uint8 array as one uint64 (little-endian machines: byte
    ``at`` is the lowest); an unaligned load."""
    if not _byte_array(buf):
        return None

    def codegen(context, builder, signature, args):
        return builder.load(_word_pointer(context, builder, signature.args[0], args[0], args[1]), align=1)

    return types.uint64(buf, types.intp), codegen


@intrinsic
def store8(typingctx, buf, at, word):
    """``buf[at:at + 8]`` = the 8 bytes of the uint64 ``word``; an unaligned store."""
    if not _byte_array(buf) or word != types.uint64:
        return None

    def codegen(context, builder, signature, args):
        builder.store(args[2], _word_pointer(context, builder, signature.args[0], args[0], args[1]), align=1)
        return context.get_dummy_value()

    return types.void(buf, types.intp, types.uint64), codegen


@njit(cache=True, nogil=True, inline="always")
def first_of_two(word, pattern_a, pattern_b):  # pragma: no cover - compiled
    """The index (0..7) of the first byte of ``word`` that is byte ``a`` or byte ``b`` (the patterns: that byte in
    all 8 places, e.g. ``0x2c2c...2c``); 8: neither.  (The zero-byte test ``(x - 0x01..) & ~x & 0x80..``
    flags false bytes only above a true one, so its lowest flag is exact.)"""
    xa = word ^ pattern_a
    xb = word ^ pattern_b
    hit = (((xa - _ONES) & ~xa) | ((xb - _ONES) & ~xb)) & _HIGHS
    if hit == np.uint64(0):
        return 8
    return np.int64(trailing_zeros(hit)) >> 3


@njit(cache=True, nogil=True, inline="always")
def first_of(word, pattern):  # pragma: no cover - compiled
    """The index (0..7) of the first byte of ``word`` that is the byte of ``pattern`` (that byte in all 8 places);
    8: none (the zero-byte test of :func:`first_of_two`, one byte)."""
    x = word ^ pattern
    hit = (x - _ONES) & ~x & _HIGHS
    if hit == np.uint64(0):
        return 8
    return np.int64(trailing_zeros(hit)) >> 3


@njit(cache=True, nogil=True, inline="always")
def string_stop(word):  # pragma: no cover - compiled
    """The index (0..7) of the first byte of ``word`` that ends a plain JSON string's text: a quote, a backslash
    or a control character (below 0x20); 8: none.  (``(x - 0x20..) & ~x & 0x80..`` flags the bytes below 0x20,
    falsely only above a true one, as the zero-byte tests: the lowest flag of the three is exact.)"""
    xa = word ^ _QUOTES
    xb = word ^ _BACKSLASHES
    hit = (((xa - _ONES) & ~xa) | ((xb - _ONES) & ~xb) | ((word - _SPACES) & ~word)) & _HIGHS
    if hit == np.uint64(0):
        return 8
    return np.int64(trailing_zeros(hit)) >> 3


@njit(cache=True, nogil=True, inline="always")
def leading_digits(word):  # pragma: no cover - compiled
    """How many of the first bytes of ``word`` are ASCII digits ``0``-``9`` (0..8).  A byte is a digit when its
    high nibble is 3 and stays 3 after adding 6; the carry of a byte >= 0xFA only reaches bytes above it, which
    do not count (they follow a byte that is no digit)."""
    y = ((word & _HIGH_NIBBLES) | (((word + _SIXES) & _HIGH_NIBBLES) >> np.uint64(4))) ^ _THREES
    nonzero = (((y & _LOW7) + _LOW7) | y) & _HIGHS  # (a byte's high bit: that byte of y is not 0)
    if nonzero == np.uint64(0):
        return 8
    return np.int64(trailing_zeros(nonzero)) >> 3


@njit(cache=True, nogil=True, inline="always")
def digits_value(word, count):  # pragma: no cover - compiled
    """The integer the first ``count`` (1..8) bytes of ``word`` write in decimal (the caller knows them digits):
    the bytes above them shifted out, the digits paired, then the pairs, then the quads (three multiplications;
    Lemire's eight-digit reading, the missing leading digits zeros)."""
    x = word << np.uint64(64 - 8 * count)
    x = ((x & _LOW_NIBBLES) * np.uint64(2561)) >> np.uint64(8)
    x = ((x & _BYTE_PAIRS) * np.uint64(6553601)) >> np.uint64(16)
    x = ((x & _HALF_PAIRS) * np.uint64(42949672960001)) >> np.uint64(32)
    return np.int64(x)
