"""The footprint estimate of a frame (:class:`FootprintEstimate`), its constants, and the output check shared by
both paths (:func:`mark_overflow`).  Public through :mod:`footprint_uq.products.footprints` (the module doc there
describes the model)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import status
from ..fast import footprint_kernels as fk
from ..uncertainty.ellipse import ellipse_axes
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD
from .v2x import cpm_fields, j2735_fields

__all__ = ["FootprintEstimate", "mark_overflow", "centre_reason_texts", "DEGENERATE", "CONTACT_MODES",
           "BOX3D_COLUMNS", "V2X_FIELDS", "V2X_POLICIES", "V2X_UNAVAILABLE_ABOVE", "V2X_MIN_FRACTION_VALID",
           "V2X_SAMPLES"]

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
        return centre_reason_texts(self.centre_reason, self.centre_bad_corner, self.n_corners)

    def centre_ellipse(self, confidence: float | None = None):
        """``(semi_major_m, semi_minor_m, orientation_deg)`` of the centre covariance."""

        return ellipse_axes(self.centre_cov_m2, confidence=confidence)


def centre_reason_texts(centre_reason: np.ndarray, centre_bad_corner: np.ndarray, n_corners: int) -> np.ndarray:
    """Object array (N,) of human-readable reasons of centres ``centre_reason`` (N,) (status codes, 0: "ok") whose
    first unusable corner is ``centre_bad_corner`` (N,) of ``n_corners``: :meth:`FootprintEstimate.centre_reason_text`
    of an estimate's columns (:meth:`~footprint_uq.products.frame_processor.FrameProcessor.boxes2d_columns`)."""
    out = np.empty(len(centre_reason), dtype=object)
    for i, (code, k) in enumerate(zip(centre_reason.tolist(), centre_bad_corner.tolist(), strict=True)):
        if code == status.OK:
            out[i] = "ok"
        elif code in _CENTRE_TEXT:
            out[i] = _CENTRE_TEXT[code]
        else:
            out[i] = f"corner {k} of {n_corners}: {status.REASONS[code]}"
    return out


def mark_overflow(est: FootprintEstimate) -> FootprintEstimate:
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
    _redo_largest(est, objs, usable, lite)
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


def _redo_largest(est: FootprintEstimate, objs: np.ndarray, usable: np.ndarray, lite: bool) -> None:
    """The largest point of the objects ``objs`` again, over their corners still ``usable`` (in place; part of
    :func:`mark_overflow`)."""
    xy, cc, cnl = est.corners_xy_world_m, est.corners_cov_m2, est.corners_nonlinearity
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
