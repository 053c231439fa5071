"""Propagation of the error budget to ground covariances.

Linear (first order): ``Cov(x, y) = J_p Sigma_p J_p^T + J_uv Sigma_uv J_uv^T``
with the closed-form Jacobians of the camera model.  Camera-level sources are
shared by every point of an image (:func:`propagate_joint` keeps their
cross-covariances); per-point sources are independent.

When the linearisation holds: the ground coordinates are ratios whose
denominator is the ray's downward component.  Where the denominator is large
(well below the horizon) the map is nearly linear over a few sigma of every
source and the linear covariance agrees with Monte Carlo to a few percent; as a
pixel approaches the horizon, the distance grows like 1/denominator, the
distribution becomes skewed with a heavy far tail and the linear sigma
under-estimates.  :func:`nonlinearity` predicts, per point and in closed form,
the relative error of the linear 1-sigma semi-major axis (a second-order
expansion of ``1/Dn``); :func:`propagate` returns it as ``nonlinearity`` with the
flag ``linear_ok`` (``nonlinearity <= linear_threshold``, default 0.05).
:func:`linearity_ratio` measures the ratio linear/Monte-Carlo, to check it.

NaN policy: where a point is invalid (ray above the horizon, non-finite input,
pixel outside the lens's valid domain, or a result that is not finite although every
input is -- ``OVERFLOW``) the mean and covariance are NaN and ``valid`` is
False; the ``reason`` array says why.  Derivatives are never returned for an
undefined point and no invalid point is ever replaced by a plausible number.
The fused kernels (:func:`footprint_uq.products.covariance.covariance_map`,
:func:`~footprint_uq.products.covariance.covariance_points`) apply the same output check.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import params as P
from .. import status
from .._checks import as_points, check_cov
from ..cameras.distortion import undistort
from ..cameras.pinhole import pixel_to_normalised
from ..cameras.rotation import R_W_C, dR_W_C
from ..errors import InputError
from .budget import ErrorBudget, load_budget
from .ellipse import ellipse_axes

__all__ = ["GroundEstimate", "JointEstimate", "MonteCarloEstimate", "propagate", "propagate_joint", "monte_carlo",
           "unscented", "linearity_ratio", "nonlinearity", "nonlinearity_from_forms", "DEFAULT_LINEAR_THRESHOLD",
           "ray_denominator", "nonlinearity_of_jacobians", "check_linear_threshold", "sample_params",
           "covariance_for_v2x", "V2X_COV_LINEAR", "V2X_COV_SAMPLED", "V2X_COV_UNAVAILABLE"]

#: default threshold of ``linear_ok``: predicted relative error of the linear 1-sigma semi-major axis
DEFAULT_LINEAR_THRESHOLD = 0.05


@dataclass
class GroundEstimate:
    """Mean and covariance of ground points, travelling together.

    Attributes
    ----------
    xy_world_m : (..., 2)   ground point in W, metres
    cov_m2 : (..., 2, 2)    covariance, m^2
    valid : (...) bool
    reason : (...) int8     :mod:`footprint_uq.status` code
    contributions : dict[str, (..., 2, 2)] or None
        Per-source covariance contributions; they add up to ``cov_m2``
        (``"cross_terms"`` holds correlations between sources, if any).
    nonlinearity : (...) float or None
        Predicted relative error of the linear 1-sigma semi-major axis
        (:func:`nonlinearity`); NaN where the point is invalid.
    linear_ok : (...) bool or None
        ``nonlinearity <= linear_threshold``; False where the point is invalid.
    linear_threshold : float
        Threshold used for ``linear_ok``.
    """

    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    valid: np.ndarray
    reason: np.ndarray
    contributions: dict | None = None
    nonlinearity: np.ndarray | None = None
    linear_ok: np.ndarray | None = None
    linear_threshold: float = DEFAULT_LINEAR_THRESHOLD

    def ellipse(self, confidence: float | None = None):
        """Semi-axes and orientation (:func:`~footprint_uq.uncertainty.ellipse.ellipse_axes`)."""
        return ellipse_axes(self.cov_m2, confidence=confidence)

    @property
    def sigma_xy_m(self) -> np.ndarray:
        """Per-axis standard deviations ``(..., 2)``."""
        return np.sqrt(np.stack([self.cov_m2[..., 0, 0], self.cov_m2[..., 1, 1]], -1))


@dataclass
class JointEstimate:
    """K points of one image with their joint covariance.

    ``xy_world_m`` (..., K, 2); ``cov_m2`` (..., 2K, 2K) ordered x0, y0, x1, y1, ...;
    ``valid``/``reason`` (..., K).  Rows and columns of invalid points are NaN.
    ``nonlinearity``/``linear_ok`` (..., K): the linearity flag of each point (its 2x2
    marginal, as :func:`propagate`); None with ``linearity=False``.
    """

    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    valid: np.ndarray
    reason: np.ndarray
    nonlinearity: np.ndarray | None = None
    linear_ok: np.ndarray | None = None
    linear_threshold: float = DEFAULT_LINEAR_THRESHOLD


@dataclass
class MonteCarloEstimate:
    """Sample mean/covariance; ``fraction_valid`` (...) is the share of samples that hit the ground."""

    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    fraction_valid: np.ndarray
    n_samples: int


def _pixel_cov(budget: ErrorBudget, pixel_cov_px2, shape):
    S = budget.pixel_covariance()
    if pixel_cov_px2 is None:
        return np.broadcast_to(S, shape + (2, 2))
    c = check_cov("pixel_cov_px2", pixel_cov_px2, 2)
    try:
        return np.broadcast_to(S + c, shape + (2, 2))
    except ValueError:
        raise InputError("pixel_cov_px2", f"shape {c.shape}",
                         f"a covariance broadcastable to the points' shape {shape + (2, 2)}") from None


def _sandwich(J, S):
    """``J S J^T`` for J (..., m, n), S (n, n) or (..., n, n).

    Overflow gives inf/NaN without a RuntimeWarning: such a point's result is not finite and is
    marked invalid (``status.OVERFLOW``) where the results are checked.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        return J @ S @ np.swapaxes(J, -1, -2)


def propagate(camera, budget, uv_px, *, pixel_cov_px2=None, breakdown: bool = False,
              linearity: bool = True, linear_threshold: float = DEFAULT_LINEAR_THRESHOLD) -> GroundEstimate:
    """Ground point and 2x2 covariance of each pixel (first order).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    uv_px : array_like, shape (..., 2)
    pixel_cov_px2 : array_like, shape (..., 2, 2), optional
        Extra per-point pixel covariance, e.g. from a probabilistic detector; added
        to the budget's imaging and resolution errors.
    breakdown : bool
        Also return the per-source contributions.
    linearity : bool
        Also compute ``nonlinearity`` and ``linear_ok`` (:func:`nonlinearity`); False
        leaves them None.
    linear_threshold : float
        ``linear_ok = nonlinearity <= linear_threshold`` (default 0.05: the linear
        1-sigma semi-major axis is predicted within 5 % of the true one).
    """
    thr = check_linear_threshold(linear_threshold)
    budget = load_budget(budget)
    uv = as_points("uv_px", uv_px, 2)
    bp = camera.backproject(uv, get_gradients=True)
    shape = bp.valid.shape
    Sp = budget.param_covariance()
    used = np.flatnonzero(np.any(Sp != 0, axis=0))
    Jp = bp.dxy_dp[..., used]
    cov = _sandwich(Jp, Sp[np.ix_(used, used)])
    Suv = _pixel_cov(budget, pixel_cov_px2, shape)
    with np.errstate(invalid="ignore"):  # inf + -inf of an overflowed point: NaN, marked invalid below
        cov = cov + _sandwich(bp.dxy_duv, Suv)
    contrib = None
    if breakdown:
        contrib = {}
        total_shared = np.zeros(shape + (2, 2))
        for name, (idx, block) in budget.shared_source_covariances().items():
            c = _sandwich(bp.dxy_dp[..., idx], block)
            contrib[name] = c
            total_shared = total_shared + c
        for name, src in (("imaging", ("imaging",)), ("resolution", ("resolution",))):
            S = budget.pixel_covariance(src)
            if np.any(S):
                contrib[name] = _sandwich(bp.dxy_duv, S)
        if pixel_cov_px2 is not None:
            det = _pixel_cov(ErrorBudget(), pixel_cov_px2, shape)  # the detector's part alone
            contrib["detector"] = _sandwich(bp.dxy_duv, det)
        shared_full = _sandwich(Jp, Sp[np.ix_(used, used)])
        cross = shared_full - total_shared
        if np.any(np.abs(np.nan_to_num(cross)) > 1e-15 * np.nan_to_num(np.abs(shared_full)).max(initial=0)):
            contrib["cross_terms"] = cross
    xy, cov, valid, reason = _check_outputs(bp.xy_world_m, cov, bp.valid, bp.reason)
    nl = ok = None
    if linearity:
        nl = nonlinearity_of_jacobians(camera, budget, uv, cov, bp.dxy_dp, bp.dxy_duv, Sp, Suv, valid)
        ok = valid & (nl <= thr)
    return GroundEstimate(xy, cov, valid, reason, contrib, nl, ok, thr)


def _check_outputs(xy, cov, valid, reason, *, joint: bool = False):
    """Outputs are checked too: a point whose position or covariance is not finite is invalid
    (:data:`footprint_uq.status.OVERFLOW`), never valid with an infinite number.

    ``cov`` is (..., 2, 2) per point or (..., 2K, 2K) joint over the last axis of ``xy``'s points.
    """
    K = xy.shape[-2] if joint else None
    if K is None:
        fin = np.isfinite(xy).all(-1) & np.isfinite(cov).all((-2, -1))
    else:
        blocks = cov.reshape(cov.shape[:-2] + (K, 2, K, 2))
        idx = np.arange(K)
        diag = np.moveaxis(blocks[..., idx, :, idx, :], 0, -3)  # (..., K, 2, 2)
        fin = np.isfinite(xy).all(-1) & np.isfinite(diag).all((-2, -1))
    bad = valid & ~fin
    if not bad.any():
        return xy, cov, valid, reason
    valid = valid & ~bad
    reason = np.where(bad, status.OVERFLOW, reason).astype(np.int8)
    xy = np.where(bad[..., None], np.nan, xy)
    if K is None:
        cov = np.where(bad[..., None, None], np.nan, cov)
    else:
        rows = np.repeat(bad, 2, axis=-1)
        cov = np.where(rows[..., :, None] | rows[..., None, :], np.nan, cov)
    return xy, cov, valid, reason


def propagate_joint(camera, budget, uv_px, *, pixel_cov_px2=None, linearity: bool = True,
                    linear_threshold: float = DEFAULT_LINEAR_THRESHOLD) -> JointEstimate:
    """Joint covariance of K points seen in the same image.

    Parameters
    ----------
    uv_px : array_like, shape (..., K, 2)
    pixel_cov_px2 : array_like, shape (..., K, 2, 2), optional
        Per-point detector covariance (independent between points).
    linearity, linear_threshold
        The per-point linearity flag, as in :func:`propagate`.

    The camera-level sources couple the points; per-point sources fill the 2x2
    diagonal blocks only.
    """
    thr = check_linear_threshold(linear_threshold)
    budget = load_budget(budget)
    uv = as_points("uv_px", uv_px, 2)
    if uv.ndim < 2:
        raise InputError("uv_px", uv.shape, "an array of shape (..., K, 2)")
    bp = camera.backproject(uv, get_gradients=True)
    K = uv.shape[-2]
    lead = bp.valid.shape[:-1]
    Sp = budget.param_covariance()
    used = np.flatnonzero(np.any(Sp != 0, axis=0))
    Jp = bp.dxy_dp[..., used].reshape(lead + (2 * K, used.size))
    cov = _sandwich(Jp, Sp[np.ix_(used, used)])
    Suv = _pixel_cov(budget, pixel_cov_px2, bp.valid.shape)
    blocks = _sandwich(bp.dxy_duv, Suv)  # (..., K, 2, 2)
    for k in range(K):
        cov[..., 2 * k:2 * k + 2, 2 * k:2 * k + 2] += blocks[..., k, :, :]
    xy, cov, valid, reason = _check_outputs(bp.xy_world_m, cov, bp.valid, bp.reason, joint=True)
    nl = ok = None
    if linearity:
        idx = np.arange(K)
        marg = cov.reshape(lead + (K, 2, K, 2))[..., idx, :, idx, :]  # (K, ..., 2, 2): advanced indices first
        marg = np.moveaxis(marg, 0, -3)
        nl = nonlinearity_of_jacobians(camera, budget, uv, marg, bp.dxy_dp, bp.dxy_duv, Sp, Suv, valid)
        ok = valid & (nl <= thr)
    return JointEstimate(xy, cov, valid, reason, nl, ok, thr)


def sample_params(budget: ErrorBudget, n: int, rng) -> np.ndarray:
    """``n`` seeded draws ``(n, 22)`` of the parameter errors of ``budget`` (zero mean, its covariance)."""
    Sp = budget.param_covariance()
    w, V = np.linalg.eigh(Sp)
    A = V * np.sqrt(np.clip(w, 0.0, None))
    return rng.standard_normal((n, P.N_PARAMS)) @ A.T


def monte_carlo(camera, budget, uv_px, *, n_samples: int = 10_000, seed: int = 0,
                pixel_cov_px2=None, chunk: int = 2000) -> MonteCarloEstimate:
    """Seeded Monte Carlo on the full (non-linear) camera model.

    Each sample draws one set of camera-level errors shared by all points and
    independent pixel noise per point.  Samples whose ray misses the ground are
    excluded from the statistics and counted in ``fraction_valid``.
    """
    budget = load_budget(budget)
    uv = as_points("uv_px", uv_px, 2)
    rng = np.random.default_rng(seed)
    shape = uv.shape[:-1]
    Suv = _pixel_cov(budget, pixel_cov_px2, shape)
    Luv = np.linalg.cholesky(Suv + 1e-300 * np.eye(2)) if np.all(np.linalg.eigvalsh(Suv) > 0) else None
    # accumulate deviations from the nominal point: raw sums of squares of georeferenced
    # coordinates (e.g. UTM northings ~5e6 m) would cancel catastrophically against the mean
    ref = camera.backproject(uv).xy_world_m
    ref = np.where(np.isfinite(ref), ref, np.asarray(camera.params[P.XM:P.YM + 1], dtype=np.float64))
    s1 = np.zeros(shape + (2,))
    s2 = np.zeros(shape + (2, 2))
    cnt = np.zeros(shape)
    done = 0
    while done < n_samples:
        m = min(chunk, n_samples - done)
        dp = sample_params(budget, m, rng).reshape((m,) + (1,) * len(shape) + (P.N_PARAMS,))
        z = rng.standard_normal((m,) + shape + (2,))
        if Luv is not None:
            noise = (Luv @ z[..., None])[..., 0]
        else:
            w, V = np.linalg.eigh(Suv)
            noise = ((V * np.sqrt(np.clip(w, 0, None))[..., None, :]) @ z[..., None])[..., 0]
        bp = camera.backproject_with(camera.params + dp, uv + noise)
        ok = bp.valid
        xy = np.where(ok[..., None], bp.xy_world_m - ref, 0.0)
        s1 += xy.sum(0)
        s2 += np.einsum("...i,...j->...ij", xy, xy).sum(0)
        cnt += ok.sum(0)
        done += m
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / cnt[..., None]
        cov = (s2 - cnt[..., None, None] * np.einsum("...i,...j->...ij", mean, mean)) / (cnt[..., None, None] - 1)
    return MonteCarloEstimate(ref + mean, cov, cnt / n_samples, n_samples)


def unscented(camera, budget, uv_px, *, pixel_cov_px2=None) -> GroundEstimate:
    """Unscented transform over the non-zero error sources (alpha=1, beta=0, kappa=0).

    Sigma points at ``+- sqrt(n)`` standard deviations along the principal axes of the
    joint (camera + pixel) covariance; mean and covariance from the equal weights.
    Points whose sigma points miss the ground are invalid.
    """
    budget = load_budget(budget)
    uv = as_points("uv_px", uv_px, 2)
    shape = uv.shape[:-1]
    Sp = budget.param_covariance()
    w, V = np.linalg.eigh(Sp)
    keep = w > 1e-300
    Ap = V[:, keep] * np.sqrt(w[keep])  # (22, m)
    Suv = _pixel_cov(budget, pixel_cov_px2, shape)
    wu, Vu = np.linalg.eigh(Suv)
    Au = Vu * np.sqrt(np.clip(wu, 0, None))[..., None, :]  # (..., 2, 2)
    n = Ap.shape[1] + 2
    s = np.sqrt(n)
    dps = [np.zeros(P.N_PARAMS)] + [sg * s * Ap[:, i] for i in range(Ap.shape[1]) for sg in (1, -1)]
    dps += [np.zeros(P.N_PARAMS)] * 4
    duvs = [np.zeros(shape + (2,))] * (1 + 2 * Ap.shape[1])
    duvs += [sg * s * Au[..., :, i] for i in range(2) for sg in (1, -1)]
    dp = np.stack(dps).reshape((len(dps),) + (1,) * len(shape) + (P.N_PARAMS,))
    du = np.stack(duvs)
    bp = camera.backproject_with(camera.params + dp, uv + du)
    wts = np.full(len(dps), 1.0 / (2 * n))
    wts[0] = 0.0
    ys = bp.xy_world_m
    mean = np.einsum("s,s...->...", wts, ys) + 0.0
    mean = mean + (1.0 - wts.sum()) * ys[0]
    dev = ys - mean
    cov = np.einsum("s,s...i,s...j->...ij", wts, dev, dev)
    valid = bp.valid.all(0)
    reason = np.where(valid, 0, np.max(bp.reason, axis=0)).astype(np.int8)
    mean = np.where(valid[..., None], mean, np.nan)
    cov = np.where(valid[..., None, None], cov, np.nan)
    return GroundEstimate(mean, cov, valid, reason)


def linearity_ratio(camera, budget, uv_px, *, n_samples: int = 20_000, seed: int = 0):
    """How well the linear result holds: ``sigma_major(linear) / sigma_major(Monte Carlo)``.

    Returns ``(ratio, fraction_valid)``, arrays of shape (...).  Near 1 where the
    linearisation holds; it drops as pixels approach the horizon.
    """
    lin = propagate(camera, budget, uv_px)
    mc = monte_carlo(camera, budget, uv_px, n_samples=n_samples, seed=seed)
    a_lin = ellipse_axes(lin.cov_m2)[0]
    a_mc = ellipse_axes(mc.cov_m2)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        return a_lin / a_mc, mc.fraction_valid


# -- linearity indicator ---------------------------------------------------------------------------
def check_linear_threshold(value) -> float:
    """The linearity threshold as a float > 0 (else :class:`InputError` naming ``linear_threshold``)."""
    try:
        t = float(value)
    except (TypeError, ValueError):
        raise InputError("linear_threshold", value, "a relative error > 0, e.g. 0.05") from None
    if not np.isfinite(t) or t <= 0:
        raise InputError("linear_threshold", value, "a relative error > 0, e.g. 0.05")
    return t


def ray_denominator(camera, uv_px):
    """The ground intersection's denominator and its gradients (reference path, numpy).

    The ground point is ``xy = C_xy + lam d_xy`` with the world ray ``d = R_W_C (x_n, y_n, 1)``
    (``x_n, y_n`` undistorted normalised coordinates), ``lam = N / Dn``, ``N = ground_dz - h``
    (< 0) and ``Dn = d_z - s_x d_x - s_y d_y`` (< 0 where the ray meets the ground; ``s_x, s_y``
    the ground slopes): ``Dn`` is the ray's component along the (upward) ground normal.

    Parameters
    ----------
    camera : Camera
    uv_px : array_like, shape (..., 2)

    Returns
    -------
    dn : (...)            ``Dn`` (dimensionless, the ray has unit boresight component)
    lam_m : (...)         ``lam = N / Dn``, metres (depth along the boresight)
    d_xy : (..., 2)       horizontal part of ``d``
    ddn_dp : (..., 22)    dDn / d(params), :data:`footprint_uq.params.PARAM_NAMES` order
    ddn_duv : (..., 2)    dDn / d(u, v), per pixel
    """

    p = np.asarray(camera.params, dtype=np.float64)
    uv = np.asarray(uv_px, dtype=np.float64)
    fx, fy, cx, cy, sk = (p[i] for i in range(5))
    xd, dxd_duv, dxd_dk = pixel_to_normalised(uv, fx, fy, cx, cy, sk, get_gradients=True)
    xn, _, dxn_dxd, dxn_ddist = undistort(xd, p[P.DIST_SLICE], get_gradients=True)
    ang = (p[P.PAN], p[P.TILT], p[P.ROLL])
    R = R_W_C(*ang)
    ray_c = np.concatenate([xn, np.ones(xn.shape[:-1] + (1,))], -1)
    d = ray_c @ R.T
    gx, gy = p[P.GSX], p[P.GSY]
    n = np.array([-gx, -gy, 1.0])
    dn = d @ n
    N = p[P.GDZ] - p[P.HM]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = N / dn
    nR = n @ R[:, :2]  # dDn/dxn (2,)
    ddn_dxd = np.einsum("j,...jk->...k", nR, dxn_dxd)
    g = np.zeros(dn.shape + (P.N_PARAMS,))
    g[..., 0:5] = np.einsum("...j,...jk->...k", ddn_dxd, dxd_dk)
    g[..., P.DIST_SLICE] = np.einsum("j,...jk->...k", nR, dxn_ddist)
    dRc = np.einsum("aij,...j->...ai", dR_W_C(*ang), ray_c)  # (..., 3 angles, 3)
    g[..., P.PAN:P.ROLL + 1] = dRc @ n
    g[..., P.GSX] = -d[..., 0]
    g[..., P.GSY] = -d[..., 1]
    g_uv = np.einsum("...j,...jk->...k", ddn_dxd, dxd_duv)
    return dn, lam, d[..., :2], g, g_uv


def nonlinearity_from_forms(lam_max_m2, e_major, dn, lam_m, d_xy, mu, gamma, *, s_num_m2=None, s_cross_m2=None,
                            mu_num=None):
    """Second-order correction of the linear semi-major axis, from per-point scalars (portable).

    With ``e`` the unit major axis of the linear covariance (eigenvalue ``lam_max``),
    ``r = J^T e`` (J the (2, n) Jacobian of the ground point over all n error sources,
    camera parameters and pixel), ``g`` the gradient of ``Dn`` over the same sources,
    ``Sigma`` their covariance, and ``r'`` = ``r`` with the camera-position entries (x_m,
    y_m) set to 0 -- the position moves the ground point additively, not through
    ``1 / Dn``::

        mu    = r^T Sigma g      (m)          covariance of the major-axis error with dDn
        gamma = g^T Sigma g      (1)          sigma_Dn^2
        s_num = r'^T Sigma r'    (m^2)        the major-axis variance without the position error
        s_crs = r^T Sigma r'     (m^2)        (= s_num when the position is uncorrelated with the rest)
        mu'   = r'^T Sigma g     (m)          (= mu: Dn does not depend on the position)
        q2    = gamma / Dn^2                  relative variance of the denominator
        b     = lam (d_xy . e)   (m)          the depth term along e: xy = C + lam d_xy / (1 + eps)
        w     = -b / Dn          (m)          D = w dDn, the linear part of the depth term
        c_L   = mu / Dn,  c_A = (mu' - w gamma) / Dn
        s_A   = s_num - 2 w mu' + w^2 gamma   variance of the numerator's linear error A
        s_LA  = s_crs - w mu                  covariance of the whole linear error L with A
        delta = 2 q2^2 b^2 - 4 q2 b c_A + q2 s_A + c_A^2 - 6 q2 c_L b + 2 q2 s_LA + 4 c_L c_A
                + (69 q2^3 + 696 q2^4) b^2
        nonlinearity = | sqrt(1 + delta / lam_max) - 1 |

    ``delta`` is the fourth-moment (second-order) change of the variance along ``e`` when
    ``1 / (1 + eps)``, ``eps = dDn / Dn``, is expanded to third order and the errors are
    jointly Gaussian (docs/uncertainty-model.md, "The linearity flag"); the last terms are the
    next terms of the pure depth error's (asymptotic) series, ``Var(1 / (1 + eps)) = q2 +
    8 q2^2 + 69 q2^3 + 696 q2^4 + ...``, which dominates near the horizon.

    ``s_num_m2``, ``s_cross_m2`` and ``mu_num`` default to ``lam_max``, ``lam_max`` and ``mu``
    (no position error).  With a position error uncorrelated with the other parameters,
    ``s_num = s_crs = lam_max - e^T Sigma_pos e`` and ``mu' = mu``.  Shapes broadcast:
    ``e_major``, ``d_xy`` (..., 2), the others (...).  Returns (...); 1.0 where
    ``1 + delta / lam_max < 0`` (the expansion has broken down), 0 where ``delta`` is 0 (also with
    ``lam_max`` 0: a budget without any uncertainty), NaN where an input is NaN.
    """
    e = np.asarray(e_major, dtype=np.float64)
    b = np.asarray(lam_m) * np.einsum("...i,...i->...", np.asarray(d_xy, dtype=np.float64), e)
    dn = np.asarray(dn, dtype=np.float64)
    lam_max = np.asarray(lam_max_m2, dtype=np.float64)
    mu = np.asarray(mu, dtype=np.float64)
    gamma = np.asarray(gamma, dtype=np.float64)
    s_num = lam_max if s_num_m2 is None else np.asarray(s_num_m2, dtype=np.float64)
    s_crs = lam_max if s_cross_m2 is None else np.asarray(s_cross_m2, dtype=np.float64)
    mu_n = mu if mu_num is None else np.asarray(mu_num, dtype=np.float64)
    with np.errstate(all="ignore"):  # invalid points may carry inf (OVERFLOW); their result is NaN
        q2 = gamma / dn**2
        w = -b / dn
        c_L = mu / dn
        c_A = (mu_n - w * gamma) / dn
        s_A = s_num - 2 * w * mu_n + w * w * gamma
        s_LA = s_crs - w * mu
        delta = (2 * q2 * q2 * b * b - 4 * q2 * b * c_A + q2 * s_A + c_A * c_A - 6 * q2 * c_L * b
                 + 2 * q2 * s_LA + 4 * c_L * c_A + (69 + 696 * q2) * q2 * q2 * q2 * b * b)
        t = np.where(delta == 0, 0.0, delta / lam_max)  # no uncertainty at all (a zero budget): exact, 0
        x = 1.0 + t
        out = np.where(x >= 0, np.abs(t) / (np.sqrt(np.abs(x)) + 1.0), 1.0)  # |sqrt(x) - 1|, no cancellation
    return np.where(np.isfinite(x), out, np.nan)


def nonlinearity_of_jacobians(camera, budget, uv, cov, J, Juv, Sp, Suv, valid):
    """:func:`nonlinearity` from an already propagated covariance: ``uv`` (..., 2) pixels, ``cov`` (..., 2, 2)
    their linear covariance, ``J``/``Juv`` the Jacobians over the 22 parameters and the pixel, ``Sp``/``Suv``
    the parameter and pixel covariances, ``valid`` the usable points (others NaN)."""
    dn, lam, d_xy, g, g_uv = ray_denominator(camera, uv)
    w_eig, V = np.linalg.eigh(np.where(valid[..., None, None], cov, np.eye(2)))
    lam_max = w_eig[..., 1]
    e = V[..., :, 1]
    r = np.einsum("...ij,...i->...j", np.nan_to_num(J), e)  # (..., 22)
    r_uv = np.einsum("...ij,...i->...j", np.nan_to_num(Juv), e)  # (..., 2)
    r_num = r.copy()
    r_num[..., P.XM:P.YM + 1] = 0.0  # the camera position moves the point additively
    Sg = g @ Sp  # Sp symmetric
    pix_g = np.einsum("...i,...ij,...j->...", r_uv, Suv, g_uv)
    pix_r = np.einsum("...i,...ij,...j->...", r_uv, Suv, r_uv)
    mu = np.einsum("...i,...i->...", r, Sg) + pix_g
    mu_num = np.einsum("...i,...i->...", r_num, Sg) + pix_g
    gamma = np.einsum("...i,...i->...", g, Sg) + np.einsum("...i,...ij,...j->...", g_uv, Suv, g_uv)
    Sr_num = r_num @ Sp
    s_num = np.einsum("...i,...i->...", r_num, Sr_num) + pix_r
    s_crs = np.einsum("...i,...i->...", r, Sr_num) + pix_r
    nl = nonlinearity_from_forms(lam_max, e, dn, lam, d_xy, mu, gamma, s_num_m2=s_num, s_cross_m2=s_crs,
                                 mu_num=mu_num)
    return np.where(valid, nl, np.nan)


def nonlinearity(camera, budget, uv_px, *, pixel_cov_px2=None) -> np.ndarray:
    """Predicted relative error of the linear 1-sigma semi-major axis, per point (closed form).

    The ground point is ``xy = C_xy + lam d_xy`` with ``lam = N / Dn``: the division by the
    ray's component along the ground normal, ``Dn``, is the model's main non-linearity
    (near the horizon ``Dn -> 0``).  Expanding ``1 / (1 + eps)``, ``eps = dDn / Dn``, to
    third order and taking the fourth moments of the jointly Gaussian errors gives the
    change ``delta`` of the variance along the linear major axis; the indicator is
    ``|sqrt(1 + delta / lam_max) - 1|`` (formula: :func:`nonlinearity_from_forms`).
    It needs, per point, only ``Dn``, ``lam``, ``d_xy``, the major axis and two quadratic
    forms of the Jacobians (``r^T Sigma g`` and ``g^T Sigma g``).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    uv_px : array_like, shape (..., 2)
    pixel_cov_px2 : array_like, shape (..., 2, 2), optional
        Extra per-point pixel covariance (as in :func:`propagate`).

    Returns
    -------
    ndarray, shape (...)
        0 where the linearisation is exact; e.g. 0.05 means the linear 1-sigma semi-major
        axis is predicted to be off by 5 % (Monte Carlo: ``linearity_ratio``).  NaN where the
        point is invalid.
    """
    est = propagate(camera, budget, uv_px, pixel_cov_px2=pixel_cov_px2)
    return est.nonlinearity


#: :func:`covariance_for_v2x` sources: the linear covariance, a sampled one, or none (encode "unavailable")
V2X_COV_LINEAR, V2X_COV_SAMPLED, V2X_COV_UNAVAILABLE = 0, 1, 2


def covariance_for_v2x(camera, budget, uv_px, *, linear_threshold: float = DEFAULT_LINEAR_THRESHOLD,
                       unavailable_above: float = 0.5, min_fraction_valid: float = 0.999, n_samples: int = 4000,
                       seed: int = 0, pixel_cov_px2=None):
    """The covariance to encode in V2X confidence fields, by the policy of docs/uncertainty-model.md.

    1. ``linear_ok``: the linear covariance;
    2. not ``linear_ok`` and ``nonlinearity <= unavailable_above``: the larger of the linear and a
       seeded Monte-Carlo covariance of that point (the one with the larger semi-major axis), so
       that the encoded confidence never promises less spread than the samples show;
    3. ``nonlinearity > unavailable_above``, fewer than ``min_fraction_valid`` of the samples
       meeting the ground, or an invalid point: NaN (encode the fields' "unavailable" values).

    Monte Carlo runs only for the points of case 2 (``n_samples`` each, ``seed``).

    Parameters
    ----------
    camera, budget, uv_px (..., 2), pixel_cov_px2 : as :func:`propagate`

    Returns
    -------
    cov_m2 : (..., 2, 2)   m^2, NaN for case 3
    source : (...) int8    :data:`V2X_COV_LINEAR`, :data:`V2X_COV_SAMPLED` or :data:`V2X_COV_UNAVAILABLE`
    estimate : GroundEstimate   the linear result with its flag
    """
    hi = check_linear_threshold(unavailable_above)
    est = propagate(camera, budget, uv_px, pixel_cov_px2=pixel_cov_px2, linear_threshold=linear_threshold)
    cov = np.array(est.cov_m2, dtype=np.float64, copy=True)
    source = np.where(est.linear_ok, V2X_COV_LINEAR, V2X_COV_UNAVAILABLE).astype(np.int8)
    mid = est.valid & ~est.linear_ok & (est.nonlinearity <= hi)
    if np.any(mid):
        uv = as_points("uv_px", uv_px, 2)
        pc = None
        if pixel_cov_px2 is not None:
            pc = np.broadcast_to(np.asarray(pixel_cov_px2, dtype=np.float64), uv.shape[:-1] + (2, 2))[mid]
        mc = monte_carlo(camera, budget, uv[mid], n_samples=n_samples, seed=seed, pixel_cov_px2=pc)
        lin = cov[mid]
        a_mc, a_lin = ellipse_axes(mc.cov_m2)[0], ellipse_axes(lin)[0]
        good = mc.fraction_valid >= min_fraction_valid
        chosen = np.where((a_mc > a_lin)[:, None, None], mc.cov_m2, lin)
        cov[mid] = np.where(good[:, None, None], chosen, np.nan)
        source[mid] = np.where(good, V2X_COV_SAMPLED, V2X_COV_UNAVAILABLE)
    cov[source == V2X_COV_UNAVAILABLE] = np.nan
    return cov, source, est
