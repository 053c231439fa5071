"""Does the uncertainty cover the real errors?  Per-object metrics and a streaming summary with a verdict.

Per object (:func:`object_metrics`): the residual ``r = truth - prediction`` in the world frame and along
the ellipse's own axes, the squared Mahalanobis distance ``NEES = r^T C^-1 r`` (chi-square with 2 degrees
of freedom if the model is right) and whether the truth is inside the 50 / 90 / 95 / 99 % ellipses
(``NEES <= -2 ln(1 - p)``).

Summary (:class:`CoverageAccumulator`, fed chunk by chunk, memory flat in the number of pairs):

* empirical coverage per level with a Wilson interval (objects taken as independent), the same interval
  at the **effective number of objects** ``n_eff`` (below) and the standard error ``sqrt(p (1 - p) / n_eff)``
  at the nominal level ``p``; with several calibration groups also the cluster-robust standard error from
  the spread between groups;
* coverage by range band, class and ``linear_ok``; a fine grid of levels for the calibration figure;
* the bias (mean residual) with its model covariance (shared calibration draws included) and a test;
* the verdict from the NEES test.

**The NEES test and the shared calibration draw.**  Objects seen by one camera share one draw of its
calibration errors, so their residuals are correlated and the NEES values are not independent.  Under the
model (Gaussian, first order), the sum ``Q = sum_i NEES_i`` has mean ``2 N`` and variance
``V = sum_g [2 tr((M_g S_g)^2) - 2 sum_{i in g} tr((A_i J_i S_g J_i^T)^2) + 4 n_g]`` with ``A_i = C_i^-1``,
``M_g = sum_{i in g} J_i^T A_i J_i`` and ``S_g`` the parameter covariance of group ``g`` (exact for
quadratic forms of jointly Gaussian residuals; it reduces to ``4 N`` for independent objects).  ``Q`` is
compared with a scaled chi-square of the same mean and variance (Satterthwaite: ``Q ~ a chi2_nu``, ``a =
V / 4N``, ``nu = 8 N^2 / V``); ``n_eff = nu / 2`` is the number of independent objects that would carry the
same information.  ``Q`` too large (one-sided p < alpha/2) -> **over-confident** (ellipses too small), too
small -> **under-confident**, else **consistent**.  What the test assumes: the model's correlation
structure (one calibration draw per group, the budget's parameter covariance), Gaussian errors (a heavy
tail raises ``Q``), first-order propagation, and the moment-matched chi-square for ``Q``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import chdtrc, ndtri

from .. import params as P
from ..errors import InputError
from ..uncertainty.ellipse import ellipse_axes
from .pairs import STATUS_ERROR, refused_reasons

__all__ = ["LEVELS", "DEFAULT_RANGE_BANDS_M", "object_metrics", "nees_threshold", "wilson_interval",
           "CoverageAccumulator", "VERDICTS", "range_band_labels"]

#: nominal levels of the ellipses checked per object
LEVELS = (0.5, 0.9, 0.95, 0.99)
#: default range bands, metres (edges; the last band is open)
DEFAULT_RANGE_BANDS_M = (0.0, 25.0, 50.0, 75.0, 100.0, 150.0)
#: the fine grid of the calibration figure
GRID = np.round(np.arange(0.05, 0.995, 0.01), 2)
VERDICTS = ("consistent", "over-confident", "under-confident")
#: objects kept (seeded random sample) for the figures and the error quantiles
SAMPLE_SIZE = 20_000
#: most kinds of refusal listed in the summary (the rest are counted as one)
MAX_REFUSAL_KINDS = 50


def nees_threshold(level) -> np.ndarray:
    """NEES bound of the ``level`` ellipse: ``-2 ln(1 - level)`` (2-D chi-square quantile)."""
    return -2.0 * np.log1p(-np.asarray(level, dtype=np.float64))


def object_metrics(residual_m, cov_m2) -> dict:
    """Per-object metrics of residuals ``(n, 2)`` under covariances ``(n, 2, 2)``.

    Returns
    -------
    dict of arrays (n,)
        ``nees``; ``r_major_m``, ``r_minor_m`` (residual along the 1-sigma ellipse's major / minor axis,
        metres), ``sigma_major_m``, ``sigma_minor_m``, ``orientation_deg``; ``inside_50`` ... ``inside_99``
        (bool).  NaN / False where the residual or the covariance is not finite.
    """
    r = np.asarray(residual_m, dtype=np.float64)
    c = np.asarray(cov_m2, dtype=np.float64)
    a, b, d = c[:, 0, 0], c[:, 0, 1], c[:, 1, 1]
    det = a * d - b * b
    with np.errstate(invalid="ignore", divide="ignore"):
        nees = (d * r[:, 0] ** 2 - 2 * b * r[:, 0] * r[:, 1] + a * r[:, 1] ** 2) / det
    nees = np.where(det > 0, nees, np.nan)
    smaj, smin, ang = ellipse_axes(c)
    t = np.deg2rad(ang)
    out = {"nees": nees, "r_major_m": r[:, 0] * np.cos(t) + r[:, 1] * np.sin(t),
           "r_minor_m": -r[:, 0] * np.sin(t) + r[:, 1] * np.cos(t),
           "sigma_major_m": smaj, "sigma_minor_m": smin, "orientation_deg": ang}
    for lv in LEVELS:
        with np.errstate(invalid="ignore"):
            out[f"inside_{round(lv * 100)}"] = nees <= nees_threshold(lv)
    return out


def wilson_interval(k, n, confidence: float = 0.95):
    """Wilson score interval of a binomial proportion ``k / n`` (arrays broadcast); NaN where ``n == 0``."""
    k, n = np.asarray(k, dtype=np.float64), np.asarray(n, dtype=np.float64)
    z = float(ndtri(0.5 + confidence / 2))
    with np.errstate(invalid="ignore", divide="ignore"):
        p = k / n
        den = 1 + z * z / n
        mid = (p + z * z / (2 * n)) / den
        half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / den
    return np.clip(mid - half, 0, 1), np.clip(mid + half, 0, 1)


def range_band_labels(edges) -> list[str]:
    e = list(edges)
    return [f"{e[i]:g}-{e[i + 1]:g} m" for i in range(len(e) - 1)] + [f">= {e[-1]:g} m"]


@dataclass
class _Cell:
    """Counts of one breakdown cell (range band, class, linear_ok)."""

    n: int = 0
    inside: np.ndarray = field(default_factory=lambda: np.zeros(len(LEVELS), dtype=np.int64))
    nees_sum: float = 0.0

    def add(self, n, inside, nees_sum):
        self.n += int(n)
        self.inside += inside
        self.nees_sum += float(nees_sum)


@dataclass
class _Group:
    """Sums of one calibration group (for the NEES variance, the bias variance and cluster errors)."""

    name: str
    S: np.ndarray
    n: int = 0
    nees_sum: float = 0.0
    inside: np.ndarray = field(default_factory=lambda: np.zeros(len(LEVELS), dtype=np.int64))
    M: np.ndarray = field(default_factory=lambda: np.zeros((P.N_PARAMS, P.N_PARAMS)))
    diag_tr: float = 0.0
    J_sum: np.ndarray = field(default_factory=lambda: np.zeros((2, P.N_PARAMS)))
    cov_obj_sum: np.ndarray = field(default_factory=lambda: np.zeros((2, 2)))
    r_sum: np.ndarray = field(default_factory=lambda: np.zeros(2))


class CoverageAccumulator:
    """Streaming coverage summary: :meth:`add` per chunk of pairs, :meth:`summary` at the end.

    Parameters
    ----------
    range_bands_m : edges of the range bands (ascending; the last band is open)
    alpha : significance of the two-sided NEES test and of the bias test (default 0.05)
    seed : seed of the random sample of objects kept for the figures
    """

    def __init__(self, *, range_bands_m=DEFAULT_RANGE_BANDS_M, alpha: float = 0.05, seed: int = 0):
        self.edges = np.asarray(range_bands_m, dtype=np.float64)
        if (self.edges.ndim != 1 or self.edges.size < 1 or not np.all(np.isfinite(self.edges))
                or np.any(np.diff(self.edges) <= 0)):
            raise InputError("range_bands_m", list(np.ravel(range_bands_m)), "finite ascending distances in metres")
        self.alpha = float(alpha)
        if not 0.0 < self.alpha <= 0.5:  # (NaN fails too: a verdict at significance NaN would say "consistent")
            raise InputError("alpha", alpha, "a significance in (0, 0.5]")
        self.band_labels = range_band_labels(self.edges)
        self.groups: dict[int, _Group] = {}
        self.by = {"range": {}, "class": {}, "linear_ok": {}}
        self.grid_counts = np.zeros(len(GRID), dtype=np.int64)
        self.status_counts: dict[str, int] = {}
        self.refused: dict[str, int] = {}
        self.n = 0
        self.rng = np.random.default_rng(seed)
        self.sample: dict[str, np.ndarray] | None = None
        self.sample_keys = np.zeros(0)

    # -- feeding -------------------------------------------------------------------------------
    def add(self, pairs, budgets: dict[int, np.ndarray], group_names: list[str] | None = None) -> dict:
        """Add a chunk of :class:`~footprint_uq.validation.pairs.Pairs`; returns its per-object metrics.

        ``budgets`` maps each group number to its parameter covariance (22, 22) (the budget's
        ``param_covariance()``).
        """
        m = object_metrics(pairs.residual_m, pairs.cov_m2)
        lost = pairs.usable & ~np.isfinite(m["nees"])
        if np.any(lost):  # never an "ok" row outside the count: an error row (in place: the per-object file agrees)
            pairs.status[lost] = STATUS_ERROR
            pairs.reason[lost] = "NEES not finite (residual or covariance beyond the float range)"
        for s, c in zip(*np.unique(pairs.status.astype(str), return_counts=True), strict=True):
            self.status_counts[str(s)] = self.status_counts.get(str(s), 0) + int(c)
        for k, c in refused_reasons(pairs.status, pairs.reason).items():
            self.refused[k] = self.refused.get(k, 0) + c
        ok = pairs.usable
        if not np.any(ok):
            return m
        idx = np.flatnonzero(ok)
        inside = np.stack([m[f"inside_{round(lv * 100)}"][idx] for lv in LEVELS], 1)
        nees = m["nees"][idx]
        self.n += idx.size
        self.grid_counts += self._grid(nees)
        self._add_groups(pairs, idx, nees, inside, budgets, group_names)
        band = np.searchsorted(self.edges, pairs.range_m[idx], side="right") - 1
        band_key = np.where(band < 0, 0, band)
        self._add_cells("range", [self.band_labels[b] for b in band_key], inside, nees)
        self._add_cells("class", [str(c) if c is not None else "(none)" for c in pairs.cls[idx]], inside, nees)
        self._add_cells("linear_ok", ["yes" if v else "no" for v in pairs.linear_ok[idx]], inside, nees)
        self._keep_sample(pairs, idx, m)
        return m

    def _grid(self, nees) -> np.ndarray:
        """Counts of NEES under each grid level's bound (a cumulative histogram)."""
        pos = np.searchsorted(nees_threshold(GRID), nees, side="left")  # first bound >= nees
        return np.cumsum(np.bincount(pos, minlength=len(GRID) + 1)[:len(GRID)])

    def _add_cells(self, kind, keys, inside, nees):
        keys = np.asarray(keys, dtype=object)
        uk, inv = np.unique(keys.astype(str), return_inverse=True)
        ins = np.stack([np.bincount(inv, weights=inside[:, j], minlength=len(uk)) for j in range(len(LEVELS))],
                       1).astype(np.int64)
        cnt = np.bincount(inv, minlength=len(uk))
        ns = np.bincount(inv, weights=nees, minlength=len(uk))
        for j, k in enumerate(uk):
            self.by[kind].setdefault(k, _Cell()).add(cnt[j], ins[j], ns[j])

    def _add_groups(self, pairs, idx, nees, inside, budgets, group_names):
        g_all = pairs.group[idx]
        for g in np.unique(g_all):
            sel = idx[g_all == g]
            loc = g_all == g
            if int(g) not in self.groups:
                name = group_names[g] if group_names is not None and 0 <= g < len(group_names) else str(g)
                self.groups[int(g)] = _Group(name, np.asarray(budgets[int(g)], dtype=np.float64))
            G = self.groups[int(g)]
            J = pairs.dxy_dp[sel]
            A = np.linalg.inv(pairs.cov_m2[sel])
            AJ = A @ J  # (k, 2, 22)
            G.M += np.einsum("kai,kaj->ij", J, AJ)
            B = AJ @ G.S @ np.swapaxes(J, -1, -2)  # A_i J_i S J_i^T (k, 2, 2)
            G.diag_tr += float(np.einsum("kab,kba->", B, B))
            G.n += sel.size
            G.nees_sum += float(nees[loc].sum())
            G.inside += inside[loc].sum(0)
            G.J_sum += J.sum(0)
            G.cov_obj_sum += pairs.cov_object_m2[sel].sum(0)
            G.r_sum += pairs.residual_m[sel].sum(0)

    def _keep_sample(self, pairs, idx, m):
        """A seeded uniform sample of at most SAMPLE_SIZE objects (smallest random keys kept)."""
        keys = self.rng.random(idx.size)
        cols = {"nees": m["nees"][idx], "r_major_m": m["r_major_m"][idx], "r_minor_m": m["r_minor_m"][idx],
                "sigma_major_m": m["sigma_major_m"][idx], "sigma_minor_m": m["sigma_minor_m"][idx],
                "error_m": np.linalg.norm(pairs.residual_m[idx], axis=1), "range_m": pairs.range_m[idx],
                "residual_x_m": pairs.residual_m[idx, 0], "residual_y_m": pairs.residual_m[idx, 1]}
        if self.sample is not None:
            keys = np.concatenate([self.sample_keys, keys])
            cols = {k: np.concatenate([self.sample[k], v]) for k, v in cols.items()}
        if keys.size > SAMPLE_SIZE:
            keep = np.argpartition(keys, SAMPLE_SIZE)[:SAMPLE_SIZE]
            keys = keys[keep]
            cols = {k: v[keep] for k, v in cols.items()}
        self.sample, self.sample_keys = cols, keys

    # -- results ---------------------------------------------------------------------------------
    def nees_test(self) -> dict:
        """The NEES test of the module doc: Q, its mean and variance under the model, p-values, verdict."""
        N = self.n
        Q = sum(G.nees_sum for G in self.groups.values())
        V = 0.0
        for G in self.groups.values():
            MS = G.M @ G.S
            V += 2.0 * float(np.trace(MS @ MS)) - 2.0 * G.diag_tr + 4.0 * G.n
        V = max(V, 4.0 * N * 1e-12)
        if N == 0:
            return {"n": 0, "verdict": None}
        a, nu = V / (4.0 * N), 8.0 * N * N / V
        p_high = float(chdtrc(nu, Q / a))  # P(Q' >= Q)
        p_low = 1.0 - p_high
        verdict = ("over-confident" if p_high < self.alpha / 2 else
                   "under-confident" if p_low < self.alpha / 2 else "consistent")
        return {"n": N, "nees_sum": Q, "nees_mean": Q / N, "expected_mean": 2.0, "variance_model": V,
                "variance_independent": 4.0 * N, "scale_a": a, "dof_nu": nu, "n_eff": nu / 2.0,
                "p_value_too_large": p_high, "p_value_too_small": p_low, "alpha": self.alpha, "verdict": verdict}

    def bias(self) -> dict:
        """Mean residual with its model covariance (shared draws included) and interval; Wald test."""
        N = self.n
        if N == 0:
            return {"n": 0}
        r = sum(G.r_sum for G in self.groups.values()) / N
        Vm = sum(G.J_sum @ G.S @ G.J_sum.T + G.cov_obj_sum for G in self.groups.values()) / N**2
        z = float(ndtri(1 - self.alpha / 2))
        half = z * np.sqrt(np.diag(Vm))
        try:
            stat = float(r @ np.linalg.solve(Vm, r))
            p = float(chdtrc(2, stat))
        except np.linalg.LinAlgError:
            stat, p = float("nan"), float("nan")
        out = {"n": N, "bias_m": r.tolist(), "cov_model_m2": Vm.tolist(), "interval_m": [(r - half).tolist(),
                                                                                          (r + half).tolist()],
               "confidence": 1 - self.alpha, "wald_chi2": stat, "p_value": p,
               "significant": bool(p < self.alpha) if np.isfinite(p) else None}
        if len(self.groups) >= 2:
            out["se_cluster_m"] = self._cluster_se_bias(r).tolist()
        return out

    def _cluster_se_bias(self, r):
        G = len(self.groups)
        dev = np.array([g.r_sum - g.n * r for g in self.groups.values()])
        return np.sqrt(G / (G - 1) * (dev**2).sum(0)) / self.n

    def coverage(self) -> list[dict]:
        """Per level: empirical coverage, Wilson intervals (independent, and at n_eff), the model's standard error
        of the coverage at the nominal level with n_eff objects (``se_n_eff``: the yardstick of "within 2 standard
        errors"), and with several groups the cluster-robust standard error from the spread between groups (it
        collapses when every group covers ~100 %: prefer ``se_n_eff``)."""
        test = self.nees_test()
        inside = sum((G.inside for G in self.groups.values()), np.zeros(len(LEVELS), dtype=np.int64))
        N = self.n
        lo, hi = wilson_interval(inside, N, 1 - self.alpha)
        neff = min(test.get("n_eff", N) or N, N) if N else 0
        lo_e, hi_e = wilson_interval(inside * (neff / N if N else 0), neff, 1 - self.alpha)
        out = []
        for j, lv in enumerate(LEVELS):
            row = {"nominal": lv, "n": N, "inside": int(inside[j]), "empirical": inside[j] / N if N else float("nan"),
                   "interval": [float(lo[j]), float(hi[j])], "interval_n_eff": [float(lo_e[j]), float(hi_e[j])],
                   "se_n_eff": float(np.sqrt(lv * (1 - lv) / neff)) if neff > 0 else float("nan")}
            if len(self.groups) >= 2:
                p = inside[j] / N
                G = len(self.groups)
                dev = np.array([g.inside[j] - p * g.n for g in self.groups.values()])
                row["se_cluster"] = float(np.sqrt(G / (G - 1) * (dev**2).sum()) / N)
            out.append(row)
        return out

    def breakdown(self, kind: str) -> list[dict]:
        """Coverage per cell of ``kind`` (``range``, ``class``, ``linear_ok``), in a stable order."""
        cells = self.by[kind]
        keys = [k for k in self.band_labels if k in cells] if kind == "range" else sorted(cells)
        out = []
        for k in keys:
            c = cells[k]
            lo, hi = wilson_interval(c.inside, c.n, 1 - self.alpha)
            row = {kind: k, "n": c.n, "nees_mean": c.nees_sum / c.n if c.n else float("nan")}
            for j, lv in enumerate(LEVELS):
                row[f"coverage_{round(lv * 100)}"] = c.inside[j] / c.n if c.n else float("nan")
            row["interval_95"] = [float(lo[2]), float(hi[2])]
            out.append(row)
        return out

    def calibration_curve(self) -> dict:
        """Empirical coverage on a fine grid of nominal levels (the calibration figure), Wilson band."""
        N = max(self.n, 1)
        lo, hi = wilson_interval(self.grid_counts, N, 1 - self.alpha)
        return {"nominal": GRID.tolist(), "empirical": (self.grid_counts / N).tolist(), "low": lo.tolist(),
                "high": hi.tolist()}

    def error_quantiles(self) -> dict:
        """Median, 95th percentile and maximum of the horizontal error |r| (exact while every object is in
        the sample, i.e. up to SAMPLE_SIZE objects; else from the sample)."""
        if self.sample is None:
            return {}
        e = self.sample["error_m"]
        return {"median_m": float(np.median(e)), "p95_m": float(np.percentile(e, 95)), "max_m": float(e.max()),
                "exact": bool(self.n <= SAMPLE_SIZE)}

    def refusals(self) -> dict:
        """The error rows: how many, and how many per kind of reason (values masked; the most frequent
        :data:`MAX_REFUSAL_KINDS` kinds, the rest as ``"(other reasons)"``)."""
        kinds = sorted(self.refused.items(), key=lambda kv: (-kv[1], kv[0]))
        by = dict(kinds[:MAX_REFUSAL_KINDS])
        rest = sum(c for _, c in kinds[MAX_REFUSAL_KINDS:])
        if rest:
            by["(other reasons)"] = rest
        return {"rows": sum(self.refused.values()), "by_reason": by}

    def summary(self) -> dict:
        """Everything, as a JSON-ready dict."""
        test = self.nees_test()
        return {"n_pairs": self.n, "rows": self.status_counts, "refused": self.refusals(),
                "verdict": test.get("verdict"), "nees_test": test,
                "coverage": self.coverage(), "bias": self.bias(), "error": self.error_quantiles(),
                "by_range": self.breakdown("range"), "by_class": self.breakdown("class"),
                "by_linear_ok": self.breakdown("linear_ok"), "calibration_curve": self.calibration_curve(),
                "groups": [{"group": G.name, "n": G.n, "nees_mean": G.nees_sum / G.n if G.n else float("nan"),
                            "coverage_95": float(G.inside[2] / G.n) if G.n else float("nan")}
                           for G in self.groups.values()]}
