"""Synthetic labelled campaigns drawn from a known budget (the truth of the fit's recovery tests).

Each camera is one calibration group: its parameter error is drawn once from the budget and shared
by all its objects; every object adds its own pixel noise.  The residuals follow exactly the model
of :func:`footprint_uq.validation.fit.fit_budget` to first order -- the test of the fit, not of the
camera model.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ..cameras.pantilt import PanTiltCamera
from ..uncertainty.budget import load_budget

__all__ = ["SyntheticCampaign", "synthetic_campaign", "synthetic_campaign_chunks", "campaign_cameras"]


class SyntheticCampaign(NamedTuple):
    """``residual_m (N, 2)``, ``dxy_dp (N, 2, 22)``, ``cov_object_m2 (N, 2, 2)``, ``group (N,)`` and the
    calibration error drawn for each group ``param_error (G, 22)``."""

    residual_m: np.ndarray
    dxy_dp: np.ndarray
    cov_object_m2: np.ndarray
    group: np.ndarray
    param_error: np.ndarray


def campaign_cameras(n_cameras: int, rng) -> list[PanTiltCamera]:
    """Roadside cameras of varied mounting: 6-14 m high, 8-25 deg tilt, any pan, 1400-2800 px focal."""
    return [PanTiltCamera(float(rng.uniform(1400, 2800)), (1920, 1080), float(rng.uniform(6, 14)),
                          float(rng.uniform(-180, 180)), float(rng.uniform(8, 25)), float(rng.normal(0, 1)),
                          (float(rng.normal(0, 50)), float(rng.normal(0, 50))))
            for _ in range(n_cameras)]


def synthetic_campaign(budget, n_cameras: int, n_objects: int, *, pixel_sigma_px: float = 2.0,
                       object_sigma_m: float = 0.0, bias_m=(0.0, 0.0), seed: int = 0) -> SyntheticCampaign:
    """Residuals of ``n_objects`` per camera, the calibration error drawn once per camera.

    Parameters
    ----------
    budget : budget spec
        The truth: its ``param_covariance()`` is the distribution of each camera's error.
    n_cameras, n_objects : int
    pixel_sigma_px : float
        Per-object pixel noise (isotropic), part of ``cov_object_m2``.
    object_sigma_m : float
        An extra per-object ground noise (metres) that is *not* in ``cov_object_m2`` (for ``object_m``).
    bias_m : (2,)
        A common offset of every residual.
    seed : int
    """
    out = list(synthetic_campaign_chunks(budget, n_cameras, n_objects, pixel_sigma_px=pixel_sigma_px,
                                         object_sigma_m=object_sigma_m, bias_m=bias_m, seed=seed))
    r, J, R, grp = (np.concatenate([o[i] for o in out]) for i in range(4))
    return SyntheticCampaign(r, J, R, grp, np.stack([o[4] for o in out]))


def synthetic_campaign_chunks(budget, n_cameras: int, n_objects: int, *, pixel_sigma_px: float = 2.0,
                              object_sigma_m: float = 0.0, bias_m=(0.0, 0.0), seed: int = 0,
                              batch: int | None = None):
    """The campaign of :func:`synthetic_campaign` (same draws), one camera at a time: yields
    ``(residual_m, dxy_dp, cov_object_m2, group, param_error)`` per camera (memory: one camera).

    ``batch``: at most this many objects per chunk (the camera's calibration error still drawn once):
    memory bounded whatever ``n_objects``; the same distribution, not the same draws as without it."""
    rng = np.random.default_rng(seed)
    S = load_budget(budget).param_covariance()
    vals, vecs = np.linalg.eigh(S)
    Lf = vecs * np.sqrt(np.clip(vals, 0, None))
    for g, cam in enumerate(campaign_cameras(n_cameras, rng)):
        e = None
        for start in range(0, n_objects, batch or max(n_objects, 1)):
            n = min(n_objects - start, batch or n_objects)
            hz = float(np.nanmax(cam.horizon_v_px(np.array([0.0, 1919.0]))))
            uv = np.column_stack([rng.uniform(0, 1919, 4 * n), rng.uniform(max(hz + 60, 0), 1079, 4 * n)])
            bp = cam.backproject(uv, get_gradients=True)
            keep = np.flatnonzero(bp.valid & (np.hypot(*(bp.xy_world_m - cam.params[13:15]).T) < 150))[:n]
            J, Juv = bp.dxy_dp[keep], bp.dxy_duv[keep]
            R = pixel_sigma_px**2 * Juv @ np.swapaxes(Juv, 1, 2)
            e = Lf @ rng.standard_normal(S.shape[0]) if e is None else e
            noise = np.einsum("nab,nb->na", Juv, rng.normal(0, pixel_sigma_px, (keep.size, 2)))
            r = J @ e + noise + rng.normal(0, object_sigma_m, (keep.size, 2)) + np.asarray(bias_m, float)
            yield r, J, R, np.full(keep.size, g), e
