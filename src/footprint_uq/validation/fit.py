"""Fit an error budget to observed residuals: variance components with a shared calibration draw.

Model (``docs/validation.md``, "Fitting the budget"): the residual of object ``i`` (truth minus
prediction, world frame, metres) is

    r_i = bias + J_i e_g + n_i,     e_g ~ N(0, Sigma(theta)),   n_i ~ N(0, R_i(theta))

where ``J_i = dxy_dp`` (2 x 22), ``g`` the calibration group of the object (camera or campaign: one
draw ``e_g`` of the camera parameters' error shared by all its objects), ``Sigma(theta)`` the
parameter covariance of an :class:`~footprint_uq.uncertainty.budget.ErrorBudget` whose *free*
terms are unknown, and ``R_i`` the per-object covariance (pixel noise, contact model) plus an
optional free per-object term ``object_m`` (``sigma_m^2 I``).  The residuals of one group are
jointly Gaussian, ``C_g = J_g Sigma J_g^T + blockdiag(R_i)``; the likelihood is evaluated through
the Woodbury identity on the (at most 22-dimensional) shared part, so a group of thousands of
objects costs a few small matrix products per object.

Estimation: REML (default; ML with ``method="ml"``) over the variances of the free terms, the bias
profiled out by generalised least squares, bounded truncated Newton (TNC) with the analytic score;
standard errors from the observed information (central differences of the score); 95 % intervals of
Satterthwaite's kind (the variance as a scaled chi-square with its effective degrees of freedom,
``nu = 2 v^2 / se_v^2``).  Identifiability: a
shared term needs draws from at least ``min_groups`` groups (one camera and one frame give one draw
of its calibration error: no sigma); terms the information matrix cannot tell apart (normalised
eigenvalue below ``collinear_tol``) are merged -- fitted as one, reported as merged, never split.  A fitted
term is "identified" only where its interval can be trusted (enough degrees of freedom, not entangled with
other terms, the profile likelihood falling off beyond both ends, no angle beside a free principal point, no
approximate merge), else "weakly identified" (docs/budget-fit.md, "What the data cannot tell").
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from scipy import optimize, stats

from .. import params as P
from ..errors import InputError
from ..io.atomic import atomic_write_text
from ..io.camera_files import save_budget
from ..uncertainty.budget import ErrorBudget, load_budget
from .fit_compact import MEMORY_PAIRS, CompactModel, CompactPairs, check_chunk, compact_chunks
from .fit_likelihood import GroupLikelihood, GroupTerms

__all__ = ["FITTABLE_TERMS", "OBJECT_TERM", "OBJECT_GROUND_TERM", "OBJECT_TERMS", "BudgetFit", "TermFit",
           "fit_budget", "cross_validate", "compact_inputs", "fit_compact", "cross_validate_compact", "CompactPairs",
           "CV_MAX_PAIRS",
           "log_likelihood", "CrossValidation", "nees_of"]

#: budget keys that can be free, with their parameters (pair keys get one sigma for both components)
FITTABLE_TERMS: dict[str, tuple[str, ...]] = {
    "focal_px": ("fx_px", "fy_px"), "principal_point_px": ("cx_px", "cy_px"),
    "position_m": ("x_m", "y_m"), "height_m": ("height_m",), "pan_deg": ("pan_rad",),
    "tilt_deg": ("tilt_rad",), "roll_deg": ("roll_rad",), "ground_height_m": ("ground_dz_m",),
    "ground_slope_deg": ("ground_slope_x", "ground_slope_y"),
}
#: the free per-object term: an isotropic sigma (metres) added to every object's own covariance
OBJECT_TERM = "object_m"
#: a per-object ground-height error (sigma, metres) acting through each object's own d(xy)/d(ground_dz):
#: local terrain, a box not on the calibrated plane -- an error that grows with range like the ground's
OBJECT_GROUND_TERM = "object_ground_m"
OBJECT_TERMS = (OBJECT_TERM, OBJECT_GROUND_TERM)
_PAIRS = ("principal_point_px", "position_m")
_LEVELS = (0.5, 0.9, 0.95, 0.99)


def _unit_covariance(term: str) -> np.ndarray:
    """Parameter covariance (22, 22) per unit *variance* of ``term`` (slope: per unit gradient^2)."""
    if term == "ground_slope_deg":
        A = np.zeros((P.N_PARAMS, P.N_PARAMS))
        idx = P.param_index(FITTABLE_TERMS[term])
        A[idx, idx] = 1.0
        return A
    one = [1.0, 1.0] if term in _PAIRS else 1.0
    return ErrorBudget.from_dict({term: one}).param_covariance()


def _sigma_of(term: str, variance: float) -> float:
    """The budget-file sigma of a term from its internal variance (slope: gradient -> degrees)."""
    s = float(np.sqrt(max(variance, 0.0)))
    return float(np.degrees(np.arctan(s))) if term == "ground_slope_deg" else s


def _variance_of(term: str, sigma: float) -> float:
    return float(np.tan(np.radians(sigma)) ** 2) if term == "ground_slope_deg" else float(sigma) ** 2


def _budget_sigma(budget: ErrorBudget, term: str) -> float:
    v = getattr(budget, term)
    return float(max(v)) if term in _PAIRS else float(v)


class _Data(NamedTuple):
    """Inputs sorted by group, Jacobians restricted to the ``k`` parameter columns that matter."""

    r: np.ndarray        # (N, 2)
    U: np.ndarray        # (N, 2, k)
    R: np.ndarray        # (N, 2, 2)
    starts: np.ndarray   # (G,) first row of each group
    gid: np.ndarray      # (N,) group index 0..G-1 of each row
    order: np.ndarray    # (N,) rows of the caller's arrays in this order
    labels: np.ndarray   # (G,) the caller's group labels
    cols: np.ndarray     # (k,) parameter columns kept


def _check_inputs(residual_m, dxy_dp, cov_object_m2, group):
    r, J, R, g = check_chunk(residual_m, dxy_dp, cov_object_m2, group)
    if r.shape[0] < 2:
        raise InputError("residual_m", f"shape {r.shape}", "an array (N, 2) with N >= 2 (truth minus prediction, m)")
    return r, J, R, g


def _prepare(residual_m, dxy_dp, cov_object_m2, group, cols) -> _Data:
    r, J, R, g = _check_inputs(residual_m, dxy_dp, cov_object_m2, group)
    labels, gid = np.unique(g, return_inverse=True)
    order = np.argsort(gid, kind="stable")
    gid = gid[order]
    starts = np.flatnonzero(np.r_[True, gid[1:] != gid[:-1]])
    return _Data(r[order], J[order][:, :, cols], R[order], starts, gid, order, labels, cols)


class _Model(GroupLikelihood):
    """The (restricted) log-likelihood of the variances ``v`` of the free terms, and its score: the dense
    reference (every per-object array in memory) of :class:`~footprint_uq.validation.fit_compact.CompactModel`,
    which the fit uses; kept for :func:`log_likelihood` and the tests.  The per-group sums are computed here
    with numpy; the algebra from the sums on is :class:`~footprint_uq.validation.fit_likelihood.GroupLikelihood`."""

    def __init__(self, data: _Data, Sfixed, A, E, fit_bias: bool, reml: bool):
        self.d, self.Sf, self.A, self.E = data, Sfixed, A, E   # A: (m_shared, k, k); E: (q, N, 2, 2)
        self.object_free, self.fit_bias, self.reml = E.shape[0] > 0, fit_bias, reml
        self.m = A.shape[0] + E.shape[0]
        self.n = data.r.shape[0]
        self._cache = None
        if not self.object_free:
            self._cache = self._object_sums(np.zeros(0))
            if self._cache is None:
                raise InputError("cov_object_m2", "a singular covariance",
                                 "positive-definite per-object covariances (or a free 'object_m' term)")

    def _object_sums(self, vo) -> dict | None:
        """Per-group sums for the per-object variances ``vo`` (None: a per-object covariance is singular)."""
        d = self.d
        D = d.R.copy()
        for v, Eq in zip(vo, self.E, strict=True):
            D += v * Eq
        det = D[:, 0, 0] * D[:, 1, 1] - D[:, 0, 1] * D[:, 1, 0]
        if np.any(det <= 0):
            return None
        Di = np.stack([np.stack([D[:, 1, 1], -D[:, 0, 1]], -1), np.stack([-D[:, 1, 0], D[:, 0, 0]], -1)], -2)
        Di /= det[:, None, None]
        V = Di @ d.U                                    # (N, 2, k)
        Dr = (Di @ d.r[..., None])[..., 0]
        red = lambda a: np.add.reduceat(a, d.starts, axis=0)  # noqa: E731
        return {"Di": Di, "V": V, "Dr_i": Dr, "M": red(np.swapaxes(d.U, 1, 2) @ V),
                "b": red(np.einsum("nak,na->nk", V, d.r)), "P": red(np.swapaxes(V, 1, 2)),
                "Dsum": red(Di), "Dr": red(Dr), "rDr": red(np.einsum("na,na->n", d.r, Dr)),
                "ld": red(np.log(det))}

    def _group_sums(self, vo, grad: bool) -> dict | None:
        """:meth:`_object_sums` (the dense sums serve the score too: ``grad`` changes nothing)."""
        return self._object_sums(vo)

    def _object_score(self, s: dict, t: GroupTerms, Phi_i) -> np.ndarray:
        """Score of the per-object variances, from the per-object arrays."""
        d, E, V, Di = self.d, self.E, s["V"], s["Di"]
        K, beta = t.K, t.beta
        Kb = np.einsum("gkl,gl->gk", K, t.bt)[d.gid]                              # (N, k)
        z = (Di @ (d.r - beta)[..., None])[..., 0] - np.einsum("nak,nk->na", V, Kb)  # C^-1 (r - beta), per object
        Z = Di - V @ t.KP[d.gid] if Phi_i is not None else None                   # rows of C^-1 X (N, 2, 2)
        go = np.empty(E.shape[0])
        for q, Eq in enumerate(E):
            EV = Eq @ V
            SE = np.add.reduceat(np.swapaxes(V, 1, 2) @ EV, d.starts, axis=0)       # (G, k, k)
            tr = np.einsum("nab,nba->", Di, Eq) - np.einsum("gkl,glk->", K, SE)
            go[q] = -0.5 * (tr - np.einsum("na,na->", z, (Eq @ z[..., None])[..., 0]))
            if Phi_i is not None:
                go[q] += 0.5 * np.trace(Phi_i @ (np.swapaxes(Z, 1, 2) @ (Eq @ Z)).sum(0))
        return go


def log_likelihood(residual_m, dxy_dp, cov_object_m2, group, budget, *, object_sigma_m: float = 0.0,
                   fit_bias: bool = True, method: str = "reml") -> float:
    """The (restricted) log-likelihood of residuals under a budget (for comparisons and checks).

    Parameters as in :func:`fit_budget`; ``budget`` is any budget :func:`load_budget` accepts.
    """
    S = load_budget(budget).param_covariance()
    cols = np.arange(P.N_PARAMS)
    data = _prepare(residual_m, dxy_dp, cov_object_m2, group, cols)
    E = np.broadcast_to(np.eye(2), (1, data.r.shape[0], 2, 2))
    model = _Model(data, S, np.zeros((0, P.N_PARAMS, P.N_PARAMS)), E, fit_bias, _method(method))
    return float(model.evaluate(np.array([object_sigma_m**2]), grad=False)[0])


def _method(method: str) -> bool:
    if method not in ("reml", "ml"):
        raise InputError("method", method, "'reml' (restricted maximum likelihood) or 'ml'")
    return method == "reml"


# ---------------------------------------------------------------------------------------------
# the fit
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class TermFit:
    """One free term of the fit.

    Attributes
    ----------
    sigma : float           fitted 1-sigma, in the term's unit (budget key: ``pan_deg`` in degrees, ...)
    se : float              standard error of ``sigma`` (observed information; NaN where not defined)
    ci95 : (float, float)   95 % interval of ``sigma``
    status : str            ``"identified"`` (its interval can be trusted: :data:`MIN_DOF`, :data:`MAX_VIF`),
                            ``"weakly identified"`` (estimated, but its interval cannot be trusted: see ``note``),
                            ``"merged"`` (see ``merged_with``), ``"unidentifiable"``
    merged_with : tuple     the other terms of a merged set (their joint effect is carried by this one)
    note : str              why a term is weakly identified, merged or unidentifiable
    dof : float             Satterthwaite's effective degrees of freedom of its variance (NaN: not fitted)
    vif : float             variance inflation of its estimate by the other free terms (the larger of the fit
                            with every term free and the final one; NaN: not fitted)
    """

    sigma: float
    se: float
    ci95: tuple[float, float]
    status: str
    merged_with: tuple[str, ...] = ()
    note: str = ""
    dof: float = np.nan
    vif: float = np.nan


@dataclass
class BudgetFit:
    """The result of :func:`fit_budget`; :meth:`to_budget` gives the fitted :class:`ErrorBudget`."""

    terms: dict[str, TermFit]
    bias_m: np.ndarray
    bias_cov_m2: np.ndarray
    log_likelihood: float
    method: str
    n_objects: int
    n_groups: int
    base_budget: ErrorBudget
    converged: bool
    message: str = ""
    information: np.ndarray | None = field(default=None, repr=False)
    fitted_names: tuple[str, ...] = ()

    @property
    def object_sigma_m(self) -> float:
        """The fitted per-object isotropic sigma (metres), 0 if ``object_m`` was not free."""
        t = self.terms.get(OBJECT_TERM)
        return t.sigma if t is not None and t.status != "unidentifiable" else 0.0

    @property
    def object_ground_sigma_m(self) -> float:
        """The fitted per-object ground-height sigma (metres), 0 if ``object_ground_m`` was not free."""
        t = self.terms.get(OBJECT_GROUND_TERM)
        return t.sigma if t is not None and t.status != "unidentifiable" else 0.0

    def to_budget(self, name: str = "fitted") -> ErrorBudget:
        """The base budget with every identified (or merged-representative) free term replaced.

        Unidentifiable terms keep the base budget's value; the other members of a merged set are
        zero (their joint effect is in the representative's sigma: see :attr:`terms`).  The per-object
        terms have no budget key (metres, not pixels): see :attr:`object_sigma_m`, :attr:`object_ground_sigma_m`.
        """
        d = self.base_budget.to_dict()
        for term, t in self.terms.items():
            if term in OBJECT_TERMS or t.status == "unidentifiable":
                continue
            d[term] = [t.sigma, t.sigma] if term in _PAIRS else t.sigma
        d["name"] = name
        merged = [f"{k} (with {', '.join(t.merged_with)})" for k, t in self.terms.items() if t.status == "merged"]
        d["description"] = (f"fitted by {self.method.upper()} to {self.n_objects} residuals in {self.n_groups} "
                            f"calibration group(s)" + (f"; merged: {'; '.join(merged)}" if merged else "")
                            + "".join(f"; per-object {k} {self.terms[k].sigma:.4g} m" for k in OBJECT_TERMS
                                      if k in self.terms))
        return ErrorBudget.from_dict(d)

    def to_dict(self) -> dict:
        return {
            "method": self.method, "n_objects": self.n_objects, "n_groups": self.n_groups,
            "log_likelihood": self.log_likelihood, "converged": self.converged, "message": self.message,
            "bias_m": self.bias_m.tolist(), "bias_sigma_m": np.sqrt(np.diag(self.bias_cov_m2)).tolist(),
            "terms": {k: {"sigma": t.sigma, "se": t.se, "ci95": list(t.ci95), "status": t.status,
                          "merged_with": list(t.merged_with), "note": t.note, "dof": t.dof, "vif": t.vif}
                      for k, t in self.terms.items()},
            "budget": self.to_budget().to_dict(),
        }

    def write(self, budget_path, summary_path=None):
        """Write the fitted budget (YAML/JSON, readable by every command) and optionally the JSON summary."""
        out = [save_budget(self.to_budget(), budget_path)]
        if summary_path is not None:
            text = json.dumps(_jsonable(self.to_dict()), indent=2, allow_nan=False) + "\n"
            out.append(atomic_write_text(summary_path, text, parents=True))
        return out


def _jsonable(x):
    if isinstance(x, dict):
        return {k: _jsonable(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not np.isfinite(x):
        return None
    return x


def _check_free(free, base: ErrorBudget) -> tuple[list[str], list[str]]:
    if isinstance(free, str):
        free = [free]
    names = list(dict.fromkeys(free))
    allowed = [*FITTABLE_TERMS, *OBJECT_TERMS]
    if not names:
        raise InputError("free", free, f"at least one of {allowed}")
    for t in names:
        if t not in allowed:
            hint = " (per-point pixel terms are inside cov_object_m2: free 'object_m' instead)" \
                if t in ("imaging_px", "resolution_px", "distortion") else ""
            raise InputError("free", t, f"one of {allowed}{hint}")
    shared = [t for t in names if t in FITTABLE_TERMS]
    if base.covariance_matrix is not None:
        clash = set(base.covariance_names) & {p for t in shared for p in FITTABLE_TERMS[t]}
        if clash:
            raise InputError("base_budget.covariance", sorted(clash), "no full-covariance entries for free terms")
    return shared, [t for t in OBJECT_TERMS if t in names]


def _object_shapes(J: np.ndarray, objs: list[str]) -> np.ndarray:
    """Per free per-object term: its covariance per unit variance, (q, N, 2, 2)."""
    out = []
    for t in objs:
        if t == OBJECT_TERM:
            out.append(np.broadcast_to(np.eye(2), (J.shape[0], 2, 2)))
        else:
            j = J[:, :, P.GDZ]
            out.append(j[:, :, None] * j[:, None, :])
    return np.stack(out) if out else np.zeros((0, J.shape[0], 2, 2))


def _informative_groups(data, A: np.ndarray) -> np.ndarray:
    """Per shared term: the number of groups whose objects it moves (a Jacobian column != 0)."""
    if A.shape[0] == 0:
        return np.zeros(0, dtype=int)
    used = np.abs(A).sum(-1) > 0                                      # (m, k) columns of each term
    big = max(max((float(np.abs(p.U).max()) if p.U.size else 0.0) for p in data.parts()), 1e-300)
    G = data.labels.size
    per_group = np.zeros((G, A.shape[0]))
    for p in data.parts():
        col = np.abs(p.U).max(1) > 1e-12 * big                        # (n, k)
        hit = (col[:, None, :] & used[None]).any(-1)                    # (n, m)
        per_group += np.stack([np.bincount(p.gid, weights=hit[:, j], minlength=G) for j in range(A.shape[0])], 1)
    return (per_group > 0).sum(0)


def _median_of(data, fn) -> float:
    """Median over every record of ``fn(part) -> (n,)`` (one quantity in memory at a time)."""
    return float(np.median(np.concatenate([fn(p) for p in data.parts()])))


def _scales(data, A: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """Per free variance: the value at which it alone explains the residuals' typical power."""
    power = max(_median_of(data, lambda p: np.sum(p.r**2, 1)) / 2, 1e-12)
    out = []
    for a in A:
        c = np.concatenate([np.einsum("nak,nak->n", p.U @ a, p.U) / 2 for p in data.parts()])
        med = float(np.median(c[c > 0])) if np.any(c > 0) else 0.0
        del c
        out.append(power / med if med > 0 else 1.0)
    for kind in kinds:
        med = 1.0 if kind == 0 else _median_of(data, lambda p: np.sum(p.jg**2, 1)) / 2
        out.append(power / med if med > 0 else 1.0)
    return np.array(out)


def _optimise(model: _Model, scale: np.ndarray, start: np.ndarray, *, retry: bool = True, maxfun: int = 1000):
    """Maximise the likelihood over variances >= 0 (scaled to order one), from two starts.

    Bounded truncated Newton (scipy's TNC): on a busy machine L-BFGS-B's BLAS calls cost ~4x more
    for these few parameters.  Converged: the projected score (per object) is below 1e-6; a second
    start is tried only where the first does not converge.
    """
    if model.m == 0:
        return np.zeros(0), True, "converged: no free term (nothing to optimise)"
    n = model.n

    def f(u):
        ll, g, _, _ = model.evaluate(u * scale)
        if not np.isfinite(ll):
            return 1e30, np.zeros_like(u)
        return -ll / n, -g * scale / n

    def projected(x):
        g = f(x)[1]
        return np.where(x > 0, np.abs(g), np.clip(-g, 0, None))

    best = None
    for u0 in (start, np.full(model.m, 0.3))[:2 if retry else 1]:  # the second start only where the first failed
        res = optimize.minimize(f, u0, jac=True, method="TNC", bounds=[(0.0, None)] * model.m,
                                options={"maxfun": maxfun, "ftol": 1e-14, "gtol": 1e-10})
        if best is None or res.fun < best.fun:
            best = res
        pg = projected(best.x)
        ok = bool(np.all(pg < CONVERGED_SCORE))
        if ok:
            break
    return best.x * scale, ok, _convergence_message(ok, float(pg.max()), str(best.message))


#: the projected score (per object) below which the fit is called converged
CONVERGED_SCORE = 1e-6


def _convergence_message(ok: bool, score: float, optimiser: str) -> str:
    """The fit's message, which never contradicts ``converged``: it starts with ``converged`` or ``not
    converged`` and states the projected score against :data:`CONVERGED_SCORE`; scipy's own wording (which
    says "Converged" when its step or function change is small, whatever the score) is quoted as *stopped*."""
    why = optimiser.replace("Converged", "stopped").replace("converged", "stopped")
    if ok:
        return f"converged: projected score {score:.2g} per object (below {CONVERGED_SCORE:g}; scipy TNC: {why})"
    return (f"not converged: projected score {score:.2g} per object, above {CONVERGED_SCORE:g} (scipy TNC: {why}); "
            "the estimates are the best point found, not the likelihood's maximum")


def _information(model: _Model, v: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Observed information (m, m) in variance units: central differences of the analytic score."""
    m = v.size
    H = np.zeros((m, m))
    for j in range(m):
        h = 1e-4 * max(v[j], 1e-2 * scale[j])
        e = np.zeros(m)
        e[j] = h
        gp, gm = model.evaluate(v + e)[1], model.evaluate(v - e)[1]
        if gp is None or gm is None:  # a step left the positive-definite region: one-sided
            gp, gm, h = model.evaluate(v + 2 * e)[1], model.evaluate(v)[1], 2 * h
        H[:, j] = -(gp - gm) / (2 * h)
    return 0.5 * (H + H.T)


def _polish(model, v: np.ndarray, scale: np.ndarray, H: np.ndarray, steps: int = 4):
    """Newton steps from the optimiser's point on the variances off their bound (the optimiser stops at a
    projected score of 1e-6 per object, which leaves ~1e-7..1e-4 relative in flat directions): the estimate
    then is the likelihood's maximum to rounding, whichever path reached it.  A step is taken only where it
    stays inside the bounds and does not lower the likelihood; ``H`` is recomputed at the new point."""
    for _ in range(steps):
        idx = np.flatnonzero(v > 0)
        if idx.size == 0:
            break
        ll0, g, _, _ = model.evaluate(v)
        if g is None:
            break
        try:
            step = np.linalg.solve(H[np.ix_(idx, idx)], g[idx])
        except np.linalg.LinAlgError:
            break
        vn = v.copy()
        vn[idx] += step
        # a Newton step near the maximum changes the likelihood by less than its rounding: tolerate that
        if not np.all(vn[idx] > 0) or not model.evaluate(vn, grad=False)[0] >= ll0 - 1e-10 * max(1.0, abs(ll0)):
            break
        v, H = vn, _information(model, vn, scale)
        if np.all(np.abs(step) <= 1e-10 * v[idx]):
            break
    return v, H


#: the normalised eigenvalue below which a merge is exact (terms with the same effect to rounding, as the camera
#: height and the ground offset on flat ground); above it, merging fixes at zero terms the data do see a little
EXACT_MERGE = 1e-6


def _weakest(H: np.ndarray) -> float:
    """The smallest eigenvalue of the normalised information."""
    d = np.sqrt(np.clip(np.diag(H), 0, None))
    return float(np.linalg.eigvalsh(H / np.outer(d, d))[0]) if H.shape[0] and np.all(d > 0) else 0.0


def _collinear(H: np.ndarray, names: list[str], tol: float) -> list[str] | None:
    """The terms of the weakest direction of the normalised information, if it is (nearly) null (its eigenvalue:
    :func:`_weakest`)."""
    d = np.sqrt(np.clip(np.diag(H), 0, None))
    if H.shape[0] < 2 or np.any(d == 0):
        return None
    lam, vec = np.linalg.eigh(H / np.outer(d, d))
    if lam[0] >= tol:
        return None
    c = np.abs(vec[:, 0])
    return [names[i] for i in np.flatnonzero(c > 0.2 * c.max())]


class _Fixed:
    """The model with the variance of term ``j`` held at ``value``: the profile likelihood of the others."""

    def __init__(self, model, j: int, value: float):
        self.model, self.j, self.value = model, j, value
        self.m, self.n = model.m - 1, model.n

    def full(self, u) -> np.ndarray:
        return np.insert(np.asarray(u, dtype=np.float64), self.j, self.value)

    def evaluate(self, u, grad: bool = True):
        ll, g, beta, cov = self.model.evaluate(self.full(u), grad)
        return ll, (None if g is None else np.delete(g, self.j)), beta, cov


#: the profile deviance each end of an interval must reach (the chi-square of 1 degree of freedom at 68 %):
#: below it, the likelihood is flatter than the interval says (a term confounded with others beyond what the
#: local information shows); the Satterthwaite ends of well-identified terms have 1-3 (lower) and 5-15 (upper)
PROFILE_DEVIANCE = 1.0
#: terms the data tell apart only through the cameras' different focal lengths: a principal-point shift of ``d``
#: px is a rotation of ``d / f`` rad about the camera's own axes (pan and tilt, and roll for a tilted camera);
#: with the principal point free, the fitted angles take part of its effect (in simulated campaigns of 8
#: cameras, the pan and tilt intervals held the truth in 1 of 15 fits where they passed every other check, the
#: profile likelihood agreeing with the interval: the likelihood itself prefers the wrong split)
CONFOUNDED = {"pan_deg": "principal_point_px", "tilt_deg": "principal_point_px", "roll_deg": "principal_point_px"}


def _profile_deviance(model, v: np.ndarray, scale: np.ndarray, j: int, value: float, ll_max: float) -> float:
    """``2 (ll_max - profile ll)`` with the variance of term ``j`` held at ``value``, the others re-fitted
    (warm start at the estimate; one start, at most 300 evaluations: a check, not a fit)."""
    if model.m == 1:
        ll = model.evaluate(np.array([value]), grad=False)[0]
    else:
        fx = _Fixed(model, j, value)
        rest, sc = np.delete(v, j), np.delete(scale, j)
        u, _, _ = _optimise(fx, sc, np.where(rest > 0, rest / sc, 1e-3), retry=False, maxfun=300)
        ll = model.evaluate(fx.full(u), grad=False)[0]
    return 2 * (ll_max - ll) if np.isfinite(ll) else np.inf


def _interval_holds(model, v, scale, j: int, t: str, ci: tuple[float, float]) -> tuple[bool, str]:
    """Does the profile likelihood agree that the truth is unlikely beyond both (finite, non-zero) ends of the
    interval ``ci`` (the term's unit) of term ``j``?  (ok, why not)"""
    ll_max = model.evaluate(v, grad=False)[0]
    for end, sigma in (("lower", ci[0]), ("upper", ci[1])):
        if not (np.isfinite(sigma) and sigma > 0):
            continue
        dev = _profile_deviance(model, v, scale, j, _variance_of(t, sigma), ll_max)
        if dev < PROFILE_DEVIANCE:
            return False, (f"the profile likelihood is flat beyond the interval's {end} end (deviance {dev:.2g} "
                           f"there, at least {PROFILE_DEVIANCE:.3g} needed): other terms take over its effect")
    return True, ""


def _interval(v: float, se_v: float) -> tuple[float, float, float]:
    """(se of sigma, lower, upper) of the 95 % interval of sigma = sqrt(v).

    Satterthwaite: the estimate is taken as a scaled chi-square, ``v_hat ~ v chi2_nu / nu`` with the
    effective degrees of freedom ``nu = 2 v_hat^2 / se_v^2`` (a variance seen through few calibration
    draws has few), and the interval is ``[nu v_hat / chi2_nu(0.975), nu v_hat / chi2_nu(0.025)]`` --
    wider above than below, as the likelihood of a variance is; its lower end is 0 below one degree of
    freedom.  At ``v_hat = 0``: ``[0, sqrt(1.96 se_v)]``.
    """
    if not np.isfinite(se_v):
        return np.nan, 0.0, np.inf
    v = max(v, 0.0)
    s = np.sqrt(v)
    se = se_v / (2 * s) if s > 0 else np.inf
    if v <= 0 or se_v <= 0:
        return se, 0.0, float(np.sqrt(v + 1.96 * se_v))
    nu = 2 * v * v / (se_v * se_v)
    with np.errstate(divide="ignore", over="ignore"):  # a handful of degrees of freedom: no upper bound
        lo, hi = nu * v / stats.chi2.ppf(0.975, nu), nu * v / stats.chi2.ppf(0.025, nu)
    if nu < 1 or not np.isfinite(lo):  # the estimate within a standard error of zero: zero is inside
        lo = 0.0
    return se, float(np.sqrt(lo)), float(np.sqrt(hi)) if np.isfinite(hi) else np.inf


def _term_matrices(base: ErrorBudget, shared: list[str]):
    """(fixed covariance with the free terms removed, unit covariances of the free terms), (22, 22)."""
    S = base.param_covariance()
    for t in shared:
        idx = P.param_index(FITTABLE_TERMS[t])
        S[idx, :] = 0.0
        S[:, idx] = 0.0
    A = np.stack([_unit_covariance(t) for t in shared]) if shared else np.zeros((0, P.N_PARAMS, P.N_PARAMS))
    return S, A


def fit_budget(residual_m, dxy_dp, cov_object_m2, group, *, free, base_budget=None, fit_bias: bool = True,
               method: str = "reml", min_groups: int = 3, collinear_tol: float = 0.01) -> BudgetFit:
    """Fit the free terms of an error budget to residuals (maximum likelihood / REML).

    Parameters
    ----------
    residual_m : array_like (N, 2)
        Truth minus prediction, world frame (x east, y north), metres.
    dxy_dp : array_like (N, 2, 22)
        Jacobian of each predicted ground point w.r.t. the camera parameters (``PARAM_NAMES`` order).
    cov_object_m2 : array_like (N, 2, 2)
        Per-object covariance (pixel / detector noise, contact model), m^2; not the calibration part.
    group : array_like (N,)
        Label of each object's calibration draw (camera, or calibration campaign): objects of one
        group share one error of the camera parameters.
    free : sequence of str
        Budget keys to fit (:data:`FITTABLE_TERMS`: ``pan_deg``, ``height_m``, ``position_m``, ...)
        and/or ``"object_m"`` (a per-object isotropic sigma in metres added to ``cov_object_m2``).
        Pair keys (``position_m``, ``principal_point_px``) get one sigma for both components.
    base_budget : budget spec, optional
        Values of the terms that are not free (default: all zero).
    fit_bias : bool
        Estimate a common mean residual (2,) (profiled by generalised least squares).
    method : {"reml", "ml"}
        Restricted (default: the bias's two degrees of freedom do not shrink the variances) or plain ML.
    min_groups : int
        A shared term needs objects in at least this many groups to be fitted; below it the term is
        reported ``"unidentifiable"`` and keeps the base budget's value.
    collinear_tol : float
        Smallest eigenvalue of the normalised information below which terms are merged.

    Returns
    -------
    BudgetFit
    """
    setup = _setup(free, base_budget, method, min_groups)
    data = compact_chunks([(residual_m, dxy_dp, cov_object_m2, group)], setup.cols, OBJECT_GROUND_TERM in setup.obj,
                          memory_pairs=None)
    return _fit_data(data, setup, fit_bias, collinear_tol)


class _Setup(NamedTuple):
    base: ErrorBudget
    shared: list
    obj: list
    reml: bool
    min_groups: int
    Sf: np.ndarray     # (22, 22) fixed part
    A: np.ndarray      # (m, 22, 22) unit covariances of the free shared terms
    cols: np.ndarray   # parameter columns that carry variance


def _setup(free, base_budget, method, min_groups) -> _Setup:
    base = ErrorBudget() if base_budget is None else load_budget(base_budget)
    shared, obj = _check_free(free, base)
    reml = _method(method)
    if int(min_groups) < 1:
        raise InputError("min_groups", min_groups, "an integer >= 1")
    Sf, A = _term_matrices(base, shared)
    cols = np.flatnonzero((np.abs(Sf).sum(0) > 0) | (np.abs(A).sum((0, 1)) > 0))
    return _Setup(base, shared, obj, reml, int(min_groups), Sf, A, cols)


def compact_inputs(chunks, *, free, base_budget=None, memory_pairs: int | None = MEMORY_PAIRS):
    """Stream ``(residual_m, dxy_dp, cov_object_m2, group)`` chunks (arrays as :func:`fit_budget`'s) into the
    compact records a fit with these ``free`` terms and ``base_budget`` needs (:func:`fit_compact`,
    :func:`cross_validate_compact`): only the Jacobian columns that carry variance, about 100 bytes a pair,
    in memory up to ``memory_pairs`` pairs, beyond in parts in a temporary folder (memory flat in the number
    of pairs; :func:`footprint_uq.validation.fit_compact.compact_chunks`)."""
    base = ErrorBudget() if base_budget is None else load_budget(base_budget)
    setup = _setup(free, base, "reml", 1)
    return compact_chunks(chunks, setup.cols, OBJECT_GROUND_TERM in setup.obj, memory_pairs=memory_pairs)


def fit_compact(data: CompactPairs, *, free, base_budget=None, fit_bias: bool = True, method: str = "reml",
                min_groups: int = 3, collinear_tol: float = 0.01, profile_check: bool = True) -> BudgetFit:
    """:func:`fit_budget` on records from :func:`compact_inputs` (built with the same ``free`` and
    ``base_budget``): the streamed form, memory ~100 bytes a pair.  ``profile_check=False`` skips the profile
    likelihood at the intervals' ends (two refits per term): the estimates are the same, a status may say
    "identified" where the check would have said "weakly identified" (the cross-validation's refits)."""
    return _fit_data(data, _setup(free, base_budget, method, min_groups), fit_bias, collinear_tol, profile_check)


def _fit_data(data: CompactPairs, setup: _Setup, fit_bias: bool, collinear_tol: float,
              profile_check: bool = True) -> BudgetFit:
    if not np.array_equal(data.cols, setup.cols) or (OBJECT_GROUND_TERM in setup.obj and not data.has_ground):
        raise InputError("data", f"records of columns {data.cols.tolist()}",
                         "records built by compact_inputs with the same free terms and base budget")
    cols, base, shared = setup.cols, setup.base, setup.shared
    A, Sf = setup.A[:, cols][:, :, cols], setup.Sf[np.ix_(cols, cols)]
    n_inf = _informative_groups(data, A)
    terms: dict[str, TermFit] = {}
    active = []
    for j, t in enumerate(shared):
        if n_inf[j] < setup.min_groups:
            Sf = Sf + _variance_of(t, _budget_sigma(base, t)) * A[j]
            terms[t] = TermFit(_budget_sigma(base, t), np.nan, (0.0, np.inf), "unidentifiable",
                               note=f"objects in {n_inf[j]} calibration group(s); one draw per group, at least "
                                    f"{setup.min_groups} needed (kept the base budget's value)")
        else:
            active.append(j)
    kinds = np.array([0 if t == OBJECT_TERM else 1 for t in setup.obj], dtype=np.int64)
    return _fit_active(data, base, shared, (setup.obj, kinds), Sf, A, active, terms, fit_bias, setup.reml,
                       collinear_tol, profile_check)


def _fit_active(data, base, shared, objects, Sf, A, active, terms, fit_bias, reml, tol, profile_check) -> BudgetFit:
    """Fit the active shared terms (+ the object term); merge collinear sets and fit again; judge each interval."""
    merged: dict[str, tuple[str, ...]] = {}
    first = None  # (information, names) of the fit with every active term: what a merge leaves behind
    approximate: list[str] = []  # merges of terms whose effects differ by more than rounding
    while True:
        obj, kinds = objects
        names = [shared[j] for j in active] + obj
        model = CompactModel(data, Sf, A[active], kinds, fit_bias, reml)
        scale = _scales(data, A[active], kinds)
        start = np.array([_variance_of(t, _budget_sigma(base, t)) for t in names if t not in OBJECT_TERMS]
                         + [0.0] * len(obj)) / scale
        start = np.where(start > 0, start, 0.1)
        v, ok, msg = _optimise(model, scale, start)
        H = _information(model, v, scale) if v.size else np.zeros((0, 0))
        v, H = _polish(model, v, scale, H)
        first = first or (H, list(names))
        group_ = _collinear(H, names, tol)
        if group_ is None or len(group_) < 2:
            break
        if abs(_weakest(H)) > EXACT_MERGE:  # (an indefinite information, negative, is no exact merge either)
            approximate.append(", ".join(sorted(group_)))
        info = {t: H[names.index(t), names.index(t)] * scale[names.index(t)] ** 2 for t in group_}
        keep = max(group_, key=info.get)
        if keep in OBJECT_TERMS:  # a per-object term stays free; a shared term it absorbs is dropped
            group_ = [keep] + [t for t in group_ if t not in OBJECT_TERMS]
        merged[keep] = tuple(sorted(set(merged.get(keep, ())) | {t for t in group_ if t != keep}
                                    | {u for t in group_ if t != keep for u in merged.pop(t, ())}))
        active = [j for j in active if shared[j] == keep or shared[j] not in group_]
    ll, _, beta, cov_beta = model.evaluate(v, grad=False)
    terms.update(_term_fits(model, scale, v, H, names, merged, first, profile_check))
    if approximate:  # the other terms' intervals are conditional on members fixed at zero that were not redundant
        why = (f"the fit merged terms whose effects differ ({'; '.join(approximate)}: fixed at zero but for one, "
               "their effect leaks into the other terms): the interval is not to be trusted, the estimate is kept")
        terms.update({t: replace(tf, status="weakly identified", note=why) for t, tf in terms.items()
                      if tf.status == "identified"})
    order = [t for t in [*shared, *OBJECT_TERMS] if t in terms]
    return BudgetFit({t: terms[t] for t in order}, beta, cov_beta, float(ll), "reml" if reml else "ml",
                     data.n, data.groups_present(), base, ok, msg, H, tuple(names))


#: a term is called identified only where its 95 % interval has held the truth in >= 93 % of simulated campaigns
#: (bench/fit_recovery.py): Satterthwaite's effective degrees of freedom at least this many ...
MIN_DOF = 2.0
#: ... and its variance not entangled with the others: the variance inflation of its estimate (the diagonal of
#: the inverse normalised information, 1 for a term the others do not affect) at most this, in the fit with
#: every term free (before any merge) as in the final one
MAX_VIF = 4.0


def _vif(H: np.ndarray) -> np.ndarray:
    """Variance inflation (m,) of each estimate: diag of the inverse of the normalised information (inf: singular)."""
    d = np.sqrt(np.clip(np.diag(H), 0, None))
    if H.size == 0:
        return np.zeros(0)
    out = np.full(H.shape[0], np.inf)
    ok = d > 0
    if not ok.any():
        return out
    Hn = H[np.ix_(ok, ok)] / np.outer(d[ok], d[ok])
    try:
        out[ok] = np.diag(np.linalg.inv(Hn))
    except np.linalg.LinAlgError:
        pass
    return np.where(np.isfinite(out) & (out > 0), out, np.inf)


def _term_fits(model, scale, v, H, names, merged, first, profile_check: bool = True) -> dict[str, TermFit]:
    """The TermFit of every fitted term: estimate, interval, and whether the interval can be trusted (without
    ``profile_check``, the profile likelihood is not consulted: for refits whose statuses nobody reads)."""
    try:
        cov_v = np.linalg.inv(H) if v.size else np.zeros((0, 0))
    except np.linalg.LinAlgError:
        cov_v = np.full_like(H, np.nan)
    vif = _vif(H)
    vif0 = dict(zip(first[1], _vif(first[0]), strict=True)) if first is not None else {}
    terms = {}
    for i, t in enumerate(names):
        se_v = float(np.sqrt(cov_v[i, i])) if cov_v[i, i] > 0 else np.nan
        se, lo, hi = _interval(v[i], se_v)
        if t == "ground_slope_deg":  # intervals of the gradient -> degrees
            se, lo, hi = np.degrees(se) if np.isfinite(se) else se, _sigma_of(t, lo**2), _sigma_of(t, hi**2)
        dof = 2 * v[i] ** 2 / se_v**2 if np.isfinite(se_v) and se_v > 0 else 0.0
        infl = max(float(vif[i]), float(vif0.get(t, vif[i])))
        if t in merged:
            st, note = "merged", f"the data cannot tell it from {', '.join(merged[t])}: their joint effect"
        elif CONFOUNDED.get(t) in (first[1] if first is not None else names):  # free, even if merged away since
            st, note = "weakly identified", (f"confounded with {CONFOUNDED[t]} (free too): a principal-point shift "
                                             "is a rotation, told apart only by the cameras' focal lengths; the "
                                             "interval is not to be trusted, the estimate is kept")
        elif dof >= MIN_DOF and infl <= MAX_VIF and (held := _interval_holds(model, v, scale, i, t, (lo, hi))
                                                     if profile_check else (True, ""))[0]:
            st, note = "identified", ""
        elif dof >= MIN_DOF and infl <= MAX_VIF:
            st, note = "weakly identified", held[1] + ": the interval is not to be trusted, the estimate is kept"
        else:
            st = "weakly identified"
            note = "; ".join(x for x in (
                f"{dof:.2g} effective degrees of freedom (at least {MIN_DOF:g} needed)" if dof < MIN_DOF else "",
                f"its estimate is entangled with other terms' (variance inflation {infl:.3g}, at most {MAX_VIF:g} "
                "for an interval to trust)" if infl > MAX_VIF else "") if x)
            note += ": the interval is not to be trusted, the estimate is kept"
        terms[t] = TermFit(_sigma_of(t, v[i]), float(se), (float(lo), float(hi)), st, merged.get(t, ()), note,
                           float(dof), infl)
        for u in merged.get(t, ()):
            terms[u] = TermFit(0.0, np.nan, (0.0, np.inf), "merged", (t,), f"merged into {t} (not split)")
    return terms


# ---------------------------------------------------------------------------------------------
# cross-validated coverage
# ---------------------------------------------------------------------------------------------
class CrossValidation(NamedTuple):
    """Coverage of held-out residuals by the ellipses of a budget fitted without them.

    Attributes
    ----------
    by : str                 ``"object"`` or ``"group"``
    n_folds : int
    levels : (L,)            nominal probabilities of the ellipses
    coverage : (L,)          fraction of held-out residuals inside each ellipse
    nees : (N,)              squared Mahalanobis distance of each residual (caller's order; NaN where the
                             fold's fit failed or the pair is not in the subsample)
    inside : (N, L) bool
    n_sampled : int          pairs the cross-validation ran on: all ``N``, or a seeded subsample of
                             ``max_pairs`` of them (``subsampled``)
    """

    by: str
    n_folds: int
    levels: np.ndarray
    coverage: np.ndarray
    nees: np.ndarray
    inside: np.ndarray
    n_sampled: int = -1

    @property
    def subsampled(self) -> bool:
        return 0 <= self.n_sampled < self.nees.size

    def to_dict(self) -> dict:
        return {"by": self.by, "n_folds": self.n_folds, "levels": self.levels.tolist(),
                "coverage": self.coverage.tolist(), "n": int(np.isfinite(self.nees).sum()),
                "n_pairs": int(self.nees.size), "n_sampled": int(self.n_sampled), "subsampled": self.subsampled}


def _folds(n: int, group, by: str, n_folds, seed: int) -> np.ndarray:
    """Fold index (n,) of every object."""
    if by == "group":
        labels, fold = np.unique(group, return_inverse=True)
        if labels.size < 2:
            raise InputError("group", f"{labels.size} group", "at least 2 groups for leave-one-group-out")
        return fold
    if by != "object":
        raise InputError("by", by, "'object' (leave-one-object-out) or 'group' (leave-one-group-out)")
    k = n if n_folds is None and n <= 100 else int(n_folds or 10)
    if not 2 <= k <= n:
        raise InputError("n_folds", n_folds, f"an integer in [2, {n}]")
    return np.random.default_rng(seed).permutation(np.arange(n) % k)


def nees_of(residual_m, dxy_dp, cov_object_m2, budget, *, object_sigma_m: float = 0.0,
            object_ground_sigma_m: float = 0.0, bias_m=(0.0, 0.0)):
    """Squared Mahalanobis distance (N,) of residuals under
    ``J Sigma(budget) J^T + R + sigma_m^2 I + sigma_gz^2 j_gz j_gz^T`` (``j_gz = dxy_dp[..., ground_dz_m]``)."""
    S = load_budget(budget).param_covariance()
    J = np.asarray(dxy_dp, dtype=np.float64)
    jg = J[:, :, P.GDZ]
    C = J @ S @ np.swapaxes(J, 1, 2) + np.asarray(cov_object_m2, dtype=np.float64) + object_sigma_m**2 * np.eye(2) \
        + object_ground_sigma_m**2 * jg[:, :, None] * jg[:, None, :]
    d = np.asarray(residual_m, dtype=np.float64) - np.asarray(bias_m, dtype=np.float64)
    return np.einsum("na,na->n", d, np.linalg.solve(C, d[..., None])[..., 0])


#: pairs above which the cross-validation runs on a seeded subsample of this many (reported, never silent)
CV_MAX_PAIRS = 20_000


def cross_validate(residual_m, dxy_dp, cov_object_m2, group, *, free, by: str = "object", n_folds=None,
                   levels=_LEVELS, seed: int = 0, max_pairs: int | None = CV_MAX_PAIRS,
                   **fit_options) -> CrossValidation:
    """Cross-validated coverage of the fitted budget's ellipses.

    ``by="object"``: leave-one-object-out (exact for N <= 100 objects; otherwise ``n_folds``-fold over
    objects, default 10, seeded); ``by="group"``: leave-one-group-out (a camera's objects are held out
    together, so its calibration draw is never seen by the fit).  Each held-out residual is judged by
    the ellipse of its marginal covariance ``J Sigma J^T + R + sigma_m^2 I`` (what a user deploying
    the budget would draw), centred on the fitted bias.  ``fit_options`` go to :func:`fit_budget`.

    Bounded cost: above ``max_pairs`` pairs (default :data:`CV_MAX_PAIRS`; ``None``: never) the folds are
    drawn from a seeded uniform subsample of ``max_pairs`` pairs (every fit then sees at most that many);
    the result says so (``n_sampled``, ``subsampled``) and the pairs outside it have ``nees`` NaN.
    """
    data = compact_inputs([(residual_m, dxy_dp, cov_object_m2, group)], free=free,
                          base_budget=fit_options.get("base_budget"), memory_pairs=None)
    return cross_validate_compact(data, free=free, by=by, n_folds=n_folds, levels=levels, seed=seed,
                                  max_pairs=max_pairs, **fit_options)


def _nees_compact(data: CompactPairs, fit: BudgetFit) -> np.ndarray:
    """NEES (n,) of the records under the fitted budget (its covariance lives in the records' columns)."""
    S = fit.to_budget().param_covariance()[np.ix_(data.cols, data.cols)]
    C = data.U @ S @ np.swapaxes(data.U, 1, 2) + fit.object_sigma_m**2 * np.eye(2)
    C[:, 0, 0] += data.R3[:, 0]
    C[:, 0, 1] += data.R3[:, 1]
    C[:, 1, 0] += data.R3[:, 1]
    C[:, 1, 1] += data.R3[:, 2]
    if fit.object_ground_sigma_m > 0:
        C += fit.object_ground_sigma_m**2 * data.jg[:, :, None] * data.jg[:, None, :]
    d = data.r - fit.bias_m
    return np.einsum("na,na->n", d, np.linalg.solve(C, d[..., None])[..., 0])


def cross_validate_compact(data: CompactPairs, *, free, by: str = "object", n_folds=None, levels=_LEVELS,
                           seed: int = 0, max_pairs: int | None = CV_MAX_PAIRS, **fit_options) -> CrossValidation:
    """:func:`cross_validate` on records from :func:`compact_inputs` (same ``free`` and ``base_budget``)."""
    lv = np.asarray(levels, dtype=np.float64)
    if lv.ndim != 1 or np.any(~(lv > 0) | ~(lv < 1)):
        raise InputError("levels", levels, "probabilities in (0, 1)")
    if max_pairs is not None and int(max_pairs) < 2:
        raise InputError("max_pairs", max_pairs, "an integer >= 2 (or None: no subsample)")
    rows = np.arange(data.n)
    if max_pairs is not None and data.n > int(max_pairs):
        rows = np.sort(np.random.default_rng(seed).choice(data.n, int(max_pairs), replace=False))
    sub = data.take(rows) if rows.size < data.n or not isinstance(data, CompactPairs) else data
    fold = _folds(sub.n, sub.gid, by, n_folds, seed)
    nees = np.full(data.n, np.nan)
    for f in np.unique(fold):
        test = fold == f
        try:
            fit = fit_compact(sub.subset(~test), free=free, profile_check=False, **fit_options)  # estimates only
        except (InputError, np.linalg.LinAlgError):
            continue
        nees[rows[test]] = _nees_compact(sub.subset(test), fit)
    ok = np.isfinite(nees)
    inside = nees[:, None] <= -2 * np.log1p(-lv)[None, :]
    cov = inside[ok].mean(0) if ok.any() else np.full(lv.size, np.nan)
    return CrossValidation(by, int(np.unique(fold).size), lv, cov, nees, inside & ok[:, None], int(sub.n))
