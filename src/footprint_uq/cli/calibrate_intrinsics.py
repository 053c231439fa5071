"""``footprint-uq calibrate intrinsics``: intrinsic calibration from checkerboard images
(:func:`footprint_uq.calibration.intrinsics_run.run_intrinsics`)."""

from __future__ import annotations

import click

from ..calibration.intrinsics_run import IntrinsicsOptions, run_intrinsics
from ..errors import InputError
from .calibrate_common import board_callback
from .common import FiniteFloatRange, note

__all__ = ["intrinsics_cmd"]


@click.command("intrinsics")
@click.argument("images", nargs=-1, required=True)
@click.option("--board", "board", required=True, metavar="COLSxROWS", callback=board_callback,
              help="Inner corners, e.g. 9x6 (the paper's board: 14x9).")
@click.option("--square-m", type=FiniteFloatRange(min=0.0, min_open=True, max=100.0), required=True, metavar="M",
              help="Square size in metres.")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--max-mean-reproj-px", type=FiniteFloatRange(min=0.0, min_open=True), default=None, metavar="T",
              help="Frame filter: drop frames whose mean reprojection error exceeds T px, recalibrate, repeat.")
@click.option("--bootstrap", type=click.IntRange(min=0), default=0, show_default=True, metavar="N",
              help="Bootstrap resamples over frames (0: none).")
@click.option("--seed", type=int, default=0, show_default=True, help="Bootstrap seed.")
@click.option("--grid-px", type=FiniteFloatRange(min=1.0), default=5.0, show_default=True,
              help="Cell size of the coverage and reprojection-error maps (px).")
@click.option("--hull", type=click.Choice(["corners", "squares"]), default="corners", show_default=True,
              help="Coverage footprint: hull of the detected corners or of the projected squares.")
@click.option("--video-step", type=click.IntRange(min=1), default=1, show_default=True, metavar="K",
              help="Use every K-th frame of video inputs.")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Processes for detection and bootstrap (default: all cores).")
@click.option("--method", type=click.Choice(["auto", "classic", "sb"]), default="auto", show_default=True,
              help="Corner detector: findChessboardCorners + cornerSubPix, findChessboardCornersSB, or classic "
                   "with SB fallback.")
@click.option("--budget-source", type=click.Choice(["opencv", "jacobian", "bootstrap", "max"]), default="opencv",
              show_default=True, help="Which standard deviations go into budget.yaml.")
@click.option("--full-covariance", is_flag=True, help="Also write the 9x9 intrinsic covariance into budget.yaml.")
@click.option("--min-views", type=click.IntRange(min=3), default=3, show_default=True,
              help="Fewest frames accepted.")
@click.option("--max-rms-px", type=FiniteFloatRange(min=0.0, min_open=True), default=2.0, show_default=True,
              metavar="PX", help="Refuse a calibration whose RMS reprojection error exceeds PX (wrong --board?).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def intrinsics_cmd(images, board, square_m, out_dir, max_mean_reproj_px, bootstrap, seed, grid_px, hull, video_step,
                   workers, method, budget_source, full_covariance, min_views, max_rms_px, quiet):
    """Intrinsic calibration from checkerboard IMAGES (files, globs, folders or videos).

    Writes to DIR: camera.yaml (OpenCV FileStorage), intrinsics.yaml (footprint-uq
    camera keys, no pose), budget.yaml (intrinsic error sizes, readable by
    --budget), summary.json, report.md, frames.csv, maps.npz and PNG figures.
    """
    if budget_source in ("bootstrap", "max") and bootstrap < 2:
        raise InputError("--budget-source", budget_source, "--bootstrap N with N >= 2 for bootstrap sigmas")
    options = IntrinsicsOptions(max_mean_reproj_px=max_mean_reproj_px, bootstrap=bootstrap, seed=seed,
                                grid_px=grid_px, video_step=video_step, workers=workers, method=method, hull=hull,
                                budget_source=budget_source, full_covariance=full_covariance, min_views=min_views,
                                max_rms_px=max_rms_px)
    res = run_intrinsics(images, board, square_m, out_dir, options, progress=not quiet, echo=note)
    cal = res["calibration"]
    n_in = len(cal.detections)
    n_found = sum(d.found for d in cal.detections)
    t = cal.paper_table()["opencv"]
    click.echo(f"frames: {n_in} input, {n_found} with the board, {len(cal.labels)} used, "
               f"{len(cal.dropped)} dropped by the filter")
    click.echo(f"fx={cal.K[0, 0]:.3f} fy={cal.K[1, 1]:.3f} cx={cal.K[0, 2]:.3f} cy={cal.K[1, 2]:.3f} px; "
               f"dist={', '.join(f'{v:.5g}' for v in cal.dist)}; RMS {cal.rms_px:.4f} px")
    click.echo(f"sigma (OpenCV {cal.opencv_version}): f={t['sigma_f_px']:.4g} c={t['sigma_c_px']:.4g} "
               f"r={t['sigma_r_px']:.4g} px; k1={t['sigma_k1']:.3g} k2={t['sigma_k2']:.3g} p1={t['sigma_p1']:.3g} "
               f"p2={t['sigma_p2']:.3g} k3={t['sigma_k3']:.3g}")
    if cal.bootstrap is not None and len(cal.bootstrap.samples) > 1:
        tb = cal.paper_table()["bootstrap"]
        click.echo(f"sigma (bootstrap, {len(cal.bootstrap.samples)} resamples): f={tb['sigma_f_px']:.4g} "
                   f"c={tb['sigma_c_px']:.4g} r={tb['sigma_r_px']:.4g} px")
    click.echo(f"wrote {len(res['files'])} files to {out_dir}")
