"""Per-pixel support of a camera solved from ground control points (``calibrate gcp``).

A GCP solve's covariance is first order about the control points: between them it holds, far
outside them it is an extrapolation.  For any pixel this module says how far the control points
support it:

* ``gcp_inside_hull`` -- inside the convex hull of the control points' pixels;
* ``gcp_leverage_ratio`` -- the solve's own pixel variance at the pixel's ground point
  (largest eigenvalue of ``J C J^T``, ``J = d uv / d params`` there, ``C`` the solve's parameter
  covariance) over its largest value at a control point: <= 1 within the support, growing with
  the extrapolation;
* ``gcp_supported`` -- either.

``summary.json`` of ``calibrate gcp`` holds what it needs (``support``: the hull, the largest leverage;
``solve_id``); ``footprint-uq locate --gcp-summary`` adds the three keys to every record and refuses a
summary of another solve than the budget's (``gcp-<solve_id>``).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .._files import read_input_text
from ..cameras import general
from ..errors import InputError
from ..io.atomic import atomic_path

__all__ = ["SUPPORT_KEYS", "leverage_px2", "inside_convex", "support_of", "load_gcp_support", "add_support",
           "save_support_map"]

#: keys added to `locate` records
SUPPORT_KEYS = ("gcp_inside_hull", "gcp_leverage_ratio", "gcp_supported")


def leverage_px2(params, cov_params, xyz_world_m) -> np.ndarray:
    """Largest eigenvalue (px^2) of the solve's pixel covariance ``J C J^T`` at world points ``(..., 3)``
    (inf where the point does not project)."""
    pr = general.project(params, np.asarray(xyz_world_m, dtype=np.float64), get_gradients=True)
    J = pr.duv_dp
    M = J @ np.asarray(cov_params) @ np.swapaxes(J, -1, -2)
    a, b, c = M[..., 0, 0], M[..., 0, 1], M[..., 1, 1]
    return np.where(pr.valid, 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b * b), np.inf)


def inside_convex(hull, uv) -> np.ndarray:
    """Pixels ``(..., 2)`` inside (or on) the convex polygon ``hull`` (M, 2), either orientation."""
    hull, uv = np.asarray(hull, dtype=np.float64).reshape(-1, 2), np.asarray(uv, dtype=np.float64)
    if len(hull) < 3:
        return np.zeros(uv.shape[:-1], bool)
    e = np.roll(hull, -1, 0) - hull
    cross = e[:, 0] * (uv[..., None, 1] - hull[:, 1]) - e[:, 1] * (uv[..., None, 0] - hull[:, 0])  # (..., M)
    return np.all(cross >= 0, -1) | np.all(cross <= 0, -1)


def support_of(params, cov_params, support: dict, uv_px) -> dict:
    """Support of pixels ``(..., 2)`` (module doc): ``inside_hull``, ``leverage_ratio``, ``supported``.

    ``support`` is ``{"hull_uv_px": (M, 2), "leverage_max_px2": float}`` (summary.json's ``support``).
    """
    uv = np.asarray(uv_px, dtype=np.float64)
    inside = inside_convex(support["hull_uv_px"], uv)
    bp = general.backproject(params, uv)
    xyz = np.concatenate([bp.xy_world_m, np.zeros(uv.shape[:-1] + (1,))], -1)
    lev = np.where(bp.valid, leverage_px2(params, cov_params, xyz), np.inf)
    ratio = lev / float(support["leverage_max_px2"])
    return {"inside_hull": inside, "leverage_ratio": ratio, "supported": inside | (ratio <= 1.0)}


def load_gcp_support(path, budget=None) -> dict:
    """summary.json of ``calibrate gcp`` -> its ``support`` block; refuses a summary of another solve than
    ``budget``'s (a budget named ``gcp-<id>`` must have the summary's ``solve_id``)."""
    p = Path(path)
    try:
        data = json.loads(read_input_text(p, "--gcp-summary"))
        sup = data["support"]
        hull = np.asarray(sup["hull_uv_px"], dtype=np.float64).reshape(-1, 2)
        lev = float(sup["leverage_max_px2"])
        sid = str(data["solve_id"])
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as e:
        raise InputError("--gcp-summary", str(p), f"summary.json of `calibrate gcp` ({type(e).__name__})") from None
    if not (np.isfinite(hull).all() and np.isfinite(lev) and lev > 0):
        raise InputError("--gcp-summary", str(p), "a finite support block (hull_uv_px, leverage_max_px2 > 0)")
    name = getattr(budget, "name", "") or ""
    if budget is not None and name != f"gcp-{sid}":
        raise InputError("--gcp-summary", f"solve {sid}", f"the summary of the budget's own solve ({name or 'none'})")
    return {"hull_uv_px": hull, "leverage_max_px2": lev}


def add_support(records: list[dict], camera, budget, support: dict) -> list[dict]:
    """Add :data:`SUPPORT_KEYS` to `locate` records (in place; returned)."""
    uv = np.array([[r["u_px"], r["v_px"]] for r in records], dtype=np.float64).reshape(-1, 2)
    s = support_of(camera.params, budget.param_covariance(), support, uv)
    for r, a, b, c in zip(records, s["inside_hull"], s["leverage_ratio"], s["supported"], strict=True):
        r.update({"gcp_inside_hull": bool(a), "gcp_leverage_ratio": float(b) if np.isfinite(b) else None,
                  "gcp_supported": bool(c)})
    return records


def save_support_map(path, camera, budget, support: dict, uv_px, *, chunk: int = 65536) -> Path:
    """The support of a map's pixels ``uv_px (H, W, 2)`` as ``.npz`` (``u_px``, ``v_px``, ``inside_hull``,
    ``leverage_ratio``, ``supported``; ``(H, W)`` each), written atomically; in chunks of ``chunk`` pixels."""
    uv = np.asarray(uv_px, dtype=np.float64)
    flat = uv.reshape(-1, 2)
    C = budget.param_covariance()
    parts = [support_of(camera.params, C, support, flat[i:i + chunk]) for i in range(0, len(flat), chunk)]
    out = {k: np.concatenate([q[k] for q in parts]).reshape(uv.shape[:-1]) for k in parts[0]}
    p = Path(path)
    with atomic_path(p) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, u_px=uv[..., 0], v_px=uv[..., 1], **out)
    return p
