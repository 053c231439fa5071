"""``footprint-uq locate``: ground position and covariance of pixels
(:func:`footprint_uq.products.locate.locate_records`)."""

from __future__ import annotations

import json

import click
import numpy as np

from .._notices import set_compile_handler
from ..errors import InputError
from ..products.gcp_support import add_support, load_gcp_support
from ..products.locate import locate_csv, locate_records
from ..products.warmup import compile_handler
from ..uncertainty.presets import PRESET_NAMES
from .common import FINITE, check_confidence, load_camera_and_budget, note, pose_options, warn

__all__ = ["locate_cmd", "MAX_PIXEL_PX"]

#: largest pixel coordinate accepted by --pixel (a million image widths away is already no pixel)
MAX_PIXEL_PX = 1e9


@click.command("locate")
@click.option("--camera", "camera_path", required=True, metavar="FILE",
              help="Camera file (YAML/JSON, OpenCV, ROS or TUMTraf; docs/file-formats.md).")
@click.option("--budget", "budget_spec", required=True, metavar="FILE_OR_PRESET",
              help=f"Error budget: a preset ({', '.join(PRESET_NAMES)}; append @deg to read Table 3's "
                   "angles as degrees instead of the printed 1e-3 deg) or a YAML/JSON budget file.")
@click.option("--pixel", "pixels", type=(FINITE, FINITE), multiple=True, required=True, metavar="U V",
              help="Pixel (u right, v down, origin at the centre of the top-left pixel); repeat for more.")
@click.option("--format", "fmt", type=click.Choice(["json", "csv"]), default="json", show_default=True,
              help="Output: a JSON list of records, or CSV with the covariance flattened (cov_xx_m2, cov_xy_m2, "
                   "cov_yy_m2).")
@click.option("--confidence", type=FINITE, default=None, metavar="P",
              help="Also report the semi-axes of the P-confidence ellipse (2-D chi-square, 0.95 -> 2.4477 sigma).")
@click.option("--linear-threshold", type=FINITE, default=0.05, show_default=True, metavar="E",
              help="linear_ok is true where the predicted relative error of the linear 1-sigma semi-major axis "
                   "(nonlinearity) is at most E.")
@click.option("--gcp-summary", default=None, metavar="FILE",
              help="summary.json of the `calibrate gcp` run the camera and budget come from: adds gcp_inside_hull, "
                   "gcp_leverage_ratio, gcp_supported (how far the control points support each pixel).")
@pose_options
def locate_cmd(camera_path, budget_spec, pixels, fmt, confidence, linear_threshold, gcp_summary, pose):
    """Ground position (x east, y north, metres) and 2x2 covariance (m^2) of pixels.

    One record per --pixel: u_px, v_px, x_m, y_m, cov_m2, sigma_major_m,
    sigma_minor_m (1 sigma), orientation_deg (major axis, counter-clockwise from
    east), nonlinearity (predicted relative error of the linear sigma_major_m:
    0.05 = 5 %), linear_ok (nonlinearity <= --linear-threshold), valid and reason
    (null when valid), budget_missing_terms (the error groups the budget has
    nothing on: "extrinsic", "ground").  With --confidence P, also confidence, semi_major_m and
    semi_minor_m of the P ellipse.  A valid pixel that is not linear_ok is also
    reported on stderr: its covariance underestimates the spread (near the
    horizon; docs/uncertainty-model.md, "The linearity flag").
    """
    confidence = check_confidence(confidence)
    uv = np.array(pixels, dtype=np.float64).reshape(-1, 2)
    bad = ~(np.isfinite(uv) & (np.abs(uv) <= MAX_PIXEL_PX)).all(-1)
    if bad.any():
        i = int(np.argmax(bad))
        raise InputError(f"--pixel (#{i + 1})", tuple(pixels[i]),
                         f"finite pixel coordinates U V of magnitude <= {MAX_PIXEL_PX:g}")
    camera, budget = load_camera_and_budget(camera_path, budget_spec, pose)
    w, h = camera.image_size_px
    for i in np.flatnonzero(~camera.in_image(uv)):
        warn(f"--pixel #{i + 1} ({uv[i, 0]:g}, {uv[i, 1]:g}) is outside the {w}x{h} image; computed anyway")
    set_compile_handler(compile_handler(note))  # a lens's undistortion not compiled yet: said, not waited for
    records = locate_records(camera, budget, uv, confidence=confidence, linear_threshold=linear_threshold)
    if gcp_summary is not None:
        add_support(records, camera, budget, load_gcp_support(gcp_summary, budget))
        for i, r in enumerate(records):
            if not r["gcp_supported"]:
                warn(f"--pixel #{i + 1} ({uv[i, 0]:g}, {uv[i, 1]:g}) is outside the control points' support "
                     f"(leverage ratio {r['gcp_leverage_ratio'] or float('inf'):.3g}): an extrapolation of the solve")
    for i, r in enumerate(records):
        if r["valid"] and not r["linear_ok"]:
            warn(f"--pixel #{i + 1} ({uv[i, 0]:g}, {uv[i, 1]:g}): linearisation error predicted "
                 f"{100 * r['nonlinearity']:.1f} % of sigma_major_m (> {100 * linear_threshold:g} %): the covariance "
                 "underestimates the spread")
    if fmt == "json":
        click.echo(json.dumps(records, indent=2, allow_nan=False))
    else:
        click.echo(locate_csv(records, confidence), nl=False)
