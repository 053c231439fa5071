"""``footprint-uq calibrate synthetic``: a synthetic checkerboard campaign and a planning study
(:func:`footprint_uq.calibration.synthetic_run.run_synthetic`)."""

from __future__ import annotations

from pathlib import Path

import click

from ..calibration.synthetic_run import SyntheticOptions, run_synthetic
from ..errors import InputError
from ..params import PAPER_COLUMNS
from .calibrate_common import board_callback
from .common import FiniteFloatRange, Stages, min_max_callback

__all__ = ["synthetic_cmd"]


@click.command("synthetic")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--views", type=click.IntRange(min=3), default=20, show_default=True, help="Board poses.")
@click.option("--board", "board", default="14x9", show_default=True, metavar="COLSxROWS",
              callback=board_callback, help="Inner corners (default: the paper's board).")
@click.option("--square-m", type=FiniteFloatRange(min=0.0, min_open=True, max=100.0), default=0.1, show_default=True,
              help="Square size in metres.")
@click.option("--margin-m", type=FiniteFloatRange(min=0.0, max=100.0), default=0.05, show_default=True,
              help="White border around the squares.")
@click.option("--camera", "camera_file", default=None, metavar="FILE",
              help="Camera/intrinsics file to simulate (default: a Basler-ace-2-like 1920x1200 camera).")
@click.option("--scale", type=FiniteFloatRange(min=0.05, max=4.0), default=1.0, show_default=True,
              help="Scale the sensor (same field of view), e.g. 0.4 for quick tests.")
@click.option("--fill", type=(FiniteFloatRange(0.01, 1.0), FiniteFloatRange(0.01, 1.0)), default=(0.3, 0.55),
              show_default=True, callback=min_max_callback,
              help="Board width as a fraction of the image width (min max).")
@click.option("--max-tilt-deg", type=FiniteFloatRange(min=10.0, max=80.0), default=40.0, show_default=True,
              help="Largest board tilt (10..80 deg: the tilts are drawn from 10 deg up; beyond 80 the board is "
                   "seen edge-on).")
@click.option("--supersample", type=click.IntRange(min=1, max=8), default=4, show_default=True,
              help="Rendering: sub-pixels per pixel side (box filter).")
@click.option("--blur-sigma-px", type=FiniteFloatRange(min=0.0, max=100.0), default=0.6, show_default=True,
              help="Rendering: Gaussian optical blur, px (0: none).")
@click.option("--noise-sigma-dn", type=FiniteFloatRange(min=0.0, max=255.0), default=2.0, show_default=True,
              help="Sensor noise, grey levels.")
@click.option("--plan", "campaigns", type=click.IntRange(min=0), default=0, metavar="M",
              help="Also run a planning study: M repeated campaigns with --corner-noise-px (no rendering).")
@click.option("--corner-noise-px", type=FiniteFloatRange(min=0.0, max=1000.0), default=0.1, show_default=True,
              help="Corner noise per coordinate for --plan.")
@click.option("--plan-bootstrap", type=click.IntRange(min=0), default=100, show_default=True, metavar="N",
              help="Bootstrap resamples of the first planning campaign (0: none).")
@click.option("--no-render", is_flag=True, help="Skip the images (e.g. with --plan only).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Seed of the board poses, the sensor noise and the planning study.")
def synthetic_cmd(out_dir, views, board, square_m, margin_m, camera_file, scale, fill, max_tilt_deg, supersample,
                  blur_sigma_px, noise_sigma_dn, campaigns, corner_noise_px, plan_bootstrap, no_render, seed):
    """Synthetic checkerboard campaign: rendered images with exact corners (truth.json), and a planning study.

    The images feed `calibrate intrinsics DIR --board ...` directly; truth.json holds the
    camera, the board poses and the exact corner positions.  --plan M prints the error
    sizes (the paper's Table 2) that this campaign delivers for a given corner noise: the
    scatter over M repetitions next to OpenCV's and the bootstrap's estimates.
    """
    if campaigns == 1:
        raise InputError("--plan", campaigns, "at least 2 campaigns")
    options = SyntheticOptions(views=views, fill=tuple(fill), max_tilt_deg=max_tilt_deg, supersample=supersample,
                               blur_sigma_px=blur_sigma_px, noise_sigma_dn=noise_sigma_dn, render=not no_render,
                               campaigns=campaigns, corner_noise_px=corner_noise_px, plan_bootstrap=plan_bootstrap,
                               seed=seed)
    with Stages("calibrate synthetic") as say:
        res = run_synthetic(out_dir, board, square_m, margin_m=margin_m, camera=camera_file, scale=scale,
                            options=options, stage=say, progress=say.count)
    cam = res["camera"]
    if res["rendered"]:
        click.echo(f"rendered {views} images of a {res['board'].label()} board ({cam.image_size_px[0]}x"
                   f"{cam.image_size_px[1]} px) with truth.json into {Path(out_dir)}")
    if res["plan"] is not None:
        click.echo(f"planning study: {views} views, corner noise {corner_noise_px:g} px, {campaigns} campaigns")
        click.echo("source     " + " ".join(f"{c[6:]:>10s}" for c in PAPER_COLUMNS))
        for src, row in res["plan"]["paper"].items():
            click.echo(f"{src:10s} " + " ".join(f"{row[c]:10.4g}" for c in PAPER_COLUMNS))
        click.echo(f"wrote {res['plan_file']}")
