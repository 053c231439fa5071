"""The parameter vector shared by every camera model.

Both camera models (the paper's pan-tilt model and the general OpenCV model)
are described by the same 22 named parameters, so that one error budget, one
propagation routine and one Monte Carlo sampler serve both.  Jacobians with
respect to the parameters are ``(..., 2, 22)`` arrays whose last axis follows
:data:`PARAM_NAMES`.

Units are in the names.  Angles in the vector are radians (the budget file
speaks degrees; :mod:`footprint_uq.uncertainty.budget` converts).  Three parameters are
perturbations with nominal value 0: the ground offset ``ground_dz_m`` and the
ground slopes ``ground_slope_x``/``ground_slope_y`` (dimensionless gradients
dz/dx, dz/dy of the ground plane, pivoting about the camera's foot point).
``height_m`` is the height of the camera centre above the nominal ground plane.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PARAM_NAMES", "N_PARAMS", "IDX", "DIST_SLICE", "param_index", "INTRINSIC_NAMES", "PAPER_COLUMNS"]

PARAM_NAMES: tuple[str, ...] = (
    "fx_px", "fy_px", "cx_px", "cy_px", "skew_px",
    "k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6",
    "x_m", "y_m", "height_m",
    "pan_rad", "tilt_rad", "roll_rad",
    "ground_dz_m", "ground_slope_x", "ground_slope_y",
)
N_PARAMS = len(PARAM_NAMES)
IDX: dict[str, int] = {name: i for i, name in enumerate(PARAM_NAMES)}

# named integer constants for the kernels
FX, FY, CX, CY, SKEW = 0, 1, 2, 3, 4
K1, K2, P1, P2, K3, K4, K5, K6 = 5, 6, 7, 8, 9, 10, 11, 12
XM, YM, HM = 13, 14, 15
PAN, TILT, ROLL = 16, 17, 18
GDZ, GSX, GSY = 19, 20, 21
DIST_SLICE = slice(K1, K6 + 1)  # OpenCV order k1, k2, p1, p2, k3, k4, k5, k6


def param_index(names) -> np.ndarray:
    """Indices of ``names`` in :data:`PARAM_NAMES` (KeyError names the unknown one)."""
    return np.array([IDX[n] for n in names], dtype=np.intp)

#: the nine intrinsics a chessboard calibration estimates (OpenCV's order; pixels and dimensionless)
INTRINSIC_NAMES = ("fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2", "p1", "p2", "k3")
#: the columns of the paper's Table 2 (intrinsic standard deviations)
PAPER_COLUMNS = ("sigma_fx_px", "sigma_fy_px", "sigma_f_px", "sigma_c_px", "sigma_r_px",
                 "sigma_k1", "sigma_k2", "sigma_p1", "sigma_p2", "sigma_k3")
