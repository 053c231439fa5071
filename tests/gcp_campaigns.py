"""Seeded synthetic ground-control-point campaigns (shared by tests/test_calibration_gcp.py and the docs figures).

One campaign: a random roadside camera (f 1000-2200 px, 5-15 m high, tilted 8-35 deg down,
any heading, roll within +-3 deg), 6-20 points on uneven ground (z ~ N(0, 0.3 m)) within 8-80 m,
click noise sigma_px ~ U(0.5, 2) px and survey noise sigma_m ~ U(0.02, 0.1) m per axis.
``python tests/gcp_campaigns.py N`` prints the coverage figures of docs/calibration.md.
"""

from __future__ import annotations

import sys
import warnings

import numpy as np
from scipy.stats import chi2

from footprint_uq import PanTiltCamera
from footprint_uq import params as P
from footprint_uq.calibration.extrinsics import Intrinsics
from footprint_uq.calibration.gcp import GCPSet, solve_gcp
from footprint_uq.cameras import general

SIZE = (1920, 1080)


def _ground_pixels(cam, rng, n):
    """n pixels whose ground point lies 8-80 m from the camera foot point."""
    out = []
    while len(out) < n:
        uv = np.column_stack([rng.uniform(60, SIZE[0] - 60, 4 * n), rng.uniform(60, SIZE[1] - 60, 4 * n)])
        bp = cam.backproject(uv)
        d = np.hypot(*(bp.xy_world_m - cam.position_world_m[:2]).T)
        ok = bp.valid & (d > 8) & (d < 80)
        out.extend(uv[ok])
    return np.array(out[:n])


def campaign(rng, *, known_intrinsics: bool):
    f = rng.uniform(1000, 2200)
    cam = PanTiltCamera(focal_px=f, image_size_px=SIZE, height_m=rng.uniform(5, 15), pan_deg=rng.uniform(-180, 180),
                        tilt_deg=rng.uniform(8, 35), roll_deg=rng.uniform(-3, 3),
                        position_m=tuple(rng.uniform(-50, 50, 2)))
    n = int(rng.integers(6, 21))
    s_px, s_m = rng.uniform(0.5, 2.0), rng.uniform(0.02, 0.1)
    uv0 = _ground_pixels(cam, rng, 3 * n)
    xyz = np.column_stack([cam.backproject(uv0).xy_world_m, rng.normal(0, 0.3, 3 * n)])
    uv_true = general.project(cam.params, xyz).uv_px
    uv_obs = uv_true + rng.normal(0, s_px, uv_true.shape)
    inside = cam.in_image(uv_obs)  # points off the image (after the height offset and noise) are not clicked
    keep = np.flatnonzero(inside)[:n]
    g = GCPSet(uv_obs[keep], xyz[keep] + rng.normal(0, s_m, (len(keep), 3)), s_px, s_m)
    intr = Intrinsics(cam.K, np.zeros(5), SIZE) if known_intrinsics else None
    return cam, g, intr, _ground_pixels(cam, rng, 3)


def coverage(n_campaigns: int, *, known_intrinsics: bool, seed: int = 0, confidence: float = 0.95):
    """Fractions of campaigns whose true pose, and of test pixels whose true ground point, lie in the region."""
    rng = np.random.default_rng(seed)
    pose_in, pix_in, n_pix = 0, 0, 0
    for _ in range(n_campaigns):
        cam, g, intr, uv_test = campaign(rng, known_intrinsics=known_intrinsics)
        # a campaign whose points the solver refuses would count as a miss: none are expected
        s = solve_gcp(g, SIZE, intrinsics=intr, leave_one_out=False)
        idx = ([P.FX] if not known_intrinsics else []) + list(range(P.XM, P.ROLL + 1))
        d = s.params[idx] - cam.params[idx]
        C = s.cov_params[np.ix_(idx, idx)]
        pose_in += d @ np.linalg.solve(C, d) <= chi2.ppf(confidence, len(idx))
        xy_hat, cov = s.ground_covariance_m2(uv_test)
        e = xy_hat - cam.backproject(uv_test).xy_world_m
        m = np.einsum("ni,ni->n", e, np.linalg.solve(cov, e[..., None])[..., 0])
        pix_in += int(np.sum(m <= chi2.ppf(confidence, 2)))
        n_pix += len(m)
    return pose_in / n_campaigns, pix_in / n_pix


if __name__ == "__main__":  # pragma: no cover - the docs figures
    import time

    n = int(sys.argv[1]) if len(sys.argv) > 1 else 1000
    for known in (True, False):
        t = time.perf_counter()
        pose, pix = coverage(n, known_intrinsics=known)
        print(f"known intrinsics={known}: {n} campaigns, pose in 95% region {pose:.4f}, "
              f"test pixels in 95% ellipse {pix:.4f} ({time.perf_counter() - t:.1f} s)")


# ------------------------------------------------------------------------------------------------------------------
# the weak-geometry regimes of issue 21 (bench/bench_gcp_regimes.py runs the full table, the tests small versions)
REGIMES = ("documented", "corner", "clustered", "lens")


def _pixels_in(params, rng, n, box):
    """n pixels inside box (u0, v0, u1, v1) whose ground point is 8-80 m from the camera's foot point."""
    out = []
    for _ in range(50):
        uv = np.column_stack([rng.uniform(box[0], box[2], 8 * n), rng.uniform(box[1], box[3], 8 * n)])
        bp = general.backproject(params, uv)
        d = np.hypot(*(bp.xy_world_m - params[[P.XM, P.YM]]).T)
        out.extend(uv[bp.valid & (d > 8) & (d < 80)])
        if len(out) >= n:
            return np.array(out[:n])
    return None


def regime_campaign(rng, regime: str):
    """One campaign of a regime: ``(true params (22,), GCPSet, intrinsics or None, test pixels (3, 2))``.

    * documented: as :func:`campaign` (known intrinsics);
    * corner: 4-5 points in one corner of the image (a box of a third of its width and height), 5 px clicks;
    * clustered: 6-8 points within +-150 px of one pixel, 5 px clicks;
    * lens: the focal length solved, the true lens mildly distorted (k1 ~ U(-0.15, 0.05)), documented otherwise.
    """
    w, h = SIZE
    while True:
        cam = PanTiltCamera(focal_px=rng.uniform(1000, 2200), image_size_px=SIZE, height_m=rng.uniform(5, 15),
                            pan_deg=rng.uniform(-180, 180), tilt_deg=rng.uniform(8, 35), roll_deg=rng.uniform(-3, 3),
                            position_m=tuple(rng.uniform(-50, 50, 2)))
        p = cam.params.copy()
        s_px, s_m = (5.0 if regime in ("corner", "clustered") else rng.uniform(0.5, 2.0)), rng.uniform(0.02, 0.1)
        if regime == "corner":
            n = int(rng.integers(4, 6))
            cu, cv = rng.integers(0, 2, 2)
            box = (cu * 2 * w / 3 + 30, cv * 2 * h / 3 + 30, cu * 2 * w / 3 + w / 3 - 30, cv * 2 * h / 3 + h / 3 - 30)
        elif regime == "clustered":
            n = int(rng.integers(6, 9))
            c = rng.uniform([200, 200], [w - 200, h - 200])
            box = (c[0] - 150, c[1] - 150, c[0] + 150, c[1] + 150)
        else:
            n = int(rng.integers(6, 21))
            box = (60, 60, w - 60, h - 60)
        if regime == "lens":
            p[P.K1] = rng.uniform(-0.15, 0.05)
        uv0 = _pixels_in(p, rng, 3 * n, box)
        uv_test = _pixels_in(p, rng, 3, (60, 60, w - 60, h - 60))
        if uv0 is None or uv_test is None:
            continue
        xyz = np.column_stack([general.backproject(p, uv0).xy_world_m, rng.normal(0, 0.3, 3 * n)])
        pr = general.project(p, xyz)
        uv_obs = pr.uv_px + rng.normal(0, s_px, pr.uv_px.shape)
        inside = pr.valid & (uv_obs[:, 0] > -0.5) & (uv_obs[:, 0] < w - 0.5) & (uv_obs[:, 1] > -0.5) \
            & (uv_obs[:, 1] < h - 0.5)
        keep = np.flatnonzero(inside)[:n]
        if len(keep) < n:
            continue
        g = GCPSet(uv_obs[keep], xyz[keep] + rng.normal(0, s_m, (n, 3)), s_px, s_m)
        intr = None if regime == "lens" else Intrinsics(cam.K, np.zeros(5), SIZE)
        return p, g, intr, uv_test


def evaluate(regime: str, n_campaigns: int, *, seed: int = 0, confidence: float = 0.95, **solve_options):
    """Per campaign of a regime: what the solve reported and whether the truth lies in its regions.

    Returns a list of dicts: ``usable``, ``flags`` (the reasons), ``refused`` (the InputError text, if the
    solve refused the points), ``pose_in`` (true pose in the ``confidence`` region of the solved parameters),
    ``pix_in`` / ``pix_supported`` (per test pixel: true ground point in the ellipse; pixel supported by the
    control points).
    """
    from footprint_uq.errors import InputError

    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n_campaigns):
        p_true, g, intr, uv_test = regime_campaign(rng, regime)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                s = solve_gcp(g, SIZE, intrinsics=intr, leave_one_out=False, **solve_options)
        except InputError as e:
            out.append({"usable": False, "flags": [], "refused": str(e), "pose_in": False,
                        "pix_in": np.zeros(3, bool), "pix_supported": np.zeros(3, bool)})
            continue
        idx = [P.IDX[n] for n in s.estimated_param_names]
        d = s.params[idx] - p_true[idx]
        C = s.cov_params[np.ix_(idx, idx)]
        pose_in = bool(d @ np.linalg.solve(C, d) <= chi2.ppf(confidence, len(idx)))
        xy_hat, cov = s.ground_covariance_m2(uv_test)
        e = xy_hat - general.backproject(p_true, uv_test).xy_world_m
        m = np.einsum("ni,ni->n", e, np.linalg.solve(cov, e[..., None])[..., 0])
        sup = s.support(uv_test)
        out.append({"usable": s.usable, "flags": list(s.flags), "refused": None, "pose_in": pose_in,
                    "pix_in": m <= chi2.ppf(confidence, 2), "pix_supported": sup["supported"]})
    return out


def table_row(recs) -> dict:
    """Coverage among usable results (and supported pixels), and how many results were flagged / refused."""
    use = [r for r in recs if r["usable"]]
    pix = np.concatenate([r["pix_in"][r["pix_supported"]] for r in use]) if use else np.zeros(0, bool)
    pix_all = np.concatenate([r["pix_in"] for r in use]) if use else np.zeros(0, bool)
    reasons = {}
    for r in recs:
        for f in ([r["refused"]] if r["refused"] else r["flags"][:1]):  # the first reason
            key = f.split(":")[0]
            reasons[key] = reasons.get(key, 0) + 1
    return {"n": len(recs), "usable": len(use), "refused": sum(r["refused"] is not None for r in recs),
            "pose_in": float(np.mean([r["pose_in"] for r in use])) if use else float("nan"),
            "pix_in_supported": float(pix.mean()) if pix.size else float("nan"), "pix_supported": int(pix.size),
            "pix_in_all": float(pix_all.mean()) if pix_all.size else float("nan"),
            "pose_in_all": float(np.mean([r["pose_in"] for r in recs if r["refused"] is None])), "reasons": reasons}
