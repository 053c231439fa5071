"""Error sizes from calibration data.

Intrinsic calibration from checkerboard images (Zhang's method through OpenCV),
the paper's coverage and reprojection-error maps, the variability of the
intrinsics (OpenCV, Jacobian, bootstrap) and a budget file the core reads; a
synthetic checkerboard renderer with exact ground truth.

>>> from footprint_uq.calibration import calibrate_intrinsics
>>> cal = calibrate_intrinsics("calib/*.png", "9x6", 0.025, max_mean_reproj_px=0.5, bootstrap=200)  # doctest: +SKIP
>>> cal.to_budget()                                                   # doctest: +SKIP
"""

from .boards import PAPER_BOARD, Checkerboard, parse_board
from .detect import Detection, FrameSource, detect_corners, detect_frames, expand_inputs
from .intrinsics import (
    INTRINSIC_NAMES,
    PAPER_COLUMNS,
    BootstrapResult,
    IntrinsicCalibration,
    bootstrap_intrinsics,
    calibrate_corners,
    calibrate_detections,
    calibrate_intrinsics,
    compare_sigmas,
    intrinsic_covariance,
    paper_sigmas,
)
from .maps import coverage_map, error_asymmetry, reprojection_error_map

__all__ = [
    "PAPER_BOARD", "Checkerboard", "parse_board", "Detection", "FrameSource", "detect_corners", "detect_frames",
    "expand_inputs", "INTRINSIC_NAMES", "PAPER_COLUMNS", "BootstrapResult", "IntrinsicCalibration",
    "bootstrap_intrinsics", "calibrate_corners", "calibrate_detections", "calibrate_intrinsics", "compare_sigmas",
    "intrinsic_covariance", "paper_sigmas", "coverage_map", "error_asymmetry", "reprojection_error_map",
]
