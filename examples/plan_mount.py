"""Deployment planning: which camera, mount height and tilt keep the 95 % uncertainty within a lane?

    python examples/plan_mount.py [--out DIR]

For each error budget (the paper's Basler1, BW-Bullet1 and BW-Cube1 cameras, Tables 2-3),
mount height and tilt, a 1920x1080 camera with f = 1400 px (about 69 deg horizontal field of
view) is swept along its image centre column from the bottom row up to the horizon.  For every
ground point the 95 % ellipse (2-D, 2.4477 sigma) is computed with ``propagate``; the
criterion is that the whole ellipse fits within one lane, i.e. its semi-major axis is at most
half a lane width (3.5 m lanes: 1.75 m).  Printed per configuration: the nearest visible
ground distance, the *reach* (the farthest distance up to which the criterion holds all the
way from the bottom of the image), and the 95 % semi-major axis at 30 m and 60 m.
Saves ``plan_mount.png`` (reach against height) and ``plan_mount.csv``.
"""

from __future__ import annotations

import csv

import numpy as np
from _common import output_dir

from footprint_uq import ErrorBudget, PanTiltCamera, ellipse_axes, linearity_ratio, propagate

out = output_dir(__doc__.splitlines()[0], "plan_mount")

LANE_WIDTH_M = 3.5
LIMIT_M = LANE_WIDTH_M / 2  # 95 % semi-major axis
# the paper's presets print pan/tilt sigmas in 1e-3 deg (0.00015 deg): angles then hardly matter.  A mount that
# sways or a pose known to 0.2 deg is a different camera ("+0.2deg").  The height error dominates these budgets
# (d(x, y)/dh = (x, y)/h): "h2cm" is basler1 with the mount height surveyed to 2 cm.
_b1 = ErrorBudget.preset("basler1")
BUDGETS = {"basler1": _b1, "bw-cube1": ErrorBudget.preset("bw-cube1"),
           "basler1+0.2deg": _b1.replace(pan_deg=0.2, tilt_deg=0.2, roll_deg=0.2, name="basler1+0.2deg"),
           "basler1,h2cm": _b1.replace(height_m=0.02, name="basler1,h2cm")}
HEIGHTS_M = (6.0, 8.0, 10.0, 12.0, 15.0)
TILTS_DEG = (10.0, 20.0, 30.0)
IMAGE = (1920, 1080)
FOCAL_PX = 1400.0
v_px = np.arange(IMAGE[1] - 0.5, -0.5, -1.0)  # bottom row first
uv_px = np.stack([np.full_like(v_px, (IMAGE[0] - 1) / 2), v_px], -1)


def sweep(budget: str, height_m: float, tilt_deg: float) -> dict:
    cam = PanTiltCamera(focal_px=FOCAL_PX, image_size_px=IMAGE, height_m=height_m, pan_deg=0.0, tilt_deg=tilt_deg)
    est = propagate(cam, BUDGETS[budget], uv_px)  # all rows of the centre column at once
    dist = np.hypot(*est.xy_world_m.T)  # from the foot of the mast, m
    a95, _, _ = ellipse_axes(est.cov_m2, confidence=0.95)
    ok = est.valid & (a95 <= LIMIT_M)
    first_bad = np.flatnonzero(~ok)
    n_ok = first_bad[0] if first_bad.size else ok.size  # contiguous from the bottom row
    reach = float(dist[n_ok - 1]) if n_ok else float("nan")
    v_reach = float(v_px[n_ok - 1]) if n_ok else float("nan")
    valid = est.valid
    at = {}
    for d in (30.0, 60.0):  # interpolate a95 at a given distance (dist increases up the image)
        at[d] = float(np.interp(d, dist[valid], a95[valid], left=np.nan, right=np.nan))
    return {"budget": budget, "height_m": height_m, "tilt_deg": tilt_deg, "near_m": float(dist[0]),
            "reach_m": reach, "v_reach_px": v_reach, "horizon_limited": bool(n_ok == valid.sum()),
            "a95_at_30m": at[30.0], "a95_at_60m": at[60.0]}


rows = [sweep(b, h, t) for b in BUDGETS for h in HEIGHTS_M for t in TILTS_DEG]
print(f"criterion: 95 % semi-major axis <= {LIMIT_M:.2f} m (the 95 % ellipse fits in a {LANE_WIDTH_M} m lane); "
      f"camera {IMAGE[0]}x{IMAGE[1]} px, f = {FOCAL_PX:.0f} px")


def fmt(x, w=7, nd=1):
    return f"{'-':>{w}}" if not np.isfinite(x) else f"{x:{w}.{nd}f}"


head = " ".join(f"{'t' + format(t, '.0f') + ' near/reach':>16}" for t in TILTS_DEG)
print(f"{'budget':<16} {'h_m':>4} {head} {'a95@30m':>8} {'a95@60m':>8}  (tilt {TILTS_DEG[1]:.0f} deg)")
for b in BUDGETS:
    for h in HEIGHTS_M:
        rr = {r["tilt_deg"]: r for r in rows if r["budget"] == b and r["height_m"] == h}
        cells = " ".join(f"{fmt(rr[t]['near_m'], 6)} /{fmt(rr[t]['reach_m'], 6)}"
                         f"{'*' if rr[t]['horizon_limited'] else ' '}" for t in TILTS_DEG)
        mid = rr[TILTS_DEG[1]]
        print(f"{b:<16} {h:4.0f} {cells} {fmt(mid['a95_at_30m'], 8, 2)} {fmt(mid['a95_at_60m'], 8, 2)}")
print("near = nearest ground in view (bottom row), reach = farthest distance up to which the criterion holds from the "
      "bottom row on (m); '-' = fails already at the bottom row / not in view; "
      "* = holds up to the top of the image (reach limited by the view)")
for b in BUDGETS:
    best = max((r for r in rows if r["budget"] == b), key=lambda r: np.nan_to_num(r["reach_m"]))
    if not np.isfinite(best["reach_m"]):
        print(f"{b}: the criterion fails everywhere in this sweep")
        continue
    cam = PanTiltCamera(focal_px=FOCAL_PX, image_size_px=IMAGE, height_m=best["height_m"], pan_deg=0.0,
                        tilt_deg=best["tilt_deg"])
    ratio, _ = linearity_ratio(cam, BUDGETS[b], [(IMAGE[0] - 1) / 2, best["v_reach_px"]], n_samples=4000, seed=3)
    print(f"best reach with {b}: {best['reach_m']:.1f} m at h = {best['height_m']:.0f} m, "
          f"tilt {best['tilt_deg']:.0f} deg "
          f"(nearest visible ground {best['near_m']:.1f} m); linear/Monte-Carlo semi-major there: {float(ratio):.3f}")

with open(out / "plan_mount.csv", "w", newline="") as fh:
    w = csv.DictWriter(fh, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)

import matplotlib.pyplot as plt  # noqa: E402

ncol = 2
nrow = -(-len(BUDGETS) // ncol)
fig, axes = plt.subplots(nrow, ncol, figsize=(4.6 * ncol, 3.4 * nrow), squeeze=False)
axes = axes.ravel()[:len(BUDGETS)]
for ax, b in zip(axes, BUDGETS, strict=True):
    for j, t in enumerate(TILTS_DEG):
        rr = [r for r in rows if r["budget"] == b and r["tilt_deg"] == t]
        ax.plot([r["height_m"] for r in rr], [r["reach_m"] for r in rr], "o-", color=f"C{j}", label=f"tilt {t:.0f} deg")
    ax.set_title(b)
    ax.set_xlabel("mount height (m)")
    ax.grid(alpha=0.3)
for ax in axes[::ncol]:
    ax.set_ylabel(f"reach (m): a95 <= {LIMIT_M:.2f} m")
axes[-1].legend(fontsize=8)
fig.suptitle(f"Reach of a lane-level (3.5 m) 95 % position, centre column, f = {FOCAL_PX:.0f} px")
fig.tight_layout()
fig.savefig(out / "plan_mount.png", dpi=100)
print(f"wrote {out / 'plan_mount.png'} and {out / 'plan_mount.csv'}")
