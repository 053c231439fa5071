"""Benchmark section "uncertainties": the full-HD pan-tilt covariance map, ours vs the ``uncertainties`` package.

Four implementations of the same per-pixel 2x2 covariance, timed in one run on the same machine:

* **ours** -- :func:`footprint_uq.products.covariance.covariance_map` (fused numba kernel) on the full
  1920x1080 grid, into preallocated output;
* **numpy** -- :func:`footprint_uq.uncertainty.propagation.propagate` (naive vectorised numpy, full Jacobians),
  on the full grid (``--quick``: every 4th pixel; its rate is per pixel either way);
* **uncertainties** -- the `uncertainties <https://pypi.org/project/uncertainties/>`_ package
  (automatic first-order propagation): the camera parameters are ``ufloat``\\ s drawn with the
  budget's covariance (:func:`uncertainties.correlated_values`, so one focal error moves fx and fy
  together), each pixel gets its own imaging and resolution ``ufloat``\\ s, the ground point is
  built through the paper's closed form (the math of :func:`footprint_uq.cameras.pantilt.paper_xy`,
  with the first-order undistortion at zero nominal distortion, the roll and the perturbed ground
  plane written out) and its covariance read with :func:`uncertainties.covariance_matrix`.  It is
  far too slow for a full-HD map, so it runs on a seeded subset of pixels below the horizon and its
  time is **extrapolated** to 1920x1080 pixels (labelled as such);
* **copy** -- ``np.copyto`` of the same number of bytes as the map's output (memory roofline).

The ``uncertainties`` covariance is also compared with ours on the subset (worst relative
difference, Frobenius norm): the two must agree to rounding.
"""

from __future__ import annotations

import time

import numpy as np
import uncertainties
from bench_maps import H, W, cameras
from bench_maps import _alloc as alloc_map_output
from uncertainties import umath

from footprint_uq import params as P
from footprint_uq import propagate
from footprint_uq.cameras.pantilt import paper_xy
from footprint_uq.products.covariance import covariance_map

#: the bench_maps budget (every term of the kernel runs)
BUDGET_CHANGES = dict(roll_deg=0.05, ground_height_m=0.05, ground_slope_deg=0.5)


def budget():
    from footprint_uq import ErrorBudget

    return ErrorBudget.preset("basler1").replace(**BUDGET_CHANGES)


def _paper_xy_u(f, c, r, h, alpha, theta):
    """The paper's (X, Y) (frame G) -- the formula of :func:`paper_xy` -- for ufloat arguments."""
    st, ct, sa, ca = umath.sin(theta), umath.cos(theta), umath.sin(alpha), umath.cos(alpha)
    s = st * f + ct * r
    X = h * (ct * ca * f - sa * c - st * ca * r) / s
    Y = h * (ct * sa * f + ca * c - st * sa * r) / s
    return X, Y


def uncertainties_covariance(cam, bud, uv_px: np.ndarray):
    """Ground points ``(N, 2)`` and covariances ``(N, 2, 2)`` by the ``uncertainties`` package.

    ``cam`` is a :class:`~footprint_uq.PanTiltCamera` (zero nominal distortion and ground
    perturbations), ``uv_px`` pixels ``(N, 2)`` below the horizon.  A Python loop over the points
    (the package works on scalars): this is the reference being benchmarked, not our method.
    """
    Sp = bud.param_covariance()
    used = np.flatnonzero(np.any(Sp != 0, axis=0))
    vals = uncertainties.correlated_values(cam.params[used], Sp[np.ix_(used, used)])
    p = {int(i): v for i, v in zip(used, vals, strict=True)}
    p.update({i: float(cam.params[i]) for i in range(P.N_PARAMS) if i not in p})
    fx, fy, cx, cy, sk = (p[i] for i in (P.FX, P.FY, P.CX, P.CY, P.SKEW))
    k1, k2, p1, p2, k3 = (p[i] for i in (P.K1, P.K2, P.P1, P.P2, P.K3))
    x0, y0, h = p[P.XM], p[P.YM], p[P.HM]
    alpha, theta, phi = p[P.PAN], p[P.TILT], p[P.ROLL]
    gdz, gx, gy = p[P.GDZ], p[P.GSX], p[P.GSY]
    cphi, sphi = umath.cos(phi), umath.sin(phi)
    s_img, s_res = np.asarray(bud.imaging_px, float), np.asarray(bud.resolution_px, float)
    xy = np.empty((len(uv_px), 2))
    cov = np.empty((len(uv_px), 2, 2))
    for n, (u0, v0) in enumerate(np.asarray(uv_px, dtype=np.float64)):
        # per-point pixel errors: independent imaging and resolution noise on each axis
        u = u0 + uncertainties.ufloat(0.0, s_img[0]) + uncertainties.ufloat(0.0, s_res[0])
        v = v0 + uncertainties.ufloat(0.0, s_img[1]) + uncertainties.ufloat(0.0, s_res[1])
        # pixel -> distorted normalised coordinates
        yd = (v - cy) / fy
        xd = (u - cx - sk * yd) / fx
        # undistortion, first order about zero nominal distortion (exact derivative there)
        r2 = xd * xd + yd * yd
        rad = k1 * r2 + k2 * r2 * r2 + k3 * r2 * r2 * r2
        xn = xd - (xd * rad + 2 * p1 * xd * yd + p2 * (r2 + 2 * xd * xd))
        yn = yd - (yd * rad + p1 * (r2 + 2 * yd * yd) + 2 * p2 * xd * yd)
        # the paper's pixel variables, rolled about the boresight
        c, r = fx * xn, fx * yn
        c1 = cphi * c - sphi * r
        r1 = sphi * c + cphi * r
        X, Y = _paper_xy_u(fx, c1, r1, h, alpha, theta)
        # ground plane z = dz + gx * ox + gy * oy (pivoting about the camera foot): scale the offset
        scale = (h - gdz) / (h + gx * Y + gy * X)
        x, y = x0 + scale * Y, y0 + scale * X
        xy[n] = x.nominal_value, y.nominal_value
        cov[n] = uncertainties.covariance_matrix([x, y])
    return xy, cov


def _subset(cam, n: int, seed: int = 0) -> np.ndarray:
    """n seeded pixels of the full-HD grid below the horizon (integer pixel centres)."""
    grid = cam.pixel_grid(1).reshape(-1, 2)
    ok = np.flatnonzero(cam.backproject(grid).valid)
    rng = np.random.default_rng(seed)
    return grid[np.sort(rng.choice(ok, size=n, replace=False))]


def run(quick: bool = False) -> list[dict]:
    runs = 5 if quick else 11
    n_u = 40 if quick else 500  # about 25 ms per pixel
    pt, _ = cameras()
    bud = budget()
    out, src, dst, nbytes = alloc_map_output()
    n_px = W * H

    # ours and the copy of the same bytes, alternating
    covariance_map(pt, bud, out=out)  # warm-up (JIT / cache load)
    t_ours, t_copy = [], []
    for _ in range(runs):
        t0 = time.perf_counter()
        covariance_map(pt, bud, out=out)
        t1 = time.perf_counter()
        np.copyto(dst, src)
        t_copy.append(time.perf_counter() - t1)
        t_ours.append(t1 - t0)
    ours, copy = float(np.median(t_ours)), float(np.median(t_copy))

    # naive numpy
    step = 4 if quick else 1
    grid = pt.pixel_grid(step)
    n_np = grid.shape[0] * grid.shape[1]
    t_np = []
    for _ in range(2 if quick else 3):
        t0 = time.perf_counter()
        propagate(pt, bud, grid)
        t_np.append(time.perf_counter() - t0)
    numpy_full = float(np.median(t_np)) / n_np * n_px

    # the uncertainties package on a subset, extrapolated
    uv = _subset(pt, n_u)
    uncertainties_covariance(pt, bud, uv[:5])  # warm-up
    t_u = []
    for _ in range(1 if quick else 3):
        t0 = time.perf_counter()
        xy_u, cov_u = uncertainties_covariance(pt, bud, uv)
        t_u.append(time.perf_counter() - t0)
    unc_full = float(np.median(t_u)) / n_u * n_px
    iu, iv = uv[:, 0].astype(int), uv[:, 1].astype(int)
    cov_ours = out[1][iv, iu]
    rel = np.linalg.norm(cov_u - cov_ours, axis=(1, 2)) / np.linalg.norm(cov_ours, axis=(1, 2))
    worst_rel = float(np.max(rel))
    xy_err = float(np.max(np.abs(out[0][iv, iu] - xy_u)))
    # the closed form used with ufloats, at roll 0, against paper_xy itself (frame G -> W: x = x0 + Y, y = y0 + X)
    fx = pt.params[P.FX]
    Xp, Yp, _ = paper_xy(fx, uv[:, 0] - pt.params[P.CX], uv[:, 1] - pt.params[P.CY], pt.params[P.HM],
                         pt.params[P.PAN], pt.params[P.TILT])
    k = np.flatnonzero(np.isfinite(Xp))[:20]
    XYu = np.array([_paper_xy_u(fx, uv[i, 0] - pt.params[P.CX], uv[i, 1] - pt.params[P.CY], pt.params[P.HM],
                                pt.params[P.PAN], pt.params[P.TILT]) for i in k])
    paper_xy_err = float(np.max(np.abs(XYu - np.stack([Xp[k], Yp[k]], 1))))
    print(f"  ours {ours * 1e3:.2f} ms, copy {copy * 1e3:.2f} ms, numpy {numpy_full * 1e3:.0f} ms (full HD), "
          f"uncertainties {unc_full:.0f} s (extrapolated from {n_u} px); cov rel. diff {worst_rel:.1e}", flush=True)

    label = f"pan-tilt, all sources, {W}x{H}"
    common = {"pixels": n_px, "reference": "ours (kernels.covariance_map)"}
    rows = [
        {**common, "case": f"ours: kernels.covariance_map, {label}", "median_ms": ours * 1e3, "runs": runs,
         "mpx_per_s": n_px / ours / 1e6, "time_vs_ours": 1.0, "extrapolated": False},
        {**common, "case": "memory roofline: np.copyto of the same bytes", "median_ms": copy * 1e3, "runs": runs,
         "copy_bytes": nbytes, "time_vs_ours": copy / ours, "extrapolated": False,
         "notes": f"{nbytes / 1e6:.1f} MB (xy + cov float64 + valid): ours takes {ours / copy:.2f}x the copy"},
        {**common, "case": "naive numpy: propagation.propagate", "median_ms": numpy_full * 1e3,
         "runs": len(t_np), "mpx_per_s": n_px / numpy_full / 1e6, "time_vs_ours": numpy_full / ours,
         "measured_pixels": n_np, "extrapolated": step != 1,
         "notes": ("full grid" if step == 1 else f"measured on every {step}th pixel ({n_np:,} px), scaled to full HD")},
        {**common, "case": f"uncertainties package, EXTRAPOLATED from {n_u:,} px", "median_ms": unc_full * 1e3,
         "runs": len(t_u), "mpx_per_s": n_px / unc_full / 1e6, "time_vs_ours": unc_full / ours,
         "measured_pixels": n_u, "measured_s": float(np.median(t_u)), "extrapolated": True,
         "cov_max_rel_diff_vs_ours": worst_rel, "xy_max_abs_diff_m": xy_err,
         "paper_xy_max_abs_diff_m": paper_xy_err,
         "notes": (f"{float(np.median(t_u)) / n_u * 1e3:.2f} ms per pixel measured on {n_u:,} seeded pixels below "
                   f"the horizon, x {n_px:,} px; its covariance equals ours there to {worst_rel:.1e} "
                   f"(worst relative difference, Frobenius), ground points to {xy_err:.1e} m; its closed form "
                   f"equals paper_xy to {paper_xy_err:.1e} m")},
    ]
    return rows


if __name__ == "__main__":
    for row in run(quick=True):
        print(row)
