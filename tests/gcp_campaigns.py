"""Seeded synthetic ground-control-point campaigns (shared by tests/test_calibration_gcp.py and the docs figures).

One campaign: a random roadside camera (f 1000-2200 px, 5-15 m high, tilted 8-35 deg down,
any heading, roll within +-3 deg), 6-20 points on uneven ground (z ~ N(0, 0.3 m)) within 8-80 m,
click noise sigma_px ~ U(0.5, 2) px and survey noise sigma_m ~ U(0.02, 0.1) m per axis.
``python tests/gcp_campaigns.py N`` prints the coverage figures of docs/calibration.md.
"""

from __future__ import annotations

import sys

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
