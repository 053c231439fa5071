"""Streaming readers of detection files: CSV, JSON Lines, Parquet, in chunks of rows.

Every reader yields :class:`Chunk` objects whose table holds only the columns the
batch needs (box, covariance and id columns), with the numeric columns as float64
and, for the text formats, the id columns in :data:`~footprint_uq.batch.schema.ID_TYPES`.
Nothing is dropped silently:

* a value that is not a number (``"abc"`` in ``u_min_px``) becomes null and the row
  carries the reason in :attr:`Chunk.pre_errors`;
* a line that cannot be parsed at all (a CSV line with the wrong number of fields,
  a JSON line that is not a JSON object) has no table row; it is listed in
  :attr:`Chunk.malformed` with its row number and reason.

Row numbers (``row``) are 0-based:

* CSV: the data line (line ``row + 2`` of the file, the header being line 1); every
  line after the header is a row (an empty line is a malformed row); fields must not
  contain newlines;
* JSON Lines: the line (line ``row + 1``); blank lines are not rows;
* Parquet: the row in file order.
"""

from __future__ import annotations

import bisect
import io
import json
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from ..errors import InputError
from . import schema as S

__all__ = ["Chunk", "DetectionReader", "open_detections", "detect_format", "FORMATS", "coerce_table",
           "iter_parquet_tables"]

#: input formats by extension
FORMATS = {".csv": "csv", ".jsonl": "jsonl", ".ndjson": "jsonl", ".parquet": "parquet", ".pq": "parquet"}


def detect_format(path, format: str | None = None) -> str:
    """``"csv"``, ``"jsonl"`` or ``"parquet"`` from ``format`` or the file extension."""
    if format is not None:
        if format not in ("csv", "jsonl", "parquet"):
            raise InputError("format", format, "one of 'csv', 'jsonl', 'parquet'")
        return format
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix in FORMATS:
        return FORMATS[suffix]
    raise InputError("detections", str(path), f"a file ending in one of {sorted(FORMATS)}")


@dataclass
class Chunk:
    """A chunk of detections.

    Attributes
    ----------
    table : pyarrow.Table     parsed rows (needed columns only)
    rows : (n,) int64         input row number of each table row
    pre_errors : list or None reason (str) of rows whose values could not be converted, else None
    malformed : list          ``(row, reason)`` of unparseable rows (no table row)
    progress : int            progress units consumed by this chunk (rows or bytes)
    """

    table: pa.Table
    rows: np.ndarray
    pre_errors: list | None = None
    malformed: list = field(default_factory=list)
    progress: int = 0


# -- value conversion -------------------------------------------------------------------------
def _to_float(v):
    if isinstance(v, bool):
        raise ValueError("boolean")
    if isinstance(v, int | float):
        return float(v)
    if isinstance(v, str):
        return float(v.strip())
    raise ValueError(type(v).__name__)


def _to_int(v):
    if isinstance(v, bool):
        raise ValueError("boolean")
    if isinstance(v, int):
        return v
    x = _to_float(v)
    if not (math.isfinite(x) and x.is_integer()):
        raise ValueError("not an integer")
    return int(x)


def _convert_values(values: list, typ: pa.DataType):
    """Python values -> (list of converted values or None, list of bad positions)."""
    out, bad = [], []
    if pa.types.is_floating(typ):
        conv = _to_float
    elif pa.types.is_integer(typ):
        conv = _to_int
    else:
        def conv(v):
            return v if isinstance(v, str) else json.dumps(v) if isinstance(v, list | dict) else str(v)
    for i, v in enumerate(values):
        if v is None:
            out.append(None)
            continue
        try:
            out.append(conv(v))
        except (ValueError, TypeError, OverflowError):
            out.append(None)
            bad.append(i)
    return out, bad


def _what(typ) -> str:
    return "a number" if pa.types.is_floating(typ) else "an integer" if pa.types.is_integer(typ) else "text"


def _cast_column(col, typ: pa.DataType, name: str, pre_errors: list):
    """Cast a column to ``typ``; values that do not convert become null with a reason in ``pre_errors``."""
    if isinstance(col, pa.ChunkedArray):
        col = col.combine_chunks()
    if col.type == typ:
        return col
    if pa.types.is_null(col.type):
        return pa.nulls(len(col), type=typ)
    if pa.types.is_boolean(col.type) and not pa.types.is_boolean(typ):  # true/false is not a number
        for i in np.flatnonzero(col.is_valid().to_numpy(zero_copy_only=False)).tolist():
            if pre_errors[i] is None:
                pre_errors[i] = f"field {name} is not {_what(typ)}"
        return pa.nulls(len(col), type=typ)
    try:
        return pc.cast(col, typ)
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
        pass
    values, bad = _convert_values(col.to_pylist(), typ)
    for i in bad:
        if pre_errors[i] is None:
            pre_errors[i] = f"field {name} is not {_what(typ)}"
    return pa.array(values, type=typ)


def coerce_table(table: pa.Table, numeric: tuple[str, ...], *, id_types: dict | None = None):
    """Numeric columns -> float64 and id columns -> ``id_types`` (None: keep), with per-row errors.

    Returns ``(table, pre_errors)``; ``pre_errors`` is None when every value converted.
    """
    pre = _LazyErrors(table.num_rows)
    arrays, names = [], []
    for name in table.column_names:
        col = table.column(name)
        if name in numeric:
            col = _cast_column(col, pa.float64(), name, pre)
        elif id_types is not None and name in id_types:
            col = _cast_column(col, id_types[name], name, pre)
        arrays.append(col)
        names.append(name)
    out = pa.Table.from_arrays(arrays, names=names)
    return out, pre.result()


class _LazyErrors:
    """Per-row reasons, allocated on the first error (most chunks have none)."""

    def __init__(self, n: int):
        self.n = n
        self.items: list | None = None

    def __getitem__(self, i):
        return None if self.items is None else self.items[i]

    def __setitem__(self, i, value):
        if self.items is None:
            self.items = [None] * self.n
        self.items[i] = value

    def result(self) -> list | None:
        return self.items


# -- readers ----------------------------------------------------------------------------------------
class DetectionReader:
    """Iterate over a detection file in chunks (:meth:`__iter__` yields :class:`Chunk`).

    Attributes
    ----------
    path, format, columns (every column name in the file), total (progress units, or None),
    unit ("rows" or "B"), id_fields (id columns present, with their output types)
    """

    def __init__(self, path, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS, format: str | None = None):
        self.path = Path(path)
        if not self.path.exists():
            raise InputError("detections", str(path), "an existing file")
        self.format = detect_format(path, format)
        if int(chunk_rows) < 1:
            raise InputError("chunk_rows", chunk_rows, "an integer >= 1")
        self.chunk_rows = int(chunk_rows)
        self.needed: tuple[str, ...] = ()
        self.numeric: tuple[str, ...] = ()
        if self.format == "parquet":
            import pyarrow.parquet as pq

            self._pf = pq.ParquetFile(self.path)
            self.columns = list(self._pf.schema_arrow.names)
            self.total, self.unit = self._pf.metadata.num_rows, "rows"
        elif self.format == "csv":
            self.columns = self._csv_header()
            self.total, self.unit = self.path.stat().st_size, "B"
        else:
            self.columns = self._jsonl_columns()
            self.total, self.unit = self.path.stat().st_size, "B"

    # layout
    def select(self, numeric: tuple[str, ...]) -> None:
        """Read only ``numeric`` (converted to float64) and the id columns present."""
        self.numeric = tuple(numeric)
        ids = tuple(c for c in S.ID_COLUMNS if c in self.columns)
        self.needed = ids + tuple(c for c in self.numeric if c not in ids)

    @property
    def id_fields(self) -> list[pa.Field]:
        if self.format == "parquet":
            sch = self._pf.schema_arrow
            return [sch.field(c) for c in S.ID_COLUMNS if c in self.columns]
        return [pa.field(c, S.ID_TYPES[c]) for c in S.ID_COLUMNS if c in self.columns]

    def __iter__(self) -> Iterator[Chunk]:
        if not self.needed:
            raise InputError("DetectionReader", "no columns selected", "select(numeric columns) first")
        if self.format == "parquet":
            return self._iter_parquet()
        if self.format == "csv":
            return self._iter_csv()
        return self._iter_jsonl()

    # parquet
    def _iter_parquet(self):
        start = 0
        # one decoding thread: the batch reads ahead in a thread of its own while the kernel uses the
        # cores; pyarrow's own pool here only adds scheduling (measured: ~25 % more CPU per row)
        for t in iter_parquet_tables(self._pf, list(self.needed), self.chunk_rows, use_threads=False):
            n = t.num_rows
            t, pre = coerce_table(t, self.numeric)
            yield Chunk(t, np.arange(start, start + n, dtype=np.int64), pre, [], n)
            start += n

    # csv
    def _csv_header(self) -> list[str]:
        import csv

        with open(self.path, newline="", encoding="utf-8-sig") as f:
            line = f.readline()
        if not line.strip():
            raise InputError("detections", str(self.path), "a CSV file whose first line is a header of column names")
        return next(csv.reader([line]))

    def _iter_csv(self):
        import pyarrow.csv as pcsv

        skipped: list[tuple[int, str]] = []  # (row, reason), found by the parser (possibly ahead of the batches)

        def on_invalid(r):
            row = (r.number - 2) if r.number is not None else None
            if row is None:  # pragma: no cover - the serial reader always knows the line number
                raise InputError("detections", f"malformed CSV line {r.text[:40]!r}", "lines with the header's fields")
            what = "empty line" if not r.text.strip() else f"{r.actual_columns} fields, expected {r.expected_columns}"
            bisect.insort(skipped, (row, f"malformed CSV line ({what})"))
            return "skip"

        counter = _CountingFile(open(self.path, "rb"))
        types = {c: pa.string() for c in self.needed}
        try:
            reader = pcsv.open_csv(
                counter,
                read_options=pcsv.ReadOptions(use_threads=False, block_size=1 << 22, encoding="utf8"),
                parse_options=pcsv.ParseOptions(invalid_row_handler=on_invalid, ignore_empty_lines=False),
                convert_options=pcsv.ConvertOptions(column_types=types, include_columns=list(self.needed),
                                                    strings_can_be_null=True))
        except pa.ArrowInvalid as e:
            counter.close()
            raise InputError("detections", str(self.path), f"a readable CSV file ({e})") from None
        nxt = 0  # next unassigned row number
        pending: list[pa.RecordBatch] = []
        pending_rows: list[np.ndarray] = []
        pending_bad: list[tuple[int, str]] = []
        n_pending = 0
        last_pos = 0
        try:
            while True:
                try:
                    batch = reader.read_next_batch()
                except StopIteration:
                    batch = None
                if batch is not None and batch.num_rows:
                    rows, nxt, bad = _assign_rows(nxt, batch.num_rows, skipped)
                    pending.append(batch)
                    pending_rows.append(rows)
                    pending_bad += bad
                    n_pending += batch.num_rows
                if batch is None:  # trailing malformed lines
                    pending_bad += [s for s in skipped if s[0] >= nxt]
                    skipped.clear()
                while n_pending >= self.chunk_rows or (batch is None and (n_pending or pending_bad)):
                    take = min(self.chunk_rows, n_pending)
                    t = pa.Table.from_batches(pending, schema=reader.schema) if pending else None
                    rows = np.concatenate(pending_rows) if pending_rows else np.zeros(0, np.int64)
                    head = t.slice(0, take) if t is not None else pa.table({c: pa.array([], pa.string())
                                                                             for c in self.needed})
                    hr = rows[:take]
                    lim = hr[-1] if take and n_pending > take else np.iinfo(np.int64).max
                    mal = [b for b in pending_bad if b[0] <= lim]
                    pending_bad = [b for b in pending_bad if b[0] > lim]
                    if t is not None and n_pending > take:
                        pending = t.slice(take).to_batches()
                        pending_rows = [rows[take:]]
                    else:
                        pending, pending_rows = [], []
                    n_pending -= take
                    head, pre = coerce_table(head, self.numeric, id_types=S.ID_TYPES)
                    pos = counter.pos
                    yield Chunk(head, hr, pre, mal, pos - last_pos)
                    last_pos = pos
                if batch is None:
                    break
        except pa.ArrowInvalid as e:
            raise InputError("detections", str(self.path), f"a readable CSV file ({e})") from None
        finally:
            counter.close()

    # jsonl
    def _jsonl_columns(self) -> list[str]:
        """Column names: the union of the keys of the first 1000 JSON objects."""
        names: dict[str, None] = {}
        with open(self.path, "rb") as f:
            for i, line in enumerate(f):
                if i >= 1000:
                    break
                try:
                    obj = json.loads(line)
                except ValueError:
                    continue
                if isinstance(obj, dict):
                    names.update(dict.fromkeys(obj))
        return list(names)

    def _iter_jsonl(self):
        import pyarrow.json as pjson

        with open(self.path, "rb") as f:
            lineno = 0
            while True:
                lines, rows, nbytes = [], [], 0
                while len(lines) < self.chunk_rows:
                    line = f.readline()
                    if not line:
                        break
                    nbytes += len(line)
                    if line.strip():
                        lines.append(line if line.endswith(b"\n") else line + b"\n")
                        rows.append(lineno)
                    lineno += 1
                if not lines and not nbytes:
                    break
                rows_a = np.asarray(rows, dtype=np.int64)
                table, pre, mal = None, None, []
                try:
                    t = pjson.read_json(io.BytesIO(b"".join(lines)),
                                        read_options=pjson.ReadOptions(use_threads=True, block_size=1 << 24))
                    if t.num_rows == len(lines):
                        table = t
                except (pa.ArrowInvalid, pa.ArrowNotImplementedError):
                    table = None
                if table is not None:
                    table = _select(table, self.needed)
                    table, pre = coerce_table(table, self.numeric, id_types=S.ID_TYPES)
                else:
                    table, pre, mal, keep = self._jsonl_slow(lines, rows_a)
                    rows_a = rows_a[keep]
                yield Chunk(table, rows_a, pre, mal, nbytes)
                if len(lines) < self.chunk_rows and not line:
                    break

    def _jsonl_slow(self, lines, rows):
        """Line by line: invalid JSON lines become malformed rows, bad values pre-errors."""
        records, keep, mal = [], [], []
        for i, line in enumerate(lines):
            try:
                obj = json.loads(line)
            except ValueError as e:
                mal.append((int(rows[i]), f"invalid JSON line: {e.msg}"))
                continue
            if not isinstance(obj, dict):
                mal.append((int(rows[i]), f"JSON line is not an object: {type(obj).__name__}"))
                continue
            records.append(obj)
            keep.append(i)
        pre: list = [None] * len(records)
        arrays = {}
        for name in self.needed:
            typ = pa.float64() if name in self.numeric else S.ID_TYPES.get(name, pa.string())
            raw = [r.get(name) for r in records]
            values, bad = _convert_values(raw, typ)
            for j in bad:
                if pre[j] is None:
                    pre[j] = f"field {name} is not {_what(typ)}"
            arrays[name] = pa.array(values, type=typ)
        return (pa.table(arrays), (pre if any(p is not None for p in pre) else None), mal,
                np.asarray(keep, dtype=np.int64))


def iter_parquet_tables(pf, columns: list, chunk_rows: int, *, use_threads: bool = True) -> Iterator[pa.Table]:
    """Tables of ``chunk_rows`` rows (the last one shorter) of a ``pyarrow.parquet.ParquetFile``, in file order.

    Reads one row group at a time (``iter_batches(row_groups=[i])``): iterating a whole file
    with one ``iter_batches`` call keeps memory growing with the file in pyarrow 15-26, one
    row group at a time does not.
    """
    buf: list[pa.Table] = []
    n_buf = 0
    for i in range(pf.num_row_groups):
        for batch in pf.iter_batches(batch_size=chunk_rows, row_groups=[i], columns=columns,
                                     use_threads=use_threads):
            buf.append(pa.Table.from_batches([batch]))
            n_buf += batch.num_rows
            while n_buf >= chunk_rows:
                t = pa.concat_tables(buf) if len(buf) > 1 else buf[0]
                yield t.slice(0, chunk_rows).combine_chunks()
                rest = t.slice(chunk_rows)
                buf, n_buf = ([rest] if rest.num_rows else []), rest.num_rows
    if n_buf:
        t = pa.concat_tables(buf) if len(buf) > 1 else buf[0]
        yield t.combine_chunks()


def _select(table: pa.Table, names) -> pa.Table:
    """The columns ``names`` of ``table``; absent ones (never seen in this chunk) as nulls."""
    cols = {n: (table.column(n) if n in table.column_names else pa.nulls(table.num_rows)) for n in names}
    return pa.table(cols)


def _assign_rows(nxt: int, n: int, skipped: list[tuple[int, str]]):
    """Row numbers of n parsed rows starting at ``nxt``, skipping malformed rows.

    Returns ``(rows, next, malformed)`` with the malformed rows inside the range (removed from ``skipped``).
    """
    j = bisect.bisect_left(skipped, (nxt, ""))
    rows = np.empty(n, dtype=np.int64)
    filled = 0
    r = nxt
    bad = []
    while filled < n:
        if j < len(skipped) and skipped[j][0] == r:
            bad.append(skipped[j])
            j += 1
            r += 1
            continue
        stop = skipped[j][0] if j < len(skipped) else r + (n - filled)
        m = min(stop - r, n - filled)
        rows[filled:filled + m] = np.arange(r, r + m)
        filled += m
        r += m
    # malformed rows right after the last parsed row belong to a later chunk
    for b in bad:
        skipped.remove(b)
    return rows, r, bad


class _CountingFile(io.RawIOBase):
    """A read-only binary file wrapper that counts the bytes read (progress of the CSV reader)."""

    def __init__(self, f):
        self._f = f
        self.pos = 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = self._f.readinto(b)
        self.pos += n or 0
        return n

    def read(self, size=-1):
        data = self._f.read(size)
        self.pos += len(data)
        return data

    def close(self) -> None:
        self._f.close()
        super().close()


def open_detections(path, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS, format: str | None = None) -> DetectionReader:
    """A :class:`DetectionReader` on a CSV, JSON Lines or Parquet file (format from the extension)."""
    return DetectionReader(path, chunk_rows=chunk_rows, format=format)
