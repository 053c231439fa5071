"""Status codes attached to every computed point (``reason`` arrays).

A point is usable only where its code is :data:`OK`.  Codes are small integers
so that they travel in arrays and Parquet columns; :data:`REASONS` gives the text.
"""

from __future__ import annotations

import numpy as np

OK = 0
ABOVE_HORIZON = 1  # ray at or above the horizon: it never meets the ground in front of the camera
NOT_FINITE = 2  # NaN or infinite input
UNDISTORT_FAILED = 3  # lens model not invertible at this pixel
OUTSIDE_IMAGE = 4  # pixel outside the image (computed, but flagged)
BEHIND_CAMERA = 5  # world point behind the camera (projection)
BEYOND_RANGE = 6  # ground point farther than the requested max_range_m (maps)
OVERFLOW = 7  # every input finite, but the result is not (absurd geometry or error sizes)
DEGENERATE = 20  # footprint centre only: the footprint polygon (K >= 3 corners) has zero area

REASONS = {
    OK: "ok",
    ABOVE_HORIZON: "above horizon: the ray does not meet the ground in front of the camera",
    NOT_FINITE: "input is not finite (NaN or inf)",
    UNDISTORT_FAILED: "undistortion did not converge (pixel outside the lens model's valid region)",
    OUTSIDE_IMAGE: "pixel outside the image",
    BEHIND_CAMERA: "point is behind the camera",
    BEYOND_RANGE: "ground point beyond the requested maximum range",
    OVERFLOW: "result is not finite (overflow: the camera geometry or the error sizes are out of range)",
    DEGENERATE: "footprint polygon has zero area",
}


def reason_text(code) -> np.ndarray | str:
    """Text of one code, or an object array of texts for an array of codes."""
    if np.ndim(code) == 0:
        return REASONS[int(code)]
    return np.vectorize(lambda c: REASONS[int(c)], otypes=[object])(code)


def backprojection_reason(valid_ground, converged, finite) -> np.ndarray:
    """Codes of back-projected pixels from three boolean masks of the same shape: the ray meets the
    ground (else ABOVE_HORIZON), the undistortion converged (else UNDISTORT_FAILED), the input is
    finite (else NOT_FINITE); a later failure overrides an earlier one."""
    r = np.full(np.shape(valid_ground), OK, dtype=np.int8)
    r[~np.asarray(valid_ground, dtype=bool)] = ABOVE_HORIZON
    r[~np.asarray(converged, dtype=bool)] = UNDISTORT_FAILED
    r[~np.asarray(finite, dtype=bool)] = NOT_FINITE
    return r
