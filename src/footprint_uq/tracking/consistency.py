"""On-line consistency of the tracker's motion model: the normalised innovation squared (NIS) per class over a window.

:class:`NisMonitor` runs beside one camera's :class:`~footprint_uq.tracking.classes.ClassTracks`: the NIS
``y^T S^-1 y`` (2 dof; for two modes, of the predicted mode mixture's moments) of every innovation the tracks'
update used in a frame (:meth:`~footprint_uq.tracking.classes.ClassTracks.frame_nis`, computed in the tracker's
compiled pass: the tracker's own innovations) is summed per class and frame.  (Before 2026-11-28 a
:class:`~footprint_uq.tracking.motion_fit.MotionBank` re-ran the tracker's filter on the frame for it, ~100 us
per 100-object frame; ``tests/test_tracking_fast.py`` holds the two to 1e-9.)
Over the last ``window_s`` seconds the class's sum of ``n`` NIS is, if the model is right, chi-square with ``2 n``
degrees of freedom (the innovations of a consistent filter are white, so one track's successive NIS are
independent); :meth:`NisMonitor.status` tests it two-sided at ``alpha`` against a tolerance band -- the sum is
flagged only beyond ``(1 + tolerance)`` times the upper quantile or below the lower one divided by it -- and
reports the ratio ``mean NIS / 2`` (above 1: the traffic is more agitated than the model says, the velocity
ellipses too small; below 1: calmer).

The window's effective count is the number of updates in it, capped at ``max_updates`` (a ring of per-frame sums:
beyond the cap the oldest frames leave first).  The band is there because a real model is never exact: with the
tracker's linearised measurement model a correct density gives mean NIS / 2 ~0.99 in the seeded traffic of
``bench/motion_nis_monitor.py``, which a window of 20 000 updates would flag without it (1 run in 4); a density x4
gives 1.2-1.4.  docs/motion-fit.md, "Consistency on line".
"""

from __future__ import annotations

import collections
import math

import numpy as np
from numba import njit
from scipy import stats

from .._checks import as_float
from ..errors import InputError

__all__ = ["NisMonitor", "health_section", "DEFAULT_WINDOW_S", "DEFAULT_ALPHA", "DEFAULT_TOLERANCE"]

#: the window, s, and the two-sided false-alarm probability of one test
DEFAULT_WINDOW_S = 30.0
DEFAULT_ALPHA = 1e-4
#: relative tolerance of the NIS sum (a model right to this is consistent)
DEFAULT_TOLERANCE = 0.05
_F64 = np.dtype(np.float64)


class NisMonitor:
    """NIS statistic per class of one camera's tracks (module doc).

    Parameters
    ----------
    tracks : ClassTracks
        The camera's tracks (their models: :attr:`~footprint_uq.tracking.classes.ClassTracks.configs`).
    window_s : float
        Length of the window, s.
    alpha : float
        Two-sided false-alarm probability of one test.
    min_updates : int
        Fewer updates in the window: no verdict (``consistent`` None).
    max_updates : int
        At most this many updates in the window (the oldest frames leave first).
    tolerance : float
        Relative tolerance band of the test (module doc).
    """

    def __init__(self, tracks, *, window_s: float = DEFAULT_WINDOW_S, alpha: float = DEFAULT_ALPHA,
                 min_updates: int = 300, max_updates: int = 20_000, tolerance: float = DEFAULT_TOLERANCE):
        self.window_s = as_float("window_s", window_s, positive=True)
        self.alpha = as_float("alpha", alpha, positive=True, hi=0.5)
        self.min_updates, self.max_updates = int(min_updates), int(max_updates)
        self.tolerance = as_float("tolerance", tolerance, nonnegative=True)
        self.tracks = tracks
        self._frames: dict = {}  # class -> deque of (time_s, nis_sum, n)
        self._sums: dict = {}  # class -> [nis_sum, n] over the deque
        self.flagged: dict = {}  # class -> the last verdict that was "inconsistent" (for the log: new flags only)

    def observe(self, time_s: float, out, classes, xy_m=None, cov_frame_m2=None, shared_m=None) -> None:
        """One frame, right after the tracks' step on it: ``out`` that step's output (n objects) and ``classes``
        their n class names (None: no class, ``""``).  The NIS come from the step itself
        (:meth:`~footprint_uq.tracking.classes.ClassTracks.frame_nis`); ``xy_m``, ``cov_frame_m2`` and
        ``shared_m`` are not needed any more (accepted for the callers of the earlier signature)."""
        nis = self.tracks.frame_nis()
        n = out.track_id.shape[0]
        if nis.shape[0] != n:
            raise InputError("out", n, f"the output of the tracks' last step ({nis.shape[0]} objects)")
        now = float(time_s)
        if n and (classes is None or type(classes) is list and len(classes) == n and classes.count(classes[0]) == n):
            # (a frame of one class, the common case: its sum in one compiled call, no dictionary of classes)
            s, k = _finite_sum(nis if type(nis) is np.ndarray and nis.dtype is _F64 and nis.flags.c_contiguous
                               else np.ascontiguousarray(nis, dtype=np.float64))
            if k:
                c = None if classes is None else classes[0]
                self._add("" if c is None else str(c), now, s, k)
        else:
            for cls, (s, k) in _class_sums(nis, classes, n).items():
                self._add(cls, now, s, k)
        if self._frames:
            self._expire(now)

    def _add(self, cls: str, now_s: float, nis_sum: float, count: int) -> None:
        """One frame's sum and count of class ``cls`` into its window."""
        dq = self._frames.get(cls)
        if dq is None:
            dq = self._frames[cls] = collections.deque()
            self._sums[cls] = [0.0, 0]
        tot = self._sums[cls]
        dq.append((now_s, nis_sum, count))
        tot[0] += nis_sum
        tot[1] += count

    def _expire(self, now_s: float) -> None:
        for cls, dq in self._frames.items():
            tot = self._sums[cls]
            while dq and (now_s - dq[0][0] > self.window_s or tot[1] - dq[0][2] >= self.max_updates):
                _, s, n = dq.popleft()
                tot[0] -= s
                tot[1] -= n

    def status(self) -> dict:
        """class (``""``: no class) -> ``{"n_updates", "nis_ratio", "p_value", "consistent", "window_s"}``:
        ``nis_ratio`` = mean NIS / 2, ``p_value`` two-sided of chi-square with ``2 n`` dof for the sum brought to
        the tolerance band's nearer edge (1 inside it), ``consistent`` False where ``p_value < alpha`` (None:
        fewer than ``min_updates`` updates)."""
        out = {}
        for cls, (s, n) in self._sums.items():
            rec = {"n_updates": int(n), "window_s": self.window_s, "nis_ratio": None, "p_value": None,
                   "consistent": None}
            if n > 0:
                rec["nis_ratio"] = s / (2.0 * n)
            if n >= self.min_updates:
                dof, k = 2.0 * n, 1.0 + self.tolerance
                p = 2.0 * min(stats.chi2.cdf(s * k, dof), stats.chi2.sf(s / k, dof))
                rec["p_value"] = float(min(p, 1.0))
                rec["consistent"] = bool(p >= self.alpha)
            out[cls] = rec
        return out

    def new_flags(self) -> list[tuple[str, dict]]:
        """Classes whose verdict turned inconsistent since the last call (each once, for the log)."""
        news = []
        for cls, rec in self.status().items():
            bad = rec["consistent"] is False
            if bad and cls not in self.flagged:
                news.append((cls, rec))
            if bad:
                self.flagged[cls] = rec
            elif rec["consistent"] and cls in self.flagged:
                del self.flagged[cls]
        return news


def _class_sums(nis, classes, n: int) -> dict:
    """class (``""``: None) -> (sum of the finite ``nis`` of its objects, their count), the classes with at least
    one; one compiled pass, summing in frame order.  One class for the frame (the common case):
    :func:`_finite_sum`, no loop over the objects in Python; several: each object's class as an index of the
    frame's distinct ones, :func:`_sums_kernel`.  :func:`_class_sums_reference` is the same in plain Python.
    (Before 2026-11-28 a one-class frame's sum was numpy's pairwise sum: the same to a few units in the last
    place.)"""
    nis = np.ascontiguousarray(nis, dtype=np.float64)
    names = [None] if classes is None else classes if isinstance(classes, list) else list(classes)
    if classes is not None and len(names) != n:
        raise InputError("classes", len(names), f"{n} class names, one per object")
    if not n:
        return {}
    if classes is None or names.count(names[0]) == n:
        s, k = _finite_sum(nis)
        return {"" if names[0] is None else str(names[0]): (s, k)} if k else {}
    first: dict = {}
    idx = np.fromiter((first.setdefault(c, len(first)) for c in names), np.int64, n)
    names = list(first)
    sums, counts = np.zeros(len(names)), np.zeros(len(names), np.int64)
    _sums_kernel(nis, idx, sums, counts)
    out: dict = {}
    for c, s, k in zip(names, sums.tolist(), counts.tolist(), strict=True):
        if k:  # (two names of one key -- None and "", 1 and "1" -- add up, as the reference's str keys do)
            key = "" if c is None else str(c)
            s0, k0 = out.get(key, (0.0, 0))
            out[key] = (s0 + s, k0 + k)
    return out


@njit(cache=True, nogil=True)
def _finite_sum(nis):  # pragma: no cover - compiled
    """(sum of the finite ``nis``, in order; their count)."""
    s, k = 0.0, 0
    for i in range(nis.shape[0]):
        v = nis[i]
        if math.isfinite(v):
            s += v
            k += 1
    return s, k


@njit(cache=True, nogil=True)
def _sums_kernel(nis, class_idx, sums, counts):  # pragma: no cover - compiled
    """Per class ``c``: ``sums[c]`` += the finite ``nis[i]`` of the objects ``i`` of class ``class_idx[i]``, in
    frame order; ``counts[c]`` += their number."""
    for i in range(nis.shape[0]):
        v = nis[i]
        if math.isfinite(v):
            c = class_idx[i]
            sums[c] += v
            counts[c] += 1


def _class_sums_reference(nis, classes, n: int) -> dict:
    """:func:`_class_sums` in plain Python, object by object (tests/test_consistency_sums.py holds the two
    together)."""
    if classes is not None and len(classes) != n:
        raise InputError("classes", len(classes), f"{n} class names, one per object")
    sums: dict = {}
    for i in range(n):
        v = float(nis[i])
        if math.isfinite(v):
            c = None if classes is None else classes[i]
            key = "" if c is None else str(c)
            s, k = sums.get(key, (0.0, 0))
            sums[key] = (s + v, k + 1)
    return sums


def _finite_or_none(x):
    return None if x is None or not math.isfinite(x) else x


def health_section(monitors: dict) -> dict:
    """The ``motion_consistency`` entry of a health record: camera -> class -> :meth:`NisMonitor.status`, with
    ``inconsistent``: the list of ``camera/class`` flagged."""
    cams, bad = {}, []
    for cam, mon in monitors.items():
        st = mon.status()
        cams[str(cam)] = {c or "(no class)": {k: _finite_or_none(v) if isinstance(v, float) else v
                                             for k, v in rec.items()} for c, rec in st.items()}
        bad += [f"{cam}/{c or '(no class)'}" for c, rec in st.items() if rec["consistent"] is False]
    return {"cameras": cams, "inconsistent": bad}
