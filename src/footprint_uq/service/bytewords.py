"""Bytes a machine word at a time inside compiled kernels: unaligned 8-byte loads and stores and the search for a
byte in a word (the service's text readers and writers, ``frame_scan`` and ``jsonrows``).

Each helper trusts its caller with the bounds (a load or store of 8 bytes at ``at`` needs ``at + 8`` within the
array): the callers check them once per span instead of once per byte.
"""

from __future__ import annotations

import numpy as np
from llvmlite import ir as llvm_ir
from numba import njit, types
from numba.cpython.unsafe.numbers import trailing_zeros
from numba.extending import intrinsic

__all__ = ["first_of_two", "load8", "store8"]

_ONES = np.uint64(0x0101010101010101)
_HIGHS = np.uint64(0x8080808080808080)


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
