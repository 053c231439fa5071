"""The flags of a footprint: the linearity options and the V2X policy where the centre is not ``linear_ok`` (the
sampled centre covariance, :func:`centre_covariance_sampled`; docs/uncertainty-model.md, "Policy for the V2X
fields"), shared by the numpy reference and :class:`~footprint_uq.products.frame_processor.FrameProcessor`.
Public through :mod:`footprint_uq.products.footprints`."""

from __future__ import annotations

import numpy as np

from .._checks import as_int
from ..errors import InputError
from ..fast import footprint_kernels as fk
from ..uncertainty.budget import load_budget
from ..uncertainty.propagation import (
    V2X_COV_LINEAR,
    V2X_COV_SAMPLED,
    V2X_COV_UNAVAILABLE,
    check_linear_threshold,
    sample_params,
)
from .footprint_estimate import (
    V2X_FIELDS,
    V2X_MIN_FRACTION_VALID,
    V2X_POLICIES,
    V2X_SAMPLES,
    V2X_UNAVAILABLE_ABOVE,
    FootprintEstimate,
)
from .footprint_geometry import footprint_centre
from .v2x import cpm_fields, j2735_fields


def check_flag_options(linear_threshold, v2x_policy, v2x_samples):
    """``(threshold, samples)`` of the linearity flag / V2X policy options, checked."""
    thr = check_linear_threshold(linear_threshold)
    if v2x_policy not in V2X_POLICIES:
        raise InputError("v2x_policy", v2x_policy, f"one of {V2X_POLICIES}")
    return thr, as_int("v2x_samples", v2x_samples, minimum=100, expected="an integer >= 100")


def centre_covariance_sampled(camera, budget, corners_px, *, pixel_cov_px2=None, n_samples: int = V2X_SAMPLES,
                              seed: int = 0, max_points: int = 1 << 20):
    """Seeded Monte-Carlo covariance of footprint centres on the full (non-linear) camera model.

    Each sample draws one set of camera-level errors (shared by the corners) and the pixel noise of
    every corner (budget + detector, correlated between corners if the detector covariance is),
    back-projects the K corners and takes the centre as the reference does (:func:`footprint_centre`:
    the vertex mean; samples whose polygon has zero area are left out).  **Common random numbers**: every
    object uses the same standard-normal draws (from ``seed``), so an object's result does not depend on which other
    objects are processed with it (frame, batch chunk, thread).  Vectorised over samples and objects
    (at most ``max_points`` back-projections at a time).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    corners_px : (n, K, 2) corner pixels of n objects
    pixel_cov_px2 : (n, 2K, 2K), optional
        Detector pixel covariance (added to the budget's imaging and resolution noise).
    n_samples, seed : int

    Returns
    -------
    cov_m2 : (n, 2, 2)          sample covariance of the centre over the samples where every corner
                                meets the ground and the centre exists (m^2; NaN with fewer than 2)
    fraction_valid : (n,)       share of such samples
    """
    budget = load_budget(budget)
    uv = np.asarray(corners_px, dtype=np.float64)
    n, K = uv.shape[:2]
    rng = np.random.default_rng(seed)
    dp = sample_params(budget, n_samples, rng)  # (S, 22), shared by all objects
    z = rng.standard_normal((n_samples, 2 * K))
    Spx = np.kron(np.eye(K), budget.pixel_covariance())
    Spx = np.broadcast_to(Spx, (n, 2 * K, 2 * K)) if pixel_cov_px2 is None else Spx + pixel_cov_px2
    w, V = np.linalg.eigh(Spx)
    A = V * np.sqrt(np.clip(w, 0.0, None))[:, None, :]  # (n, 2K, 2K): Spx = A A^T
    ref = camera.backproject(uv).xy_world_m
    ref = np.where(np.isfinite(ref), ref, 0.0).mean(1)  # deviations from a nearby point: no cancellation
    cov = np.full((n, 2, 2), np.nan)
    frac = np.zeros(n)
    step = max(1, max_points // (n_samples * K))
    params = camera.params + dp[:, None, None, :]
    for a in range(0, n, step):
        b = min(n, a + step)
        noise = np.einsum("rij,sj->sri", A[a:b], z).reshape(n_samples, b - a, K, 2)
        bp = camera.backproject_with(params, uv[None, a:b] + noise)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            C = footprint_centre(np.where(bp.valid[..., None], bp.xy_world_m, 0.0))[0] - ref[a:b]  # (S, r, 2)
        good = bp.valid.all(-1) & np.isfinite(C).all(-1)
        cnt = good.sum(0)
        C = np.where(good[..., None], C, 0.0)
        mean = C.sum(0) / np.maximum(cnt, 1)[:, None]
        d = np.where(good[..., None], C - mean, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            cov[a:b] = np.einsum("sri,srj->rij", d, d) / (cnt - 1)[:, None, None]
        cov[a:b][cnt < 2] = np.nan
        frac[a:b] = cnt / n_samples
    return cov, frac


_NO_NL = np.zeros(0)


def apply_v2x_policy(est: FootprintEstimate, camera, budget, policy: str, n_samples: int, seed: int, *,
                      corners_of, det_of) -> FootprintEstimate:
    """V2X fields where the centre is not ``linear_ok`` (in place; docs/uncertainty-model.md, "Policy for the V2X
    fields"), shared by the numpy reference and :class:`FrameProcessor`.

    ``corners_of(rows)`` gives the corner pixels (r, K, 2) and ``det_of(rows)`` the detector covariance
    (r, 2K, 2K) or None of the flagged rows: only those are sampled (:func:`centre_covariance_sampled`).
    """
    src = np.empty(len(est), dtype=np.int8)
    nl = est.centre_nonlinearity
    n_flagged = fk.v2x_source_and_flagged(est.centre_valid, _NO_NL if nl is None else nl, est.linear_threshold,
                                          V2X_COV_LINEAR, V2X_COV_UNAVAILABLE, src)
    est.v2x_source = src
    if n_flagged == 0 or policy == "linear":  # (almost every frame)
        return est
    rows = np.flatnonzero(est.centre_valid & ~est.centre_linear_ok)
    nl = est.centre_nonlinearity[rows]
    cov = np.full((rows.size, 2, 2), np.nan)
    src_r = np.full(rows.size, V2X_COV_UNAVAILABLE, dtype=np.int8)
    mid = nl <= V2X_UNAVAILABLE_ABOVE
    if policy == "sampled" and mid.any():
        r = rows[mid]
        mc, frac = centre_covariance_sampled(camera, budget, corners_of(r), pixel_cov_px2=det_of(r),
                                             n_samples=n_samples, seed=seed)
        lin = est.centre_cov_m2[r]
        a_mc, a_lin = _semi_major(mc), _semi_major(lin)
        chosen = np.where((a_mc > a_lin)[:, None, None], mc, lin)
        good = frac >= V2X_MIN_FRACTION_VALID
        cov[mid] = np.where(good[:, None, None], chosen, np.nan)
        src_r[mid] = np.where(good, V2X_COV_SAMPLED, V2X_COV_UNAVAILABLE)
    src[rows] = src_r
    est.v2x_cov_m2 = np.array(est.centre_cov_m2)
    est.v2x_cov_m2[rows] = cov
    fields = {**cpm_fields(cov, est.heading_offset_deg), **j2735_fields(cov, est.heading_offset_deg)}
    est.v2x_codes[rows] = np.stack([fields[name] for name in V2X_FIELDS], -1).astype(np.int32)
    return est


def _semi_major(cov):
    a, b, d = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    with np.errstate(invalid="ignore"):
        return np.sqrt(0.5 * (a + d) + np.hypot(0.5 * (a - d), b))
