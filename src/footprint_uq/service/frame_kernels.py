"""The service's small compiled passes over a frame's columns (kept apart from :mod:`.core`, whose edits then
leave numba's cache of every kernel valid: the package's cache key covers every file that holds a kernel)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .messages.asn1_cpm import CONTAINER_ID_PERCEIVED_OBJECTS, DEFAULT_CDD
from .messages.cpm import CONFIDENCE_LEVEL_UNAVAILABLE, COORD_GUARD_CM, COORD_MAX, COORD_MIN, TIMESTAMP_ITS_MAX
from .messages.sdsm import OFFSET_MAX
from .messages.uper_cpm import (
    REFERENCE_TIME_AT,
    CpmUperWriter,
    container_constants,
    kernel_motion,
    plain_container_kernel,
)

__all__ = ["worst_usable", "cm_dm", "plain_cpm_container", "plain_cpm_uper"]


@njit(cache=True, nogil=True)
def worst_usable(nl, usable, threshold, worst, ok):  # pragma: no cover - compiled
    """Per row of ``nl (N, K)``: the largest finite value among the ``usable`` ones into ``worst`` (NaN if none)
    and ``ok`` = that <= ``threshold`` (False if none): :meth:`.core.Service._linearity` in one pass."""
    for i in range(nl.shape[0]):
        w = -math.inf
        found = False
        for k in range(nl.shape[1]):
            v = nl[i, k]
            if usable[i, k] and math.isfinite(v):
                found = True
                w = max(w, v)
        worst[i] = w if found else math.nan
        ok[i] = found and w <= threshold


@njit(cache=True, nogil=True)
def _cm_dm_kernel(en, rows, cm_min, cm_max, dm_max, cm_guard):  # pragma: no cover - compiled
    out = np.empty((4, rows.shape[0]), np.int64)
    for j in range(rows.shape[0]):
        for a in range(2):
            v = en[rows[j], a]
            if v != v:  # NaN -> 0, as numpy.nan_to_num (only from absurd coordinates: inf - inf)
                v = 0.0
            c = np.ceil(v * 100.0 - cm_guard)  # CartesianCoordinateLarge: (n-1) x 0.01 < v <= n x 0.01
            d = np.rint(v * 10.0)
            out[a, j] = int(min(max(c, cm_min), cm_max))
            out[2 + a, j] = int(min(max(d, -dm_max), dm_max))
    return out


def cm_dm(en: np.ndarray, rows: np.ndarray):
    """:func:`~.messages.cpm.coordinate_cm` and :func:`~.messages.sdsm.offset_dm` of the east/north metres
    ``en[rows]``: x cm, y cm, x dm, y dm (the same numbers in one compiled pass)."""
    return _cm_dm_kernel(np.ascontiguousarray(en, dtype=np.float64), np.asarray(rows, dtype=np.int64),
                         float(COORD_MIN), float(COORD_MAX), float(OFFSET_MAX), COORD_GUARD_CM)


@njit(cache=True, nogil=True)
def _plain_cpm_kernel(en, rows, class_p, object_ids, v2x, at, class_idx, class_row, cv_tab, cw_tab, motion,
                      with_motion, lo, hi, n_total, corr_prefix, corr_bits, cm_min, cm_max, dm_max, cm_guard,
                      level_unavailable):  # pragma: no cover - compiled
    """:func:`plain_cpm_container` in one compiled call: the objects' cm (:func:`_cm_dm_kernel`), their
    ConfidenceLevels (``class_p (N,)``, NaN: unavailable; an empty array: none given) and the container
    (:func:`~.messages.uper_cpm.plain_container_kernel`)."""
    m = rows.shape[0]
    cm = _cm_dm_kernel(en, rows, cm_min, cm_max, dm_max, cm_guard)
    level = np.empty(m, np.int64)
    for j in range(m):
        if class_p.shape[0] == 0:
            level[j] = level_unavailable
            continue
        p = class_p[rows[j]]
        level[j] = level_unavailable if p != p else int(max(1.0, np.ceil(100.0 * p - 1e-9)))
    return plain_container_kernel(object_ids, cm, v2x, rows, at, class_idx, class_row, cv_tab, cw_tab, level,
                                  motion, with_motion, lo, hi, n_total, corr_prefix, corr_bits)


@njit(cache=True, nogil=True)
def _put_bits(out, pos, value, nbits):  # pragma: no cover - compiled
    """The ``nbits`` low bits of ``value`` ORed into ``out`` (uint8, zero there) from bit ``pos`` on, most
    significant first; the bit after them."""
    for b in range(nbits - 1, -1, -1):
        if (value >> b) & 1:
            out[pos >> 3] |= np.uint8(0x80 >> (pos & 7))
        pos += 1
    return pos


@njit(cache=True, nogil=True)
def _cpm_message(head, head_bits, ref_at, ref, cid_m1, data):  # pragma: no cover - compiled
    """The CPM's octets: its first ``head_bits`` bits (``head``, the reference time's 42 bits at ``ref_at`` zero
    there), the reference time ``ref``, then the WrappedCpmContainer of id ``cid_m1 + 1`` holding the octets
    ``data`` (containerId, the open type's length determinant, the octets), zero bits to the octet -- what
    ``uper_cpm.CpmUperWriter.encode`` writes with Python integers.  Empty: ``data`` too long for an unfragmented
    open type (16384 octets or more: the writer names it)."""
    n = data.shape[0]
    if n >= 16384:
        return np.zeros(0, np.uint8)
    hdr = 12 if n < 128 else 20
    out = np.zeros((head_bits + hdr + 8 * n + 7) // 8, np.uint8)
    out[:(head_bits + 7) // 8] = head[:(head_bits + 7) // 8]
    _put_bits(out, ref_at, ref, 42)
    pos = _put_bits(out, head_bits, (cid_m1 << 8) | n if n < 128 else (cid_m1 << 16) | 0x8000 | n, hdr)
    k, o = pos >> 3, pos & 7
    for i in range(n):
        b = np.int64(data[i])
        out[k + i] |= np.uint8(b >> o)
        if o:
            out[k + i + 1] |= np.uint8((b << (8 - o)) & 0xFF)
    return out


@njit(cache=True, nogil=True)
def _plain_cpm_message_kernel(head, head_bits, ref_at, ref, cid_m1, en, rows, class_p, object_ids, v2x, at, class_idx,
                              class_row, cv_tab, cw_tab, motion, with_motion, lo, hi, n_total, corr_prefix,
                              corr_bits, cm_min, cm_max, dm_max, cm_guard,
                              level_unavailable):  # pragma: no cover - compiled
    """:func:`plain_cpm_uper` in one compiled call: :func:`_plain_cpm_kernel`, then :func:`_cpm_message`;
    ``(octets, col)``, ``col >= 0``: a value out of range (no octets)."""
    out, col, _ = _plain_cpm_kernel(en, rows, class_p, object_ids, v2x, at, class_idx, class_row, cv_tab, cw_tab,
                                    motion, with_motion, lo, hi, n_total, corr_prefix, corr_bits, cm_min, cm_max,
                                    dm_max, cm_guard, level_unavailable)
    if col >= 0:
        return out, col
    return _cpm_message(head, head_bits, ref_at, ref, cid_m1, out), col


_NO_CLASS_P = np.zeros(0)


def _kernel_args(en, rows, class_p, object_ids, v2x, cpm_at, class_idx, class_row, class_value, class_width, cdd,
                 motion) -> tuple:
    """The arguments of :func:`_plain_cpm_kernel` (see :func:`plain_cpm_container`)."""
    lo, hi, prefix, bits = container_constants(cdd)
    m = len(rows)
    return (en, rows, _NO_CLASS_P if class_p is None else class_p, object_ids, v2x, cpm_at, class_idx, class_row,
            class_value, class_width, *kernel_motion(motion, m), lo, hi, min(m, 255), prefix, bits,
            float(COORD_MIN), float(COORD_MAX), float(OFFSET_MAX), COORD_GUARD_CM, CONFIDENCE_LEVEL_UNAVAILABLE)


def plain_cpm_container(en: np.ndarray, rows: np.ndarray, class_p: np.ndarray | None, object_ids: np.ndarray,
                        v2x: np.ndarray, cpm_at: int, class_idx: np.ndarray, class_row: np.ndarray,
                        class_value: np.ndarray, class_width: np.ndarray, *, cdd: str = DEFAULT_CDD,
                        motion=None) -> bytes | None:
    """The PerceivedObjectContainer (UPER octets) of a frame's objects ``rows`` from its columns, in one compiled
    call: :func:`cm_dm`'s cm of ``en[rows]``, the ConfidenceLevels of ``class_p[rows]`` (the service's
    ``_confidence_levels``) and :func:`~.messages.uper_cpm.plain_container_uper` -- the same bytes.

    Parameters
    ----------
    en : ndarray (N, 2) float64, C-contiguous
        The frame's objects east / north of the messages' reference (m).
    rows : ndarray (m,) int64
        The objects in the message (sorted rows of the frame).
    class_p : ndarray (N,) float64 or None
        Class confidences in [0, 1] (NaN: unavailable); None: none given.
    object_ids : ndarray (m,) int64
        Their message ids.
    v2x : ndarray (7, N) int32, C-contiguous
        The frame's V2X codes (the CPM's x / y confidence and correlation at rows ``cpm_at``..``cpm_at + 2``).
    class_idx, class_row, class_value, class_width :
        As :func:`~.messages.uper_cpm.plain_container_uper`.
    motion : MotionCodes or ObjectMotion, optional
        The m objects' motion (:func:`~.messages.motion.motion_codes`); None: no motion sent.

    Returns
    -------
    The container's octets; None where a value is out of range (the general writer then names it).
    """
    out, col, _ = _plain_cpm_kernel(*_kernel_args(en, rows, class_p, object_ids, v2x, cpm_at, class_idx, class_row,
                                                  class_value, class_width, cdd, motion))
    return None if col >= 0 else out.tobytes()


def plain_cpm_uper(writer: CpmUperWriter, reference_time_ms: int, en: np.ndarray, rows: np.ndarray,
                   class_p: np.ndarray | None, object_ids: np.ndarray, v2x: np.ndarray, cpm_at: int,
                   class_idx: np.ndarray, class_row: np.ndarray, class_value: np.ndarray, class_width: np.ndarray, *,
                   cdd: str = DEFAULT_CDD, motion=None) -> bytes | None:
    """The whole CPM (UPER octets) of :func:`plain_cpm_container`'s objects by the station's ``writer``, in one
    compiled call: ``writer.encode(reference_time_ms, plain_cpm_container(...))``, the same bytes (its head
    :attr:`~.messages.uper_cpm.CpmUperWriter.head` copied, the reference time and the container appended by
    bits).  The parameters after ``reference_time_ms`` (ms, TimestampIts) are :func:`plain_cpm_container`'s.
    None: a value out of range (the general writer then names it); a reference time or a container beyond what
    the message holds: the writer's error (:class:`~footprint_uq.errors.InputError`), as ``encode`` raises it."""
    args = _kernel_args(en, rows, class_p, object_ids, v2x, cpm_at, class_idx, class_row, class_value, class_width,
                        cdd, motion)
    if 0 <= reference_time_ms <= TIMESTAMP_ITS_MAX:
        out, col = _plain_cpm_message_kernel(writer.head, writer.head_bits, REFERENCE_TIME_AT, reference_time_ms,
                                             CONTAINER_ID_PERCEIVED_OBJECTS - 1, *args)
        if col >= 0:
            return None
        if out.size:
            return out.tobytes()
    container = plain_cpm_container(en, rows, class_p, object_ids, v2x, cpm_at, class_idx, class_row, class_value,
                                    class_width, cdd=cdd, motion=motion)
    return None if container is None else writer.encode(reference_time_ms, container)
