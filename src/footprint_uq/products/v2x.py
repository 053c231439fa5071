"""V2X message confidence fields from 2x2 ground covariances.

Two message families are covered, both vectorised over leading dimensions
(``cov_m2`` is ``(..., 2, 2)``, every output an integer array of shape ``(...)``).

Frames and true north
---------------------
Covariances come in the camera's world frame W (x, y in metres).  W is tied to
the map by ``heading_offset_deg``: the compass bearing (degrees clockwise from
true north) of the world +y axis.  0 means W is already east/north.  Every field
below is computed after rotating the covariance into true east/north::

    [E]   [ cos h   sin h] [x]
    [N] = [-sin h   cos h] [y]

ETSI CPM (TS 103 324, data types of the Common Data Dictionary TS 102 894-2)
-------------------------------------------------------------------------------
For an RSU the CPM's perceived-object positions are in "the coordinate system in
which the y-axis corresponds to the North direction, the x-axis to the East
direction" (TS 103 324 ASN.1, ``PerceivedObjects``), so the x/y confidences are
the east/north confidences.

* ``CoordinateConfidence ::= INTEGER {outOfRange (4095), unavailable (4096)} (1..4096)``,
  unit 0.01 m, default confidence level 95 %.  The CDD text: ``n`` (0 < n < 4095)
  "if the confidence value is equal to or less than n x 0,01 metre, and greater
  than (n-1) x 0,01 metre"; 4095 "if the confidence value is greater than 40,94
  metres"; 4096 "if the confidence value is not available".  Hence
  ``n = ceil(c / 0.01)`` with ``c = 1.96 sigma`` (the 1-D 95 % quantile as
  quoted by the issue; the exact value 1.95996 differs by 0.002 %), clamped
  below at 1 (a zero sigma gives 1), 4095 above 40.94 m (and for +inf), 4096 for NaN.
  The ceiling is taken on ``c / 0.01`` minus 1e-9 so that a value exactly on a
  step (e.g. 0.05 m) is not pushed up by binary rounding.
* ``CorrelationCellValue ::= INTEGER {full-negative-correlation (-100), no-correlation (0),
  full-positive-correlation (100), unavailable (101)} (-100..101)``: the Bravais-Pearson
  coefficient times 100, as carried in the xPosition/yPosition cell of a
  PerceivedObject's ``lowerTriangularCorrelationMatrices``.  Rounded to nearest;
  101 when either variance is zero (the coefficient is undefined) or NaN.

SAE J2735
---------
* ``PositionalAccuracy ::= SEQUENCE {semiMajor, semiMinor, orientation}`` with
  ``SemiMajorAxisAccuracy ::= INTEGER (0..255)`` / ``SemiMinorAxisAccuracy``: "accuracy at
  one standard dev, range 0-12.7 meter, LSB = .05m, 254 = any value equal or greater
  than 12.70 meter, 255 = unavailable".  We take the 1-sigma ellipse semi-axes and
  round **up** (``ceil(s / 0.05)``, same 1e-9 guard) so the field never understates
  the error; values >= 12.70 m give 254 (so does the sliver 12.65 < s < 12.70 m,
  whose ceiling is 254), NaN gives 255.
* ``SemiMajorAxisOrientation ::= INTEGER (0..65535)``: "orientation of semi-major axis
  relative to true north (0~359.9945078786 degrees), LSB units of 360/65535 deg,
  a value of 65535 shall be used for orientation unavailable".  An ellipse axis is
  a line, so we report the bearing in [0, 180) rounded to nearest; 65535 for NaN.
  For a circular covariance (the two axes equal within 1e-9 relative) every
  orientation is correct and the value would be decided by rounding noise; it is
  then reported as 0 (true north), deterministically.
* ``PositionConfidence ::= ENUMERATED {unavailable (0), a500m (1), a200m (2), a100m (3),
  a50m (4), a20m (5), a10m (6), a5m (7), a2m (8), a1m (9), a50cm (10), a20cm (11),
  a10cm (12), a5cm (13), a2cm (14), a1cm (15)}`` at the 95 % level, as used by
  SDSM detected objects (``PositionConfidenceSet.pos``).  The 95 % radius is taken
  conservatively as the semi-major axis of the 95 % ellipse, ``2.4477 sqrt(lambda_max)``
  (the circle through it contains at least 95 % of a Gaussian).  Rule: the
  **smallest level whose radius is >= that 95 % radius**; if the radius exceeds
  500 m no level can state it without understating and the field is 0
  (unavailable); NaN gives 0.

Sources consulted (public ASN.1 and their generated code): the ETSI ITS CDD
markdown of ``CoordinateConfidence`` and ``CorrelationCellValue``, the ETSI forge
``cpm_ts103324`` ASN.1 (RSU frame east/north), J2735 2016 ``PositionalAccuracy``
comments (as reproduced in ``j2735_v2x_msgs`` and ``jpo-ode``) and the
``PositionConfidence`` enumeration of jpo-ode's ``J2735PositionConfidenceSet``.
"""

from __future__ import annotations

import numpy as np

from .._checks import as_float
from ..errors import InputError
from ..v2x_codes import (
    CIRCULAR_RTOL,
    CPM_COORD_MAX_M,
    CPM_COORD_OUT_OF_RANGE,
    CPM_COORD_UNAVAILABLE,
    CPM_COORD_UNIT_M,
    CPM_CORR_UNAVAILABLE,
    J2735_AXIS_MAX,
    J2735_AXIS_MAX_M,
    J2735_AXIS_UNAVAILABLE,
    J2735_AXIS_UNIT_M,
    J2735_ORIENTATION_UNAVAILABLE,
    J2735_ORIENTATION_UNIT_DEG,
    J2735_POSITION_CONFIDENCE_M,
    J2735_POSITION_CONFIDENCE_NAMES,
    K95_2D,
    PSD_RTOL,
    STEP_GUARD,
    Z95_1D,
)

__all__ = [
    "Z95_1D", "K95_2D", "CPM_COORD_OUT_OF_RANGE", "CPM_COORD_UNAVAILABLE", "CPM_CORR_UNAVAILABLE",
    "J2735_AXIS_MAX", "J2735_AXIS_UNAVAILABLE", "J2735_ORIENTATION_UNAVAILABLE",
    "J2735_POSITION_CONFIDENCE_M", "J2735_POSITION_CONFIDENCE_NAMES",
    "rotate_to_true_north", "cpm_coordinate_confidence", "cpm_correlation", "cpm_fields",
    "j2735_axis_accuracy", "j2735_orientation", "j2735_position_confidence", "j2735_fields",
]
# the code values above live in the floor module footprint_uq.v2x_codes (the compiled per-frame kernel
# encodes with them); this module re-exports them beside the rules that use them


def _cov(cov_m2) -> np.ndarray:
    c = np.asarray(cov_m2, dtype=np.float64)
    if c.ndim < 2 or c.shape[-2:] != (2, 2):
        raise InputError("cov_m2", getattr(cov_m2, "shape", cov_m2), "covariances of shape (..., 2, 2) in m^2")
    d = np.stack([c[..., 0, 0], c[..., 1, 1]], -1)
    if np.any(d < 0):
        bad = np.argwhere(d < 0)[0]
        raise InputError(f"cov_m2[{', '.join(map(str, bad[:-1]))}] variance", float(d[tuple(bad)]),
                         "variances >= 0 (NaN = unavailable)")
    a, b1, b2, dd = c[..., 0, 0], c[..., 0, 1], c[..., 1, 0], c[..., 1, 1]
    with np.errstate(invalid="ignore", over="ignore"):
        det = a * dd - b1 * b2
        scale = a * dd
        not_psd = np.isfinite(det) & np.isfinite(scale) & (det < -PSD_RTOL * scale)
        not_psd |= np.isfinite(b1) & np.isfinite(b2) & (np.abs(b1 - b2) > PSD_RTOL * np.sqrt(np.abs(scale)) + 0.0)
        not_psd |= np.isnan(b1) != np.isnan(a)  # an off-diagonal NaN with a known variance
    if np.any(not_psd):
        bad = tuple(int(i) for i in np.argwhere(not_psd)[0]) if not_psd.ndim else ()
        m = c[bad]
        raise InputError(f"cov_m2{list(bad) if bad else ''}", m.tolist(),
                         "a symmetric positive semi-definite covariance (m^2), or NaN = unavailable")
    return c


def rotate_to_true_north(cov_m2, heading_offset_deg: float = 0.0) -> np.ndarray:
    """Rotate world-frame covariances ``(..., 2, 2)`` into true east/north (see module doc)."""
    c = np.asarray(cov_m2, dtype=np.float64)
    h = np.deg2rad(as_float("heading_offset_deg", heading_offset_deg))
    if h == 0.0:
        return c
    ch, sh = np.cos(h), np.sin(h)
    R = np.array([[ch, sh], [-sh, ch]])
    return R @ c @ R.T


def _ceil_steps(value_m, unit_m):
    with np.errstate(invalid="ignore"):
        return np.ceil(value_m / unit_m * (1.0 - STEP_GUARD))


def cpm_coordinate_confidence(sigma_m) -> np.ndarray:
    """ETSI ``CoordinateConfidence`` (int, 1..4096) of 1-sigma values ``sigma_m`` (m, any shape)."""
    s = np.asarray(sigma_m, dtype=np.float64)
    if np.any(s < 0):
        raise InputError("sigma_m", float(s[s < 0].ravel()[0]), "standard deviations >= 0")
    conf = Z95_1D * s
    n = _ceil_steps(conf, CPM_COORD_UNIT_M)
    out = np.where(np.isnan(s), CPM_COORD_UNAVAILABLE,
                   np.where(conf > CPM_COORD_MAX_M, CPM_COORD_OUT_OF_RANGE,
                            np.clip(np.nan_to_num(n, nan=1.0, posinf=4094.0), 1, 4094)))
    return out.astype(np.int32)


def cpm_correlation(cov_m2) -> np.ndarray:
    """ETSI ``CorrelationCellValue`` of x and y (int, -100..100, 101 unavailable)."""
    c = _cov(cov_m2)
    sxx, syy, sxy = c[..., 0, 0], c[..., 1, 1], 0.5 * (c[..., 0, 1] + c[..., 1, 0])
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = sxy / np.sqrt(sxx * syy)
        ok = np.isfinite(rho) & (sxx > 0) & (syy > 0)
        code = np.clip(np.rint(np.where(ok, rho, 0.0) * 100.0), -100, 100)
    return np.where(ok, code, CPM_CORR_UNAVAILABLE).astype(np.int32)


def cpm_fields(cov_m2, heading_offset_deg: float = 0.0) -> dict[str, np.ndarray]:
    """CPM confidence fields of world-frame covariances ``(..., 2, 2)`` (m^2).

    Returns
    -------
    dict of int32 arrays, shape (...)
        ``cpm_x_confidence`` and ``cpm_y_confidence`` (``CoordinateConfidence``, east and
        north, 0.01 m at 95 %), ``cpm_xy_correlation`` (``CorrelationCellValue``).
    """
    c = rotate_to_true_north(_cov(cov_m2), heading_offset_deg)
    with np.errstate(invalid="ignore"):
        sx, sy = np.sqrt(np.maximum(c[..., 0, 0], 0.0)), np.sqrt(np.maximum(c[..., 1, 1], 0.0))
    sx = np.where(np.isnan(c[..., 0, 0]), np.nan, sx)
    sy = np.where(np.isnan(c[..., 1, 1]), np.nan, sy)
    return {
        "cpm_x_confidence": cpm_coordinate_confidence(sx),
        "cpm_y_confidence": cpm_coordinate_confidence(sy),
        "cpm_xy_correlation": cpm_correlation(c),
    }


def _axes(c):
    a, b, d = c[..., 0, 0], 0.5 * (c[..., 0, 1] + c[..., 1, 0]), c[..., 1, 1]
    mean = 0.5 * (a + d)
    rad = np.hypot(0.5 * (a - d), b)
    l1 = mean + rad
    l2 = np.maximum(mean - rad, 0.0)
    # one infinite variance (finite covariance term): the other axis keeps its value, never "unavailable"
    l2 = np.where(np.isinf(a) & np.isfinite(d) & np.isfinite(b), d,
                  np.where(np.isinf(d) & np.isfinite(a) & np.isfinite(b), a, l2))
    ang = 0.5 * np.degrees(np.arctan2(2.0 * b, a - d))  # ccw from east, (-90, 90]
    return np.sqrt(l1), np.sqrt(l2), ang


def j2735_axis_accuracy(sigma_m) -> np.ndarray:
    """J2735 ``SemiMajorAxisAccuracy``/``SemiMinorAxisAccuracy`` (int, 0..255) of 1-sigma values (m)."""
    s = np.asarray(sigma_m, dtype=np.float64)
    if np.any(s < 0):
        raise InputError("sigma_m", float(s[s < 0].ravel()[0]), "standard deviations >= 0")
    n = _ceil_steps(s, J2735_AXIS_UNIT_M)
    out = np.where(np.isnan(s), J2735_AXIS_UNAVAILABLE,
                   np.where(s >= J2735_AXIS_MAX_M, J2735_AXIS_MAX,
                            np.clip(np.nan_to_num(n, nan=0.0, posinf=254.0), 0, J2735_AXIS_MAX)))
    return out.astype(np.int32)


def j2735_orientation(bearing_deg) -> np.ndarray:
    """J2735 ``SemiMajorAxisOrientation`` (int) of axis bearings (deg clockwise from true north)."""
    b = np.mod(np.asarray(bearing_deg, dtype=np.float64), 180.0)
    with np.errstate(invalid="ignore"):
        code = np.rint(b / J2735_ORIENTATION_UNIT_DEG)
    return np.where(np.isnan(b), J2735_ORIENTATION_UNAVAILABLE, np.nan_to_num(code)).astype(np.int32)


def j2735_position_confidence(radius95_m) -> np.ndarray:
    """J2735 ``PositionConfidence`` (int, 0..15) of 95 % radii (m): smallest level >= the radius."""
    r = np.asarray(radius95_m, dtype=np.float64)
    if np.any(r < 0):
        raise InputError("radius95_m", float(r[r < 0].ravel()[0]), "radii >= 0")
    levels = np.asarray(J2735_POSITION_CONFIDENCE_M[1:])  # decreasing 500 .. 0.01
    # number of levels whose radius is >= r (they come first): that count is the code
    with np.errstate(invalid="ignore"):
        count = (levels[None, :] >= (r.reshape(-1, 1) * (1.0 - STEP_GUARD))).sum(-1).reshape(r.shape)
    return np.where(np.isnan(r), 0, count).astype(np.int32)


def j2735_fields(cov_m2, heading_offset_deg: float = 0.0) -> dict[str, np.ndarray]:
    """J2735 fields of world-frame covariances ``(..., 2, 2)`` (m^2).

    Returns
    -------
    dict of int32 arrays, shape (...)
        ``j2735_semi_major``, ``j2735_semi_minor`` (0.05 m, 1 sigma), ``j2735_orientation``
        (360/65535 deg from true north) and ``j2735_position_confidence`` (95 %, enumeration).
    """
    c = rotate_to_true_north(_cov(cov_m2), heading_offset_deg)
    with np.errstate(invalid="ignore"):
        a, b, ang = _axes(c)
    bearing = np.mod(90.0 - ang, 180.0)  # ang is ccw from east in the true east/north frame
    with np.errstate(invalid="ignore"):
        circular = np.isfinite(a) & ((a * a - b * b) <= CIRCULAR_RTOL * (a * a + b * b))
    bearing = np.where(circular, 0.0, bearing)
    return {
        "j2735_semi_major": j2735_axis_accuracy(a),
        "j2735_semi_minor": j2735_axis_accuracy(b),
        "j2735_orientation": j2735_orientation(bearing),
        "j2735_position_confidence": j2735_position_confidence(K95_2D * a),
    }
