"""Multi-camera fusion of footprint-centre estimates, with a consistency check.

Where two or more cameras see the same object (the paper's motivation: a
receiving vehicle needs a measure of trust when fields of view overlap), their
estimates are fused by covariance weighting in information form::

    P = (sum_i C_i^-1)^-1,     x = P sum_i C_i^-1 x_i

Association
-----------
By object id only: every input row is one camera's estimate of one object, and
rows with equal ``object_id`` are the same object (a tracker or a shared
global id upstream is assumed).  The cameras' errors are assumed independent --
true for separately calibrated cameras, *not* for two estimates from the same
camera and frame (they share the calibration error); with ``camera_id`` given,
such duplicates are rejected.  Rows whose estimate is not finite (an object
whose centre could not be computed) are kept in the output, marked unused with
the reason, and do not enter the fusion.

Consistency check (Mahalanobis, chi-square)
-------------------------------------------
For each used source, against the fused mean: the residual ``r_i = x_i - x``
has covariance ``C_i - P`` (``Cov(x_i, x) = P`` for independent sources), so
``d_i^2 = r_i^T (C_i - P)^-1 r_i`` is chi-square with 2 degrees of freedom when the
stated covariances are right.  A source with ``d_i^2 > chi2_2(confidence)``
(default 0.99: 9.21) is flagged ``inconsistent``.  For two sources ``d_1^2 = d_2^2 =
(x_1 - x_2)^T (C_1 + C_2)^-1 (x_1 - x_2)``, the pairwise test.  Per object,
``chi2 = sum_i r_i^T C_i^-1 r_i`` is chi-square with ``2 (n - 1)`` degrees of
freedom; ``consistent`` is False when it exceeds its quantile at ``confidence``
or any source is flagged.  Flagged estimates are still fused (nothing is
silently dropped); :func:`pairwise_mahalanobis` gives the full pairwise table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.special import chdtri

from .._checks import as_float, as_points
from ..errors import InputError

__all__ = ["FusionResult", "fuse_by_id", "pairwise_mahalanobis", "chi2_threshold"]


def chi2_threshold(confidence: float, dof: int) -> float:
    """Quantile of the chi-square distribution with ``dof`` degrees of freedom."""
    p = as_float("confidence", confidence)
    if not 0.0 < p < 1.0:
        raise InputError("confidence", confidence, "a probability in (0, 1), e.g. 0.99")
    if dof == 2:
        return float(-2.0 * np.log1p(-p))

    return float(chdtri(dof, 1.0 - p))  # the chi-square quantile


def _inv2(c):
    a, b, cc, d = c[..., 0, 0], c[..., 0, 1], c[..., 1, 0], c[..., 1, 1]
    det = a * d - b * cc
    out = np.stack([np.stack([d, -b], -1), np.stack([-cc, a], -1)], -2) / det[..., None, None]
    return out, det


@dataclass
class FusionResult:
    """Fused objects (M of them) and per-source diagnostics (R input rows).

    Attributes
    ----------
    object_id : (M,)              unique ids, sorted
    xy_world_m : (M, 2)           fused centre (NaN if no usable source)
    cov_m2 : (M, 2, 2)            fused covariance
    n_sources : (M,) int          usable sources fused
    chi2 : (M,)                   sum_i r_i^T C_i^-1 r_i (NaN for fewer than 2 sources)
    chi2_threshold : (M,)         its quantile at ``confidence`` (2 (n - 1) dof)
    consistent : (M,) bool        no flagged source and chi2 below its threshold (True if < 2 sources)
    source_object_index : (R,)    row -> index into the fused arrays
    source_used : (R,) bool       row entered the fusion
    source_reason : (R,) object   "ok" or why not used
    source_d2 : (R,)              d_i^2 of the row against the fused mean (NaN if unused or alone)
    source_inconsistent : (R,) bool
    confidence : float
    """

    object_id: np.ndarray
    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    n_sources: np.ndarray
    chi2: np.ndarray
    chi2_threshold: np.ndarray
    consistent: np.ndarray
    source_object_index: np.ndarray
    source_used: np.ndarray
    source_reason: np.ndarray
    source_d2: np.ndarray
    source_inconsistent: np.ndarray
    confidence: float


def fuse_by_id(object_id, xy_world_m, cov_m2, *, camera_id=None, confidence: float = 0.99) -> FusionResult:
    """Fuse per-camera centre estimates of the same objects (see the module doc).

    Parameters
    ----------
    object_id : array_like (R,)
        Object id of each row (any hashable numpy dtype: ints or strings).
    xy_world_m : array_like (R, 2)
        Centre estimates in the shared world frame, metres.
    cov_m2 : array_like (R, 2, 2)
        Their covariances (positive definite where finite).
    camera_id : array_like (R,), optional
        Source camera of each row; two rows of one camera for one object raise InputError.
    confidence : float
        Level of the chi-square tests (default 0.99).
    """
    ids = np.asarray(object_id)
    xy = as_points("xy_world_m", xy_world_m, 2)
    C = np.asarray(cov_m2, dtype=np.float64)
    R = ids.shape[0] if ids.ndim == 1 else -1
    if ids.ndim != 1 or xy.shape != (R, 2) or C.shape != (R, 2, 2):
        raise InputError("object_id, xy_world_m, cov_m2", (ids.shape, xy.shape, C.shape),
                         "shapes (R,), (R, 2), (R, 2, 2) with the same R")
    thr2 = chi2_threshold(confidence, 2)
    uniq, inv = np.unique(ids, return_inverse=True)
    inv = inv.reshape(-1)
    M = uniq.shape[0]
    if camera_id is not None:
        cams = np.asarray(camera_id)
        if cams.shape != (R,):
            raise InputError("camera_id", cams.shape, f"shape ({R},)")
        pairs = np.stack([inv, np.unique(cams, return_inverse=True)[1].reshape(-1)], -1)
        u, cnt = np.unique(pairs, axis=0, return_counts=True)
        if np.any(cnt > 1):
            o, c = u[np.argmax(cnt > 1)]
            raise InputError("camera_id", f"object {uniq[o]!r} seen twice by camera {np.unique(cams)[c]!r}",
                             "one row per camera and object (same-camera estimates share calibration errors)")
    finite = np.isfinite(xy).all(-1) & np.isfinite(C).all((-1, -2))
    Cs = np.where(finite[:, None, None], C, np.eye(2))
    Ci, det = _inv2(Cs)
    sym = np.abs(Cs[:, 0, 1] - Cs[:, 1, 0]) <= 1e-9 * np.abs(Cs).max((-1, -2))
    pd = (Cs[:, 0, 0] > 0) & (det > 0) & sym
    bad = finite & ~pd
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"cov_m2[{i}]", C[i].tolist(), "a symmetric positive definite 2x2 covariance (or NaN)")
    used = finite
    reason = np.where(used, "ok", "estimate not finite (centre not computed)").astype(object)
    w = used.astype(np.float64)
    Info = np.zeros((M, 2, 2))
    np.add.at(Info, inv, Ci * w[:, None, None])
    eta = np.zeros((M, 2))
    np.add.at(eta, inv, (Ci @ np.where(used[:, None], xy, 0.0)[..., None])[..., 0] * w[:, None])
    n = np.bincount(inv, weights=w, minlength=M).astype(np.int64)
    has = n > 0
    Info_s = np.where(has[:, None, None], Info, np.eye(2))
    P, _ = _inv2(Info_s)
    x = (P @ eta[..., None])[..., 0]
    P = np.where(has[:, None, None], P, np.nan)
    x = np.where(has[:, None], x, np.nan)
    # per-source residuals against the fused mean
    r = np.where(used[:, None], xy, np.nan) - x[inv]
    multi = n[inv] >= 2
    with np.errstate(invalid="ignore", divide="ignore"):
        Sres_inv, _ = _inv2(np.where(used[:, None, None], C, np.nan) - P[inv])
        d2 = np.einsum("ri,rij,rj->r", r, Sres_inv, r)
        q = np.einsum("ri,rij,rj->r", r, np.where(used[:, None, None], Ci, np.nan), r)
    d2 = np.where(used & multi, d2, np.nan)
    flag = used & multi & (d2 > thr2)
    chi2 = np.zeros(M)
    np.add.at(chi2, inv, np.where(used, q, 0.0))
    chi2 = np.where(n >= 2, chi2, np.nan)
    dof = 2 * np.maximum(n - 1, 1)
    thr = np.array([chi2_threshold(confidence, int(k)) for k in np.unique(dof)])
    thr_m = np.where(n >= 2, thr[np.searchsorted(np.unique(dof), dof)], np.nan)
    any_flag = np.zeros(M, dtype=bool)
    np.logical_or.at(any_flag, inv, flag)
    consistent = np.where(n >= 2, ~any_flag & (chi2 <= thr_m), True)
    return FusionResult(uniq, x, P, n, chi2, thr_m, consistent, inv, used, reason, d2, flag, float(confidence))


def pairwise_mahalanobis(xy_world_m, cov_m2):
    """Pairwise squared Mahalanobis distances ``(x_i - x_j)^T (C_i + C_j)^-1 (x_i - x_j)``.

    Parameters
    ----------
    xy_world_m : (S, 2), cov_m2 : (S, 2, 2)
        Estimates of one object from S independent sources.

    Returns
    -------
    d2 : (S, S)
        Symmetric, zero diagonal; compare with ``chi2_threshold(confidence, 2)``.
    """
    xy = as_points("xy_world_m", xy_world_m, 2)
    C = np.asarray(cov_m2, dtype=np.float64)
    if xy.ndim != 2 or C.shape != (xy.shape[0], 2, 2):
        raise InputError("xy_world_m, cov_m2", (xy.shape, C.shape), "shapes (S, 2) and (S, 2, 2)")
    d = xy[:, None, :] - xy[None, :, :]
    Sinv, _ = _inv2(C[:, None] + C[None, :])
    d2 = np.einsum("abi,abij,abj->ab", d, Sinv, d)
    np.fill_diagonal(d2, 0.0)
    return d2
