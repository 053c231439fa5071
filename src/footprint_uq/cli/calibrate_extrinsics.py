"""``footprint-uq calibrate extrinsics``: the camera's extrinsic error budget from a LiDAR ground truth.

Importing this module registers the command on the ``calibrate`` group
(:mod:`footprint_uq.cli.calibrate`).  Frame-level problems (no board in a cloud,
no board in an image, unreadable files, NaN points) never stop the run: they are
listed in ``frames.csv``, ``summary.json`` and on stderr.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import click

from ..errors import InputError
from .calibrate import calibrate

__all__ = ["extrinsics_cmd", "run_extrinsics"]


def run_extrinsics(pairs, camera, board: str, square_m: float, out_dir, *, margin_m: float = 0.0, region=None,
                   ground: str = "fit", bootstrap: int = 200, seed: int = 0, budget_from: str = "per_frame",
                   correlations: bool = True, ransac_px: float = 4.0, plane_threshold_m: float = 0.05,
                   cluster_radius_m: float = 0.2, min_frames: int = 3, figures: bool = True, estimator: str = "joint",
                   max_frame_rms_px: float | None = None, echo=None) -> dict:
    """The ``calibrate extrinsics`` command as a function; returns ``{"calibration", "files"}``.

    ``pairs`` is a folder of ``<stem>.<image>`` or ``<stem>_corners.csv`` files with
    ``<stem>.<pcd|ply|npy|csv>`` clouds, or a CSV of correspondences (frame, X, Y, Z, u, v).
    ``ground`` is ``fit`` (ground-plane fit of the clouds), ``identity`` (the LiDAR
    frame is the ground frame) or a file with the 4x4 ``T_ground_lidar``.
    """
    import numpy as np

    from ..calibration import extrinsics as ex
    from ..calibration.boards import parse_board
    from ..io import save_budget, save_camera

    say = echo or (lambda m: None)
    b = parse_board(board, square_m, margin_m)
    intr = ex.load_intrinsics(camera)
    p = Path(pairs)
    T_gl, plane = None, None
    if ground not in ("fit", "identity"):
        T_gl = ex.load_transform(ground)
    if p.is_file() and p.suffix.lower() == ".csv":
        from ..io._common import read_text

        read_text(p)  # a file that is not UTF-8 text: one line naming it
        frames = ex.read_correspondences_csv(p)
        if ground == "fit":
            raise InputError("--ground", "fit", "'identity' or a T_ground_lidar file when --pairs is a "
                             "correspondences CSV (no clouds to fit the ground in)")
    elif p.is_dir():
        frames, plane = ex.frames_from_pairs(p, b, region=region, ground="fit" if ground == "fit" else "none",
                                             plane_threshold_m=plane_threshold_m, cluster_radius_m=cluster_radius_m,
                                             seed=seed, image_size_px=intr.image_size_px)
    else:
        raise InputError("--pairs", str(p), "a folder of image/corners + cloud pairs or a correspondences CSV")
    for f in frames:
        if not f.ok:
            say(f"frame {f.name}: {f.reason}")
        if f.cloud_stats.get("n_nonfinite_dropped") or f.cloud_stats.get("n_zero_dropped"):
            say(f"frame {f.name}: dropped {f.cloud_stats['n_nonfinite_dropped']} non-finite and "
                f"{f.cloud_stats['n_zero_dropped']} (0,0,0) points of {f.cloud_stats['n_read']}")
    cal = ex.calibrate_extrinsics(frames, intr, T_ground_lidar=T_gl, ground_plane=plane, ground=ground,
                                  ransac_threshold_px=ransac_px, bootstrap=bootstrap, seed=seed, min_frames=min_frames,
                                  estimator=estimator, max_frame_rms_px=max_frame_rms_px)
    for k, s in enumerate(cal.frame_status):
        if s != "ok" and frames[k].ok:
            say(f"frame {frames[k].name}: {s}")
    from ..io.atomic import atomic_path, atomic_write_text

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    files.append(save_budget(cal.budget(budget_from, correlations=correlations), out / "budget.yaml"))
    files.append(save_camera(cal.camera(), out / "camera.yaml"))
    summ = cal.summary()
    summ["budget_from"] = budget_from
    summ["board"] = {"cols": b.cols, "rows": b.rows, "square_m": b.square_m, "margin_m": b.margin_m}
    atomic_write_text(out / "summary.json", json.dumps(summ, indent=2, default=float))
    files.append(out / "summary.json")
    with atomic_path(out / "frames.csv") as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "status", "rms_px", "n_points_read", "n_nonfinite_dropped", "n_zero_dropped",
                    "lidar_board_points", *ex.POSE_NAMES])
        k = 0
        for i, f in enumerate(frames):
            fp = cal.frame_poses[i]
            pose = [""] * 6
            if cal.frame_status[i] == "ok":
                pose = [f"{v:.6g}" for v in cal.per_frame[k]]
                k += 1
            w.writerow([f.name, cal.frame_status[i], f"{fp.rms_px:.4f}" if fp else "",
                        f.cloud_stats.get("n_read", ""), f.cloud_stats.get("n_nonfinite_dropped", ""),
                        f.cloud_stats.get("n_zero_dropped", ""), f.detection.get("n_points", ""), *pose])
    files.append(out / "frames.csv")
    used = [cal.frame_poses[k] for k in cal.used]
    rows = ["frame,X,Y,Z,u,v"]
    for fp in used:
        for (x, y, z), (u, v) in zip(fp.xyz_m, fp.uv_px, strict=True):
            rows.append(",".join([fp.name] + [repr(float(q)) for q in (x, y, z, u, v)]))
    atomic_write_text(out / "correspondences.csv", "\n".join(rows) + "\n")
    files.append(out / "correspondences.csv")
    if figures:
        from ..viz.extrinsics import plot_board_poses, plot_pose_spread

        for name, fig in (("board_poses.png", plot_board_poses(cal)), ("pose_spread.png", plot_pose_spread(cal))):
            with atomic_path(out / name) as tmp:
                fig.savefig(tmp, dpi=120, bbox_inches="tight")
            files.append(out / name)
    with atomic_path(out / "poses.npz") as tmp:
        np.savez(tmp, per_frame=cal.per_frame, pose=cal.pose, cov_per_frame=cal.cov_per_frame,
                 cov_jacobian=cal.cov_jacobian,
                 cov_bootstrap=cal.cov_bootstrap if cal.cov_bootstrap is not None else np.full((6, 6), np.nan))
    files.append(out / "poses.npz")
    return {"calibration": cal, "files": files}


@calibrate.command("extrinsics")
@click.option("--pairs", required=True, metavar="DIR_OR_CSV",
              help="Folder of <stem>.<png|jpg|...> (or <stem>_corners.csv) + <stem>.<pcd|ply|npy|csv> pairs, "
                   "or a CSV of correspondences frame,X,Y,Z,u,v (X, Y, Z in the LiDAR frame).")
@click.option("--camera", required=True, metavar="FILE", help="Camera/intrinsics file (any format load_camera reads).")
@click.option("--board", required=True, metavar="COLSxROWS", help="Inner corners, e.g. 14x9.")
@click.option("--square-m", type=float, required=True, metavar="S", help="Square size in metres.")
@click.option("--margin-m", type=float, default=0.0, show_default=True, metavar="M",
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
@click.option("--ransac-px", type=click.FloatRange(min=0.1), default=4.0, show_default=True,
              help="RANSAC / inlier reprojection threshold, px.")
@click.option("--plane-threshold-m", type=click.FloatRange(min=0.001), default=0.05, show_default=True,
              help="Plane inlier distance in the clouds (about 3x the range noise).")
@click.option("--min-frames", type=click.IntRange(min=2), default=3, show_default=True)
@click.option("--max-frame-rms-px", type=click.FloatRange(min=0.0, min_open=True), default=None, metavar="T",
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
    from ..calibration.extrinsics import POSE_NAMES

    if budget_from == "bootstrap" and bootstrap < 2:
        raise InputError("--budget-from", budget_from, "--bootstrap N with N >= 2")
    res = run_extrinsics(pairs, camera, board, square_m, out_dir, margin_m=margin_m, region=region, ground=ground,
                         bootstrap=bootstrap, seed=seed, budget_from=budget_from, correlations=not no_correlations,
                         ransac_px=ransac_px, plane_threshold_m=plane_threshold_m, min_frames=min_frames,
                         estimator=estimator, max_frame_rms_px=max_frame_rms_px,
                         echo=lambda m: click.echo(f"footprint-uq: {m}", err=True))
    cal = res["calibration"]
    click.echo(f"frames: {len(cal.frames)} input, {len(cal.used)} used; reprojection RMS {cal.rms_px:.3f} px")
    click.echo("pose: " + ", ".join(f"{n}={v:.5g}" for n, v in zip(POSE_NAMES, cal.pose, strict=True)))
    click.echo(cal.table())
    click.echo(f"wrote {len(res['files'])} files to {out_dir}")
