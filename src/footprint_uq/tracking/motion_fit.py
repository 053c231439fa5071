"""The manoeuvre noise of a site's traffic, fitted to its tracks by maximum likelihood (docs/motion-fit.md).

The likelihood is that of the tracker's model (:class:`~footprint_uq.tracking.table.TrackTable`: constant-velocity
modes, the split measurement model with the calibration error ``w`` shared by a track's frames, IMM mixing), each
track's ``sum_k log p(z_k | z_1..k-1; q)``, computed by the filter that estimates ``w`` with the state
(:mod:`footprint_uq.tracking.joint_likelihood_kernels`): the tracker's own Schmidt innovations are correlated
through ``w``, their product is not a likelihood and its maximum lies above the truth (docs/motion-fit.md, section
2a).  It is evaluated for a grid of models at once (a *bank* of filters run side by side on the same tracks), in one
streamed pass over a recording: per object class, the log-likelihood of every grid model, nothing else is kept.

* one mode (a plain constant-velocity filter) of acceleration density ``q`` on a log grid: the profile
  likelihood of ``q`` gives the estimate and its 95 % interval (``2 (l_max - l(q)) <= chi2_1(0.95)``);
* optionally the tracker's two-mode IMM with the quiet mode's ``q`` on the grid and the manoeuvre mode and the
  switching at the prior's values: kept only where it beats the one-mode model by :data:`MODE_MARGIN_NATS`
  (the data show manoeuvres the one-mode model cannot explain); the manoeuvre mode's own density and the
  switching rates are not fitted (kept at the prior, and said so).

A class with too few tracks or updates, or whose interval is not bounded inside the grid, is reported as
``prior``: the prior's values are kept, with the reason (as ``calibrate budget`` keeps the base budget's value).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.interpolate import CubicSpline

from ..errors import InputError
from .joint_likelihood_kernels import joint_bank_frame
from .likelihood_kernels import bank_frame, bank_predicted
from .table import TrackerConfig, TrackOutput

__all__ = ["MotionGrid", "MotionBank", "ClassProfile", "members_of", "fit_profile", "fit_class", "fit_classes",
           "CHI2_95_1DOF", "MODE_MARGIN_NATS", "DEFAULT_Q_GRID_M2PS3", "LIKELIHOODS", "scale_gradient",
           "scale_sigma", "widen_interval"]

#: 95 % quantile of chi-square with 1 dof (the profile-likelihood interval)
CHI2_95_1DOF = 3.841458820694124
#: the IMM is kept only where its log-likelihood exceeds the one-mode model's by this (half chi2_1's 99 % quantile)
MODE_MARGIN_NATS = 0.5 * 6.634896601021214
#: the one-mode grid: 1e-4 to 100 m^2/s^3, 6 points per decade (down to 1e-4: a calm site's velocity sigmas
#: are still ~5 x too large at q = 0.01 after a few seconds of track, docs/motion-fit.md)
DEFAULT_Q_GRID_M2PS3 = np.geomspace(1e-4, 100.0, 37)
#: what a bank's members run: "joint" (the calibration error estimated with the state: the track's exact
#: likelihood, what the fit maximises) or "tracker" (the tracker's own Schmidt filter: its innovations and NIS, what
#: the on-line check watches; their product is not a likelihood, docs/motion-fit.md section 2a)
LIKELIHOODS = ("joint", "tracker")
#: positions kept per class for :func:`scale_sigma` (every ``stride``-th update; the stride doubles when full)
SCALE_SAMPLE_CAP = 4096
#: step of the central differences of ``B`` in :func:`scale_sigma`, m
SCALE_STEP_M = 0.05


@dataclass(frozen=True)
class MotionGrid:
    """The models of a bank: one-mode densities ``q_m2ps3`` and IMM quiet-mode densities ``imm_q_m2ps3`` (empty:
    no IMM members) with the prior's manoeuvre mode and switching (``prior``, a :class:`TrackerConfig`)."""

    q_m2ps3: np.ndarray = field(default_factory=lambda: DEFAULT_Q_GRID_M2PS3.copy())
    imm_q_m2ps3: np.ndarray = field(default_factory=lambda: DEFAULT_Q_GRID_M2PS3[::2].copy())
    prior: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self):
        for name in ("q_m2ps3", "imm_q_m2ps3"):
            a = np.asarray(getattr(self, name), dtype=np.float64).ravel()
            if not (np.isfinite(a).all() and (a > 0).all() and (np.diff(a) > 0).all()):
                raise InputError(name, a.tolist(), "increasing finite densities > 0, m^2/s^3")
            object.__setattr__(self, name, a)
        if self.q_m2ps3.size < 4:
            raise InputError("q_m2ps3", self.q_m2ps3.size, "at least 4 grid densities")
        if self.imm_q_m2ps3.size and (self.imm_q_m2ps3.size < 4 or self.prior.manoeuvre_accel_psd_m2ps3 is None):
            raise InputError("imm_q_m2ps3", self.imm_q_m2ps3.size,
                             "none, or at least 4 with a prior that has a manoeuvre mode")

    @property
    def n_single(self) -> int:
        return self.q_m2ps3.size

    def members(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``qs (G, 2)``, modes ``nm (G,)``, start probabilities ``mu0 (G, 2)``, leaving rates ``(G, 2)`` 1/s."""
        p = self.prior
        n1, n2 = self.q_m2ps3.size, self.imm_q_m2ps3.size
        qs = np.zeros((n1 + n2, 2))
        qs[:n1, 0] = qs[:n1, 1] = self.q_m2ps3
        qs[n1:, 0] = self.imm_q_m2ps3
        qs[n1:, 1] = p.manoeuvre_accel_psd_m2ps3 or 1.0
        nm = np.r_[np.ones(n1, np.int64), np.full(n2, 2, np.int64)]
        rates = np.array([1.0 / p.quiet_sojourn_s, 1.0 / p.manoeuvre_sojourn_s])
        mu0 = np.zeros((n1 + n2, 2))
        mu0[:n1, 0] = 1.0
        mu0[n1:] = (1.0 / rates) / (1.0 / rates).sum()  # the chain's stationary distribution, as the tracker
        return qs, nm, mu0, np.tile(rates, (n1 + n2, 1))

    def reference_member(self) -> int:
        """The one-mode member nearest the prior's quiet density: its predictions place ``B`` for every member."""
        return int(np.argmin(np.abs(np.log(self.q_m2ps3 / self.prior.accel_psd_m2ps3))))


class MotionBank:
    """One camera's tracks through a bank of filters, fed frame by frame with the tracker's association
    (:class:`~footprint_uq.tracking.table.TrackOutput`: ``track_id``, ``new_track``).

    Parameters
    ----------
    members : tuple ``(qs (G, 2), nm (G,), mu0 (G, 2), rates (G, 2))``
        The models (:meth:`MotionGrid.members`; :func:`members_of` for tracker configurations).
    rank : int
        Columns r of the frames' ``shared_m``.
    shared_at : callable ``(n, 2) -> (n, 2, r)``, optional
        ``B`` at world points (:class:`~footprint_uq.tracking.table.SharedJacobianAt`), evaluated at the tracks'
        positions predicted by member ``g_ref`` (as the tracker evaluates it at its predictions).
    sigma_v0_mps : float
        Prior sigma of a new track's velocity (the tracker's ``sigma_v0_mps``).
    timeout_s : float
        The tracker's timeout: rows of tracks not seen for twice as long are freed.
    likelihood : {"joint", "tracker"}
        :data:`LIKELIHOODS`: members with the calibration error in their state (the exact likelihood; storage
        ``(4 + r)^2`` per mode and member) or the tracker's Schmidt filter (its NIS).
    """

    def __init__(self, members, *, rank: int, shared_at=None, sigma_v0_mps: float = 50.0, timeout_s: float = 1.0,
                 g_ref: int = 0, likelihood: str = "tracker"):
        if likelihood not in LIKELIHOODS:
            raise InputError("likelihood", likelihood, f"one of {LIKELIHOODS}")
        self.likelihood = likelihood
        self.rank, self.shared_at = int(rank), shared_at
        self._qs, self._nm, self._mu0, self._rates = (np.ascontiguousarray(a) for a in members)
        self._g_ref = int(g_ref)
        self._var_v0 = float(sigma_v0_mps) ** 2
        self.timeout_s = float(timeout_s)
        self.classes: dict = {}  # class name -> index
        G = self._qs.shape[0]
        self.LL, self.NIS = np.zeros((0, G)), np.zeros((0, G))
        self.n_upd, self.n_bad, self.n_tracks = (np.zeros(0, np.int64) for _ in range(3))
        self._rows: dict = {}  # track_id -> row
        self._free: list = []
        self._cap = 0
        self._grow(64)
        self._swept_s = -math.inf
        self._scale_xy: dict = {}  # class index -> [(m, 2) position arrays, stride, positions seen, kept]

    @classmethod
    def from_grid(cls, grid: MotionGrid, *, rank: int, shared_at=None, likelihood: str = "joint") -> MotionBank:
        """The bank of a fit's grid (reference member: the one-mode density nearest the prior's quiet one; members:
        the exact likelihood)."""
        p = grid.prior
        return cls(grid.members(), rank=rank, shared_at=shared_at, sigma_v0_mps=p.sigma_v0_mps,
                   timeout_s=p.timeout_s, g_ref=grid.reference_member(), likelihood=likelihood)

    def _grow(self, cap: int) -> None:
        G, r, old = self._qs.shape[0], self.rank, self._cap

        def ext(a, shape):
            b = np.zeros((cap,) + shape)
            if old:
                b[:old] = a
            return b

        n, rc = (4 + r, 0) if self.likelihood == "joint" else (4, r)  # (joint: w in the state, no C)
        self._X = ext(getattr(self, "_X", None), (G, 2, n))
        self._P = ext(getattr(self, "_P", None), (G, 2, n, n))
        self._C = ext(getattr(self, "_C", None), (G, 2, 4, rc))
        self._MU = ext(getattr(self, "_MU", None), (G, 2))
        t = np.full(cap, np.nan)
        t[:old] = self._t_last[:old] if old else t[:old]
        self._t_last = t
        self._free += list(range(cap - 1, old - 1, -1))
        self._cap = cap

    def _class_index(self, classes, n: int) -> np.ndarray:
        out = np.empty(n, np.int64)
        for i, c in enumerate(classes if classes is not None else [None] * n):
            key = "" if c is None else str(c)
            k = self.classes.get(key)
            if k is None:
                k = self.classes[key] = len(self.classes)
                G = self._qs.shape[0]
                self.LL, self.NIS = np.vstack([self.LL, np.zeros((1, G))]), np.vstack([self.NIS, np.zeros((1, G))])
                self.n_upd, self.n_bad, self.n_tracks = (np.r_[a, 0] for a in (self.n_upd, self.n_bad, self.n_tracks))
            out[i] = k
        return out

    def _rows_of(self, out: TrackOutput, cls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        n = out.track_id.shape[0]
        rows, start = np.full(n, -1, np.int64), np.zeros(n, np.bool_)
        for i, (tid, new) in enumerate(zip(out.track_id.tolist(), out.new_track.tolist(), strict=True)):
            if tid < 0:
                continue
            s = self._rows.get(tid)
            if new or s is None:  # (a track first seen mid-way, e.g. a restarted bank: starts here)
                if s is None:
                    if not self._free:
                        self._grow(2 * self._cap)
                    s = self._free.pop()
                    self._rows[tid] = s
                start[i] = True
                self.n_tracks[cls[i]] += 1
            rows[i] = s
        return rows, start

    def _sweep(self, time_s: float, timeout_s: float) -> None:
        """Free the rows of tracks not updated for longer than ``timeout_s`` (the tracker has deleted them)."""
        if time_s - self._swept_s < timeout_s:
            return
        self._swept_s = time_s
        dead = [tid for tid, s in self._rows.items() if time_s - self._t_last[s] > timeout_s]
        for tid in dead:
            s = self._rows.pop(tid)
            self._t_last[s] = np.nan
            self._free.append(s)

    def observe(self, time_s: float, out: TrackOutput, classes, xy_m, cov_frame_m2, shared_m) -> None:
        """One frame of n objects: the tracker's output for them, their classes (n names or None), centres ``xy_m
        (n, 2)``, per-frame covariances ``cov_frame_m2 (n, 2, 2)`` and shared Jacobians ``shared_m (n, 2, r)``."""
        n = out.track_id.shape[0]
        self._sweep(time_s, 2.0 * self.timeout_s)
        cls = self._class_index(classes, n)
        rows, start = self._rows_of(out, cls)
        z = np.ascontiguousarray(xy_m, dtype=np.float64).reshape(n, 2)
        R = np.ascontiguousarray(cov_frame_m2, dtype=np.float64).reshape(n, 2, 2)
        Bf = np.ascontiguousarray(shared_m, dtype=np.float64).reshape(n, 2, self.rank)
        Bp = np.zeros((0, 2, self.rank))
        if self.shared_at is not None and self.rank and n:
            pred = np.empty((n, 2))
            bank_predicted(rows, start, float(time_s), self._X, self._MU, self._t_last, self._g_ref, pred)
            Bp = np.ascontiguousarray(self.shared_at(pred), dtype=np.float64)
        if self.likelihood == "joint":
            self._sample_positions(cls, rows, start, z)
            joint_bank_frame(rows, start, cls, float(time_s), z, R, Bp, Bf, self._X, self._P, self._MU,
                             self._t_last, self._qs, self._nm, self._rates, self._mu0, self._var_v0, self.LL, self.NIS,
                             self.n_upd, self.n_bad)
            return
        bank_frame(rows, start, cls, float(time_s), z, R, Bp, Bf, self._X, self._P, self._C, self._MU, self._t_last,
                   self._qs, self._nm, self._rates, self._mu0, self._var_v0, self.LL, self.NIS, self.n_upd, self.n_bad)

    def _sample_positions(self, cls: np.ndarray, rows: np.ndarray, start: np.ndarray, z: np.ndarray) -> None:
        """Keep every ``stride``-th updated position of each class (for :meth:`scale_sigmas`)."""
        upd = (rows >= 0) & ~start
        for k in np.unique(cls[upd]).tolist():
            rec = self._scale_xy.setdefault(k, [[], 1, 0, 0])  # [arrays, stride, seen, kept]
            pts = z[upd & (cls == k)]
            kept = pts[(rec[2] + np.arange(pts.shape[0])) % rec[1] == 0]
            rec[2] += pts.shape[0]
            if kept.shape[0]:
                rec[0].append(kept)
                rec[3] += kept.shape[0]
            if rec[3] > SCALE_SAMPLE_CAP:
                half = np.concatenate(rec[0])[::2]
                rec[0], rec[1], rec[3] = [half], 2 * rec[1], half.shape[0]

    def scale_sigmas(self) -> dict:
        """class name -> ``(sigma, n_updates)``: :func:`scale_sigma` over the class's sampled positions (0 without
        ``shared_at``, and for a ``"tracker"`` bank, which keeps no positions)."""
        out = {}
        for c, k in self.classes.items():
            rec = self._scale_xy.get(k)
            xy = np.concatenate(rec[0]) if rec else np.zeros((0, 2))
            sig = scale_sigma(self.shared_at, xy) if self.shared_at is not None and self.rank else 0.0
            out[c] = (sig, int(self.n_upd[k]))
        return out

    def sums(self) -> dict:
        """class name -> ``(LL (G,), NIS (G,), n_updates, n_bad, n_tracks)``."""
        return {c: (self.LL[k].copy(), self.NIS[k].copy(), int(self.n_upd[k]), int(self.n_bad[k]),
                    int(self.n_tracks[k])) for c, k in self.classes.items()}


def scale_gradient(shared_at, xy_m) -> np.ndarray:
    """``t (r,)``: the mean over ground points ``xy_m (m, 2)`` of ``tr(dB_c/dx)`` per calibration direction ``c``.

    The calibration error ``w`` maps the ground to the measured ground, ``x -> x + B(x) w``, whose local linear
    part is ``I + M``, ``M = sum_c w_c dB_c/dx``: a road user's random acceleration ``a`` is measured as ``(I + M)
    a``, its density per axis as ``q (I + M)(I + M)^T``, and a scalar fit finds ``log q_hat = log q + tr(M) = log q
    + t^T w`` to first order (a camera that sees the scene 2 % larger sees its traffic 4 % more agitated).  ``dB/dx``
    by central differences of ``shared_at`` (step :data:`SCALE_STEP_M`); points where ``B`` is not finite are left
    out (zeros where none is left)."""
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    d = SCALE_STEP_M
    ex, ey = np.array([d, 0.0]), np.array([0.0, d])
    dbx = (shared_at(xy + ex)[:, 0, :] - shared_at(xy - ex)[:, 0, :]) / (2 * d)
    dby = (shared_at(xy + ey)[:, 1, :] - shared_at(xy - ey)[:, 1, :]) / (2 * d)
    tr = dbx + dby
    ok = np.isfinite(tr).all(1)
    return tr[ok].mean(0) if ok.any() else np.zeros(tr.shape[1])


def scale_sigma(shared_at, xy_m) -> float:
    """The standard deviation of ``log q_hat - log q`` that one camera's calibration error adds (``|t|`` of
    :func:`scale_gradient`, ``w ~ N(0, I)``): the fit measures the traffic as this camera sees it, and from the
    camera's own tracks its scale cannot be told from the traffic's agitation."""
    return float(np.linalg.norm(scale_gradient(shared_at, xy_m))) if len(xy_m) else 0.0


def widen_interval(q_hat: float, ci95, sigma_log: float) -> list:
    """The 95 % interval ``[lo, hi]`` (hi None: unbounded) of the profile likelihood widened by a log-normal error
    of standard deviation ``sigma_log`` on each side, in ``log q``: half-widths ``sqrt(h^2 + (1.96 sigma_log)^2)``.
    A lower end at 0 stays 0; an unbounded upper end stays unbounded."""
    lo, hi = ci95
    if not sigma_log > 0.0:
        return [lo, hi]
    z = 1.959963984540054 * sigma_log
    lq = math.log(q_hat)
    lo = 0.0 if lo <= 0.0 else math.exp(lq - math.hypot(lq - math.log(lo), z))
    hi = None if hi is None else math.exp(lq + math.hypot(math.log(hi) - lq, z))
    return [lo, hi]


class ClassProfile(dict):
    """One profile-likelihood fit (a dict: ``q_hat``, ``ci95`` ``[lo, hi]`` (hi None: unbounded above),
    ``ll_max``, ``at_lower_edge``)."""


def members_of(configs) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The bank members (:class:`MotionBank`) of tracker configurations (:class:`~footprint_uq.tracking.table.
    TrackerConfig`), one each: its modes, densities, switching rates and start probabilities, as the tracker."""
    G = len(configs)
    qs, nm, mu0, rates = np.zeros((G, 2)), np.ones(G, np.int64), np.zeros((G, 2)), np.ones((G, 2))
    for g, c in enumerate(configs):
        qs[g] = c.accel_psd_m2ps3
        mu0[g, 0] = 1.0
        if c.manoeuvre_accel_psd_m2ps3 is not None:
            qs[g, 1], nm[g] = c.manoeuvre_accel_psd_m2ps3, 2
            rates[g] = 1.0 / c.quiet_sojourn_s, 1.0 / c.manoeuvre_sojourn_s
            mu0[g] = (1.0 / rates[g]) / (1.0 / rates[g]).sum()
    return qs, nm, mu0, rates


def fit_profile(q_grid, ll) -> ClassProfile:
    """The maximum and 95 % profile interval of a log-likelihood ``ll (G,)`` given on increasing densities
    ``q_grid (G,)`` (a cubic spline in ``log q``, 4000 points).  Below the grid's first point the likelihood is
    taken as flat (its limit at q -> 0 is finite): an interval reaching the first point starts at 0; one reaching
    the last is unbounded above (``hi`` None)."""
    lq = np.log(np.asarray(q_grid, dtype=np.float64))
    ll = np.asarray(ll, dtype=np.float64)
    if not np.isfinite(ll).all():
        raise InputError("log-likelihood", "non-finite", "finite values at every grid density")
    fine = np.linspace(lq[0], lq[-1], 4000)
    f = CubicSpline(lq, ll)(fine)
    i = int(np.argmax(f))
    top = float(f[i])
    inside = f >= top - 0.5 * CHI2_95_1DOF
    a = i
    while a > 0 and inside[a - 1]:
        a -= 1
    b = i
    while b < fine.size - 1 and inside[b + 1]:
        b += 1
    lo = 0.0 if a == 0 else float(np.exp(fine[a]))
    hi = None if b == fine.size - 1 else float(np.exp(fine[b]))
    return ClassProfile(q_hat=float(np.exp(fine[i])), ci95=[lo, hi], ll_max=top, at_lower_edge=i == 0)


def _prior_entry(prior: TrackerConfig) -> dict:
    return {"accel_psd_m2ps3": prior.accel_psd_m2ps3, "manoeuvre_accel_psd_m2ps3": prior.manoeuvre_accel_psd_m2ps3}


def fit_class(grid: MotionGrid, sums: tuple, *, min_tracks: int = 10, min_updates: int = 300,
              prior: TrackerConfig | None = None, scale_sigma_log: float = 0.0) -> dict:
    """The motion entry of one class (:mod:`footprint_uq.uncertainty.motion_section`) from its bank sums
    (:meth:`MotionBank.sums`): identified (the fitted one-mode density with its interval, or the IMM's quiet one
    where the IMM wins by :data:`MODE_MARGIN_NATS`), or ``prior`` with the reason.  ``scale_sigma_log``: the
    cameras' scale uncertainty in ``log q`` (:func:`scale_sigma`), by which the interval is widened
    (:func:`widen_interval`)."""
    prior = prior or grid.prior
    LL, _, n_upd, n_bad, n_tracks = sums
    entry = {**_prior_entry(prior), "status": "prior", "n_tracks": n_tracks, "n_updates": n_upd}
    if n_tracks < min_tracks or n_upd < min_updates:
        entry["note"] = (f"too little data: {n_tracks} tracks, {n_upd} updates (at least {min_tracks} tracks and "
                         f"{min_updates} updates needed); the prior kept")
        return entry
    n1 = grid.n_single
    one = fit_profile(grid.q_m2ps3, LL[:n1])
    best, mode_note, gain = one, "one mode", None
    if grid.imm_q_m2ps3.size:
        imm = fit_profile(grid.imm_q_m2ps3, LL[n1:])
        gain = imm["ll_max"] - one["ll_max"]
        if gain > MODE_MARGIN_NATS:
            best = imm
            mode_note = (f"two modes: the prior's manoeuvre mode ({prior.manoeuvre_accel_psd_m2ps3:g} m^2/s^3, "
                         f"sojourns {prior.quiet_sojourn_s:g} / {prior.manoeuvre_sojourn_s:g} s, not fitted) gains "
                         f"{gain:.1f} nats over one mode")
        else:
            mode_note = f"one mode (the prior's manoeuvre mode gains {gain:.1f} nats, below {MODE_MARGIN_NATS:.2f})"
    if best["ci95"][1] is None:
        entry["note"] = (f"not identified: the 95 % interval of the density is unbounded above within the grid "
                         f"(estimate {best['q_hat']:.3g} m^2/s^3); the prior kept")
        entry["accel_psd_ci95_m2ps3"] = best["ci95"]
        return entry
    grid_q = grid.imm_q_m2ps3 if best is not one else grid.q_m2ps3
    q_hat = max(best["q_hat"], float(grid_q[0]))
    entry.update(accel_psd_m2ps3=q_hat, accel_psd_ci95_m2ps3=widen_interval(q_hat, best["ci95"], scale_sigma_log),
                 status="identified",
                 manoeuvre_accel_psd_m2ps3=prior.manoeuvre_accel_psd_m2ps3 if best is not one else None,
                 note=mode_note + (f"; at or below the grid's lowest density {grid_q[0]:g} (calm traffic)"
                                   if best["at_lower_edge"] else "")
                 + (f"; interval widened by the camera's scale ({100 * scale_sigma_log:.1f} % in q)"
                    if scale_sigma_log > 0 else "")
                 + (f"; {n_bad} updates left out (a singular innovation)" if n_bad else ""))
    if best is not one:
        entry["quiet_sojourn_s"], entry["manoeuvre_sojourn_s"] = prior.quiet_sojourn_s, prior.manoeuvre_sojourn_s
    if gain is not None:
        entry["log_likelihood_gain"] = float(gain)
    return entry


def _pooled_sigma(parts) -> float:
    """``sqrt(sum (n_b sigma_b)^2) / sum n_b`` of ``(sigma_b, n_b)`` from independent cameras (their own ``w``)."""
    n = sum(p[1] for p in parts)
    return math.sqrt(sum((p[0] * p[1]) ** 2 for p in parts)) / n if n else 0.0


def fit_classes(grid: MotionGrid, banks, **options) -> dict:
    """The ``motion`` section (:mod:`footprint_uq.uncertainty.motion_section`) of one or more banks (cameras):
    their sums by class, each class fitted by :func:`fit_class` with its interval widened by the cameras' scale
    (:meth:`MotionBank.scale_sigmas`, pooled over independent cameras), and a ``default`` entry from all classes
    pooled (for classes the recording did not show).  ``options``: those of :func:`fit_class`."""
    total: dict = {}
    sig: dict = {}
    cams = []
    for bank in banks:
        for c, s in bank.sums().items():
            t = total.get(c)
            total[c] = s if t is None else (t[0] + s[0], t[1] + s[1], t[2] + s[2], t[3] + s[3], t[4] + s[4])
        ss = bank.scale_sigmas()
        for c, v in ss.items():
            sig.setdefault(c, []).append(v)
        n = sum(v[1] for v in ss.values())  # a camera's classes share its w: their sigmas' weighted mean
        cams.append((sum(v[0] * v[1] for v in ss.values()) / n if n else 0.0, n))
    classes = {c: fit_class(grid, s, scale_sigma_log=_pooled_sigma(sig.get(c, [])), **options)
               for c, s in sorted(total.items()) if c != ""}
    out: dict = {"classes": classes}
    if total:
        pooled = tuple(sum(s[k] for s in total.values()) for k in range(5))
        out["default"] = fit_class(grid, pooled, scale_sigma_log=_pooled_sigma(cams), **options)
    return out
