"""Extrinsic calibration against a LiDAR, from files to files (the ``footprint-uq calibrate extrinsics`` job).

:func:`run_extrinsics` reads image/cloud pairs (or a CSV of correspondences), calibrates the
camera's pose and its error budget (:func:`footprint_uq.calibration.extrinsics.calibrate_extrinsics`)
and writes ``budget.yaml``, ``camera.yaml``, ``summary.json``, ``frames.csv``,
``correspondences.csv``, ``poses.npz`` and two figures.  Frame-level problems (no board in a
cloud or an image, unreadable files, NaN points) never stop the run: they are reported through
``echo`` and listed in ``frames.csv`` and ``summary.json``.
"""

from __future__ import annotations

import csv
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..io import save_budget, save_camera
from ..io._common import read_text
from ..io.atomic import atomic_path, atomic_write_text, check_output_folder, final_paths, output_set
from ..viz.extrinsics import plot_board_poses, plot_pose_spread
from .boards import Checkerboard, parse_board
from .extrinsics import (
    POSE_NAMES,
    ExtrinsicCalibration,
    calibrate_extrinsics,
    frames_from_pairs,
    load_intrinsics,
    load_transform,
    read_correspondences_csv,
)

__all__ = ["ExtrinsicsOptions", "run_extrinsics", "GROUND_CHOICES"]

#: the ground frame choices besides a file with the 4x4 ``T_ground_lidar``
GROUND_CHOICES = ("fit", "identity")


@dataclass(frozen=True)
class ExtrinsicsOptions:
    """Settings of an extrinsic calibration run (defaults: those of the command).

    Attributes
    ----------
    margin_m : float
        White border around the squares, metres (the board's outer size matters to the LiDAR).
    region : str, optional
        Search region in the LiDAR frame: ``box:xmin,ymin,zmin,xmax,ymax,zmax`` or ``sphere:cx,cy,cz,r``.
    ground : str
        ``"fit"`` (ground-plane fit of the clouds), ``"identity"`` (the LiDAR frame is the ground
        frame) or a file with the 4x4 ``T_ground_lidar``.
    bootstrap : int
        Bootstrap resamples over frames (0: skip).
    seed : int
        RANSAC and bootstrap seed.
    budget_from : {"per_frame", "bootstrap", "jacobian"}
        Which variability goes into ``budget.yaml`` (``per_frame`` = the paper's Table 3).
    correlations : bool
        Write the 6x6 covariance into ``budget.yaml`` (else sigmas only).
    ransac_px : float
        RANSAC / inlier reprojection threshold, pixels.
    plane_threshold_m : float
        Plane inlier distance in the clouds.
    cluster_radius_m : float
        Clustering radius of the board search in the clouds.
    min_frames : int
        Fewest frames accepted.
    figures : bool
        Write ``board_poses.png`` and ``pose_spread.png``.
    estimator : {"joint", "mean"}
        Reported pose: joint fit of all corners, or mean of the single-frame poses.
    max_frame_rms_px : float, optional
        Drop frames whose own reprojection RMS exceeds this.
    """

    margin_m: float = 0.0
    region: str | None = None
    ground: str = "fit"
    bootstrap: int = 200
    seed: int = 0
    budget_from: str = "per_frame"
    correlations: bool = True
    ransac_px: float = 4.0
    plane_threshold_m: float = 0.05
    cluster_radius_m: float = 0.2
    min_frames: int = 3
    figures: bool = True
    estimator: str = "joint"
    max_frame_rms_px: float | None = None


def _read_frames(pairs, board: Checkerboard, intr, o: ExtrinsicsOptions):
    """``(frames, ground plane or None)`` from a folder of pairs or a correspondences CSV."""
    p = Path(pairs)
    if p.is_file() and p.suffix.lower() == ".csv":
        read_text(p)  # a file that is not UTF-8 text: one line naming it
        frames = read_correspondences_csv(p)
        if o.ground == "fit":
            raise InputError("--ground", "fit", "'identity' or a T_ground_lidar file when --pairs is a "
                             "correspondences CSV (no clouds to fit the ground in)")
        return frames, None
    if p.is_dir():
        return frames_from_pairs(p, board, region=o.region, ground="fit" if o.ground == "fit" else "none",
                                 plane_threshold_m=o.plane_threshold_m, cluster_radius_m=o.cluster_radius_m,
                                 seed=o.seed, image_size_px=intr.image_size_px)
    raise InputError("--pairs", str(p), "a folder of image/corners + cloud pairs or a correspondences CSV")


def _report_frames(frames, say) -> None:
    for f in frames:
        if not f.ok:
            say(f"frame {f.name}: {f.reason}")
        if f.cloud_stats.get("n_nonfinite_dropped") or f.cloud_stats.get("n_zero_dropped"):
            say(f"frame {f.name}: dropped {f.cloud_stats['n_nonfinite_dropped']} non-finite and "
                f"{f.cloud_stats['n_zero_dropped']} (0,0,0) points of {f.cloud_stats['n_read']}")


def _write_frames_csv(path: Path, frames, cal: ExtrinsicCalibration) -> Path:
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["frame", "status", "rms_px", "n_points_read", "n_nonfinite_dropped", "n_zero_dropped",
                    "lidar_board_points", *POSE_NAMES])
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
    return path


def _write_correspondences(path: Path, cal: ExtrinsicCalibration) -> Path:
    rows = ["frame,X,Y,Z,u,v"]
    for fp in (cal.frame_poses[k] for k in cal.used):
        for (x, y, z), (u, v) in zip(fp.xyz_m, fp.uv_px, strict=True):
            rows.append(",".join([fp.name] + [repr(float(q)) for q in (x, y, z, u, v)]))
    return atomic_write_text(path, "\n".join(rows) + "\n")


def _write_poses(path: Path, cal: ExtrinsicCalibration) -> Path:
    with atomic_path(path) as tmp:
        np.savez(tmp, per_frame=cal.per_frame, pose=cal.pose, cov_per_frame=cal.cov_per_frame,
                 cov_jacobian=cal.cov_jacobian,
                 cov_bootstrap=cal.cov_bootstrap if cal.cov_bootstrap is not None else np.full((6, 6), np.nan))
    return path


#: every name a run writes into its folder (swapped in as one set; anything else there: refused)
EXTRINSICS_OWN = ("budget.yaml", "camera.yaml", "summary.json", "frames.csv", "correspondences.csv", "board_poses.png",
                  "pose_spread.png", "poses.npz")


def _write_outputs(out_dir: Path, frames, cal: ExtrinsicCalibration, board: Checkerboard,
                   o: ExtrinsicsOptions) -> list:
    """The run's files as one set (:func:`footprint_uq.io.atomic.output_set`); their final paths."""
    with output_set(out_dir, EXTRINSICS_OWN, "calibrate extrinsics") as stage:
        files = _write_files(stage, frames, cal, board, o)
    return final_paths(files, stage, out_dir)


def _write_files(out: Path, frames, cal: ExtrinsicCalibration, board: Checkerboard, o: ExtrinsicsOptions) -> list:
    files = [save_budget(cal.budget(o.budget_from, correlations=o.correlations), out / "budget.yaml"),
             save_camera(cal.camera(), out / "camera.yaml")]
    summ = cal.summary()
    summ["budget_from"] = o.budget_from
    summ["board"] = {"cols": board.cols, "rows": board.rows, "square_m": board.square_m, "margin_m": board.margin_m}
    files.append(atomic_write_text(out / "summary.json", json.dumps(summ, indent=2, default=float)))
    files.append(_write_frames_csv(out / "frames.csv", frames, cal))
    files.append(_write_correspondences(out / "correspondences.csv", cal))
    if o.figures:
        for name, fig in (("board_poses.png", plot_board_poses(cal)), ("pose_spread.png", plot_pose_spread(cal))):
            with atomic_path(out / name) as tmp:
                fig.savefig(tmp, dpi=120, bbox_inches="tight")
            files.append(out / name)
    files.append(_write_poses(out / "poses.npz", cal))
    return files


def run_extrinsics(pairs, camera, board: str, square_m: float, out_dir, options: ExtrinsicsOptions | None = None, *,
                   echo: Callable[[str], None] | None = None) -> dict:
    """Calibrate the camera's pose against a LiDAR and write the pose, its error budget and the diagnostics.

    Parameters
    ----------
    pairs : path
        A folder of ``<stem>.<image>`` or ``<stem>_corners.csv`` files with
        ``<stem>.<pcd|ply|npy|csv>`` clouds, or a CSV of correspondences (frame, X, Y, Z, u, v;
        X, Y, Z in the LiDAR frame).
    camera : path
        Camera/intrinsics file (any format :func:`footprint_uq.io.load_camera` reads).
    board : str
        Inner corners, ``"COLSxROWS"``.
    square_m : float
        Square size, metres.
    out_dir : path
        Output directory (created).
    options : ExtrinsicsOptions, optional
        Ground frame, bootstrap, thresholds, estimator, outputs.
    echo : callable, optional
        Called with one line per frame problem.

    Returns
    -------
    dict
        ``calibration`` (:class:`~footprint_uq.calibration.extrinsics.ExtrinsicCalibration`) and
        ``files`` (the paths written).

    Raises
    ------
    InputError
        Unusable inputs (``pairs`` neither a folder nor a CSV, ``ground="fit"`` with a
        correspondences CSV, too few usable frames, ...).
    """
    o = options if options is not None else ExtrinsicsOptions()
    say = echo or (lambda m: None)
    b = parse_board(board, square_m, o.margin_m)
    check_output_folder(out_dir, EXTRINSICS_OWN, "calibrate extrinsics")  # before the work, not after
    intr = load_intrinsics(camera)
    T_gl = load_transform(o.ground) if o.ground not in GROUND_CHOICES else None
    frames, plane = _read_frames(pairs, b, intr, o)
    _report_frames(frames, say)
    cal = calibrate_extrinsics(frames, intr, T_ground_lidar=T_gl, ground_plane=plane, ground=o.ground,
                               ransac_threshold_px=o.ransac_px, bootstrap=o.bootstrap, seed=o.seed,
                               min_frames=o.min_frames, estimator=o.estimator, max_frame_rms_px=o.max_frame_rms_px)
    for k, s in enumerate(cal.frame_status):
        if s != "ok" and frames[k].ok:
            say(f"frame {frames[k].name}: {s}")
    return {"calibration": cal, "files": _write_outputs(Path(out_dir), frames, cal, b, o)}
