"""The paper's closed-form Table-1 partial derivatives against central finite differences.

    python examples/reproduce_paper_partials.py [--out DIR]

Kusari et al. give the ground point (X north, Y east, origin under the camera) of an image
point (c, r) (column and row from the image centre, px) for a pan-tilt camera at height h,
pan alpha and tilt theta (focal length f, px), and the partial derivatives of (X, Y) with
respect to f, c, r, h, alpha and theta (their Table 1 and the equations after it).  This
script evaluates ``footprint_uq.cameras.pantilt.paper_partials`` (a term-by-term
transcription) at a few image points, compares every derivative with a central finite
difference of ``paper_xy``, and with the library's general Jacobian (``dxy_dp``, ``dxy_duv``
of the general camera model ``footprint_uq.cameras.general.backproject``, an independent
derivation through the rotation matrix and the ray/ground intersection), then forms the
paper's Cov(X, Y) = J Cov(par) J^T with the Basler1 error sizes.  Writes ``partials.csv``.
"""

from __future__ import annotations

import csv

import numpy as np
from _common import output_dir

from footprint_uq import PanTiltCamera, propagate
from footprint_uq import params as P
from footprint_uq.cameras import general
from footprint_uq.cameras.pantilt import paper_partials, paper_xy

out = output_dir(__doc__.splitlines()[0], "reproduce_paper_partials")

f_px, h_m, pan_deg, tilt_deg = 1400.0, 8.0, 30.0, 20.0
cam = PanTiltCamera(focal_px=f_px, image_size_px=(1920, 1080), height_m=h_m, pan_deg=pan_deg, tilt_deg=tilt_deg)
cx, cy = cam.principal_point_px
uv = np.array([[1100.0, 620.0], [959.5, 900.0], [300.0, 700.0], [1700.0, 400.0]])  # (u, v) px
c, r = uv[:, 0] - cx, uv[:, 1] - cy
alpha, theta = np.deg2rad(pan_deg), np.deg2rad(tilt_deg)
args = [np.full(len(uv), f_px), c, r, np.full(len(uv), h_m), np.full(len(uv), alpha), np.full(len(uv), theta)]
names = ["f", "c", "r", "h", "alpha", "theta"]
units = {"f": "m/px", "c": "m/px", "r": "m/px", "h": "m/m", "alpha": "m/rad", "theta": "m/rad"}
steps = {"f": 1e-3, "c": 1e-3, "r": 1e-3, "h": 1e-5, "alpha": 1e-7, "theta": 1e-7}

X, Y, valid = paper_xy(*args)
part = paper_partials(*args)
bp = general.backproject(cam.params, uv, get_gradients=True)  # the general (OpenCV-style) model
J, Juv = bp.dxy_dp, bp.dxy_duv
library = {"f": J[..., P.FX] + J[..., P.FY], "c": Juv[..., 0], "r": Juv[..., 1], "h": J[..., P.HM],
           "alpha": J[..., P.PAN], "theta": J[..., P.TILT]}  # world (dx east, dy north) = paper (dY, dX)

rows = []
worst_fd = worst_lib = 0.0
for i in range(len(uv)):
    print(f"image point (c, r) = ({c[i]:.1f}, {r[i]:.1f}) px: X = {X[i]:.3f} m (north), Y = {Y[i]:.3f} m (east)")
    print(f"  {'param':<6} {'dX/dp (paper)':>14} {'finite diff':>14} {'dY/dp (paper)':>14} {'finite diff':>14} "
          f"{'vs FD':>9} {'vs general':>10}")
    for k, name in enumerate(names):
        ap, am = list(args), list(args)
        ap[k] = args[k] + steps[name]
        am[k] = args[k] - steps[name]
        Xp, Yp, _ = paper_xy(*ap)
        Xm, Ym, _ = paper_xy(*am)
        fd = np.array([Xp[i] - Xm[i], Yp[i] - Ym[i]]) / (2 * steps[name])
        an = np.array([part[name][0][i], part[name][1][i]])
        err = np.linalg.norm(an - fd) / np.linalg.norm(an)
        lib = library[name][i][::-1]  # (dy, dx) world -> (dX, dY) paper
        err_lib = np.linalg.norm(an - lib) / np.linalg.norm(an)
        worst_fd, worst_lib = max(worst_fd, err), max(worst_lib, err_lib)
        print(f"  {name:<6} {an[0]:14.6g} {fd[0]:14.6g} {an[1]:14.6g} {fd[1]:14.6g} {err:9.1e} {err_lib:10.1e}  "
              f"{units[name]}")
        rows.append({"c_px": c[i], "r_px": r[i], "param": name, "dX_paper": an[0], "dX_fd": fd[0], "dY_paper": an[1],
                     "dY_fd": fd[1], "rel_err_fd": err, "rel_err_library": err_lib})
print(f"worst relative error: paper vs finite differences {worst_fd:.1e}, paper vs general model {worst_lib:.1e}")
assert worst_fd < 1e-6 and worst_lib < 1e-9, (worst_fd, worst_lib)

# the paper's Cov(X, Y) = J Cov(par) J^T with Basler1's sizes (Table 2-3), shared terms only, one point
i = 1
sig = {"f": 0.2768, "c": 0.1713, "r": 0.1314, "h": 0.1936, "alpha": np.deg2rad(0.1524e-3),
       "theta": np.deg2rad(0.1480e-3)}
Jp = np.array([[part[n][0][i], part[n][1][i]] for n in names]).T  # (2, 6): rows X, Y
Sp = np.diag([sig[n] ** 2 for n in names])
cov_paper = Jp @ Sp @ Jp.T + np.diag([0.1061**2, 0.0861**2])[::-1, ::-1]  # + camera X0 (north), Y0 (east)
print(f"point {i}: paper J Cov(par) J^T (f, c, r, h, alpha, theta, X0, Y0; Basler1), in (X north, Y east):")
print(np.array2string(cov_paper, precision=6))
lib = propagate(cam, "basler1", uv[i]).cov_m2  # the full budget (also distortion, imaging, resolution)
print("library propagate(cam, 'basler1') in (x east, y north):")
print(np.array2string(lib, precision=6))
print("(the library adds the distortion, imaging and resolution terms and fx/fy separately, so it is "
      "slightly larger)")

path = out / "partials.csv"
with open(path, "w", newline="") as fh:
    w = csv.DictWriter(fh, fieldnames=list(rows[0]))
    w.writeheader()
    w.writerows(rows)
print(f"wrote {path}")
