"""Object footprints: ground corners, their joint covariance, largest point, centre.

Implements the paper's section "Estimating uncertainty of bounding box": the
uncertainty of a detected object is reported as

* the **largest point uncertainty** -- the footprint corner with the largest 1-sigma
  semi-major axis, the paper's upper bound on the positional uncertainty -- and
* the **footprint centre** -- the vertex mean of the footprint's ground corners
  (:func:`footprint_centre`), with its covariance propagated from the joint covariance of
  all corners through its (constant) Jacobian.  It is linear in the corners, so its
  covariance is exact for the corners' covariance and its linearity is theirs.  The area
  centroid (:func:`polygon_centroid`) divides by the polygon's area: a thin far footprint
  (a car broadside at 90 m is 2 px tall) flips orientation in some noise draws and the
  centroid then has no finite variance -- its linear semi-major axis was 11 times too small
  in the issue-21 reproducer (docs/uncertainty-model.md, "The footprint centre").  For a box's footprint (a
  parallelogram on the ground) the two are the same point.

Inputs, one call per frame of N detections
------------------------------------------
(a) :func:`footprints_from_boxes2d` -- axis-aligned image boxes ``(N, 4)`` =
    ``u_min, v_min, u_max, v_max`` (px).  The ground contact is the bottom edge ``v_max``:
    ``contact="bottom-centre"`` uses one point ``((u_min + u_max) / 2, v_max)`` (K = 1);
    ``contact="bottom-corners"`` the two points ``(u_min, v_max)``, ``(u_max, v_max)`` (K = 2).
    For K = 1 the "centre" is that point; for K = 2 it is the midpoint of the two.
(b) :func:`footprints_from_boxes3d` -- 3D boxes in the world ``(N, 7)`` =
    ``x_m, y_m, z_m, length_m, width_m, height_m, yaw`` (centre in frame W; yaw the
    direction of the length axis, counter-clockwise from +x (east), in radians -- column
    ``yaw_rad`` -- or degrees with ``yaw_unit="deg"`` -- column ``yaw_deg``).  The footprint
    is the quadrilateral of the four bottom corners, ordered counter-clockwise in W
    starting rear-right: (-l/2, -w/2), (+l/2, -w/2), (+l/2, +w/2), (-l/2, +w/2) in the
    box frame.  With ``bottom_on_ground=True`` (default) the bottom face is put on the
    ground plane (``z_m`` and ``height_m`` then only place the box, not its footprint);
    with False the corners are at ``z_m - height_m / 2``, and a bottom above the ground
    back-projects to where its ray meets the ground (a bias, not an uncertainty).
    The corners are projected into the image (``camera.project``) and back-projected
    with uncertainty, so the result is what an image-based detector would report.
(c) :func:`footprints_from_corners` -- footprint corners directly in pixels ``(N, K, 2)``,
    in polygon order (either orientation).

Detector noise (the paper: "the analysis extends to deep-learning detectors")
-----------------------------------------------------------------------------
``pixel_cov_px2`` is a probabilistic detector's own pixel covariance, added to the
budget's per-point imaging and resolution noise:

* ``(N, 2, 2)`` -- one covariance per detection, applied to each corner independently;
* ``(N, K, 2, 2)`` -- one per corner, independent between corners;
* ``(N, 2K, 2K)`` -- full, correlated between corners;
* for 2D boxes also ``box_cov_px2`` ``(N, 4, 4)`` (or ``(N, 4)`` standard deviations) on
  ``u_min, v_min, u_max, v_max`` as detectors with box-regression variance output it;
  it is mapped to the contact points through the (linear) contact-point map, so the
  two bottom corners share the ``v_max`` error.

Camera-level errors (:meth:`ErrorBudget.param_covariance`) are shared by all corners of
all objects in a frame and couple the corners (:func:`footprint_uq.uncertainty.propagation.propagate_joint`
semantics); per-point noise only fills the diagonal 2x2 blocks (or the detector's
cross terms).

Partial visibility
------------------
Each corner carries a :mod:`footprint_uq.status` code.  ``OUTSIDE_IMAGE`` corners (not
observed: they lie outside the image) are still back-projected -- their numbers are
kept and finite -- but they are not *usable* unless ``allow_outside_image=True``.
``ABOVE_HORIZON``, ``BEHIND_CAMERA`` (3D corners), ``UNDISTORT_FAILED`` and
``NOT_FINITE`` corners are NaN.  The largest point is taken over the usable corners
(NaN and index -1 if none); the centre needs every corner usable and, for K >= 3, a polygon
of non-zero area, otherwise it is NaN and ``centre_reason`` says why (the code of the first
unusable corner and its index, or :data:`DEGENERATE`).

Two paths, same numbers
-----------------------
The ``footprints_from_*`` functions are the readable numpy reference (built on
``camera.backproject`` and :mod:`footprint_uq.uncertainty.propagation` semantics).  For every-frame
use next to a detector, :class:`FrameProcessor` prepares the camera and budget once and
runs one fused numba kernel per frame (:mod:`footprint_uq.fast.footprint_kernels`); its
results agree with the reference to 1e-9 relative.  One frame of 100 3D boxes takes
about 75 us (pan-tilt) / 90 us (OpenCV with distortion) on the 2-core reference machine
(``bench/bench_footprints.py``).

The V2X fields describe the centre.  For the paper's conservative upper bound, apply
:func:`footprint_uq.products.v2x.cpm_fields` / :func:`~footprint_uq.products.v2x.j2735_fields` to
``largest_cov_m2`` instead.

The linearity flag
------------------
Every corner carries ``nonlinearity`` (predicted relative error of its linear 1-sigma
semi-major axis; :func:`footprint_uq.propagation.nonlinearity`, computed in the kernel), the
largest point its corner's, the centre the largest of its corners' (the centre is linear in the
corners: all of its non-linearity is theirs); ``*_linear_ok`` is
``nonlinearity <= linear_threshold``.  Where the centre is not ``linear_ok`` the V2X fields
follow ``v2x_policy`` (:data:`V2X_POLICIES`; docs/uncertainty-model.md, "Policy for the V2X
fields"): by default the larger of the linear and a seeded Monte-Carlo covariance of the
centre (:func:`centre_covariance_sampled`, only the flagged objects, common random numbers),
or "unavailable" beyond nonlinearity 0.5; ``v2x_source`` says which.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from .. import status
from .._checks import COV_PSD_RTOL, as_float, as_int, as_points, check_cov
from .._notices import before_kernels
from ..errors import InputError
from ..fast import footprint_kernels as fk
from ..fast.buffers import thread_buffer
from ..fast.cov_checks import first_bad_cov2
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import ellipse_axes
from ..uncertainty.propagation import (
    DEFAULT_LINEAR_THRESHOLD,
    V2X_COV_LINEAR,
    V2X_COV_SAMPLED,
    V2X_COV_UNAVAILABLE,
    check_linear_threshold,
    nonlinearity_of_jacobians,
    sample_params,
)
from .v2x import cpm_fields, j2735_fields

__all__ = [
    "FootprintEstimate", "FrameProcessor", "V2X_FIELDS", "DEGENERATE", "CONTACT_MODES", "BOX3D_COLUMNS",
    "V2X_POLICIES", "box2d_contact_points", "box3d_bottom_corners", "polygon_centroid", "footprint_centre",
    "footprints_from_corners",
    "footprints_from_boxes2d", "footprints_from_boxes3d", "centre_covariance_sampled",
]

#: centre reason code: zero-area footprint polygon (K >= 3: not a footprint)
DEGENERATE = status.DEGENERATE
_CENTRE_TEXT = {DEGENERATE: status.REASONS[DEGENERATE]}
CONTACT_MODES = ("bottom-centre", "bottom-corners")
BOX3D_COLUMNS = ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m", "yaw_rad")
#: column order of :attr:`FootprintEstimate.v2x_codes`
V2X_FIELDS = ("cpm_x_confidence", "cpm_y_confidence", "cpm_xy_correlation", "j2735_semi_major",
              "j2735_semi_minor", "j2735_orientation", "j2735_position_confidence")
#: what the V2X fields encode where the centre is not ``linear_ok`` (docs/uncertainty-model.md): "sampled" (the
#: documented policy: the larger of the linear and a seeded Monte-Carlo covariance, "unavailable" beyond
#: nonlinearity 0.5), "unavailable" (no sampling: every such centre is encoded "unavailable"), "linear" (the
#: linear covariance regardless of the flag)
V2X_POLICIES = ("sampled", "unavailable", "linear")
#: V2X policy: above this nonlinearity the centre's fields are "unavailable" (no ellipse describes the spread)
V2X_UNAVAILABLE_ABOVE = 0.5
#: V2X policy: fewer samples than this share meeting the ground -> "unavailable"
V2X_MIN_FRACTION_VALID = 0.999
#: V2X policy: Monte-Carlo samples per flagged centre (common random numbers, seed ``v2x_seed``)
V2X_SAMPLES = 2000


@dataclass
class FootprintEstimate:
    """Footprints of N objects with K corners each (leading dimension N everywhere).

    Attributes
    ----------
    corners_px : (N, K, 2)             corners in the image (u, v), px
    corners_xy_world_m : (N, K, 2)     ground corners in W, m (NaN where not computable)
    corners_cov_m2 : (N, K, 2, 2)      per-corner covariance, m^2
    joint_cov_m2 : (N, 2K, 2K)         joint covariance, order x0, y0, x1, y1, ...
    corner_reason : (N, K) int8        :mod:`footprint_uq.status` code per corner
    corner_usable : (N, K) bool        corner enters the largest point / centre
    largest_index : (N,) int           corner with the largest semi-major axis (-1: none usable)
    largest_semi_major_m : (N,)        its 1-sigma semi-major axis, m (the paper's upper bound)
    largest_xy_world_m : (N, 2), largest_cov_m2 : (N, 2, 2)
    centre_xy_world_m : (N, 2)         vertex mean of the corners (:func:`footprint_centre`; K = 2 the
                                       midpoint, K = 1 the point)
    centre_cov_m2 : (N, 2, 2)
    centre_valid : (N,) bool
    centre_reason : (N,) int           0, the status code of the first unusable corner, or DEGENERATE
    centre_bad_corner : (N,) int       index of that corner (-1 if none)
    area_m2 : (N,)                     signed shoelace area (positive = counter-clockwise in W)
    v2x_codes : (N, 7) int32           CPM and J2735 fields of the centre covariance, columns
                                       :data:`V2X_FIELDS` (see :mod:`footprint_uq.products.v2x`); :attr:`v2x` as a dict;
                                       where the centre is not ``linear_ok`` they follow ``v2x_source``
    heading_offset_deg : float         used for the V2X fields
    corners_nonlinearity : (N, K)      the linearity flag of each corner (its 2x2 covariance; NaN where not
                                       computed): predicted relative error of the linear 1-sigma semi-major axis
    centre_nonlinearity : (N,)         the centre's: the largest of its corners' (it is linear in them; NaN
                                       without a centre)
    largest_nonlinearity : (N,)        the largest point's (its corner's; NaN without one)
    linear_threshold : float           ``*_linear_ok = *_nonlinearity <= linear_threshold`` (properties)
    v2x_source : (N,) int8             what the V2X fields encode: 0 the linear centre covariance, 1 a sampled
                                       one (larger), 2 "unavailable" (:data:`V2X_POLICIES`; no centre: 2)
    centre_shared_m : (N, 2, r) or None  the centre's whitened parameter Jacobian ``B = dC/dp L``
                                       (``L L^T`` = the budget's parameter covariance, r its rank): the
                                       calibration error moves the centre by ``B w`` with one ``w ~ N(0, I_r)``
                                       shared by every object and frame of the camera; ``B B^T`` is the
                                       camera-level part of ``centre_cov_m2`` (:attr:`centre_cov_shared_m2`),
                                       the rest is new every frame (:attr:`centre_cov_frame_m2`).  NaN without
                                       a centre; None from a :class:`FrameProcessor` not asked for it
    object_rows : (R, N) or None       the fused kernel's per-object rows
                                       (:data:`footprint_uq.fast.footprint_kernels.OBJ_ROW` names them;
                                       the batch reads its columns from them); None from the reference

    ``joint_cov_m2`` is None when a :class:`FrameProcessor` was asked not to form it; the flag's arrays
    are None when it was not computed (``linearity=False``), ``corners_nonlinearity`` has 0 rows when the
    batch's lean mode skips per-corner outputs.
    """

    corners_px: np.ndarray
    corners_xy_world_m: np.ndarray
    corners_cov_m2: np.ndarray
    joint_cov_m2: np.ndarray
    corner_reason: np.ndarray
    corner_usable: np.ndarray
    largest_index: np.ndarray
    largest_semi_major_m: np.ndarray
    largest_xy_world_m: np.ndarray
    largest_cov_m2: np.ndarray
    centre_xy_world_m: np.ndarray
    centre_cov_m2: np.ndarray
    centre_valid: np.ndarray
    centre_reason: np.ndarray
    centre_bad_corner: np.ndarray
    area_m2: np.ndarray
    v2x_codes: np.ndarray
    heading_offset_deg: float = 0.0
    corners_nonlinearity: np.ndarray | None = None
    centre_nonlinearity: np.ndarray | None = None
    largest_nonlinearity: np.ndarray | None = None
    linear_threshold: float = DEFAULT_LINEAR_THRESHOLD
    v2x_source: np.ndarray | None = None
    object_rows: np.ndarray | None = None
    centre_shared_m: np.ndarray | None = None
    #: (N, 2, 2) the covariance the V2X fields encode where it is not ``centre_cov_m2`` (a flagged centre: the
    #: sampled one, or NaN for "unavailable"); None when it is ``centre_cov_m2`` for every object
    v2x_cov_m2: np.ndarray | None = None

    def _ok(self, nl):
        if nl is None:
            return None
        return nl <= self.linear_threshold  # NaN (not computed) -> False (comparisons with NaN do not warn)

    @property
    def corners_linear_ok(self) -> np.ndarray | None:
        """(N, K) bool: ``corners_nonlinearity <= linear_threshold`` (False where not computed)."""
        return self._ok(self.corners_nonlinearity)

    @property
    def centre_linear_ok(self) -> np.ndarray | None:
        """(N,) bool: ``centre_nonlinearity <= linear_threshold`` (False without a centre)."""
        return self._ok(self.centre_nonlinearity)

    @property
    def largest_linear_ok(self) -> np.ndarray | None:
        """(N,) bool: ``largest_nonlinearity <= linear_threshold`` (False without a largest point)."""
        return self._ok(self.largest_nonlinearity)

    @property
    def centre_cov_shared_m2(self) -> np.ndarray | None:
        """(N, 2, 2) the camera-level (calibration) part ``B B^T`` of ``centre_cov_m2``, m^2: the same error in
        every frame (None without :attr:`centre_shared_m`)."""
        B = self.centre_shared_m
        if B is None:
            return None
        out = np.empty(B.shape[:-2] + (2, 2))  # (three sums: a stacked (N, 2, r) matmul costs ~10x more)
        b0, b1 = B[..., 0, :], B[..., 1, :]
        out[..., 0, 0] = np.einsum("...i,...i->...", b0, b0)
        out[..., 0, 1] = out[..., 1, 0] = np.einsum("...i,...i->...", b0, b1)
        out[..., 1, 1] = np.einsum("...i,...i->...", b1, b1)
        return out

    @property
    def centre_cov_frame_m2(self) -> np.ndarray | None:
        """(N, 2, 2) the per-frame part of ``centre_cov_m2`` (imaging, resolution, detector noise), m^2:
        ``centre_cov_m2 - centre_cov_shared_m2`` (None without :attr:`centre_shared_m`)."""
        shared = self.centre_cov_shared_m2
        return None if shared is None else self.centre_cov_m2 - shared

    @property
    def v2x(self) -> dict[str, np.ndarray]:
        """The V2X fields as a dict of (N,) int32 arrays keyed by :data:`V2X_FIELDS`."""
        return {name: self.v2x_codes[:, i] for i, name in enumerate(V2X_FIELDS)}

    def __len__(self) -> int:
        return int(self.centre_valid.shape[0])

    @property
    def n_corners(self) -> int:
        return int(self.corners_px.shape[1])

    def centre_reason_text(self) -> np.ndarray:
        """Object array (N,) of human-readable reasons ("ok" where the centre is valid)."""
        out = np.empty(len(self), dtype=object)
        K = self.n_corners
        for i, (code, k) in enumerate(zip(self.centre_reason.tolist(), self.centre_bad_corner.tolist(), strict=True)):
            if code == status.OK:
                out[i] = "ok"
            elif code in _CENTRE_TEXT:
                out[i] = _CENTRE_TEXT[code]
            else:
                out[i] = f"corner {k} of {K}: {status.REASONS[code]}"
        return out

    def centre_ellipse(self, confidence: float | None = None):
        """``(semi_major_m, semi_minor_m, orientation_deg)`` of the centre covariance."""

        return ellipse_axes(self.centre_cov_m2, confidence=confidence)


# -- geometry ------------------------------------------------------------------------------
def box2d_contact_points(boxes_px, contact: str = "bottom-centre"):
    """Ground-contact pixels of axis-aligned boxes and the linear map from the box.

    Parameters
    ----------
    boxes_px : array_like (N, 4)
        ``u_min, v_min, u_max, v_max`` in pixels.
    contact : {"bottom-centre", "bottom-corners"}

    Returns
    -------
    corners_px : (N, K, 2), K = 1 or 2
    A : (2K, 4)
        ``corners.reshape(N, 2K) = boxes @ A.T`` (for mapping box covariances).
    """
    b = as_points("boxes_px", boxes_px, 4)
    if b.ndim != 2:
        raise InputError("boxes_px", b.shape, "an array of shape (N, 4): u_min, v_min, u_max, v_max")
    if contact == "bottom-centre":
        A = np.array([[0.5, 0.0, 0.5, 0.0], [0.0, 0.0, 0.0, 1.0]])
    elif contact == "bottom-corners":
        A = np.array([[1.0, 0, 0, 0], [0, 0, 0, 1.0], [0, 0, 1.0, 0], [0, 0, 0, 1.0]])
    else:
        raise InputError("contact", contact, f"one of {CONTACT_MODES}")
    K = A.shape[0] // 2
    with np.errstate(invalid="ignore"):
        bad = (b[:, 2] < b[:, 0]) | (b[:, 3] < b[:, 1])
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"boxes_px[{i}]", b[i].tolist(), "u_min <= u_max and v_min <= v_max")
    return (b @ A.T).reshape(-1, K, 2), A


def box3d_bottom_corners(boxes_world, *, yaw_unit: str = "rad", bottom_on_ground: bool = True,
                         ground_z_m: float = 0.0) -> np.ndarray:
    """Bottom corners ``(N, 4, 3)`` of 3D boxes ``(N, 7)`` in W (order: see the module doc)."""
    b = as_points("boxes_world", boxes_world, 7)
    if b.ndim != 2:
        raise InputError("boxes_world", b.shape, f"an array of shape (N, 7): {', '.join(BOX3D_COLUMNS)}")
    if yaw_unit not in ("rad", "deg"):
        raise InputError("yaw_unit", yaw_unit, "'rad' (column yaw_rad) or 'deg' (column yaw_deg)")
    with np.errstate(invalid="ignore"):
        bad = (b[:, 3] < 0) | (b[:, 4] < 0) | (b[:, 5] < 0)
    if np.any(bad):
        i = int(np.flatnonzero(bad)[0])
        raise InputError(f"boxes_world[{i}] (length_m, width_m, height_m)", b[i, 3:6].tolist(), "sizes >= 0")
    yaw = b[:, 6] if yaw_unit == "rad" else np.deg2rad(b[:, 6])
    with np.errstate(invalid="ignore"):  # an infinite yaw gives NaN corners: flagged NOT_FINITE downstream
        c, s = np.cos(yaw), np.sin(yaw)
    hl, hw = 0.5 * b[:, 3], 0.5 * b[:, 4]
    sl = np.array([-1.0, 1.0, 1.0, -1.0])
    sw = np.array([-1.0, -1.0, 1.0, 1.0])
    dl = sl[None, :] * hl[:, None]
    dw = sw[None, :] * hw[:, None]
    x = b[:, 0:1] + c[:, None] * dl - s[:, None] * dw
    y = b[:, 1:2] + s[:, None] * dl + c[:, None] * dw
    z = np.full_like(x, ground_z_m) if bottom_on_ground else np.broadcast_to(
        (b[:, 2] - 0.5 * b[:, 5])[:, None], x.shape)
    return np.stack([x, y, z], -1)


def polygon_centroid(xy_m, *, get_gradients: bool = False):
    """Area centroid of polygons ``(..., K, 2)`` (shoelace), with its Jacobian.

    Not the footprint centre the estimates report (:func:`footprint_centre`, the vertex mean): the
    area centroid divides by the area, so its linear covariance is wrong wherever noise can fold the
    polygon (docs/uncertainty-model.md, "The footprint centre").

    K = 1: the point; K = 2: the midpoint; K >= 3: ``C = sum (p_i + p_{i+1}) c_i / (6 A)``
    with ``c_i = x_i y_{i+1} - x_{i+1} y_i`` and ``A = sum c_i / 2``.  Coordinates are
    shifted to the vertex mean first (the centroid is translation-equivariant and its
    Jacobian translation-invariant), which keeps far-from-origin polygons accurate.

    Returns
    -------
    centroid : (..., 2)        NaN where the area is zero
    area : (...)               signed area (K < 3: 0)
    dC_dxy : (..., 2, 2K)      only with ``get_gradients``; columns x0, y0, x1, y1, ...
    """
    p = as_points("xy_m", xy_m, 2)
    K = p.shape[-2]
    lead = p.shape[:-2]
    if K < 3:
        C = p.mean(-2)
        if not get_gradients:
            return C, np.zeros(lead)
        G = np.zeros(lead + (2, 2 * K))
        G[..., 0, 0::2] = 1.0 / K
        G[..., 1, 1::2] = 1.0 / K
        return C, np.zeros(lead), G
    m = p.mean(-2, keepdims=True)
    q = p - m
    x, y = q[..., 0], q[..., 1]
    xn, yn = np.roll(x, -1, -1), np.roll(y, -1, -1)
    xp, yp = np.roll(x, 1, -1), np.roll(y, 1, -1)
    c = x * yn - xn * y
    A = 0.5 * c.sum(-1)
    Sx = ((x + xn) * c).sum(-1)
    Sy = ((y + yn) * c).sum(-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        deg = ~(np.abs(A) > 1e-12 * np.maximum((q * q).sum((-1, -2)), 1e-300))
        inv6A = np.where(deg, np.nan, 1.0 / (6.0 * A))
    C = np.stack([Sx * inv6A, Sy * inv6A], -1) + m[..., 0, :]
    if not get_gradients:
        return C, A
    cp = np.roll(c, 1, -1)
    dA_dx = 0.5 * (yn - yp)
    dA_dy = 0.5 * (xp - xn)
    dSx_dx = c + cp + (x + xn) * yn - (xp + x) * yp
    dSx_dy = -(x + xn) * xn + (xp + x) * xp
    dSy_dx = (y + yn) * yn - (yp + y) * yp
    dSy_dy = c + cp - (y + yn) * xn + (yp + y) * xp
    Cx_l, Cy_l = Sx * inv6A, Sy * inv6A
    G = np.empty(lead + (2, 2 * K))
    G[..., 0, 0::2] = (dSx_dx - 6.0 * Cx_l[..., None] * dA_dx) * inv6A[..., None]
    G[..., 0, 1::2] = (dSx_dy - 6.0 * Cx_l[..., None] * dA_dy) * inv6A[..., None]
    G[..., 1, 0::2] = (dSy_dx - 6.0 * Cy_l[..., None] * dA_dx) * inv6A[..., None]
    G[..., 1, 1::2] = (dSy_dy - 6.0 * Cy_l[..., None] * dA_dy) * inv6A[..., None]
    return C, A, G


def footprint_centre(xy_m, *, get_gradients: bool = False):
    """The footprint centre of polygons ``(..., K, 2)``: the vertex mean, with the polygon's area.

    The centre every path reports (docs/uncertainty-model.md, "The footprint centre"): the mean of the
    K corners, ``C = sum p_k / K`` -- linear in the corners, so it cannot invert whatever the noise does
    to the polygon (the area centroid, :func:`polygon_centroid`, divides by the area and has no finite
    variance once the area's sign can flip).  For the footprint of a box (a parallelogram on the ground)
    the two coincide.

    Returns
    -------
    centre : (..., 2)          NaN where K >= 3 and the polygon has zero area (:data:`DEGENERATE`)
    area : (...)               signed shoelace area, m^2 (K < 3: 0)
    dC_dxy : (..., 2, 2K)      only with ``get_gradients``: the constant ``(1/K) [I I ... I]``
    """
    p = as_points("xy_m", xy_m, 2)
    K = p.shape[-2]
    lead = p.shape[:-2]
    m = p.mean(-2)
    if K < 3:
        area = np.zeros(lead)
        C = m
    else:
        q = p - m[..., None, :]
        x, y = q[..., 0], q[..., 1]
        area = 0.5 * (x * np.roll(y, -1, -1) - np.roll(x, -1, -1) * y).sum(-1)
        with np.errstate(invalid="ignore"):
            deg = ~(np.abs(area) > 1e-12 * np.maximum((q * q).sum((-1, -2)), 1e-300))
        C = np.where(deg[..., None], np.nan, m)
    if not get_gradients:
        return C, area
    G = np.zeros(lead + (2, 2 * K))
    G[..., 0, 0::2] = 1.0 / K
    G[..., 1, 1::2] = 1.0 / K
    return C, area, G


# -- pixel covariances -----------------------------------------------------------------------
def _detector_joint_cov(pixel_cov_px2, N: int, K: int) -> np.ndarray | None:
    """Detector covariance as (N, 2K, 2K) (None if not given)."""
    if pixel_cov_px2 is None:
        return None
    c = np.asarray(pixel_cov_px2, dtype=np.float64)
    if c.shape == (N, 2, 2):
        check_cov("pixel_cov_px2", c, 2)
        out = np.zeros((N, 2 * K, 2 * K))
        for k in range(K):
            out[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = c
        return out
    if c.shape == (N, K, 2, 2):
        check_cov("pixel_cov_px2", c, 2)
        out = np.zeros((N, 2 * K, 2 * K))
        for k in range(K):
            out[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = c[:, k]
        return out
    if c.shape == (N, 2 * K, 2 * K):
        return check_cov("pixel_cov_px2", c, 2 * K)
    raise InputError("pixel_cov_px2", c.shape, f"shape ({N}, 2, 2), ({N}, {K}, 2, 2) or ({N}, {2 * K}, {2 * K})")


def _box_cov_to_corners(box_cov_px2, A: np.ndarray, N: int) -> np.ndarray:
    c = np.asarray(box_cov_px2, dtype=np.float64)
    if c.shape == (N, 4):
        if not np.all(np.isfinite(c)) or np.any(c < 0):
            raise InputError("box_cov_px2", "negative or non-finite sigma", "standard deviations >= 0 (N, 4)")
        c = c[:, :, None] * np.eye(4) * c[:, None, :]
    elif c.shape == (N, 4, 4):
        check_cov("box_cov_px2", c, 4)
    else:
        raise InputError("box_cov_px2", c.shape, f"shape ({N}, 4, 4) (covariance) or ({N}, 4) (sigmas)")
    return A @ c @ A.T


# -- the reference path ----------------------------------------------------------------------
def footprints_from_corners(camera, budget, corners_px, *, pixel_cov_px2=None, allow_outside_image: bool = False,
                            heading_offset_deg: float = 0.0, linearity: bool = True,
                            linear_threshold: float = DEFAULT_LINEAR_THRESHOLD, v2x_policy: str = "sampled",
                            v2x_samples: int = V2X_SAMPLES, v2x_seed: int = 0,
                            extra_reason=None) -> FootprintEstimate:
    """Footprint estimates of N objects from their corners in pixels ``(N, K, 2)``.

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    corners_px : array_like (N, K, 2)
        Footprint corners (u, v) in polygon order; K = 1 and 2 are accepted (see module doc).
    pixel_cov_px2 : array_like, optional
        Detector pixel covariance, ``(N, 2, 2)``, ``(N, K, 2, 2)`` or ``(N, 2K, 2K)``, px^2.
    allow_outside_image : bool
        Let corners outside the image enter the largest point and the centre.
    heading_offset_deg : float
    extra_reason : array_like (N, K) int8, optional
        Status codes that override OK per corner (e.g. BEHIND_CAMERA from a 3D box's projection).
        Bearing of the world +y axis from true north, for the V2X fields.
    linearity : bool
        Compute the linearity flag (per corner, largest point, centre; see :class:`FootprintEstimate`).
    linear_threshold : float
        ``linear_ok = nonlinearity <= linear_threshold`` (default 0.05).
    v2x_policy : {"sampled", "unavailable", "linear"}
        What the V2X fields encode where the centre is not ``linear_ok`` (:data:`V2X_POLICIES`;
        docs/uncertainty-model.md, "Policy for the V2X fields").
    v2x_samples, v2x_seed : int
        Monte-Carlo samples per flagged centre and their seed (policy "sampled";
        :func:`centre_covariance_sampled`).

    Returns
    -------
    FootprintEstimate
    """
    thr, v2x_samples = _check_flag_options(linear_threshold, v2x_policy, v2x_samples)
    budget = load_budget(budget)
    uv = as_points("corners_px", corners_px, 2)
    if uv.ndim != 3 or uv.shape[1] < 1:
        raise InputError("corners_px", uv.shape, "an array of shape (N, K, 2) with K >= 1")
    N, K = uv.shape[:2]
    det = _detector_joint_cov(pixel_cov_px2, N, K)
    bp = camera.backproject(uv, get_gradients=True)
    reason = bp.reason.copy()
    inside = camera.in_image(uv)
    reason[(reason == status.OK) & ~inside] = status.OUTSIDE_IMAGE
    if extra_reason is not None:  # e.g. BEHIND_CAMERA from the 3D projection
        reason = np.where(extra_reason != status.OK, extra_reason, reason).astype(np.int8)
    computed = bp.valid & ((reason == status.OK) | (reason == status.OUTSIDE_IMAGE))
    usable = computed & ((reason == status.OK) | allow_outside_image)
    xy = np.where(computed[..., None], bp.xy_world_m, np.nan)
    joint, ccov, Sp = _joint_covariance(budget, bp, det, computed)
    largest_index, largest_semi, largest_xy, largest_cov = _largest_point(xy, ccov, usable)
    any_usable, li, rows = largest_index >= 0, np.maximum(largest_index, 0), np.arange(N)
    centre, centre_cov, ok, centre_reason, centre_bad, area, shared = _centre(budget, bp, xy, joint, reason, usable,
                                                                            computed)
    fields = {**cpm_fields(centre_cov, heading_offset_deg), **j2735_fields(centre_cov, heading_offset_deg)}
    v2x = np.stack([fields[name] for name in V2X_FIELDS], -1).astype(np.int32)
    cnl = largest_nl = centre_nl = None
    if linearity:  # each corner's flag from its 2x2 covariance (budget + detector pixel noise on the diagonal)
        Suv_k = np.broadcast_to(budget.pixel_covariance(), (N, K, 2, 2))
        if det is not None:
            Suv_k = Suv_k + np.stack([det[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] for k in range(K)], 1)
        with np.errstate(invalid="ignore", over="ignore"):
            cnl = nonlinearity_of_jacobians(camera, budget, uv, ccov, bp.dxy_dp, bp.dxy_duv, Sp, Suv_k, computed)
        largest_nl = np.where(any_usable, cnl[rows, li], np.nan)
        centre_nl = np.where(ok, cnl.max(1), np.nan)  # the centre's flag: its worst corner's (NaN propagates)
    est = _mark_overflow(FootprintEstimate(
        corners_px=uv, corners_xy_world_m=xy, corners_cov_m2=ccov, joint_cov_m2=joint,
        corner_reason=reason.astype(np.int8), corner_usable=usable, largest_index=largest_index,
        largest_semi_major_m=largest_semi, largest_xy_world_m=largest_xy, largest_cov_m2=largest_cov,
        centre_xy_world_m=centre, centre_cov_m2=centre_cov, centre_valid=ok, centre_reason=centre_reason,
        centre_bad_corner=np.where(ok, -1, np.where(centre_reason == DEGENERATE, -1, centre_bad)),
        area_m2=area, v2x_codes=v2x, heading_offset_deg=float(heading_offset_deg), corners_nonlinearity=cnl,
        centre_nonlinearity=centre_nl, largest_nonlinearity=largest_nl, linear_threshold=thr,
        centre_shared_m=shared))
    return _apply_v2x_policy(est, camera, budget, v2x_policy, v2x_samples, v2x_seed,
                             corners_of=lambda r: uv[r], det_of=lambda r: None if det is None else det[r])


def _joint_covariance(budget, bp, det, computed):
    """``(joint (N, 2K, 2K), per-corner (N, K, 2, 2), the budget's parameter covariance (22, 22))`` of the
    reference path: shared camera parameters + per-point pixel noise (budget) + detector; NaN rows and columns
    for the corners not computed."""
    N, K = computed.shape
    Sp = budget.param_covariance()
    used = np.flatnonzero(np.any(Sp != 0, axis=0))
    Jp = bp.dxy_dp[..., used].reshape(N, 2 * K, used.size)
    with np.errstate(over="ignore", invalid="ignore"):  # overflow: not finite, marked OVERFLOW below
        joint = Jp @ Sp[np.ix_(used, used)] @ np.swapaxes(Jp, -1, -2)
    Juv = np.zeros((N, 2 * K, 2 * K))
    for k in range(K):
        Juv[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = bp.dxy_duv[:, k]
    Spx = np.broadcast_to(np.kron(np.eye(K), budget.pixel_covariance()), (N, 2 * K, 2 * K))
    if det is not None:
        Spx = Spx + det
    with np.errstate(over="ignore", invalid="ignore"):
        joint = joint + Juv @ Spx @ np.swapaxes(Juv, -1, -2)
    bad_rows = np.repeat(~computed, 2, axis=1)
    joint = np.where(bad_rows[:, :, None] | bad_rows[:, None, :], np.nan, joint)
    idx = np.arange(K)
    ccov = np.stack([joint[:, 2 * idx, 2 * idx], joint[:, 2 * idx, 2 * idx + 1],
                     joint[:, 2 * idx + 1, 2 * idx], joint[:, 2 * idx + 1, 2 * idx + 1]], -1).reshape(N, K, 2, 2)
    return joint, ccov, Sp


def _largest_point(xy, ccov, usable):
    """The usable corner with the largest 1-sigma semi-major axis: ``(index (-1: none), semi-major, point,
    covariance)``."""
    a, b, d = ccov[..., 0, 0], ccov[..., 0, 1], ccov[..., 1, 1]
    with np.errstate(invalid="ignore"):
        semi = np.sqrt(0.5 * (a + d) + np.hypot(0.5 * (a - d), b))
    li = np.argmax(np.where(usable, semi, -np.inf), axis=1)
    any_usable = usable.any(1)
    rows = np.arange(xy.shape[0])
    return (np.where(any_usable, li, -1), np.where(any_usable, semi[rows, li], np.nan),
            np.where(any_usable[:, None], xy[rows, li], np.nan), np.where(any_usable[:, None, None], ccov[rows, li],
                                                                           np.nan))


def _centre(budget, bp, xy, joint, reason, usable, computed):
    """The centre of the reference path: ``(point, covariance, valid, reason, first unusable corner, area,
    whitened parameter Jacobian dC/dp L)``, NaN where there is no centre."""
    N, K = usable.shape
    rows = np.arange(N)
    all_usable = usable.all(1)
    first_bad = np.argmax(~usable, axis=1)
    centre_bad = np.where(all_usable, -1, first_bad)
    centre_reason = np.where(all_usable, status.OK, reason[rows, first_bad]).astype(np.int32)
    # outside-image corners that are computed but not allowed keep the OUTSIDE_IMAGE code
    xy_c = np.where(all_usable[:, None, None], xy, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):  # overflow on absurd inputs: _mark_overflow flags it
        C, area, G = footprint_centre(xy_c, get_gradients=True)
    if K >= 3:
        degenerate = all_usable & ~np.isfinite(C).all(-1)
        centre_reason = np.where(degenerate, DEGENERATE, centre_reason)
    ok = centre_reason == status.OK
    joint_c = np.where(all_usable[:, None, None], joint, 0.0)
    G = np.where(ok[:, None, None], G, 0.0)
    with np.errstate(invalid="ignore", over="ignore"):
        ccov_c = G @ joint_c @ np.swapaxes(G, -1, -2)
    centre = np.where(ok[:, None], C, np.nan)
    centre_cov = np.where(ok[:, None, None], ccov_c, np.nan)
    bad_rows = np.repeat(~computed, 2, axis=1)
    with np.errstate(invalid="ignore", over="ignore"):  # the centre's whitened parameter Jacobian dC/dp L
        L = budget.param_factor().dense()
        shared = G @ (np.where(bad_rows[:, :, None], 0.0, bp.dxy_dp.reshape(N, 2 * K, bp.dxy_dp.shape[-1])) @ L)
    shared = np.where(ok[:, None, None], shared, np.nan)
    area = np.where(all_usable, area, np.nan)
    return centre, centre_cov, ok, centre_reason, centre_bad, area, shared


def _mark_overflow(est: FootprintEstimate) -> FootprintEstimate:
    """Outputs are checked too (in place): a corner whose ground point or covariance is not finite
    although it was computed gets :data:`~footprint_uq.status.OVERFLOW` and is not usable; its
    object's largest point, centre and V2X fields follow as for any unusable corner; a centre whose
    position or covariance is not finite is OVERFLOW too.  Shared by the numpy reference and
    :class:`FrameProcessor`, so both give the same codes.  Without per-corner covariances (the
    batch's lean mode) only the largest corner's point and semi-major axis are kept, so an object with an
    overflowing corner has no largest point (index -1, NaN); a corner covariance that overflows
    reaches the centre's and makes the centre OVERFLOW.
    """
    xy, cc, reason = est.corners_xy_world_m, est.corners_cov_m2, est.corner_reason
    computed = (reason == status.OK) | (reason == status.OUTSIDE_IMAGE)
    lite = cc.shape[0] != reason.shape[0]  # FrameProcessor without per-corner outputs (batch)
    if lite:  # the largest corner's point and covariance are kept; the others reach the centre's
        finite = np.isfinite(xy).all(-1) if xy.shape[0] == reason.shape[0] else np.ones(reason.shape, bool)
        n_obj = np.arange(reason.shape[0])
        li = np.maximum(est.largest_index, 0)
        finite[n_obj, li] &= (est.largest_index < 0) | (np.isfinite(est.largest_semi_major_m)
                                                       & np.isfinite(est.largest_xy_world_m).all(-1))
    else:
        finite = np.isfinite(xy).all(-1) & np.isfinite(cc).all((-2, -1))
    over = computed & ~finite
    centre_over = est.centre_valid & ~(np.isfinite(est.centre_xy_world_m).all(-1)
                                       & np.isfinite(est.centre_cov_m2).all((-2, -1)))
    objs = np.flatnonzero(over.any(1) | centre_over)
    if objs.size == 0:
        return est
    reason[over] = status.OVERFLOW
    est.corner_usable[over] = False
    cnl = est.corners_nonlinearity
    if cnl is not None and cnl.shape[0] == reason.shape[0]:
        cnl[over] = np.nan
    if not lite:
        xy[over] = np.nan
        cc[over] = np.nan
    elif xy.shape[0] == reason.shape[0]:
        xy[over] = np.nan
    if est.joint_cov_m2 is not None:
        rows = np.repeat(over, 2, axis=1)
        est.joint_cov_m2[rows[:, :, None] | rows[:, None, :]] = np.nan
    usable = est.corner_usable[objs]
    if lite:  # no covariances to rank the other corners by: the largest point is unavailable
        est.largest_index[objs] = -1
        est.largest_semi_major_m[objs] = np.nan
        est.largest_xy_world_m[objs] = np.nan
        if est.largest_cov_m2.shape[0]:
            est.largest_cov_m2[objs] = np.nan
        if est.largest_nonlinearity is not None:
            est.largest_nonlinearity[objs] = np.nan
    else:
        a, b, d = cc[objs, :, 0, 0], cc[objs, :, 0, 1], cc[objs, :, 1, 1]
        with np.errstate(invalid="ignore"):
            semi = np.where(usable, np.sqrt(0.5 * (a + d) + np.hypot(0.5 * (a - d), b)), -np.inf)
        li = np.argmax(semi, axis=1)
        has = usable.any(1)
        est.largest_index[objs] = np.where(has, li, -1)
        est.largest_semi_major_m[objs] = np.where(has, semi[np.arange(objs.size), li], np.nan)
        est.largest_xy_world_m[objs] = np.where(has[:, None], xy[objs, li], np.nan)
        est.largest_cov_m2[objs] = np.where(has[:, None, None], cc[objs, li], np.nan)
        if est.largest_nonlinearity is not None:
            est.largest_nonlinearity[objs] = np.where(has, cnl[objs, li], np.nan)
    first_bad = np.argmax(~usable, axis=1)
    all_usable = usable.all(1)
    code = np.where(~all_usable, reason[objs, first_bad],
                    np.where(centre_over[objs], status.OVERFLOW, est.centre_reason[objs]))
    est.centre_reason[objs] = code
    est.centre_bad_corner[objs] = np.where(all_usable, -1, first_bad)
    bad = code != status.OK
    est.centre_valid[objs] = ~bad
    est.centre_xy_world_m[objs[bad]] = np.nan
    est.centre_cov_m2[objs[bad]] = np.nan
    rows = est.object_rows
    if rows is not None and rows.shape[1] == reason.shape[0]:  # the kernel's ellipse of the centre follows it
        rows[[fk.OBJ_ROW["sigma_major_m"], fk.OBJ_ROW["sigma_minor_m"], fk.OBJ_ROW["orientation_deg"]],
             objs[bad][:, None]] = np.nan
    if est.centre_nonlinearity is not None:
        est.centre_nonlinearity[objs[bad]] = np.nan
    est.area_m2[objs[~all_usable]] = np.nan
    if est.centre_shared_m is not None and est.centre_shared_m.shape[0]:
        est.centre_shared_m[objs[bad]] = np.nan
    fields = {**cpm_fields(est.centre_cov_m2[objs], est.heading_offset_deg),
              **j2735_fields(est.centre_cov_m2[objs], est.heading_offset_deg)}
    est.v2x_codes[objs] = np.stack([fields[name] for name in V2X_FIELDS], -1).astype(np.int32)
    return est


def _check_flag_options(linear_threshold, v2x_policy, v2x_samples):
    """``(threshold, samples)`` of the linearity flag / V2X policy options, checked."""
    thr = check_linear_threshold(linear_threshold)
    if v2x_policy not in V2X_POLICIES:
        raise InputError("v2x_policy", v2x_policy, f"one of {V2X_POLICIES}")
    return thr, as_int("v2x_samples", v2x_samples, minimum=100, expected="an integer >= 100")


def centre_covariance_sampled(camera, budget, corners_px, *, pixel_cov_px2=None, n_samples: int = V2X_SAMPLES,
                              seed: int = 0, max_points: int = 1 << 20):
    """Seeded Monte-Carlo covariance of footprint centres on the full (non-linear) camera model.

    Each sample draws one set of camera-level errors (shared by the corners) and the pixel noise of
    every corner (budget + detector, correlated between corners if the detector covariance is),
    back-projects the K corners and takes the centre as the reference does (:func:`footprint_centre`:
    the vertex mean; samples whose polygon has zero area are left out).  **Common random numbers**: every
    object uses the same standard-normal draws (from ``seed``), so an object's result does not depend on which other
    objects are processed with it (frame, batch chunk, thread).  Vectorised over samples and objects
    (at most ``max_points`` back-projections at a time).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    corners_px : (n, K, 2) corner pixels of n objects
    pixel_cov_px2 : (n, 2K, 2K), optional
        Detector pixel covariance (added to the budget's imaging and resolution noise).
    n_samples, seed : int

    Returns
    -------
    cov_m2 : (n, 2, 2)          sample covariance of the centre over the samples where every corner
                                meets the ground and the centre exists (m^2; NaN with fewer than 2)
    fraction_valid : (n,)       share of such samples
    """
    budget = load_budget(budget)
    uv = np.asarray(corners_px, dtype=np.float64)
    n, K = uv.shape[:2]
    rng = np.random.default_rng(seed)
    dp = sample_params(budget, n_samples, rng)  # (S, 22), shared by all objects
    z = rng.standard_normal((n_samples, 2 * K))
    Spx = np.kron(np.eye(K), budget.pixel_covariance())
    Spx = np.broadcast_to(Spx, (n, 2 * K, 2 * K)) if pixel_cov_px2 is None else Spx + pixel_cov_px2
    w, V = np.linalg.eigh(Spx)
    A = V * np.sqrt(np.clip(w, 0.0, None))[:, None, :]  # (n, 2K, 2K): Spx = A A^T
    ref = camera.backproject(uv).xy_world_m
    ref = np.where(np.isfinite(ref), ref, 0.0).mean(1)  # deviations from a nearby point: no cancellation
    cov = np.full((n, 2, 2), np.nan)
    frac = np.zeros(n)
    step = max(1, max_points // (n_samples * K))
    params = camera.params + dp[:, None, None, :]
    for a in range(0, n, step):
        b = min(n, a + step)
        noise = np.einsum("rij,sj->sri", A[a:b], z).reshape(n_samples, b - a, K, 2)
        bp = camera.backproject_with(params, uv[None, a:b] + noise)
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            C = footprint_centre(np.where(bp.valid[..., None], bp.xy_world_m, 0.0))[0] - ref[a:b]  # (S, r, 2)
        good = bp.valid.all(-1) & np.isfinite(C).all(-1)
        cnt = good.sum(0)
        C = np.where(good[..., None], C, 0.0)
        mean = C.sum(0) / np.maximum(cnt, 1)[:, None]
        d = np.where(good[..., None], C - mean, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            cov[a:b] = np.einsum("sri,srj->rij", d, d) / (cnt - 1)[:, None, None]
        cov[a:b][cnt < 2] = np.nan
        frac[a:b] = cnt / n_samples
    return cov, frac


_NO_NL = np.zeros(0)


def _apply_v2x_policy(est: FootprintEstimate, camera, budget, policy: str, n_samples: int, seed: int, *,
                      corners_of, det_of) -> FootprintEstimate:
    """V2X fields where the centre is not ``linear_ok`` (in place; docs/uncertainty-model.md, "Policy for the V2X
    fields"), shared by the numpy reference and :class:`FrameProcessor`.

    ``corners_of(rows)`` gives the corner pixels (r, K, 2) and ``det_of(rows)`` the detector covariance
    (r, 2K, 2K) or None of the flagged rows: only those are sampled (:func:`centre_covariance_sampled`).
    """
    src = np.empty(len(est), dtype=np.int8)
    nl = est.centre_nonlinearity
    n_flagged = fk.v2x_source_and_flagged(est.centre_valid, _NO_NL if nl is None else nl, est.linear_threshold,
                                          V2X_COV_LINEAR, V2X_COV_UNAVAILABLE, src)
    est.v2x_source = src
    if n_flagged == 0 or policy == "linear":  # (almost every frame)
        return est
    rows = np.flatnonzero(est.centre_valid & ~est.centre_linear_ok)
    nl = est.centre_nonlinearity[rows]
    cov = np.full((rows.size, 2, 2), np.nan)
    src_r = np.full(rows.size, V2X_COV_UNAVAILABLE, dtype=np.int8)
    mid = nl <= V2X_UNAVAILABLE_ABOVE
    if policy == "sampled" and mid.any():
        r = rows[mid]
        mc, frac = centre_covariance_sampled(camera, budget, corners_of(r), pixel_cov_px2=det_of(r),
                                             n_samples=n_samples, seed=seed)
        lin = est.centre_cov_m2[r]
        a_mc, a_lin = _semi_major(mc), _semi_major(lin)
        chosen = np.where((a_mc > a_lin)[:, None, None], mc, lin)
        good = frac >= V2X_MIN_FRACTION_VALID
        cov[mid] = np.where(good[:, None, None], chosen, np.nan)
        src_r[mid] = np.where(good, V2X_COV_SAMPLED, V2X_COV_UNAVAILABLE)
    src[rows] = src_r
    est.v2x_cov_m2 = np.array(est.centre_cov_m2)
    est.v2x_cov_m2[rows] = cov
    fields = {**cpm_fields(cov, est.heading_offset_deg), **j2735_fields(cov, est.heading_offset_deg)}
    est.v2x_codes[rows] = np.stack([fields[name] for name in V2X_FIELDS], -1).astype(np.int32)
    return est


def _semi_major(cov):
    a, b, d = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    with np.errstate(invalid="ignore"):
        return np.sqrt(0.5 * (a + d) + np.hypot(0.5 * (a - d), b))


def footprints_from_boxes2d(camera, budget, boxes_px, *, contact: str = "bottom-centre", pixel_cov_px2=None,
                            box_cov_px2=None, allow_outside_image: bool = False,
                            heading_offset_deg: float = 0.0, **flag_options) -> FootprintEstimate:
    """Footprints of axis-aligned image boxes ``(N, 4)`` (see the module doc for ``contact``).

    ``pixel_cov_px2`` as in :func:`footprints_from_corners`; ``box_cov_px2`` ``(N, 4, 4)``
    or ``(N, 4)`` sigmas on the box coordinates (not both).  ``flag_options``: ``linearity``,
    ``linear_threshold``, ``v2x_policy``, ``v2x_samples``, ``v2x_seed`` of :func:`footprints_from_corners`.
    """
    corners, A = box2d_contact_points(boxes_px, contact)
    N, K = corners.shape[:2]
    if box_cov_px2 is not None:
        if pixel_cov_px2 is not None:
            raise InputError("box_cov_px2", "given with pixel_cov_px2", "only one detector covariance")
        pixel_cov_px2 = _box_cov_to_corners(box_cov_px2, A, N)
    return footprints_from_corners(camera, budget, corners, pixel_cov_px2=pixel_cov_px2,
                                   allow_outside_image=allow_outside_image, heading_offset_deg=heading_offset_deg,
                                   **flag_options)


def footprints_from_boxes3d(camera, budget, boxes_world, *, yaw_unit: str = "rad", bottom_on_ground: bool = True,
                            pixel_cov_px2=None, allow_outside_image: bool = False,
                            heading_offset_deg: float = 0.0, **flag_options) -> FootprintEstimate:
    """Footprints of 3D world boxes ``(N, 7)``: bottom corners -> image -> ground with uncertainty.

    Corners behind the camera get ``BEHIND_CAMERA`` and NaN.  ``flag_options`` as in
    :func:`footprints_from_boxes2d`.
    """
    X = box3d_bottom_corners(boxes_world, yaw_unit=yaw_unit, bottom_on_ground=bottom_on_ground,
                             ground_z_m=camera.ground_z_m)
    pr = camera.project(X)
    extra = np.where(pr.valid, status.OK, pr.reason).astype(np.int8)
    uv = np.where(pr.valid[..., None], pr.uv_px, np.nan)
    return footprints_from_corners(camera, budget, uv, pixel_cov_px2=pixel_cov_px2,
                                   allow_outside_image=allow_outside_image, heading_offset_deg=heading_offset_deg,
                                   extra_reason=extra, **flag_options)


# -- the per-frame fast path ---------------------------------------------------------------------
#: outputs of at least this many bytes come from pyarrow's memory pool (see :func:`empty_reusable`)
_POOL_MIN_BYTES = 1 << 20


def empty_reusable(shape, dtype=np.float64) -> np.ndarray:
    """An uninitialised array whose memory is reused after it is freed.

    Large arrays come from pyarrow's default memory pool (mimalloc or jemalloc), which keeps
    freed pages for the next allocation; numpy's (and numba's) large allocations are fresh pages
    from the kernel every time, whose first touch costs ~40 % of the footprint kernel's time
    (measured on a 2-core VM).  Small arrays come from numpy.
    """
    dtype = np.dtype(dtype)
    n = math.prod(shape)
    if n * dtype.itemsize < _POOL_MIN_BYTES:
        return np.empty(shape, dtype=dtype)

    return np.frombuffer(pa.allocate_buffer(n * dtype.itemsize), dtype=dtype, count=n).reshape(shape)


def reusable_allocator(max_bytes: int):
    """:func:`empty_reusable`'s policy decided once for arrays of at most ``max_bytes`` each: ``np.empty``
    itself when even the largest is below the pool's threshold (what :func:`empty_reusable` would choose
    for every one of them; ~0.4 us per array less), else :func:`empty_reusable`."""
    return np.empty if max_bytes < _POOL_MIN_BYTES else empty_reusable


class FrameProcessor:
    """Reusable per-frame processor: the same results as the reference functions, fused in numba.

    Camera and budget constants (parameter vector, rotation and its derivatives, the
    non-zero entries of the 22x22 parameter covariance, the budget's pixel covariance)
    are prepared once; each call then runs one compiled kernel over the frame's
    detections (see :mod:`footprint_uq.fast.footprint_kernels`).  Results agree with
    :func:`footprints_from_corners` / :func:`footprints_from_boxes2d` /
    :func:`footprints_from_boxes3d` to 1e-9 relative.

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    heading_offset_deg : float
        Bearing of the world +y axis from true north (V2X fields).
    allow_outside_image : bool
        See :func:`footprints_from_corners`.
    joint_cov : bool
        Form the (N, 2K, 2K) joint corner covariance (default True).  Without it
        ``joint_cov_m2`` is None; corner and centre covariances are unchanged.
    linearity, linear_threshold, v2x_policy, v2x_samples, v2x_seed
        The linearity flag (computed in the kernel) and the V2X policy where the centre is not
        ``linear_ok``, as in :func:`footprints_from_corners`.
    shared_jacobian : bool
        Also return each centre's whitened parameter Jacobian ``centre_shared_m`` (N, 2, r), which splits
        its covariance into the camera-level part shared by every frame and the per-frame part (the tracker
        needs it, :mod:`footprint_uq.tracking`); default False (None).

    A processor keeps only read-only constants and the kernels release the GIL, so
    one processor may serve several threads at once (e.g. chunks of a batch).

    Examples
    --------
    >>> proc = FrameProcessor(camera, "basler1")          # once
    >>> est = proc.boxes3d(boxes_world)                   # every frame, (N, 7)
    >>> est.centre_cov_m2, est.largest_semi_major_m, est.v2x["cpm_x_confidence"]
    """

    def __init__(self, camera, budget, *, heading_offset_deg: float = 0.0, allow_outside_image: bool = False,
                 joint_cov: bool = True, linearity: bool = True, linear_threshold: float = DEFAULT_LINEAR_THRESHOLD,
                 v2x_policy: str = "sampled", v2x_samples: int = V2X_SAMPLES, v2x_seed: int = 0,
                 shared_jacobian: bool = False):
        self.shared_jacobian = bool(shared_jacobian)
        self.linear_threshold, self.v2x_samples = _check_flag_options(linear_threshold, v2x_policy, v2x_samples)
        self.linearity = bool(linearity)
        self.v2x_policy = v2x_policy
        self.v2x_seed = int(v2x_seed)
        self.camera = camera
        self.budget = load_budget(budget)
        self.heading_offset_deg = as_float("heading_offset_deg", heading_offset_deg)
        self.allow_outside_image = bool(allow_outside_image)
        self.joint_cov = bool(joint_cov)
        self._fk = fk
        self._cam, self._dR = fk.camera_constants(camera)
        fac = self.budget.param_factor()
        self._Lr, self._Lc, self._Lv, self._r = fac.rowidx, fac.cols, fac.vals, fac.rank
        self._spx = np.ascontiguousarray(self.budget.pixel_covariance())
        h = np.deg2rad(self.heading_offset_deg)
        self._ch, self._sh = (1.0, 0.0) if h == 0.0 else (float(np.cos(h)), float(np.sin(h)))
        self._no_det = np.zeros((1, 1, 2, 2))
        self._no_extra = np.zeros((0, 0), dtype=np.int8)
        self._no_boxes = np.zeros((0, 7))
        #: whether per-corner coordinates and covariances (and the largest point's covariance) are
        #: formed at all; the batch sets False when it writes no corner columns (leaner, faster)
        self.corner_outputs = True
        self._kernels = False  # the compiled kernels run (footprint_uq._notices; asked until they do)

    def _use_kernels(self) -> bool:
        """Whether this call runs the compiled kernel (else the numpy reference: a command line whose kernels
        are still compiling in the background, :class:`footprint_uq.products.warmup.KernelGate`)."""
        if not self._kernels:
            self._kernels = before_kernels("objects")
        return self._kernels

    def _reference(self, est: FootprintEstimate) -> FootprintEstimate:
        """A reference estimate shaped as this processor's: the kernel's per-object rows (the batch reads
        them), no joint covariance or centre Jacobian unless asked for."""
        est.object_rows = _object_rows(est)
        if not self.joint_cov:
            est.joint_cov_m2 = None
        if not self.shared_jacobian:
            est.centre_shared_m = None
        return est

    def _det(self, pixel_cov_px2, N: int, K: int):
        if pixel_cov_px2 is None:
            return self._no_det, 0
        c = np.asarray(pixel_cov_px2, dtype=np.float64)
        if c.shape == (N, 2, 2):
            return self._checked_cov2(c)[:, None], 1
        if c.shape == (N, K, 2, 2):
            return self._checked_cov2(c), 2
        if c.shape == (N, 2 * K, 2 * K):
            return np.ascontiguousarray(check_cov("pixel_cov_px2", c, 2 * K)[:, None]), 3
        raise InputError("pixel_cov_px2", c.shape, f"shape ({N}, 2, 2), ({N}, {K}, 2, 2) or ({N}, {2 * K}, {2 * K})")

    def _checked_cov2(self, c: np.ndarray) -> np.ndarray:
        """``c`` (..., 2, 2) C-contiguous, checked as :func:`check_cov` does: in one compiled pass when the kernels
        run (the numpy checks only for a frame that fails it, for their one-line error)."""
        c = np.ascontiguousarray(c)
        if self._use_kernels() and first_bad_cov2(c.reshape(-1, 2, 2), COV_PSD_RTOL) < 0:
            return c
        return check_cov("pixel_cov_px2", c, 2)

    @staticmethod
    def _scratch() -> np.ndarray:
        """The per-frame kernel's scratch: one per thread (fast.buffers; a fresh one every frame cost ~9 us of
        page touching), so one processor may serve several threads at once."""
        return thread_buffer("frame_scratch", fk.SCRATCH_SHAPE)

    def _flag_options(self) -> dict:
        return dict(linearity=self.linearity, linear_threshold=self.linear_threshold, v2x_policy=self.v2x_policy,
                    v2x_samples=self.v2x_samples, v2x_seed=self.v2x_seed)

    def _run(self, uv, extra, pixel_cov_px2) -> FootprintEstimate:
        N, K = uv.shape[0], uv.shape[1]
        det, mode = self._det(pixel_cov_px2, N, K)
        if K > self._fk.MAX_CORNERS or not self._use_kernels():  # (beyond the kernel's chunk layout)
            return self._reference(footprints_from_corners(
                self.camera, self.budget, uv, pixel_cov_px2=pixel_cov_px2, allow_outside_image=self.allow_outside_image,
                heading_offset_deg=self.heading_offset_deg, extra_reason=extra if extra.shape[0] == N else None,
                **self._flag_options()))
        r = self._r if self.shared_jacobian else None
        alloc = reusable_allocator(self._fk.outputs_max_bytes(N, K, joint=self.joint_cov, shared_rank=r))
        out = self._fk.alloc_outputs(N, K, joint=self.joint_cov, corners=self.corner_outputs, alloc=alloc,
                                     shared_rank=r)
        n_over = self._fk.process_corners(uv, extra, self._no_boxes, False, True, self._cam, self._dR, self._Lr,
                                          self._Lc, self._Lv, self._r, self._spx, det, mode, self.allow_outside_image,
                                          self._ch, self._sh, self.linearity, out, self._scratch())
        return self._pack(uv, out, lambda r: uv[r], det, mode, n_over)

    def _pack(self, uv, out, corners_of, det, mode, n_over) -> FootprintEstimate:
        xy, ccov, joint, reason, usable, li, lcov, creason, cbad, obj, v2x, cnl, shared = out
        row = self._fk.OBJ_ROW
        # views of the kernel's per-object rows (no copies): (N, 2) and (N, 2, 2) with strides across rows
        centre = obj[row["x_m"]:row["y_m"] + 1].T
        ccentre = obj[row["cov_xx_m2"]:row["cov_yy_m2"] + 1].T.reshape(obj.shape[1], 2, 2)
        flag = self.linearity
        est = FootprintEstimate(uv, xy, ccov, joint if self.joint_cov else None, reason, usable, li,
                                obj[row["largest_sigma_major_m"]], obj[row["largest_x_m"]:row["largest_y_m"] + 1].T,
                                lcov, centre, ccentre, creason == 0, creason, cbad, obj[row["area_m2"]], v2x.T,
                                self.heading_offset_deg, cnl if flag else None,
                                obj[row["nonlinearity"]] if flag else None,
                                obj[row["largest_nonlinearity"]] if flag else None, self.linear_threshold)
        est.object_rows = obj
        if self.shared_jacobian:
            shared[creason != 0] = np.nan
            est.centre_shared_m = shared
        K = reason.shape[1]
        if n_over:  # (the kernel counts what _mark_overflow would find; almost always nothing)
            est = _mark_overflow(est)
        return _apply_v2x_policy(est, self.camera, self.budget, self.v2x_policy, self.v2x_samples,
                                 self.v2x_seed, corners_of=corners_of,
                                 det_of=lambda r: _det_joint_rows(det, mode, r, K))

    def point_shared_jacobian(self, uv_px) -> np.ndarray:
        """The whitened parameter Jacobian ``B`` (n, 2, r) of the ground points of pixels ``uv_px (n, 2)``, alone:
        :attr:`FootprintEstimate.centre_shared_m` of one-point footprints (pixels outside the image included), NaN
        where a pixel has no ground point.  One kernel pass without the rest of an estimate (the tracker evaluates
        ``B`` at every track's predicted position in every frame: ~4x less than :meth:`corners`)."""
        uv = np.ascontiguousarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
        if not self._use_kernels():
            return footprints_from_corners(self.camera, self.budget, uv, allow_outside_image=True, linearity=False,
                                           v2x_policy="linear").centre_shared_m
        return self._fk.point_shared_jacobian(uv, self._no_extra, self._no_boxes, False, True, self._cam, self._dR,
                                              self._Lr, self._Lc, self._Lv, self._r, self._spx, self._no_det, 0, True,
                                              self._ch, self._sh, False, self._scratch())

    def corners(self, corners_px, *, pixel_cov_px2=None) -> FootprintEstimate:
        """Footprints from corners in pixels ``(N, K, 2)`` (see :func:`footprints_from_corners`)."""
        uv = np.ascontiguousarray(corners_px, dtype=np.float64)
        if uv.ndim != 3 or uv.shape[2] != 2 or uv.shape[1] < 1:
            raise InputError("corners_px", uv.shape, "an array of shape (N, K, 2) with K >= 1")
        return self._run(uv, self._no_extra, pixel_cov_px2)

    def boxes2d(self, boxes_px, *, contact: str = "bottom-centre", pixel_cov_px2=None,
                box_cov_px2=None) -> FootprintEstimate:
        """Footprints of image boxes ``(N, 4)`` (see :func:`footprints_from_boxes2d`)."""
        corners, A = box2d_contact_points(boxes_px, contact)
        if box_cov_px2 is not None:
            if pixel_cov_px2 is not None:
                raise InputError("box_cov_px2", "given with pixel_cov_px2", "only one detector covariance")
            pixel_cov_px2 = _box_cov_to_corners(box_cov_px2, A, corners.shape[0])
        return self._run(np.ascontiguousarray(corners), self._no_extra, pixel_cov_px2)

    def boxes3d(self, boxes_world, *, yaw_unit: str = "rad", bottom_on_ground: bool = True,
                pixel_cov_px2=None) -> FootprintEstimate:
        """Footprints of 3D world boxes ``(N, 7)`` (see :func:`footprints_from_boxes3d`)."""
        # row-major always: a column-major table (the batch's) would be another kernel signature, i.e. a second
        # full compile of the per-frame kernel (~1 min) for a copy of 56 bytes per box (~1 % of the kernel's time)
        b = np.ascontiguousarray(boxes_world, dtype=np.float64)
        if b.ndim != 2 or b.shape[1] != 7:
            raise InputError("boxes_world", b.shape, f"an array of shape (N, 7): {', '.join(BOX3D_COLUMNS)}")
        if yaw_unit not in ("rad", "deg"):
            raise InputError("yaw_unit", yaw_unit, "'rad' (column yaw_rad) or 'deg' (column yaw_deg)")
        N = b.shape[0]
        det, mode = self._det(pixel_cov_px2, N, 4)
        if not self._use_kernels():
            return self._reference(footprints_from_boxes3d(
                self.camera, self.budget, b, yaw_unit=yaw_unit, bottom_on_ground=bottom_on_ground,
                pixel_cov_px2=pixel_cov_px2, allow_outside_image=self.allow_outside_image,
                heading_offset_deg=self.heading_offset_deg, **self._flag_options()))
        r = self._r if self.shared_jacobian else None
        alloc = reusable_allocator(self._fk.outputs_max_bytes(N, 4, joint=self.joint_cov, shared_rank=r))
        uv = alloc((N if self.corner_outputs else 0, 4, 2), np.float64)
        out = self._fk.alloc_outputs(N, 4, joint=self.joint_cov, corners=self.corner_outputs, alloc=alloc,
                                     shared_rank=r)
        bad, n_over = self._fk.process_boxes3d(b, yaw_unit == "deg", bool(bottom_on_ground), self._cam, self._dR,
                                               self._Lr, self._Lc, self._Lv, self._r, self._spx, det, mode,
                                               self.allow_outside_image, self._ch, self._sh, self.linearity, uv, out,
                                               self._scratch())
        if bad >= 0:
            raise InputError(f"boxes_world[{bad}] (length_m, width_m, height_m)", b[bad, 3:6].tolist(), "sizes >= 0")

        def corners_of(r):  # the flagged rows' pixels (the batch's lean mode keeps none)
            if uv.shape[0] == N:
                return uv[r]
            X = box3d_bottom_corners(b[r], yaw_unit=yaw_unit, bottom_on_ground=bottom_on_ground,
                                     ground_z_m=self.camera.ground_z_m)
            return self.camera.project(X).uv_px

        return self._pack(uv, out, corners_of, det, mode, n_over)


def _object_rows(est: FootprintEstimate) -> np.ndarray:
    """The fused kernel's per-object rows (:data:`footprint_uq.fast.footprint_kernels.OBJ_ROWS`, (R, N)) of a
    reference estimate: the centre, its covariance and 1-sigma ellipse, the largest point, the area, the flags."""
    row = fk.OBJ_ROW
    obj = np.full((len(fk.OBJ_ROWS), len(est)), np.nan)
    c = est.centre_cov_m2
    obj[row["x_m"]], obj[row["y_m"]] = est.centre_xy_world_m[:, 0], est.centre_xy_world_m[:, 1]
    obj[row["cov_xx_m2"]], obj[row["cov_xy_m2"]] = c[:, 0, 0], c[:, 0, 1]
    obj[row["cov_yx_m2"]], obj[row["cov_yy_m2"]] = c[:, 1, 0], c[:, 1, 1]
    obj[row["sigma_major_m"]], obj[row["sigma_minor_m"]], obj[row["orientation_deg"]] = ellipse_axes(c)
    obj[row["largest_sigma_major_m"]] = est.largest_semi_major_m
    obj[row["largest_x_m"]], obj[row["largest_y_m"]] = est.largest_xy_world_m[:, 0], est.largest_xy_world_m[:, 1]
    obj[row["area_m2"]] = est.area_m2
    if est.centre_nonlinearity is not None:
        obj[row["nonlinearity"]] = est.centre_nonlinearity
        obj[row["largest_nonlinearity"]] = est.largest_nonlinearity
    return obj


def _det_joint_rows(det, mode: int, rows, K: int):
    """The kernel's detector covariance (``FrameProcessor._det``) of ``rows`` as (r, 2K, 2K), or None."""
    if mode == 0:
        return None
    if mode == 3:
        return det[rows, 0]
    out = np.zeros((len(rows), 2 * K, 2 * K))
    for k in range(K):
        out[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = det[rows, 0] if mode == 1 else det[rows, k]
    return out
