"""One camera's tracks, keyed by the detector's ``object_id``: initiation, gating, timeout, update."""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .._checks import as_float
from ..errors import InputError
from ..fast.buffers import thread_buffer
from ..fast.footprint_kernels import SCRATCH_SHAPE, camera_constants
from ..fast.frame_columns import camera_parts
from ..products.footprints import FrameProcessor
from .filter import Initiator, SplitMeasurement
from .imm_kernels import frame_pass, frame_step, scratch
from .kernels import (
    ID_EMPTY,
    ROW_SKIP,
    ROW_START,
    claim_rows,
    expire_rows,
    frame_rows,
    frame_rows_shared,
    frame_update,
    id_insert,
    id_lookup,
    motion_fields,
    project_ground,
)
from .models import ConstantVelocity

__all__ = ["TrackerConfig", "TrackOutput", "TrackTable", "SharedJacobianAt", "CALIBRATION_MODES", "DEFAULT_GATE_CHI2"]

_NO_B = np.zeros((0, 2, 0))
#: the compiled call that forms a frame's rows (TrackTable._rows_call): frame_rows, frame_rows_shared, frame_step
_ROWS, _ROWS_SHARED, _ONE_CALL = 0, 1, 2
_NO_IDS = np.zeros(0, np.int64)  # (frame_step: the rows are the dictionary's)
_NO_ID_TABLE = (np.zeros(1, np.int64), np.full(1, ID_EMPTY, np.int64), 63)  # (and it reads no id table)
#: frame_step's motion arguments when the step is not asked for the motion fields (``m_out (8, 0)``: not run)
_NO_MOTION = (1.0, 0.0, 1.0, np.zeros(0), np.zeros(0), 0.0, np.zeros((8, 0)), np.zeros((0, 2, 2)))


class _Index(dict):
    """The table's dictionary ``object_id -> row``, counting the ids it did not find (``misses``: reset by the
    caller, one Python call per miss, none per hit): a list frame without new ids takes the one compiled call."""

    __slots__ = ("misses",)

    def __missing__(self, key) -> int:
        self.misses += 1
        return -1
_INT64_MIN, _INT64_MAX = -2 ** 63, 2 ** 63 - 1
#: how the calibration error enters the filter: "consider" (the split model, the only honest one), "white" (the
#: whole per-frame covariance as white noise) and "ignore" (only the per-frame part) are kept to show what goes
#: wrong (docs/uncertainty-model.md)
CALIBRATION_MODES = ("consider", "white", "ignore")
#: gate: squared Mahalanobis distance of the innovation (2 dof) beyond which a detection is not the same object;
#: -2 ln(1e-6): a consistent track is cut once in a million frames
DEFAULT_GATE_CHI2 = -2.0 * math.log(1e-6)
#: acceleration density of the manoeuvre mode, m^2/s^3 (docs/uncertainty-model.md, section 11)
DEFAULT_MANOEUVRE_PSD = 30.0


@dataclass(frozen=True)
class TrackerConfig:
    """Options of :class:`TrackTable` (docs/uncertainty-model.md, "Motion: velocity and heading").

    accel_psd_m2ps3 : float
        Acceleration noise of the quiet constant-velocity mode (:class:`~footprint_uq.tracking.models.
        ConstantVelocity`): a road user driving on.
    manoeuvre_accel_psd_m2ps3 : float or None
        Acceleration noise of the manoeuvre mode (turning, braking) of the interacting-multiple-model filter; None:
        the quiet mode alone (a plain constant-velocity filter, whose ellipses lag a sustained manoeuvre).
    quiet_sojourn_s, manoeuvre_sojourn_s : float
        Mean time a road user stays in each mode (the mode switches as a continuous-time Markov chain, so the
        switching probabilities follow each step's length).
    timeout_s : float
        A track not updated for longer than this is deleted; its ``object_id`` then starts a new track.
    gate_chi2 : float
        A detection whose innovation has ``y^T S^-1 y`` above this starts a new track (its id was reused).
    sigma_v0_mps : float
        Prior sigma of each velocity component of a new track (the velocity is reported from its second
        detection on).
    calibration : {"consider", "white", "ignore"}
        :data:`CALIBRATION_MODES`; anything but "consider" is for comparisons only.
    """

    accel_psd_m2ps3: float = 1.5
    timeout_s: float = 1.0
    gate_chi2: float = DEFAULT_GATE_CHI2
    sigma_v0_mps: float = 50.0
    calibration: str = "consider"
    manoeuvre_accel_psd_m2ps3: float | None = DEFAULT_MANOEUVRE_PSD
    quiet_sojourn_s: float = 3.0
    manoeuvre_sojourn_s: float = 1.0

    def __post_init__(self):
        for name in ("accel_psd_m2ps3", "timeout_s", "gate_chi2", "sigma_v0_mps", "quiet_sojourn_s",
                     "manoeuvre_sojourn_s") + (("manoeuvre_accel_psd_m2ps3",) if self.manoeuvre_accel_psd_m2ps3
                                               is not None else ()):
            object.__setattr__(self, name, as_float(name, getattr(self, name), positive=True))
        if self.calibration not in CALIBRATION_MODES:
            raise InputError("calibration", self.calibration, f"one of {CALIBRATION_MODES}")


class TrackOutput(NamedTuple):
    """Per object of one frame (leading dimension n, the frame's objects in their order).

    track_id : (n,) int64          the track's number in this table (-1: not tracked: no id, no centre, a
                                   repeated id in the frame, or a frame not later than the previous one)
    new_track : (n,) bool          the track started at this frame (new id, timeout or a jump beyond the gate)
    n_updates : (n,) int64         detections in the track so far (0 if not tracked)
    age_s : (n,)                   time since the track's first detection, s (NaN if not tracked)
    xy_m : (n, 2), cov_xy_m2 : (n, 2, 2)           filtered position in W and its covariance (calibration share
                                                   included)
    v_mps : (n, 2), cov_v_m2ps2 : (n, 2, 2)        velocity in W and its covariance (NaN before the second
                                                   detection: a single position says nothing of the velocity)
    """

    track_id: np.ndarray
    new_track: np.ndarray
    n_updates: np.ndarray
    age_s: np.ndarray
    xy_m: np.ndarray
    cov_xy_m2: np.ndarray
    v_mps: np.ndarray
    cov_v_m2ps2: np.ndarray

    @classmethod
    def untracked(cls, n: int) -> TrackOutput:
        """n objects without a track (track_id -1, NaN)."""
        nan = np.nan
        return cls(np.full(n, -1, np.int64), np.zeros(n, bool), np.zeros(n, np.int64), np.full(n, nan),
                   np.full((n, 2), nan), np.full((n, 2, 2), nan), np.full((n, 2), nan), np.full((n, 2, 2), nan))


class TrackTable:
    """The tracks of one camera, keyed by ``object_id`` (any hashable; None is never tracked).

    Each :meth:`step` takes one frame: tracks not updated for longer than ``timeout_s`` are deleted first (the
    deleter, compiled: :func:`~footprint_uq.tracking.kernels.expire_rows`); then every object whose id has a track
    is predicted to the frame's time and gated (a jump with ``y^T S^-1 y > gate_chi2`` restarts the track under a
    new ``track_id``), the others start tracks (the initiator).  Per frame, the ids are looked up in one pass over
    a dictionary (the only per-object Python work; unknown ids, a few per frame, are then given rows), or, when
    they come as an integer array, in one compiled call (:func:`~footprint_uq.tracking.kernels.id_lookup`, a hash
    table kept beside the dictionary); the rest is two compiled passes over the frame:
    :func:`~footprint_uq.tracking.kernels.frame_rows_shared` (the rows and ``B`` at the predicted positions, when
    ``shared_at`` is a :class:`SharedJacobianAt`; else :func:`~footprint_uq.tracking.kernels.frame_rows` and one
    evaluation of ``shared_at``) and :func:`~footprint_uq.tracking.imm_kernels.frame_pass` (the update, the
    starts, the outputs).  With a :class:`SharedJacobianAt` (the consider mode, the compiled pass) these and the
    deleter's sweep are one compiled call, :func:`~footprint_uq.tracking.imm_kernels.frame_step`, unless new ids
    need the Python claim (new ids of a list; more new int64 ids than free rows: the call then stops after the
    rows).  Each track runs the
    interacting-multiple-model filter over :attr:`models` (a quiet and a manoeuvre constant-velocity mode; one
    mode if ``manoeuvre_accel_psd_m2ps3`` is None); its reported state is the modes' moment-matched combination,
    and the gate cuts a track only if the detection is beyond it for every mode.

    Parameters
    ----------
    config : TrackerConfig
    rank : int
        Columns r of the frames' ``shared_m`` (the budget's factor rank, :attr:`SharedJacobianAt.rank`).
    shared_at : callable ``(n, 2) -> (n, 2, r)``, optional
        The shared Jacobian ``B`` at world points (:class:`SharedJacobianAt`).  Given, an update uses ``B`` at
        the track's *predicted* position instead of the frame's ``shared_m`` (which is evaluated at the measured
        pixel, so its small error is correlated with that frame's noise: the filter believes it knows how the
        calibration error changes from frame to frame to a fraction of the frame noise, and a 0.2 % error of B
        that follows the noise makes 30 Hz velocity ellipses cover ~60 % instead of 95 %; docs/uncertainty-model.md).
        Always give it for real use; the frame's ``shared_m`` then serves new tracks and points it cannot map.
    """

    #: True: run the compiled reference of the update (:func:`~footprint_uq.tracking.kernels.frame_update`, the
    #: filter as the numpy classes read, ~2.5x slower) instead of :func:`~footprint_uq.tracking.imm_kernels.
    #: frame_pass`; for the agreement tests and ``bench/bench_tracking.py``
    _reference_pass = False

    def __init__(self, config: TrackerConfig | None = None, *, rank: int, shared_at=None):
        self.config = config or TrackerConfig()
        self.shared_at = shared_at
        self._consider = self.config.calibration == "consider"
        self.rank = int(rank) if self._consider else 0
        #: ``shared_at`` when it is a :class:`SharedJacobianAt` of this rank: ``B`` at the predicted positions is
        #: then formed in the rows' compiled call (:func:`~footprint_uq.tracking.kernels.frame_rows_shared`, the
        #: same ``B`` to the bit) instead of a call of ``shared_at`` (two compiled calls, their Python, ~4 us)
        self._at = shared_at if (type(shared_at) is SharedJacobianAt and self.rank  # (a subclass may change B)
                                 and shared_at.rank == self.rank) else None
        #: whether the rows' call forms ``B`` (None: decided at the first frame): yes if ``B``'s kernels were ready
        #: then (that call compiles, or loads from the cache, with the table's other kernels), later only once
        #: the call is compiled in this process (:meth:`warm_up` compiles it): a service whose kernels compiled
        #: in the background meanwhile does not stop a frame for its compile
        self._fused = None if self._at is not None else False
        self._last_scratch = (None, None)  # (_frame_scratch)
        self._work(128)
        #: the modes the compiled update runs (its per-track step, in :func:`~footprint_uq.tracking.imm_kernels.
        #: frame_pass` and its reference :func:`~footprint_uq.tracking.kernels.frame_update`, is
        #: :class:`~footprint_uq.tracking.filter.InteractingModels` -- mixing, each mode's SchmidtPredictor +
        #: SchmidtUpdater, mode probabilities, combination -- in one pass; the tests hold them equal)
        cfg = self.config
        self.models = tuple(ConstantVelocity(q) for q in (cfg.accel_psd_m2ps3, cfg.manoeuvre_accel_psd_m2ps3)
                            if q is not None)
        self.model = self.models[0]
        self._qs = np.array([m.accel_psd_m2ps3 for m in self.models])
        self._rates = np.array([1.0 / cfg.quiet_sojourn_s, 1.0 / cfg.manoeuvre_sojourn_s])[:len(self.models)]
        #: the modes' probabilities of a new track: the chain's stationary distribution
        self.mu0 = (1.0 / self._rates) / (1.0 / self._rates).sum()
        self.initiator = Initiator(self.config.sigma_v0_mps)
        self._var_v0 = self.initiator.sigma_v0_mps ** 2
        self._index = _Index({None: -2})  # object_id -> slot (-2: never tracked)
        self._index.misses = 0
        #: the compiled form of ``_index`` for frames whose ids come as an int64 array (:func:`~footprint_uq.tracking.
        #: kernels.id_lookup`: keys, values, shift; None until the first such frame; a list of integers is made an
        #: int64 array for it, :func:`_list_int64`), possible while every id the table has seen is an integer
        #: of int64's range (``_int_ids``; the first other id ends it for the table's life)
        self._int_ids = True
        self._ids = None
        self._cap = 0
        self._grow(64)
        #: the compiled pass's working arrays (it allocates nothing itself)
        self._scratch = scratch(len(self.models), self.rank)
        self._stamp = 0  # frames seen: the repeated-id stamp of frame_rows
        self._next_id = 0
        self._last_time: float = -math.inf
        #: a lower bound of every live track's last update time (no track can have expired while
        #: ``time_s - _oldest_s <= timeout_s``: the deleter sweeps only when a track may have expired -- about once
        #: per timeout in a still scene, on about two frames in three when ~1 object a frame leaves it)
        self._oldest_s = math.inf
        #: frames not tracked because their time was earlier than the previous frame's
        self.n_stale_frames = 0
        #: the NIS of the last step's objects (:meth:`frame_nis`)
        self._nis = np.zeros(0)

    def __len__(self) -> int:
        return len(self._index) - 1  # (the entry of None)

    def warm_up(self) -> None:
        """Load the compiled steps (numba's cache, or compile them) without touching the tracks: three frames
        through a scratch table of the same configuration -- one object's start with its id in an int64 array (the
        compiled id look-up and claim; with a :class:`SharedJacobianAt`, the one call of the whole frame), then
        its update and a second start with the ids as a list (the dictionary; the new id into the compiled table),
        then more new int64 ids than the table has free rows (the rows claimed after a growth); then the deleter's
        sweep of every track (its compiled pass, with the id table)."""
        scratch = TrackTable(self.config, rank=self.rank, shared_at=self.shared_at)
        meas = (np.zeros((1, 2)), np.eye(2)[None].copy(), np.zeros((1, 2, self.rank)))
        scratch.step(0.0, np.zeros(1, np.int64), *meas)
        scratch.step(0.1, [0, 1], *(np.repeat(a, 2, 0) for a in meas))
        n = scratch._n_free + 1
        scratch.step(0.2, np.arange(2, 2 + n, dtype=np.int64), *(np.repeat(a, n, 0) for a in meas))
        scratch._delete_expired(math.inf)

    def _grow(self, cap: int) -> None:
        old = self._cap
        r = self.rank

        def extend(a, shape, fill):
            b = np.full((cap,) + shape, fill, dtype=a.dtype if a is not None else np.float64)
            if a is not None:
                b[:old] = a
            return b

        def g(name):
            return getattr(self, name, None)

        self._x = extend(g("_x"), (4,), 0.0)
        self._P = extend(g("_P"), (4, 4), 0.0)
        M = len(self.models)
        self._xm = extend(g("_xm"), (M, 4), 0.0)
        self._Pm = extend(g("_Pm"), (M, 4, 4), 0.0)
        # (the consider columns C (4, r) of each mode stored column by column, (r, 4): a column's 4 entries adjacent,
        # what the compiled pass walks; tracking/imm_kernels.py)
        self._Cm = extend(g("_Cm"), (M, r, 4), 0.0)
        self._mu = extend(g("_mu"), (M,), 1.0 / M)
        self._t_last = extend(g("_t_last"), (), np.nan)
        self._t_first = extend(g("_t_first"), (), np.nan)
        self._n = extend(g("_n"), (), 0).astype(np.int64)
        self._tid = extend(g("_tid"), (), -1).astype(np.int64)
        self._seen = extend(g("_seen"), (), -1).astype(np.int64)
        keys = np.empty(cap, dtype=object)
        if old:
            keys[:old] = self._keys
        self._keys = keys
        # the free rows, a stack (top: the last of the first ``_n_free``): the new rows under the old free ones
        free = np.empty(cap, np.int64)
        free[:cap - old] = np.arange(cap - 1, old - 1, -1)
        n_free = getattr(self, "_n_free", 0)
        if n_free:
            free[cap - old:cap - old + n_free] = self._free[:n_free]
        self._free, self._n_free = free, cap - old + n_free
        self._gone, self._gone_keys = np.empty(cap, np.int64), np.empty(cap, np.int64)  # (the deleter's lists)
        self._cap = cap
        self._step_args = None  # (new state arrays: _one_call_args)

    def _delete_expired(self, time_s: float) -> None:
        """The deleter: drop tracks whose last update is more than ``timeout_s`` before ``time_s`` (called when its
        sweep is due: :meth:`step` tests that first, a track and the oldest update expired).  The rows,
        the free stack, the compiled id table and the earliest update left in one compiled pass
        (:func:`~footprint_uq.tracking.kernels.expire_rows`: ~2 us with this call; before 2026-11-29, wave 13,
        ~6.5 us of numpy and Python), the dictionary in :meth:`_swept`.  Called alone before the dictionary looks
        a list's ids up, or before the separate calls; a frame of int64 ids sweeps in its one compiled call
        (:func:`~footprint_uq.tracking.imm_kernels.frame_step`)."""
        self._swept(*expire_rows(time_s, self.config.timeout_s, self._t_last, self._free, self._n_free, self._gone,
                                 self._gone_keys, *(self._ids or _NO_ID_TABLE)))

    def _swept(self, m: int, n_free: int, oldest: float) -> None:
        """After the deleter's compiled sweep (:func:`~footprint_uq.tracking.kernels.expire_rows`, alone or in
        :func:`~footprint_uq.tracking.imm_kernels.frame_step`): the free stack's height, the earliest update left,
        and the ``m`` rows gone (``_gone[:m]``) out of the dictionary."""
        self._n_free, self._oldest_s = n_free, oldest
        if m:
            index, keys = self._index, self._keys
            for s in self._gone[:m].tolist():
                del index[keys[s]]
                keys[s] = None

    def _measurement(self, xy_m, cov_frame_m2, shared_m) -> SplitMeasurement:
        """The measurement of the ``white`` and ``ignore`` modes (``consider`` takes the split as given:
        :meth:`step`): ``B B^T`` folded into the frame's covariance or left out, no consider columns."""
        R = cov_frame_m2 + (shared_m @ np.swapaxes(shared_m, -1, -2) if self.config.calibration == "white" else 0.0)
        return SplitMeasurement(xy_m, R, np.zeros((xy_m.shape[0], 2, 0)))

    def step(self, time_s: float, object_ids, xy_m, cov_frame_m2=None, shared_m=None, *,
             cov_m2=None, motion: tuple | None = None) -> TrackOutput:
        """One frame of n objects: update their tracks and return their motion (:class:`TrackOutput`).

        Parameters
        ----------
        time_s : float
            The frame's time, s.  Frames must come in time order: a frame earlier than the previous one is not
            tracked (counted in :attr:`n_stale_frames`); one at the same time continues that frame (a frame given
            in parts), where an id already updated at that time is a repeated id.
        object_ids : sequence of n hashables (None: not tracked; a repeated id: only its first object is)
        xy_m : (n, 2)               centres in W (NaN: no centre this frame; the track waits, it may time out)
        cov_frame_m2 : (n, 2, 2)    per-frame part of their covariance, m^2
        shared_m : (n, 2, r)        their whitened parameter Jacobians (the calibration part ``B B^T``)
        cov_m2 : (n, 2, 2), optional
            Instead of ``cov_frame_m2``: their whole covariance (``FootprintEstimate.centre_cov_m2``); the
            per-frame part ``cov_m2 - B B^T`` is then taken in the compiled pass (what
            ``FootprintEstimate.centre_cov_frame_m2`` gives, without its dozen numpy calls).
        motion : tuple, optional
            The motion fields of the step's output in the same compiled call, where the step is one
            (:func:`~footprint_uq.tracking.motion.track_motion` makes it): :func:`~footprint_uq.tracking.kernels.
            motion_fields`' arguments after the velocities, ``(cos_h, sin_h, ratio, yaw_rad, sigma_yaw_rad,
            heading_offset_deg, out (8, n), cov_out (n, 2, 2))`` (yaws C-contiguous float64, ``(n,)`` or
            ``(0,)``); ``out`` and ``cov_out`` receive the fields whichever way the step goes (else one call of
            ``motion_fields`` after it).
        """
        t, id64, ids, xy_rows, cov_rows, B, subtract = self._frame_inputs(time_s, object_ids, xy_m, cov_frame_m2,
                                                                          shared_m, cov_m2)
        n = xy_rows.shape[1]
        if motion is not None:
            _check_motion(motion, n)
        if t < self._last_time:
            self.n_stale_frames += 1
            self._nis = np.full(n, np.nan)
            return self._with_motion(TrackOutput.untracked(n), motion)
        self._last_time = t
        sweep = len(self._index) > 1 and t - self._oldest_s > self.config.timeout_s  # (the deleter's sweep is due)
        if sweep and id64 is None:  # (before the dictionary's look-up; int64 ids: in the rows' compiled call)
            self._delete_expired(t)
            sweep = False
        if id64 is not None and self._ids is None:
            self._id_table(64)
        self._stamp += 1
        if n > self._old.shape[0]:  # (the step's working arrays, kept: nothing of them leaves the step)
            self._work(n)
        empty = np.empty
        out = TrackOutput(empty(n, np.int64), empty(n, bool), empty(n, np.int64), empty(n), empty((n, 2)),
                          empty((n, 2, 2)), empty((n, 2)), empty((n, 2, 2)))
        self._nis = nis = empty(n)
        slots = None
        if id64 is None:  # (a list: the dictionary's rows, its misses -- the new ids -- counted)
            index = self._index
            index.misses = 0
            slots = np.fromiter(map(index.__getitem__, ids), np.int64, n)
        rows = self._rows_call(id64 is not None or not self._index.misses)
        if rows == _ONE_CALL:  # (the whole step in one compiled call, frame_step, if there is room for new ids)
            k, n_unknown, m, next_id, n_gone, n_free, oldest = frame_step(
                _NO_IDS if id64 is None else id64, self._slots if slots is None else slots, xy_rows, cov_rows, B,
                subtract, t, self._stamp, self._n_free, self._next_id, sweep, self._frame_scratch(), *out, nis,
                *(self._step_args or self._one_call_args()), *(motion or _NO_MOTION))
            if sweep:
                self._swept(n_gone, n_free, oldest)
            if m >= 0:  # (the new ids claimed and the update passed)
                self._next_id = next_id
                self._enter_claimed(id64, self._claimed, m)
                if t < self._oldest_s:  # (every row started or updated now has t_last = t)
                    self._oldest_s = t
                return out
            work, Bp = (self._slots[:n], self._act[:n], self._z[:n], self._R[:n]), self._Bp  # (stopped after the rows)
        else:
            if sweep:
                self._delete_expired(t)
            work = (np.empty(n, np.int64) if slots is None else slots, empty(n, np.int8), empty((n, 2)),
                    empty((n, 2, 2)))  # (slots, act, z, R)
            k, n_unknown, Bp = self._frame_rows(rows, t, id64, work, xy_rows, cov_rows, B, subtract)
        self._update(t, id64, ids, work, B, k, n_unknown, Bp, out, nis)
        return self._with_motion(out, motion)

    @staticmethod
    def _with_motion(out: TrackOutput, motion: tuple | None) -> TrackOutput:
        """``out``, with :meth:`step`'s ``motion`` fields of it formed by one call of :func:`~footprint_uq.tracking.
        kernels.motion_fields` if asked (a step that did not run them in its compiled call)."""
        if motion is not None:
            motion_fields(out.v_mps, out.cov_v_m2ps2, *motion)
        return out

    def _frame_inputs(self, time_s, object_ids, xy_m, cov_frame_m2, shared_m, cov_m2) -> tuple:
        """:meth:`step`'s arguments checked and in the compiled calls' forms: ``(t, id64, ids, xy_rows (2, n),
        cov_rows (2, 2, n), B (n, 2, r), subtract)`` (``id64``: the ids when they are an int64 array the compiled
        id table takes, else None; ``ids``: the ids as a list or that array)."""
        # (a finite float passes without a call into _checks: one climb less per frame; anything else gets its check)
        t = time_s if isinstance(time_s, float) and math.isfinite(time_s) else as_float("time_s", time_s)
        xy_rows = _rows(xy_m, 2) if type(xy_m) is np.ndarray and xy_m.ndim == 2 and xy_m.shape[1] == 2 else \
            np.ascontiguousarray(c_float64(xy_m).reshape(-1, 2).T)  # (2, n): the kernel's layout, an estimate's as is
        n = xy_rows.shape[1]
        id64 = None
        if self._int_ids:  # (the compiled id table: an int64 array, or a list of Python ints made one)
            if type(object_ids) is np.ndarray:
                id64 = _int64_ids(object_ids)
            elif type(object_ids) is list and object_ids and (type(object_ids[0]) is int or
                                                             isinstance(object_ids[0], np.integer)):
                id64 = _list_int64(object_ids)
        ids = object_ids if id64 is not None or isinstance(object_ids, list) else list(object_ids)
        if len(ids) != n:
            raise InputError("object_ids", len(ids), f"{n} ids, one per object")
        B = c_float64(shared_m)
        if B.shape != (n, 2, self.rank) and (self._consider or B.ndim != 3 or B.shape[:2] != (n, 2)):
            raise InputError("shared_m", B.shape, f"shape ({n}, 2, {self.rank})")
        if (cov_frame_m2 is None) == (cov_m2 is None):
            raise InputError("cov_frame_m2/cov_m2", "both" if cov_m2 is not None else "neither",
                             "exactly one of the per-frame or the whole covariance")
        subtract = cov_m2 is not None
        cov = cov_m2 if subtract else cov_frame_m2
        if type(cov) is not np.ndarray:
            cov = np.asarray(cov, dtype=np.float64)
        if cov.shape != (n, 2, 2):
            raise InputError("cov_m2" if subtract else "cov_frame_m2", cov.shape, f"shape ({n}, 2, 2)")
        return t, id64, ids, xy_rows, _rows(cov, 3), B, subtract

    def _rows_call(self, one_call: bool) -> int:
        """Which compiled call forms this frame's rows: :data:`_ONE_CALL` (:func:`~footprint_uq.tracking.imm_kernels.
        frame_step`, the whole step, if ``one_call`` -- ids as an int64 array, or a list whose ids all have rows --,
        the consider mode and the compiled pass), :data:`_ROWS_SHARED`
        (:func:`~footprint_uq.tracking.kernels.frame_rows_shared`: ``B`` at the predicted positions in the same call)
        or :data:`_ROWS` (:func:`~footprint_uq.tracking.kernels.frame_rows` and one call of ``shared_at``).  A call
        that forms ``B`` is taken if ``B``'s kernels were ready at the table's first frame (it compiles, or loads
        from the cache, with the table's other kernels), later only once it is compiled in this process (see
        ``__init__``).  (A list of ids with new ones takes two calls: they are claimed in Python between them.)"""
        ready = self._at is not None and self._at.kernel_inputs() is not None
        if self._fused is None:  # (decided at the first frame: see __init__)
            self._fused = ready
        if not ready:
            return _ROWS
        if one_call and self._consider and not self._reference_pass and (self._fused or frame_step.signatures):
            return _ONE_CALL
        return _ROWS_SHARED if (self._fused or frame_rows_shared.signatures) else _ROWS

    def _frame_rows(self, rows: int, t: float, id64, work: tuple, xy_rows, cov_rows, B, subtract) -> tuple:
        """The rows of the ids ``id64`` (an int64 array: by the compiled id table into ``work``'s slots; None: the
        slots are the dictionary's already) and the rows' compiled call (:meth:`_rows_call`) into ``work = (slots,
        act, z, R)`` (n rows each); returns ``(k, n_unknown, B_pred)`` (what :func:`~footprint_uq.tracking.kernels.
        frame_rows` returns; ``B`` at the k predicted positions, ``(0, 2, 0)`` if none)."""
        slots, act, z, R = work
        if id64 is not None:
            id_lookup(*self._ids, id64, slots)
        pred = self._pred
        args = (slots, xy_rows, cov_rows, B, subtract, z, R, t, self._t_last, self._seen, self._stamp, self._x, act,
                self._old, pred)
        if rows != _ROWS:
            Bp = self._Bp  # (rows k and on are not read: frame_pass reads Bp[:k])
            k, n_unknown = frame_rows_shared(*args, *self._at.kernel_inputs(), self._uv, Bp, self._frame_scratch())
            return k, n_unknown, Bp
        k, n_unknown = frame_rows(*args)
        Bp = c_float64(self.shared_at(pred[:k])) if self.shared_at is not None and self.rank and k else _NO_B
        return k, n_unknown, Bp

    def _update(self, t: float, id64, ids, work: tuple, B, k: int, n_unknown: int, Bp, out: TrackOutput,
                nis) -> None:
        """The rest of a frame after its rows (``work = (slots, act, z, R)``, :meth:`_frame_rows`): the unknown ids'
        rows (:meth:`_claim_int`, :meth:`_claim`) and the compiled update, starts and outputs into ``out`` and
        ``nis``."""
        n = B.shape[0]
        slots, act, xy, R = work
        old = self._old
        if n_unknown and id64 is not None:
            self._claim_int(id64, slots, act, n_unknown)
        elif n_unknown:
            self._claim(ids, slots, act, old[n - n_unknown:n][::-1].tolist())
        z, Rf, Bf = (xy, R, B) if self._consider else self._measurement(xy, R, B)  # (consider: the split as given)
        args = (act, slots, old, k, self._x, self._P, self._xm, self._Pm, self._Cm, self._mu, self._t_last,
                self._t_first, self._n, self._tid, self._next_id, t, self._qs, self._rates, self.mu0, self._var_v0,
                z, Rf, Bp, Bf, self.config.gate_chi2, *out)
        nis.fill(math.nan)
        self._next_id = frame_update(*args) if self._reference_pass else frame_pass(*args, *self._scratch, nis)
        if t < self._oldest_s:  # (every row started or updated now has t_last = t)
            self._oldest_s = t

    def _one_call_args(self) -> tuple:
        """:func:`~footprint_uq.tracking.imm_kernels.frame_step`'s arguments after the frame's own: the id table,
        the free rows, the working arrays, the camera's and ``B``'s kernel inputs, the tracks' storage, the filter's
        constants and scratch; kept in ``_step_args`` until one of them is replaced (:meth:`_grow`, :meth:`_work`,
        :meth:`_id_table`)."""
        self._step_args = (*(self._ids or _NO_ID_TABLE), self._free, self.config.timeout_s, self._gone,
                           self._gone_keys, self._z, self._R, self._act, self._old, self._pred,
                           self._uv, self._Bp, self._claimed, *self._at.kernel_inputs(), self._x, self._P, self._xm,
                           self._Pm, self._Cm, self._mu, self._t_last, self._t_first, self._n, self._tid, self._seen,
                           self._qs, self._rates, self.mu0, self._var_v0, self.config.gate_chi2, *self._scratch)
        return self._step_args

    def _id_table(self, cap: int) -> None:
        """A fresh compiled id table of ``cap`` (a power of 2) entries holding ``_index``'s ids."""
        while 2 * (len(self._index) - 1) > cap:
            cap *= 2
        keys, vals = np.zeros(cap, np.int64), np.full(cap, ID_EMPTY, np.int64)
        self._ids = (keys, vals, 64 - (cap.bit_length() - 1))
        self._step_args = None
        items = [(k, s) for k, s in self._index.items() if k is not None]
        if items:
            id_insert(*self._ids, np.array([k for k, _ in items], np.int64), np.array([s for _, s in items], np.int64))

    def _enter_ids(self, keys: list, rows: list) -> None:
        """New ids with their rows into the compiled id table if there is one (grown to stay at most half full), or
        its end if one of them is not an integer of int64's range."""
        for k in keys:
            if not ((type(k) is int or isinstance(k, np.integer | bool)) and _INT64_MIN <= k <= _INT64_MAX):
                self._int_ids = False
                self._ids = self._step_args = None
                return
        if self._ids is None:
            return
        cap = self._ids[0].shape[0]
        if 2 * (len(self._index) - 1) > cap:  # (_index holds them already)
            self._id_table(cap)
        else:
            id_insert(*self._ids, np.array(keys, np.int64), np.array(rows, np.int64))

    def _work(self, n: int) -> None:
        """The step's working arrays for frames of up to ``n`` objects (the compiled calls read their first k or n
        rows): the objects' rows ``_slots (n,)``, actions ``_act (n,)``, centres ``_z (n, 2)`` and per-frame
        covariances ``_R (n, 2, 2)``, the objects to update ``_old (n,)``, their predicted positions ``_pred (n,
        2)``, pixels ``_uv (n, 2)`` and ``B`` there ``_Bp (n, 2, r)`` (:func:`~footprint_uq.tracking.kernels.
        frame_rows_shared`), the objects given rows ``_claimed (n,)``."""
        self._slots, self._act, self._claimed = np.empty(n, np.int64), np.empty(n, np.int8), np.empty(n, np.int64)
        self._z, self._R = np.empty((n, 2)), np.empty((n, 2, 2))
        self._old, self._pred, self._uv = np.empty(n, np.int64), np.empty((n, 2)), np.empty((n, 2))
        self._Bp = np.empty((n, 2, self.rank))
        self._step_args = None

    def _frame_scratch(self) -> np.ndarray:
        """The point kernel's scratch for :func:`~footprint_uq.tracking.kernels.frame_rows_shared`: this thread's
        buffer of the per-frame kernel (``fast.buffers.thread_buffer``, the one :class:`~footprint_uq.products.
        frame_processor.FrameProcessor` uses: in cache after the frame's positions), the last thread's kept here."""
        tid = threading.get_ident()
        last = self._last_scratch  # (one tuple, read and replaced whole: safe under threads)
        if last[0] != tid:
            last = self._last_scratch = (tid, thread_buffer("frame_scratch", SCRATCH_SHAPE))
        return last[1]

    def frame_nis(self) -> np.ndarray:
        """The normalised innovation squared ``y^T S^-1 y`` (2 dof; two modes: of the predicted mode mixture's
        moments) of each of the last :meth:`step`'s objects that updated a track, ``(n,)`` in frame order; NaN for
        the others (new tracks, restarts beyond the gate, untracked objects, a stale frame) and for every object
        under the compiled reference pass (``_reference_pass``, which does not compute it).  The on-line
        consistency check's statistic (:class:`~footprint_uq.tracking.consistency.NisMonitor`)."""
        return self._nis

    def _claim(self, ids: list, slots: np.ndarray, act: np.ndarray, miss: list) -> None:
        """Rows for the unknown ids of a frame (the objects ``miss``, in frame order, from ``frame_rows``), in place:
        the first object of each with finite inputs (``act == ROW_START``) gets a free row (the table grows when
        none is left); a later object of the same id is not tracked (``act`` set to ``ROW_SKIP``)."""
        first: set = set()
        new_keys, new_rows = [], []
        for i in miss:
            key = ids[i]
            if key in first:
                act[i] = ROW_SKIP
                continue
            first.add(key)
            if act[i] == ROW_START:
                if not self._n_free:
                    self._grow(2 * self._cap)
                self._n_free = n_free = self._n_free - 1
                slots[i] = s = int(self._free[n_free])
                self._keys[s] = key
                self._index[key] = s
                new_keys.append(key)
                new_rows.append(s)
        if self._int_ids and new_keys:
            self._enter_ids(new_keys, new_rows)

    def _claim_int(self, id64: np.ndarray, slots: np.ndarray, act: np.ndarray, n_unknown: int) -> None:
        """:meth:`_claim` of a frame whose ids are an int64 array (its compiled id table exists: :meth:`step` made
        it before the look-up), in one compiled call (:func:`~footprint_uq.tracking.kernels.claim_rows`: the same
        rows in the same order, the same objects skipped) with room made first -- free rows for every unknown id
        (the table grows now rather than midway: the rows are taken in the same order) and the id table at most
        half full with them; then the new ids into the dictionary, as Python ints (equal, and of equal hash, to
        the array's scalars)."""
        while self._n_free < n_unknown:
            self._grow(2 * self._cap)
        cap = cap0 = self._ids[0].shape[0]
        while 2 * (len(self._index) - 1 + n_unknown) > cap:
            cap *= 2
        if cap != cap0:
            self._id_table(cap)
        rows = self._free[self._n_free - n_unknown:self._n_free][::-1].copy()
        claimed = np.empty(n_unknown, np.int64)
        m = claim_rows(id64, self._old, n_unknown, act, slots, rows, *self._ids, claimed)
        self._enter_claimed(id64, claimed, m)

    def _enter_claimed(self, id64: np.ndarray, claimed: np.ndarray, m: int) -> None:
        """The ``m`` new ids of a frame's int64 ids (``id64[claimed[:m]]``, given the top ``m`` free rows in that
        order by :func:`~footprint_uq.tracking.kernels.claim_rows`) off the free stack and into the dictionary,
        as Python ints (equal, and of equal hash, to the array's scalars)."""
        if not m:
            return
        self._n_free -= m
        rows = self._free[self._n_free:self._n_free + m]
        index, keys = self._index, self._keys
        if m == 1:  # (the common case: one new id in the frame)
            s = int(rows[0])
            keys[s] = key = int(id64[claimed[0]])
            index[key] = s
            return
        for key, s in zip(id64[claimed[:m]].tolist(), rows[::-1].tolist(), strict=True):
            keys[s] = key
            index[key] = s


_F8, _I8 = np.dtype(np.float64), np.dtype(np.int64)
_TRANSPOSE = {2: (1, 0), 3: (1, 2, 0)}


def _check_motion(motion: tuple, n: int) -> None:
    """:meth:`TrackTable.step`'s ``motion`` arguments of a frame of n objects, their arrays' shapes checked (the
    compiled pass writes n rows of ``out`` and ``cov_out`` and reads n yaws: another size would be read or written
    past its end)."""
    if len(motion) != 8:
        raise InputError("motion", f"{len(motion)} entries", "motion_fields' 8 arguments after the velocities")
    yaw, sigma_yaw, out, cov_out = motion[3], motion[4], motion[6], motion[7]
    if out.shape != (8, n) or cov_out.shape != (n, 2, 2) or yaw.shape[0] not in (0, n) \
            or sigma_yaw.shape[0] not in (0, n):
        raise InputError("motion", f"out {out.shape}, cov_out {cov_out.shape}, yaws {yaw.shape} / {sigma_yaw.shape}",
                         f"out (8, {n}), cov_out ({n}, 2, 2), yaws ({n},) or (0,)")


def _rows(a: np.ndarray, ndim: int) -> np.ndarray:
    """The ``(n, ...)`` array ``a`` (2 or 3 dimensions) with its first axis moved last, as a C-contiguous, writable
    float64 array: an estimate's centre columns (``centre_xy_world_m``, ``centre_cov_m2``: views of row blocks)
    are that already, their transposes taken as they are; anything else is copied."""
    t = a.transpose(_TRANSPOSE[ndim])
    if t.dtype == _F8:
        flags = t.flags
        if flags.c_contiguous and flags.writeable:
            return t
    return np.ascontiguousarray(t, dtype=np.float64)


def _int64_ids(ids: np.ndarray) -> np.ndarray | None:
    """The array ``ids`` if it is a 1-d int64 array (a copy if it is strided or read-only: one compiled signature),
    a 1-d array of another integer type as an int64 copy (every value of int64's range: equal, and of equal hash,
    to the int64 -- a reader's int32 ids, say, take the compiled look-up, not the dictionary), else None."""
    if ids.ndim != 1:
        return None
    dt = ids.dtype
    if dt is not _I8 and dt != _I8:
        fits = dt.kind == "i" or (dt.kind == "u" and (dt.itemsize < 8 or not ids.size or ids.max() <= _INT64_MAX))
        return ids.astype(np.int64) if fits else None
    flags = ids.flags
    return ids if flags.c_contiguous and flags.writeable else ids.copy()


def _list_int64(ids: list) -> np.ndarray | None:
    """A list of ids as an int64 array when numpy makes it one (every id a Python or numpy integer of int64's range,
    or a bool: equal, and of equal hash, to the integer, as the dictionary takes them), else None (None, a float,
    a string, an integer beyond int64 among them: the dictionary's look-up).  ~1.7 us for 100 ids, less than the
    dictionary's, and the frame then takes the compiled id table and its claim of new ids (one compiled call)."""
    try:
        a = np.array(ids)
    except (ValueError, OverflowError, TypeError):  # (e.g. ids of uneven nesting)
        return None
    return a if a.dtype == _I8 and a.ndim == 1 else None


def c_float64(a) -> np.ndarray:
    """``a`` as a C-contiguous, writable float64 array (a copy only if it is not one): one compiled signature."""
    if type(a) is not np.ndarray or a.dtype != _F8:
        a = np.asarray(a, dtype=np.float64)
    flags = a.flags
    return a if flags.c_contiguous and flags.writeable else a.copy()


class SharedJacobianAt:
    """``B`` (the whitened calibration Jacobian of a ground point, (n, 2, r)) at world points, for
    :class:`TrackTable`'s ``shared_at``: the points are projected into the image by the nominal camera and run
    through the fused kernel as one-point footprints (NaN where a point has no pixel or no ground point).

    For a polygon's centroid this is ``B`` at the centroid's ground point, not the centroid of its corners'
    ``B`` (they differ by a term of the order of (object size / range)^2, the same in every frame).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    """

    def __init__(self, camera, budget):
        self.processor = FrameProcessor(camera, budget, joint_cov=False, linearity=False, v2x_policy="linear",
                                        shared_jacobian=True, allow_outside_image=True)
        self.processor.corner_outputs = False
        self.camera = camera
        self.rank = int(self.processor.budget.param_factor().rank)
        self._cam = camera_constants(camera)[0]
        #: the processor's compiled call (:meth:`FrameProcessor.point_jacobian_kernel`; None until its kernels
        #: are ready) and this object's own scratch for it, used by one thread at a time (``_busy``)
        self._kernel = None
        self._inputs = None  # (kernel_inputs)
        self._scratch = np.empty(SCRATCH_SHAPE)
        self._busy = threading.Lock()

    def kernel_inputs(self) -> tuple | None:
        """The point kernel's inputs after the pixels, ``(cam_f, has_dist, dist, R, dom, dR, Lr, Lc, Lv)`` (the
        camera's ``KernelCamera`` in :func:`~footprint_uq.fast.frame_columns.camera_parts`' pieces), for
        :func:`~footprint_uq.tracking.kernels.frame_rows_shared`; None while the processor's kernels are not ready
        (ask again later)."""
        if self._kernel is None:
            self._kernel = self.processor.point_jacobian_kernel()
            if self._kernel is not None:
                cam, *rest = self._kernel[1]
                self._inputs = (*camera_parts(cam), *rest)
        return self._inputs

    def __call__(self, xy_m) -> np.ndarray:
        xy = np.ascontiguousarray(xy_m, dtype=np.float64).reshape(-1, 2)
        uv = np.empty((xy.shape[0], 2))
        project_ground(xy, self._cam, uv)
        # the kernel called from here, not through the processor's method: the tracker's frame does not climb back
        # up from products/ (bench/frame_walk.py --tracks); another thread meanwhile takes the processor's path
        if self._kernel is None:
            self.kernel_inputs()
        if self._kernel is None or not self._busy.acquire(blocking=False):
            return self.processor.point_shared_jacobian(uv)
        try:
            out = np.empty((xy.shape[0], 2, self.rank))
            self._kernel[0](uv, *self._kernel[1], out, self._scratch)
            return out
        finally:
            self._busy.release()
