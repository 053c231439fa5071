"""Column names and types of the batch detections (input) and footprints (output).

The box families, their columns and the status words are
:mod:`footprint_uq.products.detection_columns` (shared with the edge service), re-exported here.

The full description, with examples, is ``docs/batch.md``.  Names carry their unit
(``_px``, ``_m``, ``_m2``, ``_deg``, ``_rad``, ``_s``) as everywhere in footprint-uq.

Input
-----
* identification (all optional, passed through to the output): :data:`ID_COLUMNS` (``score``: the
  detector's confidence of the class, e.g. a ROS 2 bag's ``hypothesis.score``);
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

import pyarrow as pa

from ..products.detection_columns import (
    BOX2D_COLUMNS,
    BOX3D_COLUMNS,
    BOX_TYPES,
    COV_COLUMNS,
    STATUS_ERROR,
    STATUS_OK,
    STATUS_PARTIAL,
    STATUSES,
    YAW_COLUMNS,
    box_columns,
    corner_columns,
    count_corners,
    detect_box_type,
)
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

#: V2X codes written for rows without a centre covariance (the messages' "unavailable" values)
V2X_UNAVAILABLE = {"cpm_x_confidence": 4096, "cpm_y_confidence": 4096, "cpm_xy_correlation": 101,
                   "j2735_semi_major": 255, "j2735_semi_minor": 255, "j2735_orientation": 65535,
                   "j2735_position_confidence": 0}

#: status and reason are dictionary-encoded strings (few distinct values)
REASON_TYPE = pa.dictionary(pa.int32(), pa.string())

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
