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
(Modules: this one is the public entry and re-exports the parts -- :mod:`.footprint_estimate` (the estimate,
its constants, the output check), :mod:`.footprint_geometry` (contact points, box corners, the centre),
:mod:`.footprint_reference` (the numpy reference), :mod:`.footprint_flags` (linearity options and the V2X
policy) and :mod:`.frame_processor` (the compiled per-frame path).)

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

from .footprint_estimate import (
    BOX3D_COLUMNS,
    CONTACT_MODES,
    DEGENERATE,
    V2X_FIELDS,
    V2X_MIN_FRACTION_VALID,
    V2X_POLICIES,
    V2X_SAMPLES,
    V2X_UNAVAILABLE_ABOVE,
    FootprintEstimate,
)
from .footprint_flags import centre_covariance_sampled
from .footprint_geometry import box2d_contact_points, box3d_bottom_corners, footprint_centre, polygon_centroid
from .footprint_reference import footprints_from_boxes2d, footprints_from_boxes3d, footprints_from_corners
from .frame_processor import FrameProcessor, empty_reusable, reusable_allocator

__all__ = [
    "FootprintEstimate", "FrameProcessor", "V2X_FIELDS", "DEGENERATE", "CONTACT_MODES", "BOX3D_COLUMNS",
    "V2X_POLICIES", "box2d_contact_points", "box3d_bottom_corners", "polygon_centroid", "footprint_centre",
    "footprints_from_corners",
    "footprints_from_boxes2d", "footprints_from_boxes3d", "centre_covariance_sampled",
    "V2X_UNAVAILABLE_ABOVE", "V2X_MIN_FRACTION_VALID", "V2X_SAMPLES", "empty_reusable", "reusable_allocator",
]
