"""Streaming writers of footprint tables: Parquet, CSV, JSON Lines, GeoJSON (format from the extension).

All writers take the output schema once and then one table per chunk.

* Parquet keeps the types (``status``/``reason`` dictionary-encoded strings, NaN for
  numbers that could not be computed);
* CSV and JSON Lines write ``status``/``reason`` as text; CSV writes NaN as an empty field,
  JSON Lines as ``null``;
* GeoJSON (RFC 7946) needs WGS84 coordinates, i.e. a geodetic origin: one Feature per
  row (``"role": "footprint"``); geometry a Polygon of the footprint corners (K >= 3, every
  corner computed; exterior ring counter-clockwise and closed), a Point (K = 1, or the centre /
  largest point when the polygon is not available) or null (error rows); properties: every
  output column except the per-corner ones, which the geometry carries.  With the writer's
  georeference, every row with a centre covariance also gets a Feature ``"role": "ellipse"``:
  the ellipse at ``ellipse_confidence`` (95 % by default) as a Polygon of
  :data:`ELLIPSE_VERTICES` vertices (:func:`~footprint_uq.uncertainty.ellipse.ellipse_ring`,
  computed in the world frame, then put on WGS84), so that a GIS draws it as a shape.
"""

from __future__ import annotations

import abc
import json
import math
import os
from pathlib import Path

import numpy as np
import orjson
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

from ..errors import InputError
from ..io.atomic import clean_temporaries_of, commit, discard, temp_path
from ..products.footprints import V2X_FIELDS
from ..uncertainty.ellipse import ellipse_ring

__all__ = ["AUTO", "is_code_column", "OUT_FORMATS", "detect_out_format", "open_writer", "FootprintWriter",
           "decode_dictionaries", "parquet_options"]

#: vertices of a GeoJSON ellipse polygon (before the closing one): 64 keep the polygon's area within 0.2 %
#: of the ellipse's
ELLIPSE_VERTICES = 64
OUT_FORMATS = {".csv": "csv", ".jsonl": "jsonl", ".ndjson": "jsonl", ".parquet": "parquet", ".pq": "parquet",
               ".geojson": "geojson"}


def detect_out_format(path, format: str | None = None) -> str:
    if format is not None:
        if format not in set(OUT_FORMATS.values()):
            raise InputError("format", format, f"one of {sorted(set(OUT_FORMATS.values()))}")
        return format
    suffix = Path(path).suffix.lower()
    if suffix not in OUT_FORMATS:
        raise InputError("out", str(path), f"a file ending in one of {sorted(OUT_FORMATS)}")
    return OUT_FORMATS[suffix]


def decode_dictionaries(table: pa.Table) -> pa.Table:
    """Dictionary columns -> plain strings (for text formats)."""
    cols = []
    for col in table.columns:
        if pa.types.is_dictionary(col.type):
            col = pc.cast(col, col.type.value_type)
        cols.append(col)
    return pa.Table.from_arrays(cols, names=table.column_names)


def _plain_schema(schema: pa.Schema) -> pa.Schema:
    return pa.schema([pa.field(f.name, f.type.value_type) if pa.types.is_dictionary(f.type) else f for f in schema])


class FootprintWriter(abc.ABC):
    """Base class: ``write(table)`` per chunk, ``close()`` at the end (also a context manager).

    Atomic: the rows go to a hidden temporary file next to ``path`` (:attr:`tmp`);
    :meth:`close` flushes, fsyncs and renames it to ``path``, :meth:`abort` (or leaving the
    ``with`` block by an exception) removes it, leaving any previous ``path`` intact.
    ``before_commit`` (optional callable) runs just before the rename (e.g. removing a stale
    summary, so that a summary never describes another file than the one beside it).
    ``fsync`` (default True): flush every chunk to the disk and fsync before the rename; False only
    renames (:func:`footprint_uq.io.atomic.commit`: never partial for a killed process, not durable
    across a power loss).
    """

    format = ""

    def __init__(self, path, schema: pa.Schema):
        self.path = Path(path)
        clean_temporaries_of(self.path)  # left by a killed run on the same output
        self.tmp = temp_path(self.path)
        self.schema = schema
        self.rows = 0
        self.before_commit = None
        self.fsync = True
        self._done = False
        self._fd = None

    def write(self, table: pa.Table) -> None:
        self._write(table)
        self.rows += table.num_rows
        if self.fsync:
            self._sync()

    def _sync(self) -> None:
        """Flush this chunk's bytes to the disk now (in the batch's writer thread, overlapping the next
        chunk's computation), so that the final fsync before the rename has little left to do."""
        try:
            if self._fd is None:
                self._fd = os.open(self.tmp, os.O_RDONLY)
            os.fdatasync(self._fd)
        except (OSError, AttributeError):  # pragma: no cover - no fdatasync (macOS) or not yet on disk
            pass

    def _close_fd(self) -> None:
        if self._fd is not None:
            try:
                os.close(self._fd)
            except OSError:  # pragma: no cover
                pass
            self._fd = None

    @abc.abstractmethod
    def _write(self, table: pa.Table) -> None:
        """Write one chunk (each format's own writer)."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Flush and close the temporary file (each format's own writer)."""

    def close(self) -> None:
        """Finish the file and rename it to :attr:`path`."""
        if self._done:
            return
        self._done = True
        try:
            self._close()
            self._close_fd()
            if self.before_commit is not None:
                self.before_commit()
            commit(self.tmp, self.path, fsync=self.fsync)
        except BaseException:
            discard(self.tmp)
            raise

    def abort(self) -> None:
        """Drop the output: close and remove the temporary file (never raises)."""
        if self._done:
            return
        self._done = True
        try:
            self._close()
        except Exception:  # noqa: BLE001 - the file is being dropped, its close errors do not matter
            pass
        finally:
            self._close_fd()
            discard(self.tmp)

    def info(self) -> dict:
        """Entries this output adds to the job's summary (none for the file formats)."""
        return {}

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close()
        else:
            self.abort()


#: the default Parquet compression: see :func:`parquet_options`
AUTO = "auto"


def is_code_column(name: str) -> bool:
    """Small-integer code columns of the footprint table (V2X fields, corner indices and reasons)."""
    return name in V2X_FIELDS or name == "largest_index" or (name.startswith("c") and name.endswith("_reason"))


def parquet_options(schema: pa.Schema, compression: str | None = AUTO) -> dict:
    """ParquetWriter options of the footprint files.

    * dictionary encoding for text columns only (trying it on float columns costs more than the
      whole computation), statistics for the id columns only;
    * ``compression="auto"``: snappy, except for the small-integer code columns (V2X fields,
      ``largest_index``, ``c{k}_reason``), which are bit-packed (``DELTA_BINARY_PACKED``) and not
      compressed: smaller than with snappy (about 105 instead of 118 bytes per row of the default
      table) at a third of snappy's cost on them (measured with pyarrow 26, see docs/batch.md).
      Any other codec (or None) applies to every column, with the default encodings.
    """
    strings = [f.name for f in schema if pa.types.is_dictionary(f.type) or pa.types.is_string(f.type)]
    stats = [c for c in ("row", "camera_id", "frame", "timestamp_s", "source") if c in schema.names]
    opts = {"use_dictionary": strings, "write_statistics": stats, "compression": compression or "none"}
    if compression == AUTO:
        codes = [f.name for f in schema if is_code_column(f.name) and pa.types.is_integer(f.type)]
        opts["compression"] = {f.name: ("none" if f.name in codes else "snappy") for f in schema}
        if codes:
            opts["column_encoding"] = {c: "DELTA_BINARY_PACKED" for c in codes}
    return opts


class ParquetOut(FootprintWriter):
    format = "parquet"

    def __init__(self, path, schema, *, compression: str | None = AUTO):

        super().__init__(path, schema)
        self._w = pq.ParquetWriter(self.tmp, schema, **parquet_options(schema, compression))

    def _write(self, table):
        if table.num_rows:
            self._w.write_table(table.cast(self.schema) if table.schema != self.schema else table)

    def _close(self):
        self._w.close()


class CsvOut(FootprintWriter):
    format = "csv"

    def __init__(self, path, schema):

        super().__init__(path, schema)
        self._plain = _plain_schema(schema)
        self._w = pcsv.CSVWriter(str(self.tmp), self._plain)

    def _write(self, table):
        t = decode_dictionaries(table)
        # NaN -> null (an empty field), the CSV convention for "no value"
        cols = [pc.if_else(pc.is_nan(c), pa.scalar(None, c.type), c) if pa.types.is_floating(c.type) else c
                for c in t.columns]
        self._w.write_table(pa.Table.from_arrays(cols, schema=self._plain))

    def _close(self):
        self._w.close()


_ORJSON_OPTS = orjson.OPT_APPEND_NEWLINE | orjson.OPT_SERIALIZE_NUMPY | orjson.OPT_NON_STR_KEYS


class JsonlOut(FootprintWriter):
    format = "jsonl"

    def __init__(self, path, schema):
        super().__init__(path, schema)
        self._f = open(self.tmp, "wb")

    def _write(self, table):
        if not table.num_rows:
            return
        # orjson writes the shortest text that reads back to the same double (pandas' to_json keeps a
        # fixed number of decimals: a 1e-5 m^2 covariance lost half its digits) and NaN as null
        rows = decode_dictionaries(table).to_pandas().to_dict(orient="records")
        self._f.write(b"".join(orjson.dumps(r, option=_ORJSON_OPTS) for r in rows))

    def _close(self):
        self._f.close()


def _num(x):
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


class GeoJsonOut(FootprintWriter):
    format = "geojson"

    def __init__(self, path, schema, *, georef=None, ellipse_confidence: float = 0.95):
        super().__init__(path, schema)
        self.georef = georef
        self.ellipse_confidence = float(ellipse_confidence)
        if "lat_deg" not in schema.names:
            raise InputError("out", str(path), "an origin (origin_lat_deg/origin_lon_deg) for GeoJSON output: "
                             "GeoJSON coordinates are WGS84 longitude/latitude")
        K = 0
        while f"c{K}_lat_deg" in schema.names:
            K += 1
        self.K = K
        self._props = [n for n in schema.names if not (n.startswith("c") and n[1:2].isdigit())]
        self._f = open(self.tmp, "w", encoding="utf-8")
        self._f.write('{"type": "FeatureCollection", "features": [\n')
        self._first = True

    def _write(self, table):
        if not table.num_rows:
            return
        t = decode_dictionaries(table)
        props = t.select(self._props).to_pylist()
        K = self.K
        if K:
            lat = np.stack([t.column(f"c{k}_lat_deg").to_numpy(zero_copy_only=False) for k in range(K)], 1)
            lon = np.stack([t.column(f"c{k}_lon_deg").to_numpy(zero_copy_only=False) for k in range(K)], 1)
            cx = np.stack([t.column(f"c{k}_x_m").to_numpy(zero_copy_only=False) for k in range(K)], 1)
            cy = np.stack([t.column(f"c{k}_y_m").to_numpy(zero_copy_only=False) for k in range(K)], 1)
            area = 0.5 * np.sum(cx * np.roll(cy, -1, 1) - np.roll(cx, -1, 1) * cy, axis=1)
        clat = t.column("lat_deg").to_numpy(zero_copy_only=False)
        clon = t.column("lon_deg").to_numpy(zero_copy_only=False)
        rings = self._ellipse_rings(t)
        parts = []
        for i, p in enumerate(props):
            geom = None
            if K >= 3 and np.isfinite(lat[i]).all() and np.isfinite(lon[i]).all() and area[i] != 0:
                order = range(K) if area[i] > 0 else range(K - 1, -1, -1)  # counter-clockwise (x east, y north)
                ring = [[float(lon[i, k]), float(lat[i, k])] for k in order]
                ring.append(ring[0])
                geom = {"type": "Polygon", "coordinates": [ring]}
            elif math.isfinite(clat[i]) and math.isfinite(clon[i]):
                geom = {"type": "Point", "coordinates": [float(clon[i]), float(clat[i])]}
            elif K and 0 <= (k := int(p.get("largest_index", -1))) < K and math.isfinite(lat[i, k]):
                geom = {"type": "Point", "coordinates": [float(lon[i, k]), float(lat[i, k])]}
            props = {"role": "footprint", **{k: _num(v) for k, v in p.items()}}
            parts.append(json.dumps({"type": "Feature", "geometry": geom, "properties": props}, allow_nan=False,
                                    default=str))
            if rings is not None and rings[i] is not None:
                props = {**props, "role": "ellipse", "ellipse_confidence": self.ellipse_confidence}
                parts.append(json.dumps({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [rings[i]]},
                                         "properties": props}, allow_nan=False, default=str))
        sep = ",\n"
        self._f.write(("" if self._first else sep) + sep.join(parts))
        self._first = False

    def _ellipse_rings(self, t: pa.Table) -> list | None:
        """Per row: the ellipse's closed ``[lon, lat]`` ring (a list), or None (no centre covariance)."""
        if self.georef is None:
            return None
        col = {c: t.column(c).to_numpy(zero_copy_only=False) for c in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2",
                                                                        "cov_yy_m2", "sigma_minor_m")}
        centre = np.stack([col["x_m"], col["y_m"]], -1)
        cov = np.stack([np.stack([col["cov_xx_m2"], col["cov_xy_m2"]], -1),
                        np.stack([col["cov_xy_m2"], col["cov_yy_m2"]], -1)], -2)
        with np.errstate(invalid="ignore"):
            ok = np.isfinite(centre).all(-1) & np.isfinite(cov).all((-1, -2)) & (col["sigma_minor_m"] > 0)
        out: list = [None] * t.num_rows
        if not ok.any():
            return out
        ring = ellipse_ring(centre[ok], cov[ok], confidence=self.ellipse_confidence, n=ELLIPSE_VERTICES)
        lat, lon = self.georef.to_wgs84(ring)
        for j, i in enumerate(np.flatnonzero(ok).tolist()):
            if np.isfinite(lat[j]).all() and np.isfinite(lon[j]).all():
                out[i] = np.stack([lon[j], lat[j]], -1).tolist()
                out[i][-1] = out[i][0]  # closed exactly, whatever the projection's rounding
        return out

    def _close(self):
        try:
            self._f.write("\n]}\n")
        finally:
            self._f.close()


def open_writer(path, schema: pa.Schema, *, format: str | None = None, compression: str | None = AUTO,
                fsync: bool = True, georef=None, ellipse_confidence: float = 0.95):
    """A :class:`FootprintWriter` for ``path`` (format from the extension; ``fsync`` as in :class:`FootprintWriter`;
    GeoJSON: with ``georef``, a :class:`~footprint_uq.products.geo.GeoReference`, also the
    ``ellipse_confidence`` ellipses as polygons)."""
    fmt = detect_out_format(path, format)
    if fmt == "parquet":
        w = ParquetOut(path, schema, compression=compression)
    elif fmt == "csv":
        w = CsvOut(path, schema)
    elif fmt == "jsonl":
        w = JsonlOut(path, schema)
    else:
        w = GeoJsonOut(path, schema, georef=georef, ellipse_confidence=ellipse_confidence)
    w.fsync = bool(fsync)
    return w
