"""Velocity, speed, heading and yaw with their confidences, as the V2X messages' motion fields take them.

Conventions (docs/conventions.md): velocities are rotated from the world frame W into true east / north by the
camera's ``heading_offset_deg`` (the bearing of W's +y axis, as the messages' positions); headings and yaws are
compass bearings, degrees clockwise from true north in [0, 360).

Heading near zero speed (the NaN policy, as the ``uncertainties`` package: a value whose confidence cannot be
stated keeps its value and gets a NaN sigma): the heading is ``atan2(v_east, v_north)`` wherever the speed is
not 0; its sigma (delta method, ``sigma^2 = g^T Sigma_v g`` with ``g = (v_north, -v_east) / speed^2``) is given
only where ``speed >= heading_min_ratio * sigma_v_max`` (the velocity ellipse's largest 1-sigma semi-axis):
below that the direction of the velocity is not known well enough for a Gaussian interval (at a ratio of 3 the
ellipse's 2.45-sigma contour nearly reaches zero speed) and ``sigma_heading_deg`` is NaN ("unavailable").
The speed's sigma is the delta method's along the estimated direction; it is NaN at exactly zero speed.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .._checks import as_float
from ..errors import InputError
from .kernels import motion_fields
from .table import TrackOutput, TrackTable, c_float64

__all__ = ["ObjectMotion", "MotionArrays", "MOTION_FIELDS", "object_motion", "track_motion",
           "DEFAULT_HEADING_MIN_RATIO", "yaw_compass_deg"]

#: heading sigma only where speed >= this many sigma of the velocity's largest semi-axis
DEFAULT_HEADING_MIN_RATIO = 3.0


class ObjectMotion(NamedTuple):
    """Per-object motion of one frame (arrays of length n; NaN = unknown), as the tracker gives it and the V2X
    messages (``service.messages.motion``: CPM velocity / yawAngle / objectAge, SDSM speed / heading) take it.

    v_east_mps, v_north_mps : (n,)    velocity, true east / north, m/s
    cov_v_m2ps2 : (n, 2, 2)           its covariance (east, north), m^2/s^2
    speed_mps, sigma_speed_mps : (n,)
    heading_deg, sigma_heading_deg : (n,)   direction of motion, compass (clockwise from true north), deg
    yaw_deg, sigma_yaw_deg : (n,)     body orientation (front; a 3-D box's yaw as a compass bearing of its length
                                      axis), deg
    age_s : (n,)                      time since the track's first detection, s
    """

    v_east_mps: np.ndarray
    v_north_mps: np.ndarray
    cov_v_m2ps2: np.ndarray
    speed_mps: np.ndarray
    sigma_speed_mps: np.ndarray
    heading_deg: np.ndarray
    sigma_heading_deg: np.ndarray
    yaw_deg: np.ndarray
    sigma_yaw_deg: np.ndarray
    age_s: np.ndarray

    def take(self, rows) -> ObjectMotion:
        """The motion of the objects ``rows`` (an index array), in that order."""
        return ObjectMotion(*(np.asarray(a)[rows] for a in self))


#: the tracker's name for :class:`ObjectMotion` (one class)
MotionArrays = ObjectMotion


MOTION_FIELDS = MotionArrays._fields


def yaw_compass_deg(yaw_rad, heading_offset_deg: float = 0.0) -> np.ndarray:
    """3-D box yaws (radians counter-clockwise from W's +x, the box columns' ``yaw_rad``) as compass bearings
    (degrees clockwise from true north, [0, 360))."""
    return np.mod(90.0 - np.rad2deg(np.asarray(yaw_rad, dtype=np.float64)) + heading_offset_deg, 360.0)


def object_motion(tracks: TrackOutput, *, heading_offset_deg: float = 0.0, yaw_rad=None, sigma_yaw_rad=None,
                  heading_min_ratio: float = DEFAULT_HEADING_MIN_RATIO, motion_pass: tuple | None = None,
                  age_s: np.ndarray | None = None) -> ObjectMotion:
    """The motion fields of a frame's objects from the tracker's output (see the module doc for the policies).

    Parameters
    ----------
    tracks : TrackOutput
        :meth:`footprint_uq.tracking.table.TrackTable.step`'s output for the frame (n objects).
    heading_offset_deg : float
        Bearing of W's +y axis from true north (the camera's, as for its positions).
    yaw_rad, sigma_yaw_rad : (n,), optional
        3-D boxes' yaw (W, counter-clockwise from +x, rad) and its sigma if the detector gives one (else NaN).
    heading_min_ratio : float
        Speed / largest velocity sigma below which the heading's sigma is NaN.
    motion_pass : (kernel, extra), optional
        A compiled call to run instead of :func:`~footprint_uq.tracking.kernels.motion_fields`, as
        ``kernel(*motion_fields' arguments, age_s (n,), *extra)``: it runs that pass (whose outputs are the
        motion's) and whatever else it does with them in the same call (the service: the messages' codes,
        ``service/messages/motion.py`` ``codes_pass``).
    age_s : (n,), optional
        The motion's ``age_s``: a C-contiguous float64 array is taken as it is, not copied
        (:meth:`~footprint_uq.tracking.camera_tracker.CameraTracker.step_frame`: its own step's ``tracks.age_s``,
        which nothing writes), anything else converted (another length: :class:`~footprint_uq.errors.InputError`);
        None: a copy of ``tracks.age_s``.
    """
    # (what the tracker hands -- finite floats, C-contiguous float64 rows, float64 columns of n -- passes a few
    # attribute tests without a call, as in TrackTable.step: the frame's walk stays in tracking/)
    h, ratio = _options(heading_offset_deg, heading_min_ratio)
    n = len(tracks.track_id)
    v, cov = c_float64(tracks.v_mps), c_float64(tracks.cov_v_m2ps2)
    age = tracks.age_s.copy() if age_s is None else _column("age_s", age_s, n)
    hr = math.radians(h)
    out, cov_out = np.empty((8, n)), np.empty((n, 2, 2))
    yaw = _NONE if yaw_rad is None else _column("yaw_rad", yaw_rad, n, True)
    sigma_yaw = _NONE if sigma_yaw_rad is None else _column("sigma_yaw_rad", sigma_yaw_rad, n)
    if v.shape != (n, 2) or cov.shape != (n, 2, 2):  # (the kernel reads n rows of each: a malformed output's
        # shorter rows would be read past their end)
        bad = ("tracks.v_mps", v.shape, f"shape ({n}, 2)") if v.shape != (n, 2) else \
            ("tracks.cov_v_m2ps2", cov.shape, f"shape ({n}, 2, 2)")
        raise InputError(*bad)
    args = (v, cov, math.cos(hr), math.sin(hr), ratio, yaw, sigma_yaw, h, out, cov_out)
    if motion_pass is None:
        motion_fields(*args)
    else:
        motion_pass[0](*args, age, *motion_pass[1])
    return _motion_of(out, cov_out, age)


def track_motion(table: TrackTable, time_s: float, object_ids, xy_m, cov_frame_m2=None, shared_m=None, *,
                 cov_m2=None, heading_offset_deg: float = 0.0, yaw_rad=None, sigma_yaw_rad=None,
                 heading_min_ratio: float = DEFAULT_HEADING_MIN_RATIO) -> tuple[TrackOutput, ObjectMotion]:
    """A frame through ``table`` and the motion fields of its objects: :meth:`~footprint_uq.tracking.table.
    TrackTable.step` then :func:`object_motion` (same arguments, the same numbers to the bit), the fields formed in
    the step's compiled call where the step is one (:func:`~footprint_uq.tracking.imm_kernels.frame_step`: one
    call from the centres to the motion, ~1.5 us less per 100-object frame than the two calls).

    The motion's ``age_s`` is the output's own ``age_s`` array (one array: neither is written after the step).
    Bad motion arguments (heading, ratio, yaws of another length) raise :class:`~footprint_uq.errors.InputError`
    before the step, so the tracks are left as they were.

    Returns
    -------
    (TrackOutput, ObjectMotion)
        The step's output and the motion of the frame's objects, in frame order.
    """
    h, ratio = _options(heading_offset_deg, heading_min_ratio)
    n = xy_m.shape[0] if type(xy_m) is _ND and xy_m.ndim == 2 else c_float64(xy_m).reshape(-1, 2).shape[0]
    # (the yaws contiguous, unlike object_motion's: frame_step has one signature, its compile is long; a float64
    # column of n, as a frame's boxes hand it, copied without _column's conversions, ~0.4 us less)
    yaw = _NONE if yaw_rad is None else _contiguous("yaw_rad", yaw_rad, n)
    sigma_yaw = _NONE if sigma_yaw_rad is None else _contiguous("sigma_yaw_rad", sigma_yaw_rad, n)
    hr = math.radians(h)
    out, cov_out = np.empty((8, n)), np.empty((n, 2, 2))
    tracks = table.step(time_s, object_ids, xy_m, cov_frame_m2, shared_m, cov_m2=cov_m2,
                        motion=(math.cos(hr), math.sin(hr), ratio, yaw, sigma_yaw, h, out, cov_out))
    return tracks, _motion_of(out, cov_out, tracks.age_s)


def _motion_of(out: np.ndarray, cov_out: np.ndarray, age: np.ndarray) -> ObjectMotion:
    """The :class:`ObjectMotion` of :func:`~footprint_uq.tracking.kernels.motion_fields`' outputs ``out (8, n)``
    and ``cov_out (n, 2, 2)`` with ``age`` (its rows as views by index: ~0.2 us less than unpacking the array
    through its iterator)."""
    return _new_motion(ObjectMotion, (out[0], out[1], cov_out, out[2], out[3], out[4], out[5], out[6], out[7], age))


def _options(h, ratio) -> tuple[float, float]:
    """``heading_offset_deg`` and ``heading_min_ratio`` checked: finite floats pass without a call into ``_checks``
    (the tracker's frames), anything else is converted or named."""
    if not (isinstance(h, float) and math.isfinite(h)):
        h = as_float("heading_offset_deg", h)
    if not (isinstance(ratio, float) and math.isfinite(ratio) and ratio > 0.0):
        ratio = as_float("heading_min_ratio", ratio, positive=True)
    return h, ratio


#: a tuple of :class:`ObjectMotion`'s ten fields made an ObjectMotion without the named tuple's ``__new__``
_new_motion = tuple.__new__
_F8 = np.dtype(np.float64)
_ND = np.ndarray


_NONE = np.empty(0)


def _contiguous(name: str, a, n: int) -> np.ndarray:
    """``a`` as a C-contiguous, writable float64 (n,) array (:func:`_column` without its strided case: a strided
    float64 column of n copied at once; a read-only one copied too -- numba would compile a read-only
    specialisation of ``frame_step``)."""
    if not (a.__class__ is _ND and a.dtype is _F8 and a.ndim == 1 and len(a) == n):
        a = _column(name, a, n)
    flags = a.flags
    return a if flags.c_contiguous and flags.writeable else a.copy()


def _column(name: str, a, n: int, strided: bool = False) -> np.ndarray:
    """``a`` as a float64 (n,) array: a C-contiguous float64 (n,) array as it is, and a strided one where
    ``strided`` (a column of the frame's boxes, the yaw: motion_fields has a signature for it); anything else as a
    contiguous copy (a compiled pass of the signatures it has, nothing compiled in a frame)."""
    if a.__class__ is _ND and a.dtype is _F8 and a.ndim == 1 and len(a) == n and (strided or a.flags.c_contiguous):
        return a
    a = np.ascontiguousarray(a, dtype=np.float64).reshape(-1)
    if a.shape[0] != n:
        raise InputError(name, a.shape, f"{n} values, one per object")
    return a
