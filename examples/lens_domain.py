"""The lens's valid domain: a wide-angle lens whose distortion polynomial folds inside the image.

    python examples/lens_domain.py [--out DIR]

A 1920x1080 camera with f = 950 px, k1 = -0.33, k2 = 0.045 (a common wide-angle lens): the
radial polynomial r (1 + k1 r^2 + k2 r^4) peaks at r = 1.2534 (distorted radius 0.7428, i.e.
706 px from the principal point), so the image corners lie past the fold and have no ray.
The script draws the valid region (``lens_domain.png``) and checks, on a grid every 8 px,
that every path -- ``propagate`` (numpy reference), ``covariance_map``,
``covariance_points`` and ``FrameProcessor`` -- gives the same status codes and the same
numbers.
"""

from __future__ import annotations

import numpy as np
from _common import output_dir

from footprint_uq import propagate
from footprint_uq.cameras.opencv import OpenCVCamera
from footprint_uq.cameras.rotation import R_W_C
from footprint_uq.products.covariance import covariance_map, covariance_points
from footprint_uq.products.footprints import FrameProcessor
from footprint_uq.status import UNDISTORT_FAILED
from footprint_uq.viz import save_figure
from footprint_uq.viz.lens import plot_lens_domain

out = output_dir(__doc__.splitlines()[0], "lens_domain")

K = np.array([[950.0, 0.0, 959.5], [0.0, 950.0, 539.5], [0.0, 0.0, 1.0]])
R_cam_world = R_W_C(np.deg2rad(30.0), np.deg2rad(15.0), 0.0).T  # pan 30 deg, tilt 15 deg
camera = OpenCVCamera(K, [-0.33, 0.045, 0.0, 0.0, 0.0], R_cam_world, -R_cam_world @ [0.0, 0.0, 8.0], (1920, 1080))
dom = camera.lens_domain
print(f"fold radius (undistorted, normalised): {dom.r_fold[0]:.4f}")
print(f"largest distorted radius (normalised): {dom.r_max_distorted[0]:.4f} = {950 * dom.r_max_distorted[0]:.0f} px")

uv = camera.pixel_grid(8)
ref = propagate(camera, "bw-cube1", uv)
xy_m, cov_m, _, reason_m = covariance_map(camera, "bw-cube1", 8, get_reason=True)
xy_p, cov_p, _, reason_p = covariance_points(camera, "bw-cube1", uv, get_reason=True)
est = FrameProcessor(camera, "bw-cube1").corners(uv.reshape(-1, 1, 2))
reason_f = est.corner_reason.reshape(uv.shape[:2])
ok = ref.valid
print(f"grid every 8 px: {uv.shape[0] * uv.shape[1]} pixels, {int((ref.reason == UNDISTORT_FAILED).sum())} past "
      f"the fold, {int(ok.sum())} on the ground")
print("status codes equal to the reference:  map", bool((reason_m == ref.reason).all()),
      " points", bool((reason_p == ref.reason).all()), " FrameProcessor", bool((reason_f == ref.reason).all()))
for name, xy, cov in (("map", xy_m, cov_m), ("points", xy_p, cov_p)):
    dxy = np.abs(xy[ok] - ref.xy_world_m[ok]).max()
    dcov = (np.abs(cov[ok] - ref.cov_m2[ok]).max(axis=(-2, -1)) / np.abs(ref.cov_m2[ok]).max(axis=(-2, -1))).max()
    print(f"{name:>7}: largest position difference {dxy:.1e} m, largest relative covariance difference {dcov:.1e}")
fig = plot_lens_domain(camera)
print("wrote", save_figure(fig, out / "lens_domain.png"))
