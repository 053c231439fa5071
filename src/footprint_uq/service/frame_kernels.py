"""The service's small compiled passes over a frame's columns (kept apart from :mod:`.core`, whose edits then
leave numba's cache of every kernel valid: the package's cache key covers every file that holds a kernel)."""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

from .messages.asn1_cpm import CONTAINER_ID_PERCEIVED_OBJECTS, DEFAULT_CDD
from .messages.cpm import CONFIDENCE_LEVEL_UNAVAILABLE, COORD_GUARD_CM, COORD_MAX, COORD_MIN, TIMESTAMP_ITS_MAX
from .messages.sdsm import OFFSET_MAX
from .messages.uper_cpm import (
    REFERENCE_TIME_AT,
    CpmUperWriter,
    container_constants,
    kernel_motion,
    plain_container_kernel,
    plain_objects_bits,
    write_plain_objects,
)

__all__ = ["worst_usable", "cm_dm", "plain_cpm_container", "plain_cpm_uper", "LeanCpm", "lean_cpm_constants",
           "lean_cpm_uper", "enu_columns", "enu_modes", "ENU_PLAIN", "ENU_FMA_LAST", "ENU_FMA_FIRST", "ENU_GIVEN"]


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


# -- the lean frame's CPM: one call of few arguments, the world -> ENU transform inside ------------------------------

#: how a compiled pass forms east / north ``e_j = d0 Rt[0, j] + d1 Rt[1, j]`` of ``d = xy - origin`` (``Rt``: the map
#: tie's rotation transposed) to the bit as numpy's ``d @ Rt`` does it here (BLAS: :func:`enu_modes` finds out):
#: two products rounded, then added; ``fma(d1, Rt[1, j], round(d0 Rt[0, j]))``; ``fma(d0, Rt[0, j], round(d1
#: Rt[1, j]))``; or the values are east / north already (numpy's product formed by the caller)
ENU_PLAIN, ENU_FMA_LAST, ENU_FMA_FIRST, ENU_GIVEN = 0, 1, 2, 3


@intrinsic
def _fma(typingctx, a, b, c):
    """``a * b + c`` rounded once (LLVM's ``llvm.fma.f64``: the FMA instruction, or libm's exact fma)."""
    if not all(isinstance(t, types.Float) for t in (a, b, c)):
        return None

    def codegen(context, builder, signature, args):
        return builder.fma(*args)

    return types.float64(types.float64, types.float64, types.float64), codegen


@njit(cache=True, nogil=True, inline="always")
def _enu_of(d0, d1, r0, r1, mode):  # pragma: no cover - compiled
    """``d0 r0 + d1 r1`` with the roundings of ``mode`` (:data:`ENU_PLAIN` ...)."""
    if mode == ENU_FMA_LAST:
        return _fma(d1, r1, d0 * r0)
    if mode == ENU_FMA_FIRST:
        return _fma(d0, r0, d1 * r1)
    return d0 * r0 + d1 * r1


@njit(cache=True, nogil=True)
def enu_columns(xy, tie, mode):  # pragma: no cover - compiled
    """East / north ``(2, N)`` (m) of the world points ``xy (2, N)`` (m) under the map tie ``tie`` = (origin x, y,
    ``Rt[0, 0], Rt[0, 1], Rt[1, 0], Rt[1, 1]``) with the roundings of ``mode`` (:data:`ENU_GIVEN`: a copy): what
    the lean CPM's kernel computes, for :func:`enu_modes` and the tests."""
    out = np.empty((2, xy.shape[1]))
    for i in range(xy.shape[1]):
        if mode == ENU_GIVEN:
            out[0, i], out[1, i] = xy[0, i], xy[1, i]
            continue
        d0, d1 = xy[0, i] - tie[0], xy[1, i] - tie[1]
        out[0, i] = _enu_of(d0, d1, tie[2], tie[4], mode)
        out[1, i] = _enu_of(d0, d1, tie[3], tie[5], mode)
    return out


#: the frame sizes :func:`enu_modes` asks numpy about, in both layouts (one object: a vector-matrix product, asked
#: 256 times; more: a matrix product, whose kernels differ in their tails and, for many rows, in their blocking)
_PROBE_SIZES = ((1,) * 256, (2, 3, 5, 8, 17, 100, 255, 1001, 4099, 10000))


@functools.cache
def enu_modes() -> tuple[int, int] | None:
    """Which :data:`ENU_PLAIN` / :data:`ENU_FMA_LAST` / :data:`ENU_FMA_FIRST` gives numpy's ``(xy - origin) @
    Rt`` (the service's ``CameraSetup.world_to_enu``) to the bit on this machine, for one point and for more:
    ``(mode_one, mode_many)``, found once by asking numpy (its BLAS picks its kernels by CPU: an FMA kernel sums
    ``d1 Rt[1, j]`` into the rounded ``d0 Rt[0, j]``), over points in both memory layouts; None when no mode gives
    every probe's bits (the caller then keeps numpy's product)."""
    rng = np.random.default_rng(20261129)
    c, s = math.cos(0.7), math.sin(0.7)
    rt = np.array([[c, s], [-s, c]]).T  # (as GeoReference.R_enu_world.T: a transposed view)
    origin = np.array([123.456, -78.9])
    tie = np.array([origin[0], origin[1], rt[0, 0], rt[0, 1], rt[1, 0], rt[1, 1]])
    modes = []
    for sizes in _PROBE_SIZES:
        probes = []
        for n in sizes:
            xy = rng.normal(size=(n, 2)) * rng.choice([1.0, 300.0, 4e4], size=(n, 1))
            for pts in (xy, np.asfortranarray(xy)):
                probes.append((np.ascontiguousarray(pts.T), ((pts - origin) @ rt).T))
        found = [m for m in (ENU_FMA_LAST, ENU_FMA_FIRST, ENU_PLAIN)
                 if all(np.array_equal(enu_columns(xy, tie, m), want) for xy, want in probes)]
        if len(found) != 1:  # (none; or the probes did not tell the modes apart: numpy's product kept)
            return None
        modes.append(found[0])
    return modes[0], modes[1]


class LeanCpm(NamedTuple):
    """A camera's constants of :func:`lean_cpm_uper`, packed once: ``ints`` (int64: the layout of :data:`_CI`, the
    container's column ranges and the class tables), ``head`` (the station's fixed octets,
    :attr:`~.messages.uper_cpm.CpmUperWriter.head`) and ``tie`` (float64 (6,): origin x, y (m), ``Rt``)."""

    ints: np.ndarray
    head: np.ndarray
    tie: np.ndarray


#: offsets in :attr:`LeanCpm.ints`: head bits, reference time's bit, container id - 1, the CPM's V2X row, the
#: correlation's prefix and bits, the ENU modes (one point, more), the number of class-table rows, then the
#: container's column ranges (lo, hi) and the class tables (values, widths)
(_CI_HEAD_BITS, _CI_REF_AT, _CI_CID_M1, _CI_AT, _CI_CORR_PREFIX, _CI_CORR_BITS, _CI_ENU_ONE, _CI_ENU_MANY,
 _CI_NCLASS, _CI_LO) = range(10)
_NCOLS = container_constants()[0].shape[0]
_CI_HI = _CI_LO + _NCOLS
_CI_CLASS = _CI_HI + _NCOLS
_CM_MIN, _CM_MAX = float(COORD_MIN), float(COORD_MAX)
_NO_MOTION = kernel_motion(None, 0)[0]


def lean_cpm_constants(writer: CpmUperWriter, cdd: str, origin_m: np.ndarray, rotation_t: np.ndarray, cpm_at: int,
                       class_value: np.ndarray, class_width: np.ndarray) -> LeanCpm | None:
    """A camera's :class:`LeanCpm`: its station's ``writer``, CDD release ``cdd``, map tie (``origin_m`` (2,) m and
    ``rotation_t``, the world -> ENU rotation transposed: ``CameraSetup.world_to_enu``), the CPM's row
    ``cpm_at`` of the V2X codes and the class tables (``class_value``, ``class_width``: one entry per row).  None
    when numpy's world -> ENU product cannot be matched to the bit here (:func:`enu_modes`)."""
    modes = enu_modes()
    if modes is None:
        return None
    lo, hi, prefix, bits = container_constants(cdd)
    ints = np.concatenate([
        np.array([writer.head_bits, REFERENCE_TIME_AT, CONTAINER_ID_PERCEIVED_OBJECTS - 1, cpm_at, prefix, bits,
                  *modes, len(class_value)], np.int64), lo, hi, np.asarray(class_value, np.int64),
        np.asarray(class_width, np.int64)])
    rt = np.asarray(rotation_t, np.float64)
    tie = np.array([*np.asarray(origin_m, np.float64), rt[0, 0], rt[0, 1], rt[1, 0], rt[1, 1]])
    return LeanCpm(ints, writer.head, tie)


@njit(cache=True, nogil=True, inline="always")
def _cm_of(v):  # pragma: no cover - compiled
    """:func:`_cm_dm_kernel`'s cm of one coordinate (m)."""
    if v != v:
        v = 0.0
    return int(min(max(np.ceil(v * 100.0 - COORD_GUARD_CM), _CM_MIN), _CM_MAX))


@njit(cache=True, nogil=True)
def _lean_cm_levels(ci, tie, values, rows, class_p):  # pragma: no cover - compiled
    """The cm ``(2, m)`` of the objects ``rows`` (their world x / y in rows 0 and 1 of ``values``, made east / north
    as numpy makes them: :func:`enu_columns`) and their ConfidenceLevels ``(m,)`` (as :func:`_plain_cpm_kernel`)."""
    m = rows.shape[0]
    mode = ci[_CI_ENU_ONE] if values.shape[1] == 1 else ci[_CI_ENU_MANY]
    cm = np.empty((2, m), np.int64)
    level = np.empty(m, np.int64)
    for j in range(m):
        r = rows[j]
        e0, e1 = values[0, r], values[1, r]
        if mode != ENU_GIVEN:
            d0, d1 = e0 - tie[0], e1 - tie[1]
            e0, e1 = _enu_of(d0, d1, tie[2], tie[4], mode), _enu_of(d0, d1, tie[3], tie[5], mode)
        cm[0, j], cm[1, j] = _cm_of(e0), _cm_of(e1)
        if class_p.shape[0] == 0:
            level[j] = CONFIDENCE_LEVEL_UNAVAILABLE
            continue
        p = class_p[r]
        level[j] = CONFIDENCE_LEVEL_UNAVAILABLE if p != p else int(max(1.0, np.ceil(100.0 * p - 1e-9)))
    return cm, level


@njit(cache=True, nogil=True)
def _lean_cpm_kernel(ci, head, tie, ref, values, rows, class_p, object_ids, v2x, class_idx, class_row, motion,
                     with_motion):  # pragma: no cover - compiled
    """:func:`lean_cpm_uper` in one compiled call: the cm and levels (:func:`_lean_cm_levels`), the container's
    size and checks (:func:`~.messages.uper_cpm.plain_objects_bits`) and the message -- the head, the reference
    time, the container's length determinant and the container written in place after them
    (:func:`~.messages.uper_cpm.write_plain_objects`: no column table, no container copied bit by bit).  Empty: declined
    (a value out of range, a container of 16384 octets or more, motion rows of another shape)."""
    m = rows.shape[0]
    empty = np.zeros(0, np.uint8)
    if with_motion and (motion.shape[0] < 10 or motion.shape[1] != m):
        return empty
    cm, level = _lean_cm_levels(ci, tie, values, rows, class_p)
    nc, at = ci[_CI_NCLASS], ci[_CI_AT]
    cv, cw = ci[_CI_CLASS:_CI_CLASS + nc], ci[_CI_CLASS + nc:_CI_CLASS + 2 * nc]
    nbits = plain_objects_bits(object_ids, cm, v2x, rows, at, class_idx, class_row, cv, cw, level, motion,
                               with_motion, ci[_CI_LO:_CI_HI], ci[_CI_HI:_CI_CLASS], ci[_CI_CORR_BITS])
    n = (nbits + 7) // 8
    if nbits < 0 or n >= 16384:
        return empty
    hb, cid = ci[_CI_HEAD_BITS], ci[_CI_CID_M1]
    hdr = 12 if n < 128 else 20
    out = np.zeros((hb + hdr + 8 * n + 7) // 8, np.uint8)
    out[:(hb + 7) // 8] = head[:(hb + 7) // 8]
    _put_bits(out, ci[_CI_REF_AT], ref, 42)
    pos = _put_bits(out, hb, (cid << 8) | n if n < 128 else (cid << 16) | 0x8000 | n, hdr)
    lead = (np.int64(out[pos >> 3]) >> (8 - (pos & 7))) if pos & 7 else np.int64(0)
    write_plain_objects(out, pos, lead, object_ids, cm, v2x, rows, at, class_idx, class_row, cv, cw, level, motion,
                        with_motion, ci[_CI_CORR_PREFIX], ci[_CI_CORR_BITS])
    return out


def lean_cpm_uper(consts: LeanCpm, reference_time_ms: int, values: np.ndarray, rows: np.ndarray,
                  class_p: np.ndarray | None, object_ids: np.ndarray, v2x: np.ndarray, class_idx: np.ndarray,
                  class_row: np.ndarray, motion: np.ndarray | None = None) -> bytes | None:
    """:func:`plain_cpm_uper` of the service's lean frame in one compiled call of 13 arguments, the camera's
    constants packed once (:func:`lean_cpm_constants`) and the world -> ENU transform inside: the same bytes.

    Parameters
    ----------
    consts : LeanCpm
    reference_time_ms : int
        TimestampIts (ms).
    values : ndarray (q >= 2, N) float64, C-contiguous
        The frame's columns, world x / y of each object (m) in rows 0 and 1 (``FrameColumns.values``).
    rows, class_p, object_ids, v2x, class_idx, class_row :
        As :func:`plain_cpm_uper` (``v2x`` (7, N) int32, the CPM's rows at ``consts``' ``cpm_at``).
    motion : ndarray (>= 10, m) int64, C-contiguous, optional
        :func:`~.messages.motion.motion_rows`' codes of the m objects; None: no motion sent.

    Returns
    -------
    The message's octets; None where this call declines (a reference time out of range, a value out of range,
    a container too long, motion rows of another shape): :func:`plain_cpm_uper` then answers (None or the
    writer's error), as before.
    """
    if not 0 <= reference_time_ms <= TIMESTAMP_ITS_MAX:
        return None
    out = _lean_cpm_kernel(consts.ints, consts.head, consts.tie, reference_time_ms, values, rows,
                           _NO_CLASS_P if class_p is None else class_p, object_ids, v2x, class_idx, class_row,
                           _NO_MOTION if motion is None else motion, motion is not None)
    return out.tobytes() if out.size else None
