"""Code values and units of the V2X message fields (ETSI CPM, SAE J2735), as plain constants.

A floor module (imports nothing of the package): the compiled per-frame kernel
(:mod:`footprint_uq.fast.footprint_kernels`) encodes the fields with these numbers, and
:mod:`footprint_uq.products.v2x` -- where the fields, their rules and their sources are
documented -- re-exports them.
"""

from __future__ import annotations

import math

__all__ = [
    "Z95_1D", "K95_2D", "CPM_COORD_UNIT_M", "CPM_COORD_MAX_M", "CPM_COORD_OUT_OF_RANGE", "CPM_COORD_UNAVAILABLE",
    "CPM_CORR_UNAVAILABLE", "J2735_AXIS_UNIT_M", "J2735_AXIS_MAX", "J2735_AXIS_MAX_M", "J2735_AXIS_UNAVAILABLE",
    "J2735_ORIENTATION_UNIT_DEG", "J2735_ORIENTATION_UNAVAILABLE", "J2735_POSITION_CONFIDENCE_M",
    "J2735_POSITION_CONFIDENCE_NAMES", "CIRCULAR_RTOL", "STEP_GUARD", "PSD_RTOL",
]

#: 1-D 95 % multiplier used for CPM confidences (the issue's 1.96 sigma)
Z95_1D = 1.96
#: 2-D 95 % multiplier sqrt(chi2_2(0.95)) = sqrt(-2 ln 0.05)
K95_2D = math.sqrt(-2.0 * math.log(0.05))

CPM_COORD_UNIT_M = 0.01
CPM_COORD_MAX_M = 40.94
CPM_COORD_OUT_OF_RANGE = 4095
CPM_COORD_UNAVAILABLE = 4096
CPM_CORR_UNAVAILABLE = 101

J2735_AXIS_UNIT_M = 0.05
J2735_AXIS_MAX = 254  # any value >= 12.70 m
J2735_AXIS_MAX_M = 12.70
J2735_AXIS_UNAVAILABLE = 255
J2735_ORIENTATION_UNIT_DEG = 360.0 / 65535.0
J2735_ORIENTATION_UNAVAILABLE = 65535

#: radius (m) of PositionConfidence levels 1..15 (index 0 = unavailable)
J2735_POSITION_CONFIDENCE_M = (math.nan, 500.0, 200.0, 100.0, 50.0, 20.0, 10.0, 5.0, 2.0, 1.0,
                               0.5, 0.2, 0.1, 0.05, 0.02, 0.01)
J2735_POSITION_CONFIDENCE_NAMES = ("unavailable", "a500m", "a200m", "a100m", "a50m", "a20m", "a10m",
                                   "a5m", "a2m", "a1m", "a50cm", "a20cm", "a10cm", "a5cm", "a2cm", "a1cm")

CIRCULAR_RTOL = 1e-9  # axes this close: orientation reported as 0 (north)
STEP_GUARD = 1e-9  # relative guard against binary rounding pushing an exact step up
#: relative tolerance of the PSD / symmetry test of the covariances (rounding of a computed covariance is ~1e-16)
PSD_RTOL = 1e-9
