"""Where a 2-D box touches the ground: bottom-centre point vs the contact model's footprint centre.

    python examples/contact_figure.py [--out DIR]

(docs/figures/contact-model.png is this figure; docs/uncertainty-model.md, section 3c.)
A camera 8 m up, 14 deg down; cars of the shipped size prior at 20-110 m with random yaw, rendered as
cuboids (the 2-D box is the bounding box of the eight projected corners, 2 px noise on every edge).
Left: one car from above -- its footprint, the back-projected bottom-centre point (the nearest corner's
image row), and the footprint centre estimated with unknown yaw and with a 3-D detector's yaw, with
their 95 % ellipses.  Right: the residuals (truth - estimate) of 300 cars along and across the line of
sight, for both contact models; printed: median errors and the 95 % ellipses' coverage.
"""

from __future__ import annotations

import matplotlib.pyplot as plt
import numpy as np
from _common import output_dir
from matplotlib.patches import Ellipse, Polygon

from footprint_uq.cameras.pantilt import PanTiltCamera
from footprint_uq.products.contact import bottom_centre, footprint_centre, load_size_priors
from footprint_uq.uncertainty.ellipse import chi2_scale, ellipse_axes
from footprint_uq.viz import save_figure

out = output_dir(__doc__.splitlines()[0], "contact_figure")
cam = PanTiltCamera(2000.0, (1920, 1080), 8.0, 30.0, 14.0, 0.5, (5.0, -3.0))
prior = load_size_priors()[0]["car"]
S_EDGE = 2.0
COV_UV = np.diag([S_EDGE**2 / 2, S_EDGE**2])


def footprint(centre, size, yaw):
    """Ground corners (n, 4, 2) and the cuboids' 8 corners (n, 8, 3) in the world frame."""
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    dl = 0.5 * size[:, :1] * np.array([-1, 1, 1, -1])
    dw = 0.5 * size[:, 1:2] * np.array([-1, -1, 1, 1])
    xy = np.stack([centre[:, :1] + c * dl - s * dw, centre[:, 1:] + s * dl + c * dw], -1)
    z = np.zeros(xy.shape[:-1] + (1,))
    top = np.concatenate([xy, z + size[:, 2:3, None]], -1)
    return xy, np.concatenate([np.concatenate([xy, z], -1), top], 1)


def boxes_of(cuboids, rng):
    uv = cam.project(cuboids).uv_px
    b = np.column_stack([uv[..., 0].min(1), uv[..., 1].min(1), uv[..., 0].max(1), uv[..., 1].max(1)])
    return b + rng.normal(0, S_EDGE, b.shape)


rng = np.random.default_rng(2026)
n = 300
centre = cam.backproject(np.column_stack([rng.uniform(250, 1670, n), rng.uniform(380, 1000, n)])).xy_world_m
size = prior.mean_m + prior.sigma_m * rng.standard_normal((n, 3))
yaw = rng.uniform(0, 2 * np.pi, n)
poly, cuboids = footprint(centre, size, yaw)
boxes = boxes_of(cuboids, rng)
fc = footprint_centre(cam, {}, boxes, ["car"] * n, cov_uv_px2=COV_UV, box_sigma_px=S_EDGE)
fy = footprint_centre(cam, {}, boxes, ["car"] * n, yaw_rad=yaw, cov_uv_px2=COV_UV, box_sigma_px=S_EDGE)
bc = bottom_centre(cam, {}, boxes, ["car"] * n, cov_uv_px2=COV_UV)

k95 = chi2_scale(0.95)
fig, (ax, bx) = plt.subplots(1, 2, figsize=(11, 5.2))
i = int(np.argmin(np.abs(np.linalg.norm(centre - cam.params[13:15], axis=1) - 35)))  # a car about 35 m away
ax.add_patch(Polygon(poly[i], closed=True, fill=False, color="k", lw=1.5, label="true footprint"))
ax.plot(*centre[i], "k+", ms=12, label="true footprint centre")
los = centre[i] - cam.params[13:15]
los /= np.linalg.norm(los)
ax.plot(*np.stack([centre[i] - 6 * los, centre[i] + 3 * los]).T, ":", color="grey", label="line of sight")


def ellipse(a, r, color, label, marker):
    maj, mnr, ang = ellipse_axes(r.cov_m2[i] if a is None else r.cov_object_m2[i])
    a_ = ax if a is None else a
    a_.add_patch(Ellipse(r.xy_world_m[i], 2 * k95 * maj, 2 * k95 * mnr, angle=ang, fill=False, color=color))
    a_.plot(*r.xy_world_m[i], marker, color=color, label=label)


ellipse(ax, bc, "tab:red", "bottom-centre point (95 % ellipse: pixel noise)", "x")
ellipse(ax, fc, "tab:blue", "footprint centre, yaw unknown", "o")
ellipse(ax, fy, "tab:green", "footprint centre, yaw from a 3-D detector", "s")
ax.set_aspect("equal")
ax.set_xlim(centre[i, 0] - 5, centre[i, 0] + 5)
ax.set_ylim(centre[i, 1] - 5, centre[i, 1] + 5)
ax.set_xlabel("x east (m)")
ax.set_ylabel("y north (m)")
ax.set_title("one car, 35 m from the camera")
ax.legend(fontsize=7, loc="lower left")


def along_across(r):
    d = centre - r.xy_world_m
    e = centre - cam.params[13:15]
    e /= np.linalg.norm(e, axis=1)[:, None]
    return np.column_stack([(d * e).sum(1), d[:, 1] * e[:, 0] - d[:, 0] * e[:, 1]]), d


for r, color, label in ((bc, "tab:red", "bottom-centre"), (fc, "tab:blue", "footprint centre (yaw unknown)")):
    aa, d = along_across(r)
    nees = np.einsum("na,na->n", d, np.linalg.solve(r.cov_object_m2, d[..., None])[..., 0])
    err = np.linalg.norm(d, axis=1)
    print(f"{label:32s} median error {np.median(err):.3f} m, p95 {np.percentile(err, 95):.3f} m, "
          f"mean residual along the line of sight {aa[:, 0].mean():+.3f} m, "
          f"inside the 95 % ellipse {100 * np.mean(nees <= k95**2):.1f} %")
    bx.plot(aa[:, 1], aa[:, 0], ".", ms=3, color=color, alpha=0.6, label=label)
err_y = np.linalg.norm(centre - fy.xy_world_m, axis=1)
print(f"{'footprint centre (yaw known)':32s} median error {np.median(err_y):.3f} m")
bx.axhline(0, color="k", lw=0.5)
bx.axvline(0, color="k", lw=0.5)
bx.set_xlabel("residual across the line of sight (m)")
bx.set_ylabel("residual along the line of sight (m, + = beyond)")
bx.set_title(f"{n} cars at 20-110 m, random yaw, 2 px box noise")
bx.legend(fontsize=8)
fig.tight_layout()
path = save_figure(fig, out / "contact_figure.png")
print(f"wrote {path}")
