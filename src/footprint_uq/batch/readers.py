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

Row numbers (``row``) are 0-based and count **physical lines** (ended by LF or CRLF; the
last line may have no terminator), so that rows in = lines in, whatever a line holds:

* CSV: the data line (line ``row + 2`` of the file, the header being line 1); every
  line after the header is a row.  A line that is not one CSV record by itself (a stray
  or unterminated quote, a quoted line break, the wrong number of fields, bytes that are
  not UTF-8, a carriage return inside the line) is a malformed row with its reason; an
  empty line is an error row.  The header must be UTF-8 (a byte-order mark is allowed),
  else the file is refused.  Blocks of lines are parsed by pyarrow when the result is
  certain to be one record per line (checked), else line by line with Python's ``csv``
  module in strict mode;
* JSON Lines: the line (line ``row + 1``); a blank line is an error row (``empty line``);
* Parquet: the row in file order (an empty, truncated or garbage file: :class:`InputError`).

A FIFO (a named pipe, ``/dev/stdin`` of a pipe) is read once, as a stream, in CSV and JSON Lines (the
header / the first 1000 objects are kept and replayed); Parquet needs seeking and refuses it in one line;
a device, socket or directory is refused (:mod:`footprint_uq._files`: never a hang).

:attr:`DetectionReader.lines` counts the physical lines read, independently of the
parser; the batch checks rows in against it.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.csv as pcsv
import pyarrow.json as pjson
import pyarrow.parquet as pq

from .._files import is_stream, open_input, require_regular
from ..errors import InputError
from . import schema as S

__all__ = ["Chunk", "DetectionReader", "open_detections", "detect_format", "FORMATS", "coerce_table",
           "iter_parquet_tables", "open_parquet"]

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


class _Prefixed:
    """A read-once stream with bytes already taken from it put back in front (``read(n)`` may return fewer
    than ``n`` bytes; an empty result is the end)."""

    def __init__(self, prefix: bytes, f):
        self.prefix, self.f = prefix, f

    def read(self, n: int = -1) -> bytes:
        if self.prefix:
            out = self.prefix if n < 0 else self.prefix[:n]
            self.prefix = self.prefix[len(out):]
            return out
        return self.f.read(n)

    def close(self) -> None:
        self.f.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


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


_INT64 = (-(2**63), 2**63 - 1)


def _to_int(v):
    if isinstance(v, bool):
        raise ValueError("boolean")
    if not isinstance(v, int):
        x = _to_float(v)
        if not (math.isfinite(x) and x.is_integer()):
            raise ValueError("not an integer")
        v = int(x)
    if not _INT64[0] <= v <= _INT64[1]:  # a 64-bit integer column (frame)
        raise ValueError("out of the 64-bit range")
    return v


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
    path, format, columns (every column name in the file), family_columns (the columns that decide the box
    family: JSON Lines, those of the objects of the file's prevalent family, see :meth:`_jsonl_columns`;
    else ``columns``), total (progress units, or None), unit ("rows" or "B"), id_fields (id columns
    present, with their output types)
    """

    def __init__(self, path, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS, format: str | None = None):
        self.path = Path(path)
        if not self.path.exists():
            raise InputError("detections", str(path), "an existing file")
        self.format = detect_format(path, format)
        #: a FIFO's stream (read once: CSV and JSON Lines), None for a regular file
        self._stream = None
        if self.format == "parquet":
            require_regular(self.path, "detections", "Parquet needs a seekable file; convert the stream to CSV or "
                            "JSON Lines, or save it to a file first")
        elif is_stream(self.path):
            self._stream = open_input(self.path, "detections")
        else:
            open_input(self.path, "detections").close()  # a device, socket or directory: refused here
        if int(chunk_rows) < 1:
            raise InputError("chunk_rows", chunk_rows, "an integer >= 1")
        self.chunk_rows = int(chunk_rows)
        self.needed: tuple[str, ...] = ()
        self.numeric: tuple[str, ...] = ()
        #: physical lines read so far (CSV: after the header; JSON Lines: all), None for Parquet
        self.lines: int | None = None if self.format == "parquet" else 0
        self.family_columns: list[str] | None = None
        if self.format == "parquet":
            self._pf = open_parquet(self.path, "detections")
            self.columns = list(self._pf.schema_arrow.names)
            self.total, self.unit = self._pf.metadata.num_rows, "rows"
        elif self.format == "csv":
            self.columns = self._csv_header()
            self.total, self.unit = self._size(), "B"
        else:
            self.columns, self.family_columns = self._jsonl_columns()
            self.total, self.unit = self._size(), "B"
        if self.family_columns is None:
            self.family_columns = list(self.columns)

    def _size(self) -> int | None:
        return None if self._stream is not None else self.path.stat().st_size

    def _body(self):
        """The file after what :meth:`_csv_header` / :meth:`_jsonl_columns` took (a stream: once only)."""
        if self._stream is None:
            f = open(self.path, "rb")  # noqa: SIM115 - closed by the caller
            if self.format == "csv":
                f.seek(self._header_bytes)
            return f
        f, self._stream = self._stream, _USED
        if f is _USED:
            raise InputError("detections", str(self.path), "a regular file to read twice (a FIFO is read once)")
        return f

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
        tables = iter_parquet_tables(self._pf, list(self.needed), self.chunk_rows, use_threads=False,
                                     where=str(self.path))
        for t in tables:
            n = t.num_rows
            t, pre = coerce_table(t, self.numeric)
            yield Chunk(t, np.arange(start, start + n, dtype=np.int64), pre, [], n)
            start += n

    # csv
    def _csv_header(self) -> list[str]:
        if self._stream is not None:
            raw = _read_line(self._stream)
            self._stream = _Prefixed(b"", self._stream)
        else:
            with open(self.path, "rb") as f:
                raw = f.readline()
        self._header_bytes = len(raw)
        text = raw[3:] if raw.startswith(_BOM) else raw
        try:
            text = text.decode("utf-8").rstrip("\r\n")
        except UnicodeDecodeError as e:
            raise InputError("detections", str(self.path),
                             f"a UTF-8 CSV file (header line: {_utf8_error(e)})") from None
        if not text.strip():
            raise InputError("detections", str(self.path), "a CSV file whose first line is a header of column names")
        try:
            names = next(csv.reader([text], strict=True))
        except csv.Error as e:
            raise InputError("detections", str(self.path), f"a CSV header line of column names ({e})") from None
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise InputError("detections", str(self.path), f"a CSV header without duplicate columns (got {dup[0]!r} "
                             "twice)")
        return names

    def _iter_csv(self):
        with self._body() as f:
            row = 0
            for block, ends in _line_blocks(f, self.chunk_rows):
                n = ends.size
                self.lines += n
                try:
                    chunk = self._csv_fast(block, ends, row)
                except _SlowPath:
                    chunk = self._csv_slow(block, ends, row)
                chunk.progress = len(block)
                yield chunk
                row += n

    def _csv_convert_options(self):

        return pcsv.ConvertOptions(column_types={c: pa.string() for c in self.needed},
                                   include_columns=list(self.needed), strings_can_be_null=True)

    def _csv_fast(self, block: bytes, ends: np.ndarray, row0: int) -> Chunk:
        """pyarrow's parser on a block whose lines are certain to be one record each, else :class:`_SlowPath`.

        Certain: the block is UTF-8, has no carriage return outside CRLF, and the parser finds
        exactly one record (or one invalid row) per physical line, a sentinel line included (an
        unterminated quote on the last line would swallow it).
        """

        n = ends.size
        try:
            block.decode("utf-8")
        except UnicodeDecodeError:
            raise _SlowPath from None
        if block.count(b"\r") != block.count(b"\r\n"):
            raise _SlowPath
        invalid: list = []

        def on_invalid(r):
            invalid.append((r.number, r.actual_columns, r.expected_columns))
            return "skip"

        sentinel = b"" if block.endswith(b"\n") or not block else b"\n"
        sentinel += b"," * (len(self.columns) - 1) + b"\n"
        try:
            t = pcsv.read_csv(io.BytesIO(block + sentinel),
                              read_options=pcsv.ReadOptions(use_threads=False, column_names=self.columns,
                                                            block_size=max(1 << 20, len(block) + 1024)),
                              parse_options=pcsv.ParseOptions(invalid_row_handler=on_invalid,
                                                              ignore_empty_lines=False),
                              convert_options=self._csv_convert_options())
        except (pa.ArrowException, ValueError):
            raise _SlowPath from None
        if t.num_rows + len(invalid) != n + 1 or any(num is None or not 1 <= num <= n for num, _, _ in invalid):
            raise _SlowPath
        t = t.slice(0, t.num_rows - 1)  # the sentinel
        bad = np.zeros(n, dtype=bool)
        mal = []
        for num, got, want in invalid:
            bad[num - 1] = True
            mal.append((row0 + num - 1, f"malformed CSV line ({got} fields, expected {want})"))
        rows = row0 + np.flatnonzero(~bad)
        t, pre = coerce_table(t, self.numeric, id_types=S.ID_TYPES)
        empty = _empty_lines(block, ends)[~bad]
        if empty.any():
            pre = pre if pre is not None else [None] * t.num_rows
            for i in np.flatnonzero(empty).tolist():
                pre[i] = "malformed CSV line (empty line)"
        return Chunk(t, rows.astype(np.int64), pre, sorted(mal))

    def _csv_slow(self, block: bytes, ends: np.ndarray, row0: int) -> Chunk:
        """Line by line with Python's csv module (strict quoting within one line)."""


        ncol = len(self.columns)
        idx = [self.columns.index(c) for c in self.needed]
        nulls = set(pcsv.ConvertOptions().null_values)
        keep, values, mal = [], [], []
        start = 0
        for i, end in enumerate(ends.tolist()):
            raw = block[start:end]
            start = end
            row = row0 + i
            raw = raw[:-1] if raw.endswith(b"\n") else raw
            raw = raw[:-1] if raw.endswith(b"\r") else raw
            try:
                text = raw.decode("utf-8")
            except UnicodeDecodeError as e:
                mal.append((row, f"malformed CSV line (not UTF-8: {_utf8_error(e)})"))
                continue
            if not text:
                fields = None
            elif "\r" in text:
                mal.append((row, "malformed CSV line (carriage return inside the line)"))
                continue
            else:
                try:
                    fields = next(csv.reader([text], strict=True))
                except csv.Error as e:
                    why = "unterminated quote" if "unexpected end of data" in str(e) else str(e)
                    mal.append((row, f"malformed CSV line ({why})"))
                    continue
                if len(fields) != ncol:
                    mal.append((row, f"malformed CSV line ({len(fields)} fields, expected {ncol})"))
                    continue
            keep.append(i)
            values.append(fields)
        cols = {}
        for name, j in zip(self.needed, idx, strict=True):
            cols[name] = pa.array([None if f is None or f[j] in nulls else f[j] for f in values], pa.string())
        t, pre = coerce_table(pa.table(cols) if cols else pa.table({}), self.numeric, id_types=S.ID_TYPES)
        empty = [k for k, f in enumerate(values) if f is None]
        if empty:
            pre = pre if pre is not None else [None] * t.num_rows
            for k in empty:
                pre[k] = "malformed CSV line (empty line)"
        return Chunk(t, row0 + np.asarray(keep, dtype=np.int64), pre, mal)

    # jsonl
    def _jsonl_columns(self) -> tuple[list[str], list[str]]:
        """``(columns, family_columns)``: the union of the keys of the first 1000 JSON objects, and the union of
        the keys of those of them whose box family is the prevalent one (most objects; a tie: the first seen)
        or that have no complete box.

        One rule for a line of another box family wherever it is: the family is decided by the file's
        objects, not by one odd line among the first 1000, so that line is an error row (its box columns
        missing) as it is at row 300,000 -- never a refusal of the whole file.
        """
        keys: list[tuple[str, ...]] = []
        head: list[bytes] = []
        with (open(self.path, "rb") if self._stream is None else contextlib.nullcontext(self._stream)) as f:
            for i in range(1000):
                line = _read_line(f)
                if not line:
                    break
                head.append(line)
                if i == 0 and line.startswith(_BOM):
                    line = line[3:]
                try:
                    obj = json.loads(line)
                except (ValueError, RecursionError):
                    continue
                if isinstance(obj, dict):
                    keys.append(tuple(str(k) for k in obj))
        if self._stream is not None:  # the lines read are replayed in front of the rest of the stream
            self._stream = _Prefixed(b"".join(head), self._stream)
        families = [S.detect_box_type(k) for k in keys]
        votes = Counter(f for f in families if f is not None)
        top = max(votes, key=lambda f: (votes[f], -families.index(f))) if votes else None
        names: dict[str, None] = {}
        family: dict[str, None] = {}
        for k, fam in zip(keys, families, strict=True):
            names.update(dict.fromkeys(k))
            if fam is None or fam == top:
                family.update(dict.fromkeys(k))
        return list(names), list(family)

    def _iter_jsonl(self):
        with self._body() as f:
            row0 = 0
            first = True
            for block, ends in _line_blocks(f, self.chunk_rows):
                n = ends.size
                self.lines += n
                starts = np.concatenate([[0], ends[:-1]]).tolist()
                lines = [block[a:b] for a, b in zip(starts, ends.tolist(), strict=True)]
                if first and lines[0].startswith(_BOM):
                    lines[0] = lines[0][3:]
                first = False
                lines = [x if x.endswith(b"\n") else x + b"\n" for x in lines]
                rows_a = row0 + np.arange(n, dtype=np.int64)
                row0 += n
                table, pre, mal = None, None, []
                # pyarrow's parser only sees blocks of lines that each hold one object: pyarrow 26.0.1
                # crashes the process (SIGSEGV) on a block whose first value is a bare `null`
                objects = all(x.lstrip()[:1] == b"{" and x.rstrip()[-1:] == b"}" for x in lines)
                if objects:
                    try:
                        t = pjson.read_json(io.BytesIO(b"".join(lines)),
                                            read_options=pjson.ReadOptions(use_threads=True, block_size=1 << 24))
                        if t.num_rows == n:
                            table = t
                    except (pa.ArrowException, ValueError):
                        table = None
                if table is not None:
                    try:
                        table = _select(table, self.needed)
                        table, pre = coerce_table(table, self.numeric, id_types=S.ID_TYPES)
                    except (pa.ArrowException, ValueError, TypeError):  # nested values pyarrow cannot cast
                        table = None
                if table is None:
                    table, pre, mal, keep = self._jsonl_slow(lines, rows_a)
                    rows_a = rows_a[keep]
                yield Chunk(table, rows_a, pre, mal, len(block))

    def _jsonl_slow(self, lines, rows):
        """Line by line: invalid JSON lines become malformed rows, bad values pre-errors."""
        records, keep, mal = [], [], []
        for i, line in enumerate(lines):
            if not line.strip():
                mal.append((int(rows[i]), "empty line"))
                continue
            try:
                text = line.decode("utf-8")
            except UnicodeDecodeError as e:
                mal.append((int(rows[i]), f"invalid JSON line: not UTF-8 ({_utf8_error(e)})"))
                continue
            try:
                obj = json.loads(text)
            except json.JSONDecodeError as e:
                mal.append((int(rows[i]), f"invalid JSON line: {e.msg}"))
                continue
            except (ValueError, RecursionError) as e:
                mal.append((int(rows[i]), f"invalid JSON line: {_first_line(e)}"))
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
        return (pa.table(arrays) if arrays else pa.table({}), (pre if any(p is not None for p in pre) else None),
                mal, np.asarray(keep, dtype=np.int64))


class _SlowPath(Exception):
    """The fast CSV parser cannot be trusted on this block: parse it line by line."""


_BOM = b"\xef\xbb\xbf"
#: a reader's stream once handed out (a FIFO is read once)
_USED = object()


def _read_line(f) -> bytes:
    """One physical line (with its LF) of a binary file or stream, b"" at the end."""
    if hasattr(f, "readline"):
        return f.readline()
    out = bytearray()
    while not out.endswith(b"\n"):
        b = f.read(1)
        if not b:
            break
        out += b
    return bytes(out)


def _utf8_error(e: UnicodeDecodeError) -> str:
    return f"byte 0x{e.object[e.start]:02x} at column {e.start + 1}"


def _first_line(e: BaseException) -> str:
    text = str(e).splitlines()
    return (text[0] if text else type(e).__name__)[:120]


def _line_blocks(f, max_lines: int, read_size: int = 1 << 22):
    """``(block, ends)`` of up to ``max_lines`` physical lines of binary file ``f``.

    A physical line ends with ``\\n`` (LF or CRLF); the last one may have no terminator.
    ``ends`` (int64) are the offsets just past each line in ``block``.
    """
    buf = b""
    nl = np.zeros(0, dtype=np.int64)  # newline offsets in buf
    eof = False
    while True:
        while nl.size < max_lines and not eof:
            data = f.read(read_size)
            if not data:
                eof = True
                break
            new = np.flatnonzero(np.frombuffer(data, dtype=np.uint8) == 10) + len(buf)
            buf += data
            nl = np.concatenate([nl, new])
        if nl.size >= max_lines:
            cut = int(nl[max_lines - 1]) + 1
            ends = nl[:max_lines] + 1
            yield buf[:cut], ends
            buf = buf[cut:]
            nl = nl[max_lines:] - cut
            continue
        # end of file: the rest
        if not buf:
            return
        ends = nl + 1
        if not buf.endswith(b"\n"):
            ends = np.concatenate([ends, [len(buf)]])
        yield buf, ends.astype(np.int64)
        return


def _empty_lines(block: bytes, ends: np.ndarray) -> np.ndarray:
    """(n,) bool: physical lines with nothing but their terminator (LF or CRLF)."""
    a = np.frombuffer(block, dtype=np.uint8)
    starts = np.concatenate([[0], ends[:-1]]).astype(np.int64)
    length = ends - starts
    term = (length > 0) & (a[np.maximum(ends - 1, 0)] == 10) if a.size else np.zeros(ends.size, bool)
    content = length - term
    cr = np.zeros(ends.size, dtype=bool)
    one = content == 1
    if one.any():
        cr[one] = a[starts[one]] == 13
    return (content == 0) | cr


def open_parquet(path, field: str = "detections"):
    """``pyarrow.parquet.ParquetFile`` of ``path``; an empty, truncated or garbage file is an InputError."""

    try:
        return pq.ParquetFile(path)
    except (pa.ArrowException, OSError, ValueError) as e:
        raise InputError(field, str(path), f"a readable Parquet file ({_first_line(e)})") from None


def _guarded_batches(pf, i: int, where: str, **kw):
    """``pf.iter_batches(row_groups=[i])`` where a corrupt page raises :class:`InputError` naming ``where``."""
    it = pf.iter_batches(row_groups=[i], **kw)
    while True:
        try:
            batch = next(it)
        except StopIteration:
            return
        except (pa.ArrowException, OSError, ValueError) as e:
            raise InputError("detections", where, f"a readable Parquet file (row group {i}: {_first_line(e)})"
                             ) from None
        yield batch


def iter_parquet_tables(pf, columns: list, chunk_rows: int, *, use_threads: bool = True,
                        where: str = "detections") -> Iterator[pa.Table]:
    """Tables of ``chunk_rows`` rows (the last one shorter) of a ``pyarrow.parquet.ParquetFile``, in file order.

    Reads one row group at a time (``iter_batches(row_groups=[i])``): iterating a whole file
    with one ``iter_batches`` call keeps memory growing with the file in pyarrow 15-26, one
    row group at a time does not.  A corrupt or truncated page raises :class:`InputError`
    naming ``where`` (the file).
    """
    buf: list[pa.Table] = []
    n_buf = 0
    for i in range(pf.num_row_groups):
        for batch in _guarded_batches(pf, i, where, batch_size=chunk_rows, columns=columns,
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


def open_detections(path, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS, format: str | None = None) -> DetectionReader:
    """A :class:`DetectionReader` on a CSV, JSON Lines or Parquet file (format from the extension)."""
    return DetectionReader(path, chunk_rows=chunk_rows, format=format)
