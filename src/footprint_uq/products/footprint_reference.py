"""The readable numpy reference of the footprints (:func:`footprints_from_corners`, ``..._boxes2d``,
``..._boxes3d``), built on ``camera.backproject`` and :mod:`footprint_uq.uncertainty.propagation` semantics: the
path every test holds the compiled frame processor to (1e-9 relative).  Public through
:mod:`footprint_uq.products.footprints` (whose module doc describes the model)."""

from __future__ import annotations

import numpy as np

from .. import status
from .._checks import as_points
from ..errors import InputError
from ..uncertainty.budget import load_budget
from ..uncertainty.propagation import (
    DEFAULT_LINEAR_THRESHOLD,
    nonlinearity_of_jacobians,
)
from .footprint_estimate import DEGENERATE, V2X_FIELDS, V2X_SAMPLES, FootprintEstimate, mark_overflow
from .footprint_flags import apply_v2x_policy, check_flag_options
from .footprint_geometry import (
    box2d_contact_points,
    box3d_bottom_corners,
    box_cov_to_corners,
    detector_joint_cov,
    footprint_centre,
)
from .v2x import cpm_fields, j2735_fields


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
    thr, v2x_samples = check_flag_options(linear_threshold, v2x_policy, v2x_samples)
    budget = load_budget(budget)
    uv = as_points("corners_px", corners_px, 2)
    if uv.ndim != 3 or uv.shape[1] < 1:
        raise InputError("corners_px", uv.shape, "an array of shape (N, K, 2) with K >= 1")
    N, K = uv.shape[:2]
    det = detector_joint_cov(pixel_cov_px2, N, K)
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
    est = mark_overflow(FootprintEstimate(
        corners_px=uv, corners_xy_world_m=xy, corners_cov_m2=ccov, joint_cov_m2=joint,
        corner_reason=reason.astype(np.int8), corner_usable=usable, largest_index=largest_index,
        largest_semi_major_m=largest_semi, largest_xy_world_m=largest_xy, largest_cov_m2=largest_cov,
        centre_xy_world_m=centre, centre_cov_m2=centre_cov, centre_valid=ok, centre_reason=centre_reason,
        centre_bad_corner=np.where(ok, -1, np.where(centre_reason == DEGENERATE, -1, centre_bad)),
        area_m2=area, v2x_codes=v2x, heading_offset_deg=float(heading_offset_deg), corners_nonlinearity=cnl,
        centre_nonlinearity=centre_nl, largest_nonlinearity=largest_nl, linear_threshold=thr,
        centre_shared_m=shared))
    return apply_v2x_policy(est, camera, budget, v2x_policy, v2x_samples, v2x_seed,
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
    with np.errstate(invalid="ignore", over="ignore"):  # overflow on absurd inputs: mark_overflow flags it
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
        pixel_cov_px2 = box_cov_to_corners(box_cov_px2, A, N)
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
