"""Object motion for the V2X messages: the interface a tracker fills, and its message fields.

:class:`ObjectMotion` holds, per object of a frame (arrays of length ``n``, in the order of the objects
given to the message builders), the motion a tracker estimated.  NaN means unknown: the field is then
left out of the CPM (an OPTIONAL component) or set to J3224's "unavailable".

Frames and angles (docs/conventions.md): velocities are **true east / north** (the messages' frame:
the world frame W rotated by the heading offset); ``heading_deg`` (direction of motion) and ``yaw_deg``
(the body's longitudinal axis, its front) are **compass bearings, degrees clockwise from true north**.
All sigmas are 1-sigma; the messages state 95 % confidences (``1.96 sigma``, as the position's).

Conversions (the CDD clause of each data element: ETSI TS 102 894-2 V2.1.1 / V2.2.1, ``ETSI-ITS-CDD``;
J2735 2016 for the SDSM):

=====================================  ===========================================================
CPM ``velocity.cartesianVelocity``     ``VelocityComponentValue`` (0.01 m/s): ``n`` if the value is
  x (east), y (north)                  "equal to or less than n x 0,01 m/s, and greater than (n-1) x
                                       0,01 m/s" -> ceil; -16383 at or below -163.83 m/s, 16382 at or
                                       above 163.81 m/s
  their confidences                    ``SpeedConfidence`` (0.01 m/s, 95 %): ``n`` "if the confidence
                                       value is equal to or less than n * 0,01 m/s" -> ceil of
                                       1.96 sigma (sigma from ``cov_v_m2ps2``'s diagonal), at least
                                       1; 126 above 1.25 m/s; 127 unknown
CPM ``angles.zAngle``                  ``CartesianAngleValue`` (0.1 deg, counter-clockwise from the
  (the yaw)                            x axis = east): ``n`` if the angle is "equal to or less than
                                       n x 0,1 degrees, and greater than (n-1) x 0,1 degrees" -> ceil
                                       of ``(90 - yaw_deg) mod 360``; 3600 "shall not be used": 0
  its confidence                       ``AngleConfidence`` (0.1 deg, 95 %): ceil of 1.96 sigma, at
                                       least 1; 126 above 12.5 deg; 127 unknown
CPM ``objectAge``                      ``DeltaTimeMilliSecondSigned (0..2047)``: "the difference in
                                       time between the moment it has been first detected and the
                                       reference time of the message"; "1500 indicates that the object
                                       has been observed for more than 1.5 s" -> floor of the age in
                                       ms, at most 2047
SDSM ``speed``                         J2735 ``Speed`` (0.02 m/s, 8191 unavailable): nearest, at most
                                       8190
SDSM ``speedConfidence``               J2735 ``SpeedConfidence`` (95 %): the tightest level (100, 10,
                                       5, 1, 0.1, 0.05, 0.01 m/s) >= 1.96 sigma; unavailable above
                                       100 m/s or unknown
SDSM ``heading``                       J2735 ``Heading`` (0.0125 deg clockwise from north, 28800
                                       unavailable): nearest, modulo 360 deg
SDSM ``headingConf``                   J2735 ``HeadingConfidence`` (95 %): the tightest level (10, 5,
                                       1, 0.1, 0.05, 0.01, 0.0125 deg) >= 1.96 sigma; unavailable above
                                       10 deg or unknown
=====================================  ===========================================================

A confidence never understates: every rule above rounds the 95 % value up to a level that contains it.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
from numba import njit

from ...errors import InputError
from ...tracking.kernels import motion_fields
from ...tracking.motion import ObjectMotion

__all__ = ["ObjectMotion", "MotionCodes", "motion_codes", "motion_rows", "MOTION_ROWS", "motion_codes_reference",
           "CodedMotion", "codes_pass", "coded",
           "unknown_motion", "SPEED_CONFIDENCE_NAMES", "HEADING_CONFIDENCE_NAMES", "SPEED_CONFIDENCE_MPS",
           "HEADING_CONFIDENCE_DEG"]

Z95 = 1.96
#: relative guard against binary rounding pushing a value exactly on a step up (as products.v2x)
_GUARD = 1e-9

VELOCITY_UNAVAILABLE = 16383
VELOCITY_MIN, VELOCITY_MAX = -16383, 16382
CONF_OUT_OF_RANGE, CONF_UNAVAILABLE = 126, 127
ANGLE_UNAVAILABLE = 3601
AGE_MAX_MS = 2047
SDSM_SPEED_UNAVAILABLE = 8191
SDSM_HEADING_UNAVAILABLE = 28800

#: J2735 SpeedConfidence levels (m/s, 95 %) of codes 1..7 and the names of codes 0..7
SPEED_CONFIDENCE_MPS = (100.0, 10.0, 5.0, 1.0, 0.1, 0.05, 0.01)
SPEED_CONFIDENCE_NAMES = ("unavailable", "prec100ms", "prec10ms", "prec5ms", "prec1ms", "prec0-1ms", "prec0-05ms",
                          "prec0-01ms")
#: J2735 HeadingConfidence levels (deg, 95 %) of codes 1..7 (the last two in the standard's order) and names
HEADING_CONFIDENCE_DEG = (10.0, 5.0, 1.0, 0.1, 0.05, 0.01, 0.0125)
HEADING_CONFIDENCE_NAMES = ("unavailable", "prec10deg", "prec05deg", "prec01deg", "prec0-1deg", "prec0-05deg",
                            "prec0-01deg", "prec0-0125deg")


def unknown_motion(n: int) -> ObjectMotion:
    """An :class:`ObjectMotion` of ``n`` objects with every field unknown (NaN)."""
    nan = np.full(n, np.nan)
    return ObjectMotion(nan, nan, np.full((n, 2, 2), np.nan), nan, nan, nan, nan, nan, nan, nan)


class MotionCodes(NamedTuple):
    """The message fields of an :class:`ObjectMotion` (int64 arrays of length n)."""

    #: CPM velocity: present (any component known), x/y VelocityComponentValue and SpeedConfidence
    has_velocity: np.ndarray
    vx: np.ndarray
    vx_conf: np.ndarray
    vy: np.ndarray
    vy_conf: np.ndarray
    #: CPM angles.zAngle: present, CartesianAngleValue, AngleConfidence
    has_yaw: np.ndarray
    yaw: np.ndarray
    yaw_conf: np.ndarray
    #: CPM objectAge: present, ms
    has_age: np.ndarray
    age_ms: np.ndarray
    #: SDSM: speed (0.02 m/s), SpeedConfidence code, heading (0.0125 deg), HeadingConfidence code
    sdsm_speed: np.ndarray
    sdsm_speed_conf: np.ndarray
    sdsm_heading: np.ndarray
    sdsm_heading_conf: np.ndarray


def _arr(name, v, n, shape=()):
    a = np.ascontiguousarray(v, dtype=np.float64)
    if a.shape != (n, *shape):
        raise InputError(f"motion.{name}", a.shape, f"an array of shape {(n, *shape)}")
    return a


def _check_sigma(name, s):
    with np.errstate(invalid="ignore"):
        if np.any(s < 0):
            raise InputError(f"motion.{name}", float(s[s < 0][0]), "a standard deviation >= 0 (NaN = unknown)")


def _ceil(x):
    with np.errstate(invalid="ignore"):
        return np.ceil(x * (1.0 - _GUARD) - _GUARD)


def _confidence(sigma, unit, out_of_range_above):
    """CDD confidence code (1..125, 126 out of range, 127 unavailable) of 1-sigma values."""
    c = Z95 * sigma
    with np.errstate(invalid="ignore"):
        n = np.clip(np.nan_to_num(_ceil(c / unit), nan=1.0), 1, 125)
        return np.where(np.isnan(c), CONF_UNAVAILABLE, np.where(c > out_of_range_above, CONF_OUT_OF_RANGE, n)
                        ).astype(np.int64)


def _velocity_value(v):
    with np.errstate(invalid="ignore"):
        n = np.clip(np.nan_to_num(_ceil(v * 100.0), nan=0.0), VELOCITY_MIN, VELOCITY_MAX)
        n = np.where(v >= 163.81, VELOCITY_MAX, np.where(v <= -163.83, VELOCITY_MIN, n))
    return np.where(np.isnan(v), VELOCITY_UNAVAILABLE, n).astype(np.int64)


def _level_code(c95, levels):
    """J2735 confidence enumeration: the code of the tightest level >= ``c95`` (0: none / unknown)."""
    lv = np.asarray(levels)
    with np.errstate(invalid="ignore"):
        ok = lv[None, :] >= (c95.reshape(-1, 1) * (1.0 - _GUARD))
    tight = np.where(ok, lv[None, :], np.inf)
    code = np.argmin(tight, axis=1) + 1
    return np.where(ok.any(1) & ~np.isnan(c95.ravel()), code, 0).reshape(c95.shape).astype(np.int64)


#: the fields :func:`motion_codes` checks, in its order: sigmas and ages (>= 0), then values (finite or NaN)
_NONNEGATIVE = ("sigma_speed_mps", "sigma_heading_deg", "sigma_yaw_deg", "age_s", "speed_mps", "cov_v_m2ps2[0, 0]",
                "cov_v_m2ps2[1, 1]")
_FINITE = ("v_east_mps", "v_north_mps", "heading_deg", "yaw_deg")


def _motion_arrays(motion: ObjectMotion, n: int) -> tuple:
    """``motion``'s fields as float arrays of shape ``(n,)`` (``cov_v_m2ps2``: ``(n, 2, 2)``), shapes checked:
    v_east, v_north, cov_v, speed, sigma_speed, heading, sigma_heading, yaw, sigma_yaw, age.  Fields that are
    already C-contiguous float64 arrays of those shapes (a tracker's, :func:`~footprint_uq.tracking.motion.
    object_motion`) are taken as they are after one check of the ten (the compiled pass's one signature)."""
    ve, vn, cov, sp, ssp, hd, shd, yw, syw, age = motion
    try:
        if ({(a.__class__, a.dtype, a.shape, a.strides) for a in (ve, vn, sp, ssp, hd, shd, yw, syw, age)}
                == {(np.ndarray, _F8, (n,), _STRIDE_1D)} and cov.__class__ is np.ndarray and cov.dtype == _F8
                and cov.shape == (n, 2, 2) and cov.strides == _STRIDE_COV):
            return ve, vn, cov, sp, ssp, hd, shd, yw, syw, age
    except AttributeError:  # (a field that is not an array: converted below)
        pass
    ve, vn = _arr("v_east_mps", ve, n), _arr("v_north_mps", vn, n)
    cov = _arr("cov_v_m2ps2", cov, n, (2, 2))
    sp, ssp = _arr("speed_mps", sp, n), _arr("sigma_speed_mps", ssp, n)
    hd, shd = _arr("heading_deg", hd, n), _arr("sigma_heading_deg", shd, n)
    yw, syw = _arr("yaw_deg", yw, n), _arr("sigma_yaw_deg", syw, n)
    age = _arr("age_s", age, n)
    return ve, vn, cov, sp, ssp, hd, shd, yw, syw, age


_F8 = np.dtype(np.float64)
_STRIDE_1D, _STRIDE_COV = (8,), (32, 16, 8)
_ALL_ROWS = np.zeros(0, np.int64)
#: :func:`motion_rows`' rows: the CPM PerceivedObject's 10 motion rows (velocity present, x, x confidence, y,
#: y confidence, angles present, zAngle, its confidence, objectAge present, objectAge), then the SDSM's 4
#: (speed, its confidence, heading, its confidence)
MOTION_ROWS = ("has_velocity", "vx", "vx_conf", "vy", "vy_conf", "has_yaw", "yaw", "yaw_conf", "has_age", "age_ms",
               "sdsm_speed", "sdsm_speed_conf", "sdsm_heading", "sdsm_heading_conf")


def motion_rows(motion: ObjectMotion, n: int, rows: np.ndarray | None = None) -> np.ndarray:
    """The message codes of ``motion`` (n objects) as one ``(14, m)`` int64 array, C-contiguous, in one compiled
    pass (:func:`_rows_kernel`): the rows of :data:`MOTION_ROWS` -- its first 10 rows are what the CPM's
    container kernel takes (``uper_cpm.kernel_motion``), the last 4 the SDSM's -- of the objects ``rows``
    ((m,) int64 indices into the n, in the message's order; None: all n in order, no copy of the motion).

    Checked as :func:`motion_codes` (shapes ``(n,)`` / ``(n, 2, 2)``; sigmas, speeds, ages >= 0 and values not
    infinite in the objects ``rows``): :class:`~footprint_uq.errors.InputError` naming the field, the first in
    the order of the checks with a bad object, and that object's value.  A :class:`CodedMotion` that keeps codes
    (:func:`coded`) gives them up instead (the objects ``rows`` of them; no second pass)."""
    kept = motion.take_codes(n) if type(motion) is CodedMotion else None
    if kept is None:
        ve, vn, cov, sp, ssp, hd, shd, yw, syw, age = cols = _motion_arrays(motion, n)
    every = rows is None
    sel = _ALL_ROWS if every else np.ascontiguousarray(rows, dtype=np.int64)
    if not every and sel.ndim != 1:
        raise InputError("rows", sel.shape, "a 1-D array of object indices")
    if not every and sel.size and (sel.min() < 0 or sel.max() >= n):
        raise InputError("rows", int(sel.min() if sel.min() < 0 else sel.max()), f"object indices in [0, {n})")
    if kept is not None:  # (computed with the record's rows, every object checked: the objects rows of them)
        return kept if every else np.ascontiguousarray(kept.take(sel, axis=1))
    out = np.empty((14, n if every else sel.shape[0]), np.int64)
    bad, row = _rows_kernel(ve, vn, cov, sp, ssp, hd, shd, yw, syw, age, sel, every, out)
    if bad >= 0:
        i = row if every else int(sel[row])
        if bad >= len(_NONNEGATIVE):
            k = bad - len(_NONNEGATIVE)
            raise InputError(f"motion.{_FINITE[k]}", float(cols[(0, 1, 5, 7)[k]][i]),
                             "a finite number (NaN = unknown)")
        value = (ssp[i], shd[i], syw[i], age[i], sp[i], cov[i, 0, 0], cov[i, 1, 1])[bad]
        raise InputError(f"motion.{_NONNEGATIVE[bad]}", float(value), "a standard deviation >= 0 (NaN = unknown)")
    return out


class CodedMotion(ObjectMotion):
    """An :class:`ObjectMotion` that keeps its message codes for one use: :func:`codes_pass` computes them for
    every object in the pass that makes the motion's fields, and the next :func:`motion_rows` (or
    :func:`motion_codes`) of the same ``n`` objects takes them -- the objects it asks for -- instead of a second
    pass over the same columns; then they are gone (a later call computes them again).  The service's tracked
    frame with messages: ``Service._step_tracks`` makes the tracker's motion one (:func:`coded`).  The codes are
    those of the arrays as the pass made them: an array changed in between is not seen (the service changes
    none).  Kept only when every object passed the checks: a bad value is named by the pass that needs the codes,
    as for any :class:`ObjectMotion`."""

    codes = None  #: (14, n) int64 or None (:func:`coded`, :meth:`take_codes`)

    @classmethod
    def of(cls, motion: ObjectMotion) -> CodedMotion:
        """``motion``'s arrays (not copied) as a CodedMotion without codes."""
        return tuple.__new__(cls, motion)

    def take_codes(self, n: int) -> np.ndarray | None:
        """The kept codes of ``n`` objects (None: none kept, or of another count), given up."""
        codes, self.codes = self.codes, None
        return codes if codes is not None and codes.shape[1] == n else None


def codes_pass(n: int) -> tuple:
    """``(kernel, (codes (14, n), status (1,)))``: :func:`~footprint_uq.tracking.motion.object_motion`'s
    ``motion_pass`` (through :meth:`~footprint_uq.tracking.camera_tracker.CameraTracker.step_frame`) that runs its
    pass (:func:`~footprint_uq.tracking.kernels.motion_fields`, called as it is: the same arrays to the bit) and
    then the messages' codes of every object of the motion into ``codes``, in one compiled call
    (:func:`_fields_and_codes`); :func:`coded` then keeps them.  The service's tracked frame
    (``Service._step_tracks``)."""
    return _fields_and_codes, (np.empty((14, n), np.int64), _NOT_RUN.copy())


def coded(motion: ObjectMotion, motion_pass: tuple) -> CodedMotion:
    """``motion`` (made by :func:`codes_pass`' ``motion_pass``) as a :class:`CodedMotion` keeping the pass's codes
    for the next :func:`motion_rows` when every object passed the checks (a bad value: none kept; that call names
    it)."""
    codes, status = motion_pass[1]
    m = CodedMotion.of(motion)
    if status[0] == -1:  # (-2: the pass did not run, or its codes were not of the motion's size)
        m.codes = codes
    return m


_NOT_RUN = np.full(1, -2, np.int64)


def motion_codes(motion: ObjectMotion, n: int, rows: np.ndarray | None = None) -> MotionCodes:
    """The CPM and SDSM fields of ``motion`` (module doc), checked: shapes ``(n,)`` / ``(n, 2, 2)``, sigmas
    and ages >= 0 -> :class:`~footprint_uq.errors.InputError` naming the field.  One compiled pass
    (:func:`motion_rows`, whose ``rows`` selects objects; :func:`motion_codes_reference` is the same in numpy)."""
    c = motion_rows(motion, n, rows)
    return MotionCodes(c[0] != 0, c[1], c[2], c[3], c[4], c[5] != 0, c[6], c[7], c[8] != 0, c[9], c[10], c[11],
                       c[12], c[13])


@njit(cache=True, nogil=True, inline="always")
def _ceil_k(x):  # pragma: no cover - compiled
    return np.ceil(x * (1.0 - _GUARD) - _GUARD)


@njit(cache=True, nogil=True, inline="always")
def _conf_k(sigma, unit, out_of_range_above):  # pragma: no cover - compiled
    c = Z95 * sigma
    if math.isnan(c):
        return CONF_UNAVAILABLE
    if c > out_of_range_above:
        return CONF_OUT_OF_RANGE
    return int(min(max(_ceil_k(c / unit), 1.0), 125.0))


@njit(cache=True, nogil=True, inline="always")
def _velocity_k(v):  # pragma: no cover - compiled
    if math.isnan(v):
        return VELOCITY_UNAVAILABLE
    if v >= 163.81:
        return VELOCITY_MAX
    if v <= -163.83:
        return VELOCITY_MIN
    return int(min(max(_ceil_k(v * 100.0), float(VELOCITY_MIN)), float(VELOCITY_MAX)))


@njit(cache=True, nogil=True, inline="always")
def _level_k(c95, levels):  # pragma: no cover - compiled
    """``levels``: a tuple (a compile-time constant: no array, whose reference count a call per object would
    update)."""
    if math.isnan(c95):
        return 0
    best, code = math.inf, 0
    for k in range(len(levels)):
        if levels[k] >= c95 * (1.0 - _GUARD) and levels[k] < best:
            best, code = levels[k], k + 1
    return code


@njit(cache=True, nogil=True, inline="always")
def _wrap_k(x, period):  # pragma: no cover - compiled
    """``np.mod(x, period)`` (``period > 0``), the same bits, without its division where ``x`` is in ``[0, period)``
    already (the pass's headings and codes, nearly always: ``np.mod`` would give ``x`` itself, and for ``-0.0``
    the ``+0.0`` that a code's ``int`` makes 0 as well).  The heading's two were a third of the pass (100 moving
    objects: 3.5 -> 2.4 us)."""
    return x if 0.0 <= x < period else np.mod(x, period)


@njit(cache=True, nogil=True, inline="always")
def _first_bad_k(ssp, shd, syw, age, sp, c00, c11, ve, vn, hd, yw):  # pragma: no cover - compiled
    """The first check an object's values fail, as an index of ``_NONNEGATIVE + _FINITE`` (11: none).  Scalars
    only (a function of the arrays, even inlined, cost ~0.2 us per object in reference counts)."""
    if ssp < 0.0:
        return 0
    if shd < 0.0:
        return 1
    if syw < 0.0:
        return 2
    if age < 0.0:
        return 3
    if sp < 0.0:
        return 4
    if c00 < 0.0:
        return 5
    if c11 < 0.0:
        return 6
    if math.isinf(ve):
        return 7
    if math.isinf(vn):
        return 8
    if math.isinf(hd):
        return 9
    if math.isinf(yw):
        return 10
    return 11


@njit(cache=True, nogil=True)
def _rows_kernel(ve, vn, cov, sp, ssp, hd, shd, yw, syw, age, rows, every, out):  # pragma: no cover - compiled
    """:func:`motion_codes_reference`'s arithmetic in one pass into ``out (14, m)`` (:data:`MOTION_ROWS`) for the
    objects ``rows`` (``every``: all, in order).  Returns ``(field, j)``: the first field (an index of
    ``_NONNEGATIVE + _FINITE``, checked field by field) with a bad object and the first such object ``j`` (of
    the m), ``(-1, -1)`` if none -- one pass: an object's own first bad field, kept where it is earlier than
    every earlier object's."""
    m = out.shape[1]
    bad_f, bad_j = 11, -1
    for j in range(m):
        i = j if every else rows[j]
        vei, vni, c00, c11, spi, sspi = ve[i], vn[i], cov[i, 0, 0], cov[i, 1, 1], sp[i], ssp[i]
        hdi, shdi, ywi, sywi, a = hd[i], shd[i], yw[i], syw[i], age[i]
        f = _first_bad_k(sspi, shdi, sywi, a, spi, c00, c11, vei, vni, hdi, ywi)
        if f < bad_f:
            bad_f, bad_j = f, j
        out[0, j] = 0 if math.isnan(vei) and math.isnan(vni) else 1
        out[1, j], out[3, j] = _velocity_k(vei), _velocity_k(vni)
        out[2, j] = _conf_k(math.sqrt(c00), 0.01, 1.25)
        out[4, j] = _conf_k(math.sqrt(c11), 0.01, 1.25)
        if math.isnan(ywi):
            out[5, j], out[6, j] = 0, ANGLE_UNAVAILABLE
        else:
            z = _wrap_k(90.0 - ywi, 360.0)
            out[5, j] = 1
            out[6, j] = ANGLE_UNAVAILABLE if math.isnan(z) else int(_wrap_k(_ceil_k(z * 10.0), 3600.0))
        out[7, j] = _conf_k(sywi, 0.1, 12.5)
        if math.isnan(a):
            out[8, j], out[9, j] = 0, 0
        else:
            out[8, j], out[9, j] = 1, int(min(math.floor(a * 1000.0 + 1e-6), float(AGE_MAX_MS)))
        out[10, j] = SDSM_SPEED_UNAVAILABLE if math.isnan(spi) else int(min(np.rint(spi / 0.02), 8190.0))
        out[11, j] = _level_k(Z95 * sspi, SPEED_CONFIDENCE_MPS)
        out[12, j] = (SDSM_HEADING_UNAVAILABLE if math.isnan(hdi)
                      else int(_wrap_k(np.rint(_wrap_k(hdi, 360.0) / 0.0125), 28800.0)))
        out[13, j] = _level_k(Z95 * shdi, HEADING_CONFIDENCE_DEG)
    if bad_j >= 0:
        return bad_f, bad_j
    return -1, -1


@njit(cache=True, nogil=True)
def _fields_and_codes(v, cov, ch, sh, ratio, yaw_rad, sigma_yaw_rad, heading_offset_deg, out, cov_out, age,
                      codes, status):  # pragma: no cover - compiled
    """:func:`~footprint_uq.tracking.kernels.motion_fields` (its arguments, called: compiled as it is, the same
    bits) and then :func:`_rows_kernel` of its outputs and ``age (n,)`` into ``codes (14, n)``, every object (not
    written if ``codes`` is not ``(14, n)``); ``status[0]`` receives the first bad field's index (-1: none)."""
    motion_fields(v, cov, ch, sh, ratio, yaw_rad, sigma_yaw_rad, heading_offset_deg, out, cov_out)
    if codes.shape[1] != age.shape[0] or age.shape[0] != out.shape[1]:
        status[0] = -2
        return
    status[0], _ = _rows_kernel(out[0], out[1], cov_out, out[2], out[3], out[4], out[5], out[6], out[7], age,
                                np.empty(0, np.int64), True, codes)


def motion_codes_reference(motion: ObjectMotion, n: int) -> MotionCodes:
    """:func:`motion_codes` in numpy: the readable reference (~100 array operations per frame) that
    tests/test_service_messages.py holds the compiled pass to, value for value."""
    ve, vn, cov, sp, ssp, hd, shd, yw, syw, age = _motion_arrays(motion, n)
    for name, s in (("sigma_speed_mps", ssp), ("sigma_heading_deg", shd), ("sigma_yaw_deg", syw), ("age_s", age),
                    ("speed_mps", sp), ("cov_v_m2ps2[0, 0]", cov[:, 0, 0]), ("cov_v_m2ps2[1, 1]", cov[:, 1, 1])):
        _check_sigma(name, s)
    for name, a in (("v_east_mps", ve), ("v_north_mps", vn), ("heading_deg", hd), ("yaw_deg", yw)):
        if np.isinf(a).any():
            raise InputError(f"motion.{name}", float(a[np.isinf(a)][0]), "a finite number (NaN = unknown)")
    sx, sy = np.sqrt(cov[:, 0, 0]), np.sqrt(cov[:, 1, 1])
    has_v = ~(np.isnan(ve) & np.isnan(vn))
    z = np.mod(90.0 - yw, 360.0)
    yaw = np.where(np.isnan(z), ANGLE_UNAVAILABLE, np.nan_to_num(_ceil(z * 10.0)) % 3600).astype(np.int64)
    with np.errstate(invalid="ignore"):
        age_ms = np.where(np.isnan(age), 0, np.minimum(np.floor(np.nan_to_num(age) * 1000.0 + 1e-6), AGE_MAX_MS))
        speed = np.where(np.isnan(sp), SDSM_SPEED_UNAVAILABLE, np.minimum(np.rint(np.nan_to_num(sp) / 0.02), 8190))
        head = np.where(np.isnan(hd), SDSM_HEADING_UNAVAILABLE, np.rint(np.mod(np.nan_to_num(hd), 360.0) / 0.0125)
                        % 28800)
    return MotionCodes(
        has_v, _velocity_value(ve), _confidence(sx, 0.01, 1.25), _velocity_value(vn), _confidence(sy, 0.01, 1.25),
        ~np.isnan(yw), yaw, _confidence(syw, 0.1, 12.5), ~np.isnan(age), age_ms.astype(np.int64),
        speed.astype(np.int64), _level_code(Z95 * ssp, SPEED_CONFIDENCE_MPS), head.astype(np.int64),
        _level_code(Z95 * shd, HEADING_CONFIDENCE_DEG))
