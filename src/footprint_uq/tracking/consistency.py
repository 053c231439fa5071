"""On-line consistency of the tracker's motion model: the normalised innovation squared (NIS) per class over a window.

:class:`NisMonitor` runs beside one camera's :class:`~footprint_uq.tracking.classes.ClassTracks`: every frame's
tracked objects go through a :class:`~footprint_uq.tracking.motion_fit.MotionBank` with one member per motion
model of the tracks (the same filter, the same association: the tracker's own innovations), whose NIS
``y^T S^-1 y`` (2 dof; for two modes, of the predicted mode mixture's moments) is summed per class and frame.
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

from scipy import stats

from .._checks import as_float
from .motion_fit import MotionBank, members_of

__all__ = ["NisMonitor", "health_section", "DEFAULT_WINDOW_S", "DEFAULT_ALPHA", "DEFAULT_TOLERANCE"]

#: the window, s, and the two-sided false-alarm probability of one test
DEFAULT_WINDOW_S = 30.0
DEFAULT_ALPHA = 1e-4
#: relative tolerance of the NIS sum (a model right to this is consistent)
DEFAULT_TOLERANCE = 0.05


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
        cfg0 = tracks.configs[0]
        at = None if tracks.shared_at is None else _TracksJacobian(tracks)
        self.bank = MotionBank(members_of(tracks.configs), rank=tracks.rank, shared_at=at,
                               sigma_v0_mps=cfg0.sigma_v0_mps, timeout_s=cfg0.timeout_s)
        self._frames: dict = {}  # class -> deque of (time_s, nis_sum, n)
        self._sums: dict = {}  # class -> [nis_sum, n] over the deque
        self.flagged: dict = {}  # class -> the last verdict that was "inconsistent" (for the log: new flags only)

    def _member(self, cls: str) -> int:
        c = self.tracks.per_class.get(cls)
        return 0 if c is None else self.tracks.configs.index(c)

    def observe(self, time_s: float, out, classes, xy_m, cov_frame_m2, shared_m) -> None:
        """One frame (as :meth:`~footprint_uq.tracking.motion_fit.MotionBank.observe`, after the tracks' step)."""
        before_nis, before_n = self.bank.NIS.copy(), self.bank.n_upd.copy()
        self.bank.observe(time_s, out, classes, xy_m, cov_frame_m2, shared_m)
        for cls, k in self.bank.classes.items():
            n = int(self.bank.n_upd[k] - (before_n[k] if k < before_n.shape[0] else 0))
            if n == 0:
                continue
            g = self._member(cls)
            s = float(self.bank.NIS[k, g] - (before_nis[k, g] if k < before_nis.shape[0] else 0.0))
            dq = self._frames.setdefault(cls, collections.deque())
            tot = self._sums.setdefault(cls, [0.0, 0])
            dq.append((float(time_s), s, n))
            tot[0] += s
            tot[1] += n
        self._expire(float(time_s))

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


class _TracksJacobian:
    """The monitor's bank's ``shared_at``: ``B`` at the predicted positions as the tracks' last step evaluated it
    (:meth:`~footprint_uq.tracking.classes.ClassTracks.shared_predicted`; the bank runs the tracker's filter on
    the same objects right after it, so its predictions are the tracks' own), instead of a second evaluation of
    the footprint kernel.  A frame that is not the tracks' last one (another object count) gets ``B`` evaluated
    at its points by ``tracks.shared_at``, as before.  With several motion models per camera each class's ``B``
    is its own table's (the bank evaluated every class's at the default model's prediction)."""

    def __init__(self, tracks):
        self.tracks = tracks

    def __call__(self, xy_m):
        B = self.tracks.shared_predicted()
        if B.shape[0] != len(xy_m):
            return self.tracks.shared_at(xy_m)
        return B


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
