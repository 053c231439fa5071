"""Quickstart: locate a pixel on the ground, its covariance, ellipse and per-source breakdown.

    python examples/quickstart.py [--out DIR]

A 1920x1080 roadside camera (f = 1400 px) 8 m high, pan 30 deg (compass heading),
tilted 20 deg down, with the paper's Basler1 error budget (Tables 2-3 of Kusari et al.).
Prints the ground point, its 2x2 covariance, the 1-sigma and 95 % ellipses, the
contribution of every error source, and a check of the linear covariance against
Monte Carlo and the unscented transform; saves ``quickstart_ellipse.png``.
"""

from __future__ import annotations

import numpy as np
from _common import output_dir

from footprint_uq import PanTiltCamera, ellipse_axes, monte_carlo, propagate, unscented
from footprint_uq.uncertainty.ellipse import ellipse_points

out = output_dir(__doc__.splitlines()[0], "quickstart")

cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
budget = "basler1"
uv_px = np.array([[959.5, 800.0], [1700.0, 450.0]])  # u right, v down (pixel centres)

est = propagate(cam, budget, uv_px, breakdown=True)
a1, b1, ori = ellipse_axes(est.cov_m2)
a95, b95, _ = ellipse_axes(est.cov_m2, confidence=0.95)
for i, uv in enumerate(uv_px):
    x, y = est.xy_world_m[i]
    print(f"pixel (u, v) = ({uv[0]:.1f}, {uv[1]:.1f}) px -> ground x = {x:.3f} m east, y = {y:.3f} m north, "
          f"range {np.hypot(x, y):.1f} m")
    c = est.cov_m2[i]
    print(f"  cov_m2 = [[{c[0, 0]:.5f}, {c[0, 1]:.5f}], [{c[1, 0]:.5f}, {c[1, 1]:.5f}]]")
    print(f"  1-sigma ellipse: semi-major {a1[i]:.3f} m, semi-minor {b1[i]:.3f} m, "
          f"orientation {ori[i]:.1f} deg ccw from east")
    print(f"  95 % ellipse:    semi-major {a95[i]:.3f} m, semi-minor {b95[i]:.3f} m")
    print("  breakdown (share of the trace of cov_m2):")
    total = np.trace(c)
    for name, contrib in sorted(est.contributions.items(), key=lambda kv: -np.trace(kv[1][i])):
        tr = np.trace(contrib[i])
        print(f"    {name:<16s} {100.0 * tr / total:6.2f} %   sqrt(trace) {np.sqrt(max(tr, 0.0)):.4f} m")

# linear vs Monte Carlo vs unscented (seeded)
mc = monte_carlo(cam, budget, uv_px, n_samples=20_000, seed=1)
ut = unscented(cam, budget, uv_px)
print("semi-major axis (1 sigma), m:   linear    Monte Carlo   unscented")
for i in range(len(uv_px)):
    print(f"  pixel {i}:                       {a1[i]:.4f}    {ellipse_axes(mc.cov_m2[i])[0]:.4f}        "
          f"{ellipse_axes(ut.cov_m2[i])[0]:.4f}")

above = propagate(cam, budget, [959.5, 20.0])
print(f"pixel (959.5, 20.0) px: valid={bool(above.valid)}, reason code {int(above.reason)} "
      f"(above the horizon: NaN, never a made-up number)")

import matplotlib.pyplot as plt  # noqa: E402

fig, ax = plt.subplots(figsize=(6, 5))
for i in range(len(uv_px)):
    for conf, style in ((None, "-"), (0.95, "--")):
        p = ellipse_points(est.xy_world_m[i], est.cov_m2[i], confidence=conf)
        ax.plot(p[:, 0], p[:, 1], style, color=f"C{i}", label=f"pixel {i}, {'1 sigma' if conf is None else '95 %'}")
    ax.plot(*est.xy_world_m[i], "+", color=f"C{i}")
ax.set_aspect("equal")
ax.set_xlabel("x east (m)")
ax.set_ylabel("y north (m)")
ax.legend(fontsize=8)
ax.set_title("Ground uncertainty ellipses (basler1)")
path = out / "quickstart_ellipse.png"
fig.savefig(path, dpi=100, bbox_inches="tight")
print(f"wrote {path}")
