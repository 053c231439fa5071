"""``footprint-uq calibrate extrinsics``: the camera's extrinsic error budget from a LiDAR ground truth
(:func:`footprint_uq.calibration.extrinsics_run.run_extrinsics`).

Frame-level problems (no board in a cloud, no board in an image, unreadable files, NaN points)
never stop the run: they are listed in ``frames.csv``, ``summary.json`` and on stderr.
"""

from __future__ import annotations

import click

from ..calibration.extrinsics import POSE_NAMES
from ..calibration.extrinsics_run import ExtrinsicsOptions, run_extrinsics
from ..errors import InputError
from .common import FINITE, FiniteFloatRange, note

__all__ = ["extrinsics_cmd"]


@click.command("extrinsics")
@click.option("--pairs", required=True, metavar="DIR_OR_CSV",
              help="Folder of <stem>.<png|jpg|...> (or <stem>_corners.csv) + <stem>.<pcd|ply|npy|csv> pairs, "
                   "or a CSV of correspondences frame,X,Y,Z,u,v (X, Y, Z in the LiDAR frame).")
@click.option("--camera", required=True, metavar="FILE", help="Camera/intrinsics file (any format load_camera reads).")
@click.option("--board", required=True, metavar="COLSxROWS", help="Inner corners, e.g. 14x9.")
@click.option("--square-m", type=FINITE, required=True, metavar="S", help="Square size in metres.")
@click.option("--margin-m", type=FINITE, default=0.0, show_default=True, metavar="M",
              help="White border around the squares, metres (the board's outer size matters to the LiDAR).")
@click.option("--region", default=None, metavar="SPEC",
              help="Search region in the LiDAR frame: box:xmin,ymin,zmin,xmax,ymax,zmax or sphere:cx,cy,cz,r.")
@click.option("--ground", default="fit", show_default=True, metavar="fit|identity|FILE",
              help="Ground frame: fit the ground plane in the clouds, use the LiDAR frame, or a 4x4 T_ground_lidar.")
@click.option("--bootstrap", type=click.IntRange(min=0), default=200, show_default=True, metavar="N",
              help="Bootstrap resamples over frames (0: skip).")
@click.option("--seed", type=int, default=0, show_default=True, help="RANSAC and bootstrap seed.")
@click.option("--budget-from", type=click.Choice(["per_frame", "bootstrap", "jacobian"]), default="per_frame",
              show_default=True, help="Which variability goes into budget.yaml (per_frame = the paper's Table 3).")
@click.option("--no-correlations", is_flag=True, help="Write sigmas only (no 6x6 covariance) into budget.yaml.")
@click.option("--ransac-px", type=FiniteFloatRange(min=0.1), default=4.0, show_default=True,
              help="RANSAC / inlier reprojection threshold, px.")
@click.option("--plane-threshold-m", type=FiniteFloatRange(min=0.001), default=0.05, show_default=True,
              help="Plane inlier distance in the clouds (about 3x the range noise).")
@click.option("--min-frames", type=click.IntRange(min=2), default=3, show_default=True,
              help="Usable frames needed (a spread from fewer than 3 frames is meaningless).")
@click.option("--max-frame-rms-px", type=FiniteFloatRange(min=0.0, min_open=True), default=None, metavar="T",
              help="Drop frames whose own reprojection RMS exceeds T px (reported in frames.csv).")
@click.option("--estimator", type=click.Choice(["joint", "mean"]), default="joint", show_default=True,
              help="Reported pose: joint fit of all corners, or mean of the single-frame poses (more robust when "
                   "the LiDAR board fits dominate, e.g. few boards close to the camera).")
@click.option("--out", "out_dir", required=True, metavar="DIR", help="Output directory (created).")
def extrinsics_cmd(pairs, camera, board, square_m, margin_m, region, ground, bootstrap, seed, budget_from,
                   no_correlations, ransac_px, plane_threshold_m, min_frames, max_frame_rms_px, estimator, out_dir):
    """Extrinsic calibration against a LiDAR: pose and its error budget (position, height, pan, tilt, roll).

    Writes to DIR: budget.yaml (extrinsic error sizes, readable by --budget),
    camera.yaml (camera with the estimated pose in the ground frame), summary.json
    (the three variabilities side by side), frames.csv, correspondences.csv,
    poses.npz and the figures board_poses.png and pose_spread.png.
    """
    if budget_from == "bootstrap" and bootstrap < 2:
        raise InputError("--budget-from", budget_from, "--bootstrap N with N >= 2")
    options = ExtrinsicsOptions(margin_m=margin_m, region=region, ground=ground, bootstrap=bootstrap, seed=seed,
                                budget_from=budget_from, correlations=not no_correlations, ransac_px=ransac_px,
                                plane_threshold_m=plane_threshold_m, min_frames=min_frames, estimator=estimator,
                                max_frame_rms_px=max_frame_rms_px)
    res = run_extrinsics(pairs, camera, board, square_m, out_dir, options, echo=note)
    cal = res["calibration"]
    click.echo(f"frames: {len(cal.frames)} input, {len(cal.used)} used; reprojection RMS {cal.rms_px:.3f} px")
    click.echo("pose: " + ", ".join(f"{n}={v:.5g}" for n, v in zip(POSE_NAMES, cal.pose, strict=True)))
    click.echo(cal.table())
    click.echo(f"wrote {len(res['files'])} files to {out_dir}")
