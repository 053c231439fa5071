"""Column names and types of the batch detections (input) and footprints (output).

The full description, with examples, is ``docs/batch.md``.  Names carry their unit
(``_px``, ``_m``, ``_m2``, ``_deg``, ``_rad``, ``_s``) as everywhere in footprint-uq.

Input
-----
* identification (all optional, passed through to the output): :data:`ID_COLUMNS`;
* one box family, chosen with ``box_type`` or detected from the columns present:

  - ``"2d"``: :data:`BOX2D_COLUMNS` (axis-aligned image box, pixels);
  - ``"3d"``: :data:`BOX3D_COLUMNS` plus ``yaw_rad`` *or* ``yaw_deg`` (box in the world frame W);
  - ``"corners"``: ``u0_px, v0_px, u1_px, v1_px, ...`` (K >= 1 footprint corners in pixels,
    polygon order), see :func:`corner_columns`;

* optional detector pixel covariance :data:`COV_COLUMNS` (px^2), applied to every
  ground-contact point of the row, added to the budget's per-point noise.

Output
------
:func:`output_schema`: ``row`` (0-based index of the input row), the id columns
present in the input, ``status`` (:data:`STATUSES`), ``reason``, the footprint centre and its
covariance, ellipse, the linearity flag (:data:`FLAG_COLUMNS`), largest point, area, the V2X fields,
optionally lat/lon and per-corner columns.
"""

from __future__ import annotations

import re

import pyarrow as pa

from ..products.footprints import V2X_FIELDS

__all__ = ["DEFAULT_CHUNK_ROWS", "ID_COLUMNS", "ID_TYPES",
           "BOX2D_COLUMNS", "BOX3D_COLUMNS", "YAW_COLUMNS", "COV_COLUMNS", "BOX_TYPES",
           "STATUSES", "STATUS_OK", "STATUS_PARTIAL", "STATUS_ERROR", "V2X_UNAVAILABLE", "corner_columns",
           "count_corners", "detect_box_type", "box_columns", "numeric_input_columns", "output_schema",
           "corner_output_columns", "CENTRE_COLUMNS", "FLAG_COLUMNS", "REASON_TYPE"]

#: rows per chunk by default: peak memory about 0.35 GB + 0.8 kB x chunk_rows (docs/batch.md)
DEFAULT_CHUNK_ROWS = 131_072

#: identification columns passed through unchanged (all optional); ``score`` (the detector's confidence),
#: ``image`` (the image / label file a detection comes from) and ``line`` (its 1-based line in that file) are
#: what the detector-format readers carry (:mod:`footprint_uq.batch.formats`, docs/integrations.md)
ID_COLUMNS = ("camera_id", "frame", "timestamp_s", "object_id", "class", "score", "image", "line")
#: their types when read from text formats (CSV, JSON Lines); Parquet keeps its own types
ID_TYPES = {"camera_id": pa.string(), "frame": pa.int64(), "timestamp_s": pa.float64(), "object_id": pa.string(),
            "class": pa.string(), "score": pa.float64(), "image": pa.string(), "line": pa.int64()}
BOX2D_COLUMNS = ("u_min_px", "v_min_px", "u_max_px", "v_max_px")
BOX3D_COLUMNS = ("x_m", "y_m", "z_m", "length_m", "width_m", "height_m")
YAW_COLUMNS = ("yaw_rad", "yaw_deg")
COV_COLUMNS = ("cov_uu_px2", "cov_uv_px2", "cov_vv_px2")
BOX_TYPES = ("2d", "3d", "corners")

STATUS_OK = "ok"            # footprint centre computed
STATUS_PARTIAL = "partial"  # centre not computable, but at least one corner usable (largest point given)
STATUS_ERROR = "error"      # nothing computed: bad row or no usable corner
STATUSES = (STATUS_OK, STATUS_PARTIAL, STATUS_ERROR)

#: V2X codes written for rows without a centre covariance (the messages' "unavailable" values)
V2X_UNAVAILABLE = {"cpm_x_confidence": 4096, "cpm_y_confidence": 4096, "cpm_xy_correlation": 101,
                   "j2735_semi_major": 255, "j2735_semi_minor": 255, "j2735_orientation": 65535,
                   "j2735_position_confidence": 0}

#: status and reason are dictionary-encoded strings (few distinct values)
REASON_TYPE = pa.dictionary(pa.int32(), pa.string())

_CORNER_RE = re.compile(r"^[uv](\d+)_px$")


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
    """The box family of a set of column names (None if none is complete)."""
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


def numeric_input_columns(box_type: str, names) -> tuple[str, ...]:
    """Every numeric input column used (box columns, then the covariance columns present)."""
    names = set(names)
    return box_columns(box_type, names) + tuple(c for c in COV_COLUMNS if c in names)


CENTRE_COLUMNS = ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2", "sigma_major_m", "sigma_minor_m",
                  "orientation_deg")
#: the centre's linearity flag (docs/uncertainty-model.md, "The linearity flag"): ``nonlinearity`` (float, NaN
#: without a centre) and ``linear_ok`` (bool, ``nonlinearity <= linear_threshold``)
FLAG_COLUMNS = ("nonlinearity", "linear_ok")


def corner_output_columns(k: int, geo: bool, linearity: bool = True) -> list[tuple[str, pa.DataType]]:
    cols = [(f"c{k}_u_px", pa.float64()), (f"c{k}_v_px", pa.float64()), (f"c{k}_x_m", pa.float64()),
            (f"c{k}_y_m", pa.float64()), (f"c{k}_cov_xx_m2", pa.float64()), (f"c{k}_cov_xy_m2", pa.float64()),
            (f"c{k}_cov_yy_m2", pa.float64())]
    if linearity:
        cols.append((f"c{k}_nonlinearity", pa.float64()))
    cols.append((f"c{k}_reason", pa.int8()))
    if geo:
        cols += [(f"c{k}_lat_deg", pa.float64()), (f"c{k}_lon_deg", pa.float64())]
    return cols


def output_schema(id_fields: list[pa.Field], n_corners: int, *, confidence: bool, geo: bool,
                  corners: bool, linearity: bool = True) -> pa.Schema:
    """Schema of the footprint table.

    Parameters
    ----------
    id_fields : the id columns present in the input (their types)
    n_corners : K, ground-contact points per detection
    confidence : add ``semi_major_m``/``semi_minor_m`` (ellipse at the requested confidence)
    geo : add ``lat_deg``/``lon_deg`` (WGS84) of the centre (and of the corners with ``corners``)
    corners : add the per-corner columns ``c{k}_*``
    linearity : add the linearity flag's columns (:data:`FLAG_COLUMNS`, and ``c{k}_nonlinearity`` with
        ``corners``); without it they are absent, not filled
    """
    # computed columns are never null ("no value" is NaN or the message's "unavailable" code); declaring them
    # non-nullable spares the Parquet writer the definition levels (~40 ns per row of 27 columns)
    def c(name, typ):
        return pa.field(name, typ, nullable=False)

    f = [c("row", pa.int64())] + list(id_fields)
    f += [c("status", REASON_TYPE), c("reason", REASON_TYPE)]
    f += [c(name, pa.float64()) for name in CENTRE_COLUMNS]
    if confidence:
        f += [c("semi_major_m", pa.float64()), c("semi_minor_m", pa.float64())]
    if linearity:
        f += [c("nonlinearity", pa.float64()), c("linear_ok", pa.bool_())]
    f += [c("largest_index", pa.int8()), c("largest_sigma_major_m", pa.float64()),
          c("largest_x_m", pa.float64()), c("largest_y_m", pa.float64()), c("area_m2", pa.float64())]
    f += [c(name, pa.int32()) for name in V2X_FIELDS]
    if geo:
        f += [c("lat_deg", pa.float64()), c("lon_deg", pa.float64())]
    if corners:
        for k in range(n_corners):
            f += [c(n, t) for n, t in corner_output_columns(k, geo, linearity)]
    return pa.schema(f)
