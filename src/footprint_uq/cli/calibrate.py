"""``footprint-uq calibrate ...``: error sizes from calibration data.

The ``calibrate`` group holds one command per calibration (``intrinsics`` here).
To add one (e.g. ``extrinsics``): define a ``click.Command`` in its own module,
keeping heavy imports inside the function so that ``footprint-uq --help`` stays
fast, and register it at the bottom of this file with one
``calibrate.add_command(cmd)`` line.  The group itself is registered in
:mod:`footprint_uq.cli.main` with ``main.add_command(calibrate)``.

Bad input raises :class:`footprint_uq.errors.InputError`; the top-level group
turns it into a one-line message and exit status 2.  Frame-level problems
(unreadable image, no board found) never stop the run: they are listed in
``frames.csv``, ``summary.json`` and on stderr.
"""

from __future__ import annotations

import click
import numpy as np

from ..errors import InputError

__all__ = ["calibrate", "intrinsics_cmd", "run_intrinsics", "synthetic_cmd"]


@click.group("calibrate")
def calibrate():
    """Error budgets from calibration data (checkerboard images, ...)."""


def _board_option(spec: str) -> str:
    from ..calibration.boards import parse_board

    parse_board(spec)  # raises InputError naming the field
    return spec


def run_intrinsics(images, board: str, square_m: float, out_dir, *, max_mean_reproj_px=None, bootstrap: int = 0,
                   seed: int = 0, grid_px: float = 5.0, video_step: int = 1, workers=None, method: str = "auto",
                   hull: str = "corners", budget_source: str = "opencv", full_covariance: bool = False,
                   min_views: int = 3, progress: bool = True, echo=None, max_rms_px: float | None = 2.0) -> dict:
    """The ``calibrate intrinsics`` command as a function; returns the written files.

    Detection results are written to ``OUT/frames.csv`` before calibrating, so
    that the frame list survives a calibration that cannot proceed (too few
    frames): the error is then raised after the file is written.
    """
    import os
    from pathlib import Path

    from ..calibration.boards import parse_board
    from ..calibration.detect import detect_frames
    from ..calibration.intrinsics import calibrate_detections, write_frames_csv

    echo = echo or (lambda msg: None)
    b = parse_board(board, square_m)
    dets = detect_frames(images, b, video_step=video_step, workers=workers, method=method, progress=progress)
    for d in dets:
        if not d.found:
            echo(f"frame {d.label}: {d.reason}")
    out = Path(out_dir)
    try:
        cal = calibrate_detections(dets, b, max_mean_reproj_px=max_mean_reproj_px, bootstrap=bootstrap, seed=seed,
                                   min_views=min_views, workers=(os.cpu_count() or 1) if workers is None else workers,
                                   progress=progress, max_rms_px=max_rms_px)
    except InputError:
        out.mkdir(parents=True, exist_ok=True)
        write_frames_csv([{"label": d.label, "path": d.source.path, "frame_index": d.source.frame_index,
                           "found": d.found, "method": d.method, "used": False, "reason": d.reason} for d in dets],
                         out / "frames.csv")
        raise
    for d in cal.dropped:
        echo(f"frame {d['label']}: dropped, {d['reason']}")
    files = cal.save(out, grid_px=grid_px, hull=hull, budget_source=budget_source, full_covariance=full_covariance)
    return {"calibration": cal, "files": files}


@calibrate.command("intrinsics")
@click.argument("images", nargs=-1, required=True)
@click.option("--board", "board", required=True, metavar="COLSxROWS", callback=lambda c, p, v: _board_option(v),
              help="Inner corners, e.g. 9x6 (the paper's board: 14x9).")
@click.option("--square-m", type=click.FloatRange(min=0.0, min_open=True, max=100.0), required=True, metavar="M",
              help="Square size in metres.")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--max-mean-reproj-px", type=click.FloatRange(min=0.0, min_open=True), default=None, metavar="T",
              help="Frame filter: drop frames whose mean reprojection error exceeds T px, recalibrate, repeat.")
@click.option("--bootstrap", type=click.IntRange(min=0), default=0, show_default=True, metavar="N",
              help="Bootstrap resamples over frames (0: none).")
@click.option("--seed", type=int, default=0, show_default=True, help="Bootstrap seed.")
@click.option("--grid-px", type=click.FloatRange(min=1.0), default=5.0, show_default=True,
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
@click.option("--max-rms-px", type=click.FloatRange(min=0.0, min_open=True), default=2.0, show_default=True,
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
    res = run_intrinsics(images, board, square_m, out_dir, max_mean_reproj_px=max_mean_reproj_px,
                         bootstrap=bootstrap, seed=seed, grid_px=grid_px, video_step=video_step, workers=workers,
                         method=method, hull=hull, budget_source=budget_source, full_covariance=full_covariance,
                         min_views=min_views, progress=not quiet, max_rms_px=max_rms_px,
                         echo=lambda m: click.echo(f"footprint-uq: {m}", err=True))
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



def _synthetic_camera(camera_file, scale):
    from ..calibration.synthetic import DEFAULT_CAMERA, SyntheticCamera

    if camera_file is None:
        cam = DEFAULT_CAMERA
    else:
        from ..io import load_intrinsics

        K, dist, size = load_intrinsics(camera_file)
        if size is None:
            raise InputError("--camera", camera_file, "a camera file that states the image size")
        d = np.zeros(5)
        d[:min(5, len(dist))] = np.asarray(dist, dtype=float)[:5]
        if len(dist) > 5 and np.any(np.asarray(dist)[5:]):
            raise InputError("--camera dist", list(dist), "at most k1, k2, p1, p2, k3 (the renderer's lens model)")
        if abs(K[0, 1]) > 0:
            raise InputError("--camera K skew", K[0, 1], "zero skew (the renderer's lens model)")
        cam = SyntheticCamera(K[0, 0], K[1, 1], K[0, 2], K[1, 2], tuple(size), tuple(d))
    return cam if scale == 1.0 else cam.scaled(scale)


@calibrate.command("synthetic")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
@click.option("--views", type=click.IntRange(min=3), default=20, show_default=True, help="Board poses.")
@click.option("--board", "board", default="14x9", show_default=True, metavar="COLSxROWS",
              callback=lambda c, p, v: _board_option(v), help="Inner corners (default: the paper's board).")
@click.option("--square-m", type=click.FloatRange(min=0.0, min_open=True, max=100.0), default=0.1, show_default=True,
              help="Square size in metres.")
@click.option("--margin-m", type=click.FloatRange(min=0.0, max=100.0), default=0.05, show_default=True,
              help="White border around the squares.")
@click.option("--camera", "camera_file", default=None, metavar="FILE",
              help="Camera/intrinsics file to simulate (default: a Basler-ace-2-like 1920x1200 camera).")
@click.option("--scale", type=click.FloatRange(min=0.05, max=4.0), default=1.0, show_default=True,
              help="Scale the sensor (same field of view), e.g. 0.4 for quick tests.")
@click.option("--fill", type=(click.FloatRange(0.01, 1.0), click.FloatRange(0.01, 1.0)), default=(0.3, 0.55),
              show_default=True,
              help="Board width as a fraction of the image width (min max).")
@click.option("--max-tilt-deg", type=click.FloatRange(min=10.0, max=80.0), default=40.0, show_default=True,
              help="Largest board tilt (10..80 deg: the tilts are drawn from 10 deg up; beyond 80 the board is "
                   "seen edge-on).")
@click.option("--supersample", type=click.IntRange(min=1, max=8), default=4, show_default=True)
@click.option("--blur-sigma-px", type=click.FloatRange(min=0.0, max=100.0), default=0.6, show_default=True)
@click.option("--noise-sigma-dn", type=click.FloatRange(min=0.0, max=255.0), default=2.0, show_default=True,
              help="Sensor noise, grey levels.")
@click.option("--plan", "campaigns", type=click.IntRange(min=0), default=0, metavar="M",
              help="Also run a planning study: M repeated campaigns with --corner-noise-px (no rendering).")
@click.option("--corner-noise-px", type=click.FloatRange(min=0.0, max=1000.0), default=0.1, show_default=True,
              help="Corner noise per coordinate for --plan.")
@click.option("--plan-bootstrap", type=click.IntRange(min=0), default=100, show_default=True, metavar="N",
              help="Bootstrap resamples of the first planning campaign (0: none).")
@click.option("--no-render", is_flag=True, help="Skip the images (e.g. with --plan only).")
@click.option("--seed", type=int, default=0, show_default=True)
def synthetic_cmd(out_dir, views, board, square_m, margin_m, camera_file, scale, fill, max_tilt_deg, supersample,
                  blur_sigma_px, noise_sigma_dn, campaigns, corner_noise_px, plan_bootstrap, no_render, seed):
    """Synthetic checkerboard campaign: rendered images with exact corners (truth.json), and a planning study.

    The images feed `calibrate intrinsics DIR --board ...` directly; truth.json holds the
    camera, the board poses and the exact corner positions.  --plan M prints the error
    sizes (the paper's Table 2) that this campaign delivers for a given corner noise: the
    scatter over M repetitions next to OpenCV's and the bootstrap's estimates.
    """
    import json
    from pathlib import Path

    from ..calibration.boards import parse_board
    from ..calibration.intrinsics import PAPER_COLUMNS, _jsonable
    from ..calibration.synthetic import simulate_campaigns, write_campaign

    b = parse_board(board, square_m, margin_m)
    cam = _synthetic_camera(camera_file, scale)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    pose_kw = {"fill": tuple(fill), "max_tilt_deg": max_tilt_deg}
    if not no_render:
        write_campaign(out, cam, b, views, seed=seed, pose_kw=pose_kw, supersample=supersample,
                       blur_sigma_px=blur_sigma_px, noise_sigma_dn=noise_sigma_dn)
        click.echo(f"rendered {views} images of a {b.label()} board ({cam.image_size_px[0]}x{cam.image_size_px[1]} "
                   f"px) with truth.json into {out}")
    if campaigns:
        if campaigns < 2:
            raise InputError("--plan", campaigns, "at least 2 campaigns")
        r = simulate_campaigns(cam, b, views, corner_noise_px=corner_noise_px, n_campaigns=campaigns,
                               bootstrap=plan_bootstrap, seed=seed, pose_kw=pose_kw)
        from ..io.atomic import atomic_write_text

        atomic_write_text(out / "plan.json", json.dumps(_jsonable(r), indent=2))
        click.echo(f"planning study: {views} views, corner noise {corner_noise_px:g} px, {campaigns} campaigns")
        click.echo("source     " + " ".join(f"{c[6:]:>10s}" for c in PAPER_COLUMNS))
        for src, row in r["paper"].items():
            click.echo(f"{src:10s} " + " ".join(f"{row[c]:10.4g}" for c in PAPER_COLUMNS))
        click.echo(f"wrote {out / 'plan.json'}")


# -- the registry of calibrate sub-commands: one line per command ---------------------------
# (intrinsics is defined above with @calibrate.command; others: calibrate.add_command(cmd))
