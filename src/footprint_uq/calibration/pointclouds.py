"""Point-cloud files: PCD (ascii, binary, binary_compressed), PLY (ascii, binary), NPY and CSV.

Every reader returns a :class:`PointCloud`: the points ``xyz_m`` as float64
``(N, 3)`` in the sensor frame (metres), any other per-point fields (``intensity``,
``ring``, ...) as ``(N,)`` arrays, and the counts of points that were dropped and
why.  Nothing is dropped silently: points with a non-finite coordinate (NaN/inf,
the "no return" marker of many drivers) and, optionally, points exactly at the
sensor origin (Ouster's and Velodyne's organised clouds write ``(0, 0, 0)`` for
"no return") are removed and counted in ``n_nonfinite_dropped`` / ``n_zero_dropped``,
and logged at INFO level.

A malformed file raises :class:`footprint_uq.errors.InputError` naming the file,
what was found and what was expected.

Writers (:func:`write_pcd`, :func:`write_ply`, :func:`write_npy`, :func:`write_csv`)
produce files the readers read back bit for bit (float32 or float64 coordinates).
"""

from __future__ import annotations

import logging
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numba
import numpy as np

from ..errors import InputError
from ..io.atomic import atomic_path

__all__ = [
    "PointCloud", "read_point_cloud", "read_pcd", "read_ply", "read_npy", "read_csv",
    "write_pcd", "write_ply", "write_npy", "write_csv", "write_point_cloud", "SUPPORTED_SUFFIXES",
    "lzf_compress", "lzf_decompress",
]

log = logging.getLogger(__name__)

SUPPORTED_SUFFIXES = (".pcd", ".ply", ".npy", ".csv")


@dataclass
class PointCloud:
    """Points of one scan.

    Attributes
    ----------
    xyz_m : ndarray (N, 3) float64
        Finite points in the sensor frame, metres.
    fields : dict[str, ndarray (N,)]
        Other per-point fields (e.g. ``intensity``, ``ring``), aligned with ``xyz_m``.
    source : str
        File name (or ``"<array>"``).
    n_read : int
        Points in the file before any removal.
    n_nonfinite_dropped : int
        Points removed because a coordinate was NaN or infinite.
    n_zero_dropped : int
        Points removed because they were exactly ``(0, 0, 0)`` (no-return marker).
    """

    xyz_m: np.ndarray
    fields: dict = field(default_factory=dict)
    source: str = "<array>"
    n_read: int = 0
    n_nonfinite_dropped: int = 0
    n_zero_dropped: int = 0

    def __len__(self) -> int:
        return int(self.xyz_m.shape[0])

    def stats(self) -> dict:
        """Counts for reports: ``{"source", "n_read", "n_points", "n_nonfinite_dropped", "n_zero_dropped"}``."""
        return {"source": self.source, "n_read": self.n_read, "n_points": len(self),
                "n_nonfinite_dropped": self.n_nonfinite_dropped, "n_zero_dropped": self.n_zero_dropped}

    @classmethod
    def from_arrays(cls, xyz_m, fields=None, *, source="<array>", drop_zero=True) -> PointCloud:
        """Build from an ``(N, 3)`` array (+ fields), dropping and counting non-finite / zero points."""
        xyz = np.asarray(xyz_m, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(f"{source}: points", getattr(xyz, "shape", xyz), "an array of shape (N, 3)")
        fields = {k: np.asarray(v).ravel() for k, v in (fields or {}).items()}
        for k, v in fields.items():
            if v.shape[0] != xyz.shape[0]:
                raise InputError(f"{source}: field {k}", f"{v.shape[0]} values", f"{xyz.shape[0]} (one per point)")
        finite = np.isfinite(xyz).all(axis=1)
        zero = finite & (xyz == 0.0).all(axis=1) if drop_zero else np.zeros(len(xyz), bool)
        keep = finite & ~zero
        n_nf, n_z = int((~finite).sum()), int(zero.sum())
        if n_nf or n_z:
            log.info("%s: dropped %d non-finite and %d (0,0,0) points of %d", source, n_nf, n_z, len(xyz))
        return cls(np.ascontiguousarray(xyz[keep]), {k: v[keep] for k, v in fields.items()}, str(source),
                   int(len(xyz)), n_nf, n_z)


# ---------------------------------------------------------------------------------------------
# LZF (the compression of PCD "binary_compressed"), compiled with numba
# ---------------------------------------------------------------------------------------------
def _lzf_decompress_py(src, out):  # pragma: no cover - compiled by numba below
    ip, op, n_in, n_out = 0, 0, src.shape[0], out.shape[0]
    while ip < n_in:
        ctrl = np.int64(src[ip])
        ip += 1
        if ctrl < 32:
            ln = ctrl + 1
            if op + ln > n_out or ip + ln > n_in:
                return -1
            for k in range(ln):
                out[op + k] = src[ip + k]
            op += ln
            ip += ln
        else:
            ln = ctrl >> 5
            if ln == 7:
                if ip >= n_in:
                    return -1
                ln += np.int64(src[ip])
                ip += 1
            if ip >= n_in:
                return -1
            ref = op - ((ctrl & 0x1F) << 8) - np.int64(src[ip]) - 1
            ip += 1
            ln += 2
            if ref < 0 or op + ln > n_out:
                return -1
            for k in range(ln):  # byte by byte: the source may overlap the destination
                out[op + k] = out[ref + k]
            op += ln
    return op


def _lzf_compress_py(src, out):  # pragma: no cover - compiled by numba below
    n = src.shape[0]
    htab = np.full(1 << 14, -1, np.int64)
    ip, op, lit = 0, 1, 0  # out[op - lit - 1] is the pending literal-run control byte
    n_out = out.shape[0]
    while ip + 2 < n:
        h = ((np.int64(src[ip]) << 16) | (np.int64(src[ip + 1]) << 8) | np.int64(src[ip + 2]))
        h = ((h * 2654435761) >> 10) & ((1 << 14) - 1)
        ref = htab[h]
        htab[h] = ip
        off = ip - ref - 1
        if (ref >= 0 and off < 8192 and src[ref] == src[ip] and src[ref + 1] == src[ip + 1]
                and src[ref + 2] == src[ip + 2]):
            maxlen = min(264, n - ip)
            ln = 3
            while ln < maxlen and src[ref + ln] == src[ip + ln]:
                ln += 1
            if op + 3 > n_out:
                return -1
            if lit == 0:
                op -= 1  # no pending literal run: drop its control byte
            else:
                out[op - lit - 1] = lit - 1
            lit = 0
            L = ln - 2
            if L < 7:
                out[op] = (L << 5) | (off >> 8)
                op += 1
            else:
                out[op] = (7 << 5) | (off >> 8)
                out[op + 1] = L - 7
                op += 2
            out[op] = off & 0xFF
            op += 1
            op += 1  # room for the next literal-run control byte
            ip += ln
        else:
            if op >= n_out:
                return -1
            out[op] = src[ip]
            op += 1
            lit += 1
            ip += 1
            if lit == 32:
                out[op - lit - 1] = 31
                lit = 0
                op += 1
    while ip < n:
        if op >= n_out:
            return -1
        out[op] = src[ip]
        op += 1
        lit += 1
        ip += 1
        if lit == 32:
            out[op - lit - 1] = 31
            lit = 0
            op += 1
    if lit == 0:
        op -= 1
    else:
        out[op - lit - 1] = lit - 1
    return op


_lzf_jit: dict = {}


def _jit(name):
    if name not in _lzf_jit:

        _lzf_jit[name] = numba.njit(cache=False, nogil=True)(
            _lzf_decompress_py if name == "d" else _lzf_compress_py)
    return _lzf_jit[name]


def lzf_decompress(data: bytes, size: int) -> bytes:
    """Decompress LZF ``data`` to exactly ``size`` bytes; ValueError if it is corrupt."""
    src = np.frombuffer(data, dtype=np.uint8)
    out = np.empty(int(size), dtype=np.uint8)
    n = _jit("d")(src, out) if src.size else 0
    if n != size:
        raise ValueError(f"LZF stream decodes to {n} bytes, header says {size}")
    return out.tobytes()


def lzf_compress(data: bytes) -> bytes:
    """LZF-compress ``data`` (liblzf format, as PCL writes it)."""
    src = np.frombuffer(data, dtype=np.uint8)
    if src.size == 0:
        return b""
    out = np.empty(src.size + src.size // 16 + 64, dtype=np.uint8)
    n = _jit("c")(src, out)
    if n < 0:  # pragma: no cover - the buffer bound above is always sufficient
        raise RuntimeError("LZF output buffer too small")
    return out[:n].tobytes()


# ---------------------------------------------------------------------------------------------
# PCD
# ---------------------------------------------------------------------------------------------
_PCD_TYPES = {("F", 4): "f4", ("F", 8): "f8", ("U", 1): "u1", ("U", 2): "u2", ("U", 4): "u4", ("U", 8): "u8",
              ("I", 1): "i1", ("I", 2): "i2", ("I", 4): "i4", ("I", 8): "i8"}


def _bad(path, what, value, expected):
    return InputError(f"{path}: {what}", value, expected)


def _pcd_header(path, raw: bytes):
    hdr: dict = {}
    pos = 0
    while True:
        end = raw.find(b"\n", pos)
        if end < 0:
            raise _bad(path, "PCD header", "no DATA line",
                       "a PCD header ending with 'DATA ascii|binary|binary_compressed'")
        line = raw[pos:end].decode("ascii", errors="replace").strip()
        pos = end + 1
        if not line or line.startswith("#"):
            continue
        key, _, rest = line.partition(" ")
        hdr[key.upper()] = rest.split()
        if key.upper() == "DATA":
            return hdr, pos
        if len(hdr) > 20:
            raise _bad(path, "PCD header", line[:40], "PCD header keys (VERSION FIELDS SIZE TYPE COUNT WIDTH ...)")


def _pcd_layout(path: Path, hdr: dict) -> tuple[list, list, int, list]:
    """The point layout of a PCD header: ``(field names, counts, number of points, numpy dtype fields)``."""
    for k in ("FIELDS", "SIZE", "TYPE"):
        if k not in hdr:
            raise _bad(path, "PCD header", f"no {k} line", "FIELDS, SIZE and TYPE lines")
    names = hdr["FIELDS"]
    n_f = len(names)
    counts = hdr.get("COUNT", ["1"] * n_f)
    if not (len(hdr["SIZE"]) == len(hdr["TYPE"]) == len(counts) == n_f):
        raise _bad(path, "PCD header", f"{n_f} FIELDS, {len(hdr['SIZE'])} SIZE, {len(hdr['TYPE'])} TYPE, "
                   f"{len(counts)} COUNT", "one SIZE, TYPE and COUNT per field")
    try:
        sizes = [int(s) for s in hdr["SIZE"]]
        counts = [int(c) for c in counts]
        width = int(hdr.get("WIDTH", ["0"])[0])
        height = int(hdr.get("HEIGHT", ["1"])[0])
        n_pts = int(hdr["POINTS"][0]) if "POINTS" in hdr else width * height
    except (ValueError, IndexError):
        raise _bad(path, "PCD header", {k: hdr.get(k) for k in ("SIZE", "COUNT", "WIDTH", "HEIGHT", "POINTS")},
                   "integers") from None
    if n_pts < 0:
        raise _bad(path, "PCD POINTS", n_pts, "a count >= 0")
    dtypes = []
    seen: dict = {}
    for name, t, s, c in zip(names, hdr["TYPE"], sizes, counts, strict=True):
        key = (t.upper(), s)
        if key not in _PCD_TYPES:
            raise _bad(path, f"PCD field {name}", f"TYPE {t} SIZE {s}", "F 4/8, U or I 1/2/4/8")
        uniq = name if name not in seen else f"{name}__{seen[name]}"
        seen[name] = seen.get(name, 0) + 1
        dtypes.append((uniq, "<" + _PCD_TYPES[key], (c,) if c > 1 else ()))
    lower = [n.lower() for n in names]
    for ax in "xyz":
        if ax not in lower:
            raise _bad(path, "PCD FIELDS", names, "fields x, y and z")
    return names, counts, n_pts, dtypes


def _pcd_ascii(path: Path, body: bytes, n_pts: int, dtypes: list, counts: list) -> dict:
    """Columns of a ``DATA ascii`` body (float64)."""
    text = body.decode("ascii", errors="replace")
    ncol = sum(counts)
    rows = [ln for ln in text.splitlines() if ln.strip()]
    if len(rows) < n_pts:
        raise _bad(path, "PCD data", f"{len(rows)} rows", f"{n_pts} rows (POINTS)")
    try:
        table = np.loadtxt(rows[:n_pts], dtype=np.float64, ndmin=2) if n_pts else np.zeros((0, ncol))
    except ValueError:
        _raise_bad_row(path, rows[:n_pts], ncol, first_row=1)
    if table.shape[1] != ncol:
        raise _bad(path, "PCD data", f"{table.shape[1]} columns", f"{ncol} columns (sum of COUNT)")
    cols, off = {}, 0
    for (uniq, _, _shp), c in zip(dtypes, counts, strict=True):
        cols[uniq] = table[:, off] if c == 1 else table[:, off:off + c]
        off += c
    return cols


def _pcd_binary_compressed(path: Path, body: bytes, n_pts: int, dtypes: list, dt: np.dtype) -> dict:
    """Columns of a ``DATA binary_compressed`` body (LZF, structure of arrays)."""
    if len(body) < 8:
        raise _bad(path, "PCD binary_compressed data", f"{len(body)} bytes", "8 size bytes then LZF data")
    csize, usize = struct.unpack("<II", body[:8])
    if len(body) < 8 + csize:
        raise _bad(path, "PCD binary_compressed data", f"{len(body) - 8} bytes", f"{csize} compressed bytes")
    if usize != n_pts * dt.itemsize:
        raise _bad(path, "PCD binary_compressed size", usize, f"{n_pts * dt.itemsize} bytes ({n_pts} points)")
    try:
        dec = lzf_decompress(body[8:8 + csize], usize)
    except ValueError as e:
        raise _bad(path, "PCD binary_compressed data", str(e), "a valid LZF stream") from None
    cols, off = {}, 0
    for uniq, typ, shp in dtypes:  # structure-of-arrays: one field after the other
        fdt = np.dtype((typ, shp)) if shp else np.dtype(typ)
        nb = fdt.itemsize * n_pts
        cols[uniq] = np.frombuffer(dec[off:off + nb], dtype=fdt.base).reshape((n_pts,) + tuple(shp))
        off += nb
    return cols


def read_pcd(path, *, drop_zero: bool = True) -> PointCloud:
    """Read a PCD file (DATA ascii, binary or binary_compressed); see :class:`PointCloud`."""
    path = Path(path)
    raw = _read_bytes(path)
    if not (raw.startswith(b"#") or raw.startswith(b"VERSION") or raw.startswith(b"FIELDS")):
        raise _bad(path, "PCD header", raw[:20], "a PCD file starting with '# .PCD' or 'VERSION'")
    hdr, pos = _pcd_header(path, raw)
    names, counts, n_pts, dtypes = _pcd_layout(path, hdr)
    dt = np.dtype(dtypes)
    mode = hdr["DATA"][0].lower() if hdr["DATA"] else ""
    body = raw[pos:]
    if mode == "ascii":
        cols = _pcd_ascii(path, body, n_pts, dtypes, counts)
    elif mode == "binary":
        need = n_pts * dt.itemsize
        if len(body) < need:
            raise _bad(path, "PCD binary data", f"{len(body)} bytes", f"{need} bytes ({n_pts} points x {dt.itemsize})")
        arr = np.frombuffer(body, dtype=dt, count=n_pts)
        cols = {n: arr[n] for n in dt.names}
    elif mode == "binary_compressed":
        cols = _pcd_binary_compressed(path, body, n_pts, dtypes, dt)
    else:
        raise _bad(path, "PCD DATA", hdr["DATA"], "ascii, binary or binary_compressed")
    return _assemble(path, names, dtypes, cols, drop_zero)


def _assemble(path, names, dtypes, cols, drop_zero):
    lower = {n.lower(): uniq for n, (uniq, _, _) in zip(names, dtypes, strict=True)}
    xyz = np.stack([np.asarray(cols[lower[a]], dtype=np.float64).ravel() for a in "xyz"], axis=1)
    fields = {}
    for n, (uniq, _, shp) in zip(names, dtypes, strict=True):
        if n.lower() in ("x", "y", "z") or n.startswith("_") or shp:
            continue  # padding ('_') and multi-count fields (e.g. descriptors) are not per-point scalars
        fields[uniq] = np.asarray(cols[uniq])
    return PointCloud.from_arrays(xyz, fields, source=str(path), drop_zero=drop_zero)


def _raise_bad_row(path, rows, ncol, first_row):
    for i, r in enumerate(rows):
        toks = r.replace(",", " ").split()
        try:
            [float(t) for t in toks]
        except ValueError:
            raise _bad(path, f"row {i + first_row}", r[:60], f"{ncol} numbers") from None
        if len(toks) != ncol:
            raise _bad(path, f"row {i + first_row}", r[:60], f"{ncol} numbers")
    raise _bad(path, "data", "unparsable rows", f"{ncol} numbers per row")  # pragma: no cover


def write_pcd(path, xyz_m, fields=None, *, data: str = "binary", dtype="f4") -> Path:
    """Write a PCD v0.7 file (``data`` = ascii, binary or binary_compressed).

    ``xyz_m`` is ``(N, 3)``; ``fields`` maps names to ``(N,)`` arrays (kept in their dtype,
    float64 -> F8, float32 -> F4, integers -> U/I).  ``dtype`` is the coordinate type (f4 or f8).
    """
    path = Path(path)
    xyz = np.asarray(xyz_m)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError("xyz_m", getattr(xyz, "shape", None), "an array of shape (N, 3)")
    if data not in ("ascii", "binary", "binary_compressed"):
        raise InputError("data", data, "ascii, binary or binary_compressed")
    n = xyz.shape[0]
    cols = [("x", xyz[:, 0].astype(dtype)), ("y", xyz[:, 1].astype(dtype)), ("z", xyz[:, 2].astype(dtype))]
    for k, v in (fields or {}).items():
        v = np.asarray(v).ravel()
        if v.shape[0] != n:
            raise InputError(f"fields[{k}]", f"{v.shape[0]} values", f"{n} (one per point)")
        if v.dtype == np.float64 or v.dtype.kind not in "fiu":
            v = v.astype(np.float64) if v.dtype.kind not in "iu" else v
        cols.append((k, v))
    types, sizes = [], []
    for _, v in cols:
        kind = {"f": "F", "u": "U", "i": "I"}[v.dtype.kind]
        types.append(kind)
        sizes.append(str(v.dtype.itemsize))
    header = (
        "# .PCD v0.7 - Point Cloud Data file format (written by footprint-uq)\nVERSION 0.7\n"
        f"FIELDS {' '.join(k for k, _ in cols)}\nSIZE {' '.join(sizes)}\nTYPE {' '.join(types)}\n"
        f"COUNT {' '.join('1' for _ in cols)}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
        f"DATA {data}\n"
    ).encode("ascii")
    if data == "ascii":
        lines = []
        for i in range(n):
            lines.append(" ".join(_fmt_num(v[i]) for _, v in cols))
        body = ("\n".join(lines) + ("\n" if n else "")).encode("ascii")
    elif data == "binary":
        dt = np.dtype([(k, "<" + v.dtype.str[1:]) for k, v in cols])
        arr = np.empty(n, dtype=dt)
        for k, v in cols:
            arr[k] = v
        body = arr.tobytes()
    else:
        soa = b"".join(np.ascontiguousarray(v.astype("<" + v.dtype.str[1:])).tobytes() for _, v in cols)
        comp = lzf_compress(soa)
        body = struct.pack("<II", len(comp), len(soa)) + comp
    path.write_bytes(header + body)
    return path


def _fmt_num(x) -> str:
    if isinstance(x, (np.floating, float)):
        return repr(float(x)) if np.isfinite(x) else ("nan" if np.isnan(x) else ("inf" if x > 0 else "-inf"))
    return str(int(x))


# ---------------------------------------------------------------------------------------------
# PLY
# ---------------------------------------------------------------------------------------------
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}
_PLY_NAMES = {"f4": "float", "f8": "double", "u1": "uchar", "i1": "char", "u2": "ushort", "i2": "short",
              "u4": "uint", "i4": "int"}


def read_ply(path, *, drop_zero: bool = True) -> PointCloud:
    """Read the ``vertex`` element of a PLY file (ascii, binary_little_endian or binary_big_endian)."""
    path = Path(path)
    raw = _read_bytes(path)
    if not raw.startswith(b"ply"):
        raise _bad(path, "PLY header", raw[:20], "a PLY file starting with 'ply'")
    end = raw.find(b"end_header")
    if end < 0:
        raise _bad(path, "PLY header", "no end_header", "a PLY header ending with 'end_header'")
    nl = raw.find(b"\n", end)
    body = raw[nl + 1:] if nl >= 0 else b""
    fmt = None
    elements: list = []  # [name, count, [(prop, type)], has_list]
    for line in raw[:end].decode("ascii", errors="replace").splitlines()[1:]:
        tok = line.split()
        if not tok or tok[0] in ("comment", "obj_info"):
            continue
        if tok[0] == "format":
            fmt = tok[1] if len(tok) > 1 else ""
        elif tok[0] == "element":
            try:
                elements.append([tok[1], int(tok[2]), [], False])
            except (IndexError, ValueError):
                raise _bad(path, "PLY element", line, "'element <name> <count>'") from None
        elif tok[0] == "property":
            if not elements:
                raise _bad(path, "PLY property", line, "a property after an 'element' line")
            if len(tok) >= 2 and tok[1] == "list":
                elements[-1][3] = True
                elements[-1][2].append((tok[-1], "list"))
            elif len(tok) == 3 and tok[1] in _PLY_TYPES:
                elements[-1][2].append((tok[2], _PLY_TYPES[tok[1]]))
            else:
                raise _bad(path, "PLY property", line, f"'property <type> <name>' with type in {sorted(_PLY_TYPES)}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _bad(path, "PLY format", fmt, "ascii, binary_little_endian or binary_big_endian")
    names_e = [e[0] for e in elements]
    if "vertex" not in names_e:
        raise _bad(path, "PLY elements", names_e, "a 'vertex' element")
    iv = names_e.index("vertex")
    for e in elements[:iv]:
        if e[3] or e[1]:
            raise _bad(path, "PLY elements", names_e, "the 'vertex' element first (or after empty elements)")
    _, n_pts, props, has_list = elements[iv]
    if has_list:
        raise _bad(path, "PLY vertex properties", [p for p, _ in props], "scalar vertex properties (no lists)")
    names = [p for p, _ in props]
    for ax in "xyz":
        if ax not in [n.lower() for n in names]:
            raise _bad(path, "PLY vertex properties", names, "properties x, y and z")
    dtypes = [(p, t, ()) for p, t in props]
    if fmt == "ascii":
        rows = body.decode("ascii", errors="replace").splitlines()
        rows = [r for r in rows if r.strip()][:n_pts]
        if len(rows) < n_pts:
            raise _bad(path, "PLY vertex data", f"{len(rows)} rows", f"{n_pts} rows (element vertex)")
        try:
            table = np.loadtxt(rows, dtype=np.float64, ndmin=2) if n_pts else np.zeros((0, len(props)))
        except ValueError:
            _raise_bad_row(path, rows, len(props), first_row=1)
        if table.shape[1] != len(props):
            raise _bad(path, "PLY vertex data", f"{table.shape[1]} columns", f"{len(props)} vertex properties")
        cols = {p: table[:, i] for i, (p, _) in enumerate(props)}
    else:
        order = "<" if fmt == "binary_little_endian" else ">"
        dt = np.dtype([(p, order + t) for p, t in props])
        need = n_pts * dt.itemsize
        if len(body) < need:
            raise _bad(path, "PLY vertex data", f"{len(body)} bytes", f"{need} bytes ({n_pts} vertices)")
        arr = np.frombuffer(body, dtype=dt, count=n_pts)
        cols = {p: arr[p].astype(arr[p].dtype.newbyteorder("=")) for p in dt.names}
    return _assemble(path, names, dtypes, cols, drop_zero)


def write_ply(path, xyz_m, fields=None, *, fmt: str = "binary_little_endian", dtype="f4") -> Path:
    """Write a vertex-only PLY file (``fmt`` = ascii or binary_little_endian)."""
    path = Path(path)
    xyz = np.asarray(xyz_m)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError("xyz_m", getattr(xyz, "shape", None), "an array of shape (N, 3)")
    if fmt not in ("ascii", "binary_little_endian"):
        raise InputError("fmt", fmt, "ascii or binary_little_endian")
    n = xyz.shape[0]
    cols = [("x", xyz[:, 0].astype(dtype)), ("y", xyz[:, 1].astype(dtype)), ("z", xyz[:, 2].astype(dtype))]
    for k, v in (fields or {}).items():
        v = np.asarray(v).ravel()
        if v.shape[0] != n:
            raise InputError(f"fields[{k}]", f"{v.shape[0]} values", f"{n} (one per point)")
        if v.dtype.str[1:] not in _PLY_NAMES:
            v = v.astype(np.float64)
        cols.append((k, v))
    head = [f"ply\nformat {fmt} 1.0\ncomment written by footprint-uq\nelement vertex {n}"]
    head += [f"property {_PLY_NAMES[v.dtype.str[1:]]} {k}" for k, v in cols]
    header = ("\n".join(head) + "\nend_header\n").encode("ascii")
    if fmt == "ascii":
        body = "".join(" ".join(_fmt_num(v[i]) for _, v in cols) + "\n" for i in range(n)).encode("ascii")
    else:
        dt = np.dtype([(k, "<" + v.dtype.str[1:]) for k, v in cols])
        arr = np.empty(n, dtype=dt)
        for k, v in cols:
            arr[k] = v
        body = arr.tobytes()
    path.write_bytes(header + body)
    return path


# ---------------------------------------------------------------------------------------------
# NPY and CSV
# ---------------------------------------------------------------------------------------------
def read_npy(path, *, drop_zero: bool = True) -> PointCloud:
    """Read an ``.npy`` array: ``(N, 3+)`` (x, y, z[, intensity, extra...]) or a structured array with x, y, z."""
    path = Path(path)
    try:
        arr = np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as e:
        raise _bad(path, "NPY", type(e).__name__, f"a NumPy .npy array ({str(e).splitlines()[0][:60]})") from None
    if arr.dtype.names:
        names = list(arr.dtype.names)
        if not all(a in names for a in "xyz"):
            raise _bad(path, "NPY fields", names, "fields x, y and z")
        xyz = np.stack([arr[a].astype(np.float64).ravel() for a in "xyz"], 1)
        fields = {n: arr[n].ravel() for n in names if n not in "xyz" and arr[n].ndim == arr.ndim}
        return PointCloud.from_arrays(xyz, fields, source=str(path), drop_zero=drop_zero)
    if arr.ndim != 2 or arr.shape[1] < 3 or arr.dtype.kind not in "fiu":
        raise _bad(path, "NPY array", f"shape {arr.shape} dtype {arr.dtype}", "a numeric (N, 3+) array")
    fields = {}
    if arr.shape[1] >= 4:
        fields["intensity"] = arr[:, 3].astype(np.float64)
    for j in range(4, arr.shape[1]):
        fields[f"col{j}"] = arr[:, j].astype(np.float64)
    return PointCloud.from_arrays(arr[:, :3].astype(np.float64), fields, source=str(path), drop_zero=drop_zero)


def write_npy(path, xyz_m, intensity=None) -> Path:
    """Write an ``(N, 3)`` (or ``(N, 4)`` with intensity) float64 ``.npy``."""
    xyz = np.asarray(xyz_m, dtype=np.float64)
    arr = xyz if intensity is None else np.column_stack([xyz, np.asarray(intensity, dtype=np.float64)])
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.save(f, arr)
    return Path(path)


def read_csv(path, *, drop_zero: bool = True) -> PointCloud:
    """Read a CSV of points: columns x, y, z[, intensity, ...] with or without a header line.

    With a header the columns are found by name (case-insensitive; x, y and z required);
    without one the first three columns are x, y, z and the fourth, if any, the intensity.
    Separators: comma, semicolon or whitespace.
    """
    path = Path(path)
    text = _read_bytes(path).decode("utf-8", errors="replace")
    lines = [(i + 1, ln) for i, ln in enumerate(text.splitlines()) if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise _bad(path, "CSV", "empty file", "rows x, y, z[, intensity]")
    sep = "," if "," in lines[0][1] else (";" if ";" in lines[0][1] else None)

    def split(s):
        return [t.strip() for t in (s.split(sep) if sep else s.split())]

    first = split(lines[0][1])
    try:
        [float(t) for t in first]
        names = None
    except ValueError:
        names = [t.lower() for t in first]
        lines = lines[1:]
    if names is not None:
        for a in "xyz":
            if a not in names:
                raise _bad(path, "CSV header", first, "columns named x, y and z")
        ncol = len(names)
    else:
        ncol = len(first)
        if ncol < 3:
            raise _bad(path, "row 1", lines[0][1][:60], "at least 3 numbers (x, y, z)")
        names = ["x", "y", "z"] + (["intensity"] if ncol >= 4 else []) + [f"col{j}" for j in range(4, ncol)]
    table = np.empty((len(lines), ncol))
    for k, (lineno, ln) in enumerate(lines):
        toks = split(ln)
        if len(toks) != ncol:
            raise _bad(path, f"row {lineno}", ln[:60], f"{ncol} values")
        try:
            table[k] = [float(t) for t in toks]
        except ValueError:
            raise _bad(path, f"row {lineno}", ln[:60], f"{ncol} numbers") from None
    idx = {n: j for j, n in enumerate(names)}
    xyz = table[:, [idx["x"], idx["y"], idx["z"]]]
    fields = {n: table[:, j] for n, j in idx.items() if n not in ("x", "y", "z")}
    return PointCloud.from_arrays(xyz, fields, source=str(path), drop_zero=drop_zero)


def write_csv(path, xyz_m, fields=None) -> Path:
    """Write a CSV with header ``x,y,z[,field...]`` (full float64 precision)."""
    xyz = np.asarray(xyz_m, dtype=np.float64)
    cols = [xyz[:, 0], xyz[:, 1], xyz[:, 2]]
    cols += [np.asarray(v, dtype=np.float64).ravel() for v in (fields or {}).values()]
    names = ["x", "y", "z"] + list((fields or {}).keys())
    np.savetxt(Path(path), np.column_stack(cols), delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return Path(path)


# ---------------------------------------------------------------------------------------------
# dispatch
# ---------------------------------------------------------------------------------------------
def _read_bytes(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise InputError("point cloud", str(path), "an existing file") from None
    except OSError as e:
        raise InputError("point cloud", str(path), f"a readable file ({e.strerror})") from None


def read_point_cloud(path, *, drop_zero: bool = True) -> PointCloud:
    """Read a point cloud by its suffix (.pcd, .ply, .npy, .csv; .txt/.xyz read as CSV)."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf == ".pcd":
        return read_pcd(path, drop_zero=drop_zero)
    if suf == ".ply":
        return read_ply(path, drop_zero=drop_zero)
    if suf == ".npy":
        return read_npy(path, drop_zero=drop_zero)
    if suf in (".csv", ".txt", ".xyz"):
        return read_csv(path, drop_zero=drop_zero)
    raise InputError("point cloud", str(path), f"a file ending in one of {', '.join(SUPPORTED_SUFFIXES)}")


def write_point_cloud(path, xyz_m, fields=None, **kw) -> Path:
    """Write by suffix: .pcd (binary by default), .ply, .npy (intensity field only), .csv."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf == ".pcd":
        return write_pcd(path, xyz_m, fields, **kw)
    if suf == ".ply":
        return write_ply(path, xyz_m, fields, **kw)
    if suf == ".npy":
        return write_npy(path, xyz_m, (fields or {}).get("intensity"))
    if suf == ".csv":
        return write_csv(path, xyz_m, fields)
    raise InputError("point cloud", str(path), f"a file ending in one of {', '.join(SUPPORTED_SUFFIXES)}")
