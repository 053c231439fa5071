"""The detection columns every input path shares: the box families, their column names and how a set of
names picks one, the detector's pixel covariance columns and their limit, the per-object status words.

The batch (:mod:`footprint_uq.batch.schema`, which re-exports these with its Arrow types) and the edge service
(:mod:`footprint_uq.service.detections`) read detections with the same names; both import them from here, so
that the service reads its frames without the batch (and its pyarrow) beneath it.  Names carry their unit
(``_px``, ``_m``, ``_rad``, ``_deg``, ``_px2``) as everywhere in footprint-uq; the full description is
``docs/batch.md``.
"""

from __future__ import annotations

__all__ = ["BOX2D_COLUMNS", "BOX3D_COLUMNS", "YAW_COLUMNS", "COV_COLUMNS", "BOX_TYPES", "MAX_PIXEL_VAR_PX2",
           "STATUS_OK", "STATUS_PARTIAL", "STATUS_ERROR", "STATUSES", "corner_columns", "count_corners",
           "detect_box_type", "box_columns"]

#: 2D boxes: an axis-aligned image box, pixels
BOX2D_COLUMNS = ("u_min_px", "v_min_px", "u_max_px", "v_max_px")
#: 3D boxes in the world frame W (plus one of :data:`YAW_COLUMNS`)
BOX3D_COLUMNS = ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m")
YAW_COLUMNS = ("yaw_rad", "yaw_deg")
#: the detector's pixel covariance of every ground-contact point of a detection, px^2 (all three or none)
COV_COLUMNS = ("cov_uu_px2", "cov_uv_px2", "cov_vv_px2")
BOX_TYPES = ("2d", "3d", "corners")
#: largest detector pixel (co)variance accepted, px^2 (a 1e6-px sigma: far beyond any image)
MAX_PIXEL_VAR_PX2 = 1e12

STATUS_OK = "ok"            # footprint centre computed
STATUS_PARTIAL = "partial"  # centre not computable, but at least one corner usable (largest point given)
STATUS_ERROR = "error"      # nothing computed: bad row or no usable corner
STATUSES = (STATUS_OK, STATUS_PARTIAL, STATUS_ERROR)


def corner_columns(K: int) -> tuple[str, ...]:
    """Input corner columns for K corners: ``u0_px, v0_px, u1_px, v1_px, ...``."""
    return tuple(name for k in range(K) for name in (f"u{k}_px", f"v{k}_px"))


def count_corners(names) -> int:
    """Number K of consecutive corners ``u0_px, v0_px ... u{K-1}_px, v{K-1}_px`` present (0 if none)."""
    names = set(names)
    K = 0
    while f"u{K}_px" in names and f"v{K}_px" in names:
        K += 1
    return K


def detect_box_type(names) -> str | None:
    """The box family of a set of column names (None if none, or more than one, is complete)."""
    names = set(names)
    found = [t for t, ok in (("2d", all(c in names for c in BOX2D_COLUMNS)),
                             ("3d", all(c in names for c in BOX3D_COLUMNS) and any(y in names for y in YAW_COLUMNS)),
                             ("corners", count_corners(names) > 0)) if ok]
    return found[0] if len(found) == 1 else None


def box_columns(box_type: str, names) -> tuple[str, ...]:
    """Numeric box columns of ``box_type`` in kernel order (3D: the yaw column present; yaw_rad preferred)."""
    if box_type == "2d":
        return BOX2D_COLUMNS
    if box_type == "3d":
        yaw = "yaw_rad" if "yaw_rad" in set(names) else "yaw_deg"
        return BOX3D_COLUMNS + (yaw,)
    return corner_columns(count_corners(names))
