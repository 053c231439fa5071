"""The IMM's own parameters fitted to a site's tracks: the manoeuvre mode's density and the mean sojourns.

:mod:`footprint_uq.tracking.motion_fit` fits the quiet density ``q`` (one mode, or the tracker's IMM with the
prior's manoeuvre mode and switching).  Here the IMM's four parameters are fitted together by maximum likelihood
of the tracker's own innovations (the same bank of filters, :class:`~footprint_uq.tracking.motion_fit.MotionBank`,
in the same streamed pass): a product grid of IMM members over

* ``q_quiet`` (m^2/s^3), the quiet mode's density;
* ``q_manoeuvre`` (m^2/s^3), the manoeuvre mode's density;
* ``quiet_sojourn_s`` and ``manoeuvre_sojourn_s``, the mean times in each mode (the switching probabilities of a
  step of ``h`` seconds follow, as in the tracker: a continuous-time Markov chain),

beside the one-mode grid.  Each parameter's **profile** log-likelihood (the maximum over the others) gives its
estimate and 95 % interval (``2 (l_max - l) <= chi2_1(0.95)``, a cubic spline in the log of the parameter).  A
parameter whose interval reaches an end of its grid is **not identified**: it keeps the prior's value (as a class
with too little data keeps the prior's ``q``), and the others are fitted with it held there.  The IMM is kept for
a class only where it beats the one-mode model by half the 99 % quantile of chi-square with as many degrees of
freedom as the IMM adds (1 + the identified manoeuvre parameters); else the class gets the one-mode fit.
docs/motion-fit.md, section 2, "Two modes fitted".
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.stats import chi2

from ..errors import InputError
from ..uncertainty.budget import load_budget
from .classes import ClassTracks, tracker_configs
from .motion_campaigns import campaign_frames, coverage_pass
from .motion_fit import CHI2_95_1DOF, DEFAULT_Q_GRID_M2PS3, MotionBank, MotionGrid, fit_class, fit_profile
from .synthetic import default_camera
from .table import SharedJacobianAt, TrackerConfig, TrackTable

__all__ = ["ImmGrid", "IMM_PARAMETERS", "profile_interval", "fit_imm_class", "fit_imm_classes", "ImmCampaigns",
           "run_imm_campaigns"]

#: the IMM's parameters in the order of the product grid's axes (the motion section's keys)
IMM_PARAMETERS = ("accel_psd_m2ps3", "manoeuvre_accel_psd_m2ps3", "quiet_sojourn_s", "manoeuvre_sojourn_s")
#: the motion section's key of each parameter's 95 % interval
_CI_KEYS = ("accel_psd_ci95_m2ps3", "manoeuvre_accel_psd_ci95_m2ps3", "quiet_sojourn_ci95_s",
            "manoeuvre_sojourn_ci95_s")


def _axis(name: str, a) -> np.ndarray:
    a = np.asarray(a, dtype=np.float64).ravel()
    if not (a.size >= 3 and np.isfinite(a).all() and (a > 0).all() and (np.diff(a) > 0).all()):
        raise InputError(name, a.tolist(), "at least 3 increasing finite values > 0")
    return a


@dataclass(frozen=True)
class ImmGrid:
    """The bank's models: the one-mode grid ``q_m2ps3`` and the IMM product grid ``q_quiet_m2ps3 x
    q_manoeuvre_m2ps3 x quiet_sojourn_s x manoeuvre_sojourn_s`` (each axis at least 3 increasing values; the
    prior's values should lie on them: a parameter that is not identified is held at the nearest node).

    The defaults: 13 quiet densities 1e-3..10 (3 per decade), manoeuvre densities 1, 3, 10, 30, 100, sojourns 1,
    3, 10 s (quiet) and 0.3, 1, 3, 10 s (manoeuvre): 780 IMM members beside 37 one-mode ones (~10 x the work of
    ``--modes auto``)."""

    q_m2ps3: np.ndarray = field(default_factory=lambda: DEFAULT_Q_GRID_M2PS3.copy())
    q_quiet_m2ps3: np.ndarray = field(default_factory=lambda: np.geomspace(1e-3, 10.0, 13))
    q_manoeuvre_m2ps3: np.ndarray = field(default_factory=lambda: np.array([1.0, 3.0, 10.0, 30.0, 100.0]))
    quiet_sojourn_s: np.ndarray = field(default_factory=lambda: np.array([1.0, 3.0, 10.0]))
    manoeuvre_sojourn_s: np.ndarray = field(default_factory=lambda: np.array([0.3, 1.0, 3.0, 10.0]))
    prior: TrackerConfig = field(default_factory=TrackerConfig)

    def __post_init__(self):
        for name in ("q_quiet_m2ps3", "q_manoeuvre_m2ps3", "quiet_sojourn_s", "manoeuvre_sojourn_s"):
            object.__setattr__(self, name, _axis(name, getattr(self, name)))
        object.__setattr__(self, "q_m2ps3", MotionGrid(self.q_m2ps3, np.zeros(0), self.prior).q_m2ps3)

    @property
    def one(self) -> MotionGrid:
        """The one-mode part (a :class:`~footprint_uq.tracking.motion_fit.MotionGrid` without IMM members)."""
        return MotionGrid(self.q_m2ps3, np.zeros(0), self.prior)

    @property
    def n_single(self) -> int:
        return self.q_m2ps3.size

    @property
    def axes(self) -> tuple[np.ndarray, ...]:
        """The product grid's axes, in :data:`IMM_PARAMETERS` order."""
        return self.q_quiet_m2ps3, self.q_manoeuvre_m2ps3, self.quiet_sojourn_s, self.manoeuvre_sojourn_s

    @property
    def shape(self) -> tuple[int, ...]:
        return tuple(a.size for a in self.axes)

    def members(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The bank members (:class:`~footprint_uq.tracking.motion_fit.MotionBank`): the one-mode grid, then the
        product grid in C order (``qs (G, 2)``, modes ``(G,)``, start probabilities ``(G, 2)``, rates ``(G, 2)``)."""
        qs1, nm1, mu1, r1 = self.one.members()
        g = np.meshgrid(*self.axes, indexing="ij")
        qq, qm, tq, tm = (a.ravel() for a in g)
        qs2 = np.column_stack([qq, qm])
        rates2 = np.column_stack([1.0 / tq, 1.0 / tm])
        mu2 = np.column_stack([tq, tm]) / (tq + tm)[:, None]  # the chain's stationary distribution
        return (np.vstack([qs1, qs2]), np.r_[nm1, np.full(qq.size, 2, np.int64)], np.vstack([mu1, mu2]),
                np.vstack([r1, rates2]))

    def reference_member(self) -> int:
        return self.one.reference_member()

    def prior_index(self) -> tuple[int, ...]:
        """The node of each axis nearest the prior's value (log distance)."""
        p = self.prior
        vals = (p.accel_psd_m2ps3, p.manoeuvre_accel_psd_m2ps3 or 30.0, p.quiet_sojourn_s, p.manoeuvre_sojourn_s)
        return tuple(int(np.argmin(np.abs(np.log(a / v)))) for a, v in zip(self.axes, vals, strict=True))


def profile_interval(values, profile) -> dict:
    """The maximum and 95 % interval of a profile log-likelihood ``profile (K,)`` on increasing ``values (K,)``
    (a cubic spline in ``log value``; K = 3: a parabola): ``{"hat", "ci95": [lo, hi], "ll_max"}``, ``lo`` / ``hi``
    None where the interval reaches the grid's first / last value (not bounded within the grid)."""
    lv = np.log(np.asarray(values, dtype=np.float64))
    prof = np.asarray(profile, dtype=np.float64)
    if not np.isfinite(prof).all():
        raise InputError("profile log-likelihood", "non-finite", "finite values at every grid node")
    fine = np.linspace(lv[0], lv[-1], 2000)
    f = CubicSpline(lv, prof)(fine)
    i = int(np.argmax(f))
    inside = f >= f[i] - 0.5 * CHI2_95_1DOF
    a = i
    while a > 0 and inside[a - 1]:
        a -= 1
    b = i
    while b < fine.size - 1 and inside[b + 1]:
        b += 1
    lo = None if a == 0 else float(np.exp(fine[a]))
    hi = None if b == fine.size - 1 else float(np.exp(fine[b]))
    return {"hat": float(np.exp(fine[i])), "ll_max": float(f[i]), "ci95": [lo, hi]}


def _profile(LL4: np.ndarray, k: int) -> np.ndarray:
    """The profile of axis k: the maximum over the other axes."""
    return LL4.max(axis=tuple(j for j in range(LL4.ndim) if j != k))


def _identified(k: int, prof: dict, profile: np.ndarray) -> bool:
    """Bounded on both sides within the grid, its best node inside (q_quiet: at or down to the lowest node is
    "calm", as the one-mode fit reads it)."""
    lo, hi = prof["ci95"]
    i = int(np.argmax(profile))
    if k == 0:
        return hi is not None and i < profile.size - 1
    return lo is not None and hi is not None and 0 < i < profile.size - 1


def fit_imm_class(grid: ImmGrid, sums: tuple, *, min_tracks: int = 10, min_updates: int = 300) -> dict:
    """The motion entry of one class from its bank sums (:meth:`~footprint_uq.tracking.motion_fit.MotionBank.
    sums` of a bank of ``grid.members()``): the one-mode fit (:func:`~footprint_uq.tracking.motion_fit.fit_class`),
    replaced by the fitted IMM where that wins by its margin (module doc)."""
    LL, NIS, n_upd, n_bad, n_tracks = sums
    n1 = grid.n_single
    entry = fit_class(grid.one, (LL[:n1], NIS[:n1], n_upd, n_bad, n_tracks), min_tracks=min_tracks,
                      min_updates=min_updates)
    if entry["status"] != "identified" and "too little data" in entry.get("note", ""):
        return entry
    LL4 = np.asarray(LL[n1:], dtype=np.float64).reshape(grid.shape)
    ident = [_identified(k, profile_interval(grid.axes[k], _profile(LL4, k)), _profile(LL4, k)) for k in range(4)]
    held = grid.prior_index()
    sub = LL4[tuple(slice(None) if ident[k] else slice(held[k], held[k] + 1) for k in range(4))]
    if not ident[0]:
        return {**entry, "note": entry.get("note", "") + "; IMM: its quiet density is not identified"}
    profs = [profile_interval(grid.axes[k], _profile(sub, k)) if ident[k] else None for k in range(4)]
    one_ll = fit_profile(grid.q_m2ps3, LL[:n1])["ll_max"]  # (both maxima of their profiles' splines)
    gain = max(float(sub.max()), *(p["ll_max"] for p in profs if p is not None)) - one_ll
    dof = 1 + sum(ident[1:])
    margin = 0.5 * float(chi2.ppf(0.99, dof))
    fitted = [IMM_PARAMETERS[k] for k in range(1, 4) if ident[k]]
    kept = [IMM_PARAMETERS[k] for k in range(1, 4) if not ident[k]]
    summary = (f"IMM fitted ({', '.join(fitted) or 'none of the manoeuvre parameters'} identified"
               + (f"; {', '.join(kept)} not identified, held at the prior" if kept else "") + ")")
    if gain <= margin:
        entry["note"] = (entry.get("note", "") + f"; {summary} gains {gain:.1f} nats over one mode, below its "
                         f"margin {margin:.2f}: one mode kept")
        entry["log_likelihood_gain"] = gain
        return entry
    vals = [profs[k]["hat"] if ident[k] else float(grid.axes[k][held[k]]) for k in range(4)]
    q_lo = 0.0 if profs[0]["ci95"][0] is None else profs[0]["ci95"][0]
    out = {"accel_psd_m2ps3": max(vals[0], float(grid.axes[0][0])), "manoeuvre_accel_psd_m2ps3": vals[1],
           "quiet_sojourn_s": vals[2], "manoeuvre_sojourn_s": vals[3], "accel_psd_ci95_m2ps3": [q_lo,
                                                                                             profs[0]["ci95"][1]],
           "status": "identified", "n_tracks": n_tracks, "n_updates": n_upd, "log_likelihood_gain": gain,
           "note": f"two modes: {summary}, gains {gain:.1f} nats over one mode (margin {margin:.2f})"
                   + (f"; {n_bad} updates left out (a singular innovation)" if n_bad else "")}
    for k in range(1, 4):
        if ident[k]:
            out[_CI_KEYS[k]] = profs[k]["ci95"]
    return out


def fit_imm_classes(grid: ImmGrid, banks, **options) -> dict:
    """The ``motion`` section of one or more banks of ``grid.members()``: every class by :func:`fit_imm_class`,
    and a ``default`` entry from all classes pooled (as :func:`~footprint_uq.tracking.motion_fit.fit_classes`)."""
    total: dict = {}
    for bank in banks:
        for c, s in bank.sums().items():
            t = total.get(c)
            total[c] = s if t is None else tuple(a + b for a, b in zip(t, s, strict=True))
    out: dict = {"classes": {c: fit_imm_class(grid, s, **options) for c, s in sorted(total.items()) if c != ""}}
    if total:
        out["default"] = fit_imm_class(grid, tuple(sum(s[k] for s in total.values()) for k in range(5)), **options)
    return out


class ImmCampaigns(NamedTuple):
    """:func:`run_imm_campaigns`' result: every campaign's entry, and the pooled 95 % coverage of velocity and
    heading of the trackers of those entries, with their counts."""

    entries: list
    coverage_velocity: float
    coverage_heading: float
    n_velocity: int
    n_heading: int


def _coverage(frames, tracks: ClassTracks) -> tuple[np.ndarray, np.ndarray]:
    """Track the campaigns' frames; ``(hits, counts)`` of the 95 % velocity ellipse and heading interval
    (:func:`~footprint_uq.tracking.motion_campaigns.coverage_pass`, the count of ``run_campaigns``)."""
    hits, counts = np.zeros(2), np.zeros(2)
    coverage_pass(frames, tracks, hits, counts)
    return hits, counts


def run_imm_campaigns(q_true: float, *, scenario: str = "turning", n_campaigns: int = 20, n_objects: int = 10,
                      duration_s: float = 4.0, rate_hz: float = 30.0, seed: int = 0, grid: ImmGrid | None = None,
                      budget="basler1@deg", min_tracks: int = 10, min_updates: int = 300) -> ImmCampaigns:
    """The seeded campaigns of :func:`~footprint_uq.tracking.motion_campaigns.campaign_frames` (``scenario``:
    "turning", "stopping", "straight"), every campaign fitted by :func:`fit_imm_class`, then tracked again with
    its fitted model and checked by coverage (as :func:`~footprint_uq.tracking.motion_campaigns.run_campaigns`
    does for the one-mode fit)."""
    grid = grid or ImmGrid()
    camera = default_camera()
    at = SharedJacobianAt(camera, load_budget(budget))
    kw = dict(duration_s=duration_s, rate_hz=rate_hz, seed=seed, budget=budget, camera=camera, scenario=scenario)
    assoc = TrackTable(grid.prior, rank=at.rank, shared_at=at)
    p = grid.prior
    # the tracker's own innovations, as these campaigns were measured (docs/motion-fit.md, "The IMM fitted"):
    # `calibrate motion --modes imm` fits with the joint likelihood (section 2a), ~14 x the memory per track
    bank = MotionBank(grid.members(), rank=at.rank, shared_at=at, sigma_v0_mps=p.sigma_v0_mps, timeout_s=p.timeout_s,
                      g_ref=grid.reference_member(), likelihood="tracker")
    for t, ids, classes, xy, cov, B, _ in campaign_frames(q_true, n_campaigns, n_objects, **kw):
        bank.observe(t, assoc.step(t, ids, xy, cov, B), classes, xy, cov, B)
    sums = bank.sums()
    entries = [fit_imm_class(grid, sums[str(c)], min_tracks=min_tracks, min_updates=min_updates)
               for c in range(n_campaigns)]
    default, per_class = tracker_configs({"classes": {str(c): e for c, e in enumerate(entries)}}, grid.prior)
    hits, counts = _coverage(campaign_frames(q_true, n_campaigns, n_objects, **kw),
                             ClassTracks(default, per_class, rank=at.rank, shared_at=at))
    cov = hits / np.maximum(counts, 1)
    return ImmCampaigns(entries, float(cov[0]), float(cov[1]), int(counts[0]), int(counts[1]))
