"""Intrinsic calibration from images to files (the ``footprint-uq calibrate intrinsics`` job).

:func:`run_intrinsics` detects the board in every frame, calibrates (Zhang / OpenCV, frame
filter, bootstrap) and writes the results (:meth:`IntrinsicCalibration.save`).  Frame-level
problems (unreadable image, no board found) never stop the run: they are reported through
``echo`` and listed in ``frames.csv``.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..io.atomic import check_output_folder, final_paths, output_set
from .boards import parse_board
from .detect import detect_frames
from .intrinsics import calibrate_detections, write_frames_csv

__all__ = ["IntrinsicsOptions", "run_intrinsics", "INTRINSICS_OWN"]

#: every name a run writes into its folder (the folder is swapped in as one set; anything else there: refused)
INTRINSICS_OWN = ("frames.csv", "camera.yaml", "intrinsics.yaml", "budget.yaml", "maps.npz", "summary.json",
                  "report.md", "report.html", "coverage.png", "reprojection_error.png", "asymmetry.png",
                  "view_errors.png", "sigmas.png")


@dataclass(frozen=True)
class IntrinsicsOptions:
    """Settings of an intrinsic calibration run (defaults: those of the command).

    Attributes
    ----------
    max_mean_reproj_px : float, optional
        Frame filter: drop frames whose mean reprojection error exceeds this, recalibrate, repeat.
    bootstrap : int
        Bootstrap resamples over frames (0: none).
    seed : int
        Bootstrap seed.
    grid_px : float
        Cell size of the coverage and reprojection-error maps, pixels.
    video_step : int
        Use every k-th frame of video inputs.
    workers : int, optional
        Processes for detection and bootstrap (default: all cores).
    method : {"auto", "classic", "sb"}
        Corner detector (:func:`footprint_uq.calibration.detect.detect_frames`).
    hull : {"corners", "squares"}
        Coverage footprint: hull of the detected corners or of the projected squares.
    budget_source : {"opencv", "jacobian", "bootstrap", "max"}
        Which standard deviations go into ``budget.yaml``.
    full_covariance : bool
        Also write the 9x9 intrinsic covariance into ``budget.yaml``.
    min_views : int
        Fewest frames accepted.
    max_rms_px : float, optional
        Refuse a calibration whose RMS reprojection error exceeds this (a wrong board?).
    """

    max_mean_reproj_px: float | None = None
    bootstrap: int = 0
    seed: int = 0
    grid_px: float = 5.0
    video_step: int = 1
    workers: int | None = None
    method: str = "auto"
    hull: str = "corners"
    budget_source: str = "opencv"
    full_covariance: bool = False
    min_views: int = 3
    max_rms_px: float | None = 2.0


def run_intrinsics(images, board: str, square_m: float, out_dir, options: IntrinsicsOptions | None = None, *,
                   progress: bool = True, echo: Callable[[str], None] | None = None) -> dict:
    """Calibrate the intrinsics from checkerboard images and write the results into ``out_dir``.

    Parameters
    ----------
    images : path, glob, folder, video, or a sequence of them
        The frames (:func:`footprint_uq.calibration.detect.expand_inputs`).
    board : str
        Inner corners, ``"COLSxROWS"``.
    square_m : float
        Square size, metres.
    out_dir : path
        Output directory (created): ``camera.yaml``, ``intrinsics.yaml``, ``budget.yaml``,
        ``summary.json``, ``report.md``, ``frames.csv``, ``maps.npz`` and PNG figures.
    options : IntrinsicsOptions, optional
        Filter, bootstrap, detector and output settings.
    progress : bool
        Show progress bars.
    echo : callable, optional
        Called with one line per frame without a board and per frame dropped by the filter.

    Returns
    -------
    dict
        ``calibration`` (:class:`~footprint_uq.calibration.intrinsics.IntrinsicCalibration`) and
        ``files`` (file name -> path).

    Raises
    ------
    InputError
        The calibration cannot proceed (too few frames, RMS too large, ...); the run's set is then
        ``frames.csv`` alone, so that the frame list survives (it replaces the previous set: the folder
        always describes one run).

    The files are one set: built in a hidden folder beside ``out_dir`` and swapped in together
    (:func:`footprint_uq.io.atomic.output_set`); ``out_dir`` must be new or hold only a previous run's
    files (:data:`INTRINSICS_OWN`).
    """
    o = options if options is not None else IntrinsicsOptions()
    say = echo or (lambda msg: None)
    b = parse_board(board, square_m)
    check_output_folder(out_dir, INTRINSICS_OWN, "calibrate intrinsics")  # before the detection, not after
    dets = detect_frames(images, b, video_step=o.video_step, workers=o.workers, method=o.method, progress=progress)
    for d in dets:
        if not d.found:
            say(f"frame {d.label}: {d.reason}")
    out = Path(out_dir)
    try:
        cal = calibrate_detections(dets, b, max_mean_reproj_px=o.max_mean_reproj_px, bootstrap=o.bootstrap,
                                   seed=o.seed, min_views=o.min_views,
                                   workers=(os.cpu_count() or 1) if o.workers is None else o.workers,
                                   progress=progress, max_rms_px=o.max_rms_px)
    except InputError:
        with output_set(out, INTRINSICS_OWN, "calibrate intrinsics") as stage:
            write_frames_csv([{"label": d.label, "path": d.source.path, "frame_index": d.source.frame_index,
                               "found": d.found, "method": d.method, "used": False, "reason": d.reason}
                              for d in dets], stage / "frames.csv")
        raise
    for d in cal.dropped:
        say(f"frame {d['label']}: dropped, {d['reason']}")
    with output_set(out, INTRINSICS_OWN, "calibrate intrinsics") as stage:
        files = cal.save(stage, grid_px=o.grid_px, hull=o.hull, budget_source=o.budget_source,
                         full_covariance=o.full_covariance)
    return {"calibration": cal, "files": {k: str(v) for k, v in final_paths(files, stage, out).items()}}
