"""``footprint-uq calibrate gcp``: a camera and its error budget from ground control points.

The work is done by :func:`footprint_uq.calibration.gcp_run.run_gcp`; the command is registered on
the ``calibrate`` group in :mod:`footprint_uq.cli.calibrate`.
"""

from __future__ import annotations

import click

from ..calibration.gcp_run import run_gcp
from .common import FINITE, LATITUDE_DEG, LONGITUDE_DEG, FiniteFloatRange

__all__ = ["gcp_cmd"]


@click.command("gcp")
@click.option("--points", required=True, metavar="CSV",
              help="GCP table: u_px, v_px and x_m, y_m[, z_m] (world frame) or lat_deg, lon_deg[, alt_m]; "
                   "optional sigma_px, sigma_m, name.")
@click.option("--image-size", required=True, metavar="WxH", help="Image size, e.g. 1920x1080.")
@click.option("--intrinsics", default=None, metavar="FILE",
              help="Camera/intrinsics file (K, distortion); without it the focal length is solved too (>= 6 points).")
@click.option("--intrinsics-budget", default=None, metavar="FILE",
              help="Budget file of the intrinsics (e.g. from `calibrate intrinsics`): its covariance is propagated.")
@click.option("--pixel-sigma-px", type=FiniteFloatRange(min=0.0), default=1.0, show_default=True,
              help="Default 1-sigma click noise per image axis.")
@click.option("--survey-sigma-m", type=FiniteFloatRange(min=0.0), default=0.05, show_default=True,
              help="Default 1-sigma survey noise per world axis.")
@click.option("--origin-lat", "origin_lat", type=LATITUDE_DEG, default=None, metavar="DEG",
              help="Latitude of the world origin (lat/lon tables; default: mean of the points).")
@click.option("--origin-lon", "origin_lon", type=LONGITUDE_DEG, default=None, metavar="DEG",
              help="Longitude of the world origin.")
@click.option("--origin-alt-m", type=FINITE, default=None, metavar="M",
              help="Altitude of the ground plane z = 0 (alt_m tables; default: median of the points).")
@click.option("--image", default=None, metavar="FILE",
              help="The photo (PNG/JPEG, at most 60 Mpx), drawn behind the points in gcp.png.")
@click.option("--solve-k1", is_flag=True, help="Solve the radial distortion k1 freely (one more point needed).")
@click.option("--lens-k1-sigma", type=FiniteFloatRange(0.0, 1.0), default=0.1, show_default=True,
              help="Without --intrinsics: the prior standard deviation of the unknown lens's k1 (0: no distortion).")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
def gcp_cmd(points, image_size, intrinsics, intrinsics_budget, pixel_sigma_px, survey_sigma_m, origin_lat, origin_lon,
            origin_alt_m, image, solve_k1, lens_k1_sigma, out_dir):
    """Camera pose (and focal length) from ground control points, with the full covariance of the solve.

    Writes to DIR: camera.yaml, budget.yaml (full parameter covariance), residuals.csv
    (per point and leave-one-out), summary.json, gcp.png and summary.html.
    """
    res = run_gcp(points, image_size, out_dir, intrinsics=intrinsics, intrinsics_budget=intrinsics_budget,
                  pixel_sigma_px=pixel_sigma_px, survey_sigma_m=survey_sigma_m, origin_lat_deg=origin_lat,
                  origin_lon_deg=origin_lon, origin_alt_m=origin_alt_m, image=image, solve_k1=solve_k1,
                  lens_k1_sigma=lens_k1_sigma)
    sol = res["solution"]
    click.echo(f"{len(sol.gcps.uv_px)} points: RMS {sol.rms_px:.3f} px, reduced chi-square {sol.reduced_chi2:.3f}")
    click.echo("; ".join(f"{r['parameter']}={r['value']:.6g} +- {r['sigma']:.3g}" for r in sol.pose_table()))
    for f in sol.flags:
        click.echo(f"footprint-uq: warning: NOT USABLE: {f}", err=True)
    if sol.inflation > 1.0:
        click.echo(f"covariance inflated x{sol.inflation:.3g} (the cost rises slower than its quadratic model)")
    click.echo(f"wrote {len(res['files'])} files to {out_dir}" + ("" if sol.usable else
                                                                 " (flagged: see summary.json 'flags')"))
