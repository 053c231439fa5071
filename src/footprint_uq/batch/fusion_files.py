"""Multi-camera fusion of footprint files (``footprint-uq fuse``), every input row accounted for.

Reads the per-camera footprint outputs of ``footprint-uq objects`` (or
:func:`footprint_uq.batch.process_table`), associates the estimates of the same
object by a key (default ``frame, object_id``), fuses the footprint centres by
covariance weighting in information form (:func:`footprint_uq.products.fusion.fuse_by_id`)
and writes one row per (frame, object) with the fused centre, its covariance,
ellipse, the number of cameras used, the consistency test and the CPM/J2735
fields of the fused covariance, plus one row per input row (the *sources*)
saying whether it was used and why not.  Full description (columns, CLI):
``docs/uncertainty-model.md``, section "Multi-camera fusion".

Association
-----------
**By key only**: rows with equal key values (after type normalisation: ``frame``
as an integer, ``object_id`` and any other key column as text) are the same
object.  The ids must therefore be shared across cameras, e.g. from a
multi-camera tracker or a global id assigned upstream; no geometric gating is
done (the Mahalanobis check *reports* estimates that disagree, it does not
re-associate them).  The cameras are assumed synchronised on ``frame``.

Independence
------------
The fusion assumes the cameras' errors are independent (separately calibrated
cameras).  Two rows of the *same* camera for one key share that camera's
calibration error and cannot be fused as independent: all such rows are
rejected (``duplicate: ...``) and the object is fused from the other cameras.

Rows not used (``used`` False in the sources table, first applicable reason)
----------------------------------------------------------------------------
``malformed CSV line ...`` / ``invalid JSON line ...`` (unparseable line),
``field NAME is not a number`` (or ``an integer``), ``missing key field NAME``,
``missing camera_id``, ``input status partial: ...`` / ``input status error: ...``
(the footprint row had no centre), ``missing or non-finite field NAME``,
``covariance not positive definite``, ``duplicate: N rows of one camera for this key``.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from .._checks import as_float
from ..errors import InputError
from ..io.atomic import atomic_write_text, same_file
from ..products.footprints import V2X_FIELDS
from ..products.fusion import chi2_threshold, fuse_by_id
from ..products.v2x import cpm_fields, j2735_fields
from ..uncertainty.ellipse import ellipse_axes
from .readers import coerce_table, open_detections
from .writers import detect_out_format, open_writer

__all__ = ["DEFAULT_KEY", "ESTIMATE_COLUMNS", "CAMERA_ID_FROM", "FuseSummary", "FusedFootprints", "fuse_footprints",
           "fuse_files", "sources_path", "summary_path"]

#: default association key
DEFAULT_KEY = ("frame", "object_id")
#: the estimate columns every input must have (footprint centre and covariance)
ESTIMATE_COLUMNS = ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2")
#: where camera ids come from
CAMERA_ID_FROM = ("filename", "column")
#: key types: frame an integer, anything else compared as text
_KEY_TYPES = {"frame": pa.int64()}
#: the footprint status of a row with a centre (footprint_uq.batch.schema.STATUS_OK)
_STATUS_OK = "ok"


def summary_path(out) -> Path:
    """``<out>.summary.json``, where :func:`fuse_files` writes the summary (as ``footprint-uq objects``)."""
    out = Path(out)
    return out.with_name(out.name + ".summary.json")


def sources_path(out) -> Path:
    """Default sources table next to ``out``: ``fused.parquet`` -> ``fused.sources.parquet``."""
    out = Path(out)
    return out.with_name(out.stem + ".sources" + out.suffix)


def _key_type(name: str) -> pa.DataType:
    return _KEY_TYPES.get(name, pa.string())


@dataclass
class _Part:
    """One input, normalised: a table of parsed rows plus its unparseable rows."""

    name: str
    table: pa.Table          # columns: keys, camera_id, estimates, status, reason, row (optional)
    source_rows: np.ndarray  # (n,) 0-based row in the input
    pre: list                # (n,) None or the reason a value did not convert
    malformed: list          # [(row, reason)]
    camera: str | None       # camera id for the whole input (filename mode), else None
    lines: int | None = None  # physical lines of a CSV (after the header) / JSON Lines input, else None


@dataclass
class FuseSummary:
    """Row and object accounting of a fusion job (``rows_in == rows_used + rows_rejected``)."""

    rows_in: int = 0
    rows_used: int = 0
    rows_rejected: int = 0
    objects_out: int = 0
    objects_fused: int = 0
    objects_single: int = 0
    objects_unavailable: int = 0
    objects_inconsistent: int = 0
    sources_inconsistent: int = 0
    reasons: dict = field(default_factory=dict)
    inputs: list = field(default_factory=list)
    elapsed_s: float = 0.0
    info: dict = field(default_factory=dict)
    #: physical lines of the text inputs (CSV after the header, JSON Lines) plus the Parquet rows
    lines_in: int | None = None

    @property
    def consistent(self) -> bool:
        lines_ok = self.lines_in is None or self.lines_in == self.rows_in
        return lines_ok and self.rows_in == self.rows_used + self.rows_rejected

    def to_dict(self) -> dict:
        lines = {} if self.lines_in is None else {"lines_in": self.lines_in}
        return {**lines, "rows_in": self.rows_in, "rows_used": self.rows_used, "rows_rejected": self.rows_rejected,
                "consistent": self.consistent, "objects_out": self.objects_out, "objects_fused": self.objects_fused,
                "objects_single": self.objects_single, "objects_unavailable": self.objects_unavailable,
                "objects_inconsistent": self.objects_inconsistent, "sources_inconsistent": self.sources_inconsistent,
                "reasons": dict(sorted(self.reasons.items(), key=lambda kv: -kv[1])), "inputs": self.inputs,
                "elapsed_s": round(self.elapsed_s, 6), **self.info}

    def text(self) -> str:
        return (f"rows in {self.rows_in}, rows used {self.rows_used}, rows rejected {self.rows_rejected}; "
                f"objects out {self.objects_out} (fused {self.objects_fused}, single camera {self.objects_single}, "
                f"unavailable {self.objects_unavailable}), inconsistent objects {self.objects_inconsistent}")


@dataclass
class FusedFootprints:
    """Result of :func:`fuse_footprints`.

    Attributes
    ----------
    objects : pyarrow.Table    one row per key (fused centre, covariance, ellipse, consistency, V2X fields)
    sources : pyarrow.Table    one row per input row (used, reason, d2, inconsistent)
    summary : FuseSummary
    """

    objects: pa.Table
    sources: pa.Table
    summary: FuseSummary


#: largest |x_m|, |y_m| of a footprint accepted for fusion (metres; projected map coordinates are ~1e7)
MAX_COORD_M = 1e9
#: range of the variances accepted for fusion (m^2): beyond it the information form overflows
MAX_VAR_M2 = 1e12
MIN_VAR_M2 = 1e-18


# -- reading ---------------------------------------------------------------------------------------
def _check_columns(names, key, need_camera: bool, where: str) -> None:
    names = set(names)
    missing = [c for c in ESTIMATE_COLUMNS if c not in names]
    if missing:
        raise InputError(f"{where} columns", f"missing {missing}",
                         f"footprint columns {list(ESTIMATE_COLUMNS)} (the output of footprint-uq objects)")
    missing = [c for c in key if c not in names]
    if missing:
        raise InputError(f"{where} columns", f"missing key {missing}", f"the key columns {list(key)} in every input")
    if need_camera and "camera_id" not in names:
        raise InputError(f"{where} columns", "no camera_id",
                         "a camera_id column with --camera-id-from column (or use filename)")


def _normalise(table: pa.Table, key, pre: list) -> pa.Table:
    """Keys -> their types, camera_id/status/reason -> text, numbers -> float64 (conversion errors into ``pre``)."""

    numeric = tuple(c for c in ESTIMATE_COLUMNS + ("row",) if c in table.column_names)
    id_types = {k: _key_type(k) for k in key}
    for c in ("camera_id", "status", "reason"):
        if c in table.column_names and c not in id_types:
            id_types[c] = pa.string()
    t, pre2 = coerce_table(table, numeric, id_types=id_types)
    if pre2 is not None:
        for i, p in enumerate(pre2):
            if p is not None and pre[i] is None:
                pre[i] = p
    return t


def _read_footprints(path, *, key=DEFAULT_KEY, camera_id_from: str = "filename", chunk_rows: int = 262_144) -> _Part:
    """Read one footprint file (CSV, JSON Lines or Parquet) for fusion, keeping every row's number.

    Unparseable lines and values that do not convert are kept with their reason
    (they become rejected rows), row numbers as in ``docs/batch.md`` ("Row numbers").
    """

    p = Path(path)
    if not p.is_file():
        raise InputError("INPUT", str(path), "an existing footprint file (.csv, .jsonl/.ndjson, .parquet/.pq)")
    reader = open_detections(p, chunk_rows=chunk_rows)
    _check_columns(reader.columns, key, camera_id_from == "column", str(p))
    numeric = ESTIMATE_COLUMNS + (("row",) if "row" in reader.columns else ())
    reader.select(numeric)
    extra = [c for c in tuple(key) + ("camera_id", "status", "reason")
             if c in reader.columns and c not in reader.needed]
    reader.needed = tuple(reader.needed) + tuple(extra)
    tables, rows, pre, malformed = [], [], [], []
    for ch in reader:
        tables.append(ch.table)
        rows.append(ch.rows)
        pre += ch.pre_errors if ch.pre_errors is not None else [None] * ch.table.num_rows
        malformed += ch.malformed
    if tables:
        cols = list(reader.needed)
        table = pa.concat_tables([t.select(cols) for t in tables], promote_options="permissive")
    else:
        table = pa.table({c: pa.array([], pa.string()) for c in reader.needed})
    table = _normalise(table, key, pre)
    src_rows = np.concatenate(rows) if rows else np.zeros(0, np.int64)
    cam = p.stem if camera_id_from == "filename" else None
    return _Part(str(p), table, src_rows, pre, sorted(malformed), cam,
                 reader.lines if reader.lines is not None else reader.total)


def _as_table(obj) -> pa.Table:
    if isinstance(obj, pa.Table):
        return obj
    if isinstance(obj, pa.RecordBatch):
        return pa.Table.from_batches([obj])
    if isinstance(obj, pd.DataFrame):
        return pa.Table.from_pandas(obj, preserve_index=False)
    if isinstance(obj, dict):
        return pa.table({k: (v if isinstance(v, pa.Array | pa.ChunkedArray) else np.asarray(v))
                         for k, v in obj.items()})
    raise InputError("tables", type(obj).__name__, "pyarrow Tables, pandas DataFrames or dicts of columns")


# -- fusion ----------------------------------------------------------------------------------------
def _column(table: pa.Table, name: str, typ: pa.DataType, n_extra: int) -> pa.Array:
    """Column ``name`` as one Arrow array of ``typ`` (all null if absent), plus ``n_extra`` nulls."""
    n = table.num_rows
    if name in table.column_names:
        col = table.column(name)
        col = col.combine_chunks() if isinstance(col, pa.ChunkedArray) else col
        if col.type != typ:

            col = pc.cast(col, typ)
    else:
        col = pa.nulls(n, typ)
    return pa.concat_arrays([col, pa.nulls(n_extra, typ)]) if n_extra else col


def _floats(table: pa.Table, name: str) -> np.ndarray:
    col = table.column(name)
    col = col.combine_chunks() if isinstance(col, pa.ChunkedArray) else col
    return col.to_numpy(zero_copy_only=False).astype(np.float64)


def _codes(arr: pa.Array) -> tuple[np.ndarray, pa.Array]:
    """Integer codes (-1 for null) of an Arrow array and its sorted distinct values (codes index them)."""

    enc = pc.dictionary_encode(arr)
    values = enc.dictionary
    order = pc.array_sort_indices(values).to_numpy()
    rank = np.empty(len(values), dtype=np.int64)
    rank[order] = np.arange(len(values))
    idx = enc.indices.fill_null(-1).to_numpy(zero_copy_only=False).astype(np.int64)
    codes = np.where(idx >= 0, rank[np.maximum(idx, 0)] if len(values) else -1, -1)
    return codes, values.take(pa.array(order))


@dataclass
class _Rows:
    """Every row of every input stacked (parsed rows of a part first, then its unparseable ones)."""

    inp: np.ndarray       # (R,) int32 index of the input
    srow: np.ndarray      # (R,) int64 0-based row in that input
    cam: pa.Array         # (R,) camera id (text)
    reason: np.ndarray    # (R,) object: None, or why the row is not used
    det_row: np.ndarray   # (R,) detection row of the footprint (NaN if absent)
    X: np.ndarray         # (R, 5) ESTIMATE_COLUMNS as float64
    keyvals: dict         # key column -> (R,) Arrow array


def _part_camera(part: _Part, n: int, m: int) -> pa.Array:
    """Camera id of each of the ``n + m`` rows of ``part`` (its file's id, or its ``camera_id`` column)."""
    if part.camera is None:
        return _column(part.table, "camera_id", pa.string(), m)
    c = pa.DictionaryArray.from_arrays(pa.array(np.zeros(n + m, np.int32)), pa.array([part.camera]))
    return c.cast(pa.string())


def _mark_status_reasons(t: pa.Table, rs: np.ndarray, todo: np.ndarray) -> None:
    """Rows whose input ``status`` is not ok get ``input status S: R`` in ``rs`` (in place, ``todo`` too)."""
    st_col = _column(t, "status", pa.string(), 0)
    not_ok = pc.fill_null(pc.not_equal(st_col, _STATUS_OK), True).to_numpy(zero_copy_only=False)
    bad = np.flatnonzero(todo & not_ok)
    if not bad.size:
        return
    # only the rows without a centre are turned into Python strings
    st = st_col.take(pa.array(bad)).to_pylist()
    why = (_column(t, "reason", pa.string(), 0).take(pa.array(bad)).to_pylist()
           if "reason" in t.column_names else [None] * bad.size)
    for j, a, b in zip(bad.tolist(), st, why, strict=True):
        rs[j] = f"input status {a}: {b}" if b not in (None, "") else f"input status {a}"
    todo[bad] = False


def _mark_estimate_reasons(est: np.ndarray, rs: np.ndarray, todo: np.ndarray) -> None:
    """Rows with a non-finite, out-of-range or non positive definite estimate get their reason in ``rs``."""
    for j, name in enumerate(ESTIMATE_COLUMNS):
        bad = todo & ~np.isfinite(est[:, j])
        rs[bad] = f"missing or non-finite field {name}"
        todo &= ~bad
    for j, name in enumerate(ESTIMATE_COLUMNS[:2]):
        bad = todo & (np.abs(est[:, j]) > MAX_COORD_M)
        rs[bad] = f"field {name} out of range (|{name}| > {MAX_COORD_M:g} m)"
        todo &= ~bad
    cxx, cxy, cyy = est[:, 2], est[:, 3], est[:, 4]
    with np.errstate(invalid="ignore", over="ignore"):
        pd_ok = (cxx > 0) & (cyy > 0) & (cxx * cyy - cxy * cxy > 0)
        scale_ok = (np.maximum(cxx, cyy) <= MAX_VAR_M2) & (np.minimum(cxx, cyy) >= MIN_VAR_M2)
    rs[todo & ~pd_ok] = "covariance not positive definite"
    todo &= pd_ok
    rs[todo & ~scale_ok] = f"covariance out of range (variances must lie in [{MIN_VAR_M2:g}, {MAX_VAR_M2:g}] m^2)"


def _part_reasons(part: _Part, key, keyvals: dict, cam: pa.Array, est: np.ndarray) -> np.ndarray:
    """Per-row reasons of one part, first applicable wins (vectorised masks; loops over a few columns only)."""
    t = part.table
    n, m = t.num_rows, len(part.malformed)
    rs = np.empty(n + m, dtype=object)
    rs[:n] = part.pre
    rs[n:] = [r for _, r in part.malformed]
    parsed = rs[:n]  # a view: writing into it writes into rs
    todo = parsed == None  # noqa: E711 - elementwise on an object array
    for k in key:
        miss = todo & keyvals[k].slice(0, n).is_null().to_numpy(zero_copy_only=False)
        parsed[miss] = f"missing key field {k}"
        todo &= ~miss
    if part.camera is None:
        miss = todo & cam.slice(0, n).is_null().to_numpy(zero_copy_only=False)
        parsed[miss] = "missing camera_id"
        todo &= ~miss
    if "status" in t.column_names:
        _mark_status_reasons(t, parsed, todo)
    _mark_estimate_reasons(est[:n], parsed, todo)
    return rs


def _stack_parts(parts: list[_Part], key, summary: FuseSummary) -> _Rows:
    """Stack every row of every input, with the reason of each row that cannot be used (None: usable)."""
    inp, srow, cam, reason, det_row, X, keyvals = [], [], [], [], [], [], {k: [] for k in key}
    for i, part in enumerate(parts):
        t = part.table
        n, m = t.num_rows, len(part.malformed)
        inp.append(np.full(n + m, i, dtype=np.int32))
        srow.append(np.concatenate([part.source_rows.astype(np.int64),
                                    np.asarray([r for r, _ in part.malformed], dtype=np.int64)]))
        c = _part_camera(part, n, m)
        cam.append(c)
        kv = {k: _column(t, k, _key_type(k), m) for k in key}
        for k in key:
            keyvals[k].append(kv[k])
        est = np.full((n + m, 5), np.nan)
        for j, name in enumerate(ESTIMATE_COLUMNS):
            est[:n, j] = _floats(t, name)
        X.append(est)
        dr = np.full(n + m, np.nan)
        if "row" in t.column_names:
            dr[:n] = _floats(t, "row")
        det_row.append(dr)
        reason.append(_part_reasons(part, key, kv, c, est))
        summary.inputs.append({"input": part.name, "camera_id": part.camera, "rows": n + m})
    if not parts:
        return _Rows(np.zeros(0, np.int32), np.zeros(0, np.int64), pa.array([], pa.string()),
                     np.zeros(0, dtype=object), np.zeros(0), np.zeros((0, 5)),
                     {k: pa.array([], _key_type(k)) for k in key})
    return _Rows(np.concatenate(inp), np.concatenate(srow), pa.concat_arrays(cam), np.concatenate(reason),
                 np.concatenate(det_row), np.concatenate(X), {k: pa.concat_arrays(v) for k, v in keyvals.items()})


@dataclass
class _Groups:
    """Rows grouped by key: one group per object."""

    keyed: np.ndarray     # (R,) bool: every key field present
    group: np.ndarray     # (R,) int64 group of the row (-1 if not keyed)
    groups: np.ndarray    # (M, k) key codes of each group
    kuniq: list           # per key column, the sorted distinct values (codes index them)
    camc: np.ndarray      # (R,) camera code (-1: null)
    cam_uniq: pa.Array    # sorted distinct camera ids

    @property
    def M(self) -> int:
        """Number of groups (objects)."""
        return self.groups.shape[0]


def _associate(rows: _Rows, key) -> _Groups:
    """Group rows by key; rows of one camera seen twice for a key are rejected (``duplicate: ...``)."""
    R = rows.inp.shape[0]
    kcodes, kuniq = [], []
    for k in key:
        c, u = _codes(rows.keyvals[k])
        kcodes.append(c)
        kuniq.append(u)
    kc = np.stack(kcodes, 1) if R else np.zeros((0, len(key)), np.int64)
    keyed = (kc >= 0).all(1)
    groups, ginv = _row_codes(kc[keyed])
    group = np.full(R, -1, dtype=np.int64)
    group[keyed] = ginv
    # same camera twice for one key: shared calibration error, not independent -> reject all of them
    camc, cam_uniq = _codes(rows.cam)
    cand = (rows.reason == None) & keyed  # noqa: E711
    if np.any(cand):
        pairs = np.stack([group[cand], np.maximum(camc[cand], 0)], 1)
        _, pinv = _row_codes(pairs)
        cnt = np.bincount(pinv)[pinv]
        idx = np.flatnonzero(cand)[cnt > 1]
        for j, n_dup in zip(idx.tolist(), cnt[cnt > 1].tolist(), strict=True):
            rows.reason[j] = f"duplicate: {n_dup} rows of one camera for this key"
    return _Groups(keyed, group, groups, kuniq, camc, cam_uniq)


@dataclass
class _Fused:
    """Per-object fusion results (M objects) and per-row test results (R rows)."""

    fx: np.ndarray        # (M, 2) fused centre (m)
    fP: np.ndarray        # (M, 2, 2) fused covariance (m^2)
    nsrc: np.ndarray      # (M,) cameras used
    chi2: np.ndarray      # (M,)
    chi2_thr: np.ndarray  # (M,)
    cons: np.ndarray      # (M,) bool
    d2: np.ndarray        # (R,) squared Mahalanobis distance of each row to the fused centre
    flag: np.ndarray      # (R,) bool: row inconsistent with the fused centre
    overflow: np.ndarray  # (M,) bool: fused result not finite


def _fuse_groups(rows: _Rows, g: _Groups, used_in: np.ndarray, confidence: float) -> _Fused:
    """Fuse the usable rows of each group in information form; rejected rows enter as NaN (unused)."""
    R, M, keyed, group, X = rows.inp.shape[0], g.M, g.keyed, g.group, rows.X
    xy = np.where(used_in[:, None], X[:, :2], np.nan)
    C = np.empty((R, 2, 2))
    C[:, 0, 0], C[:, 0, 1], C[:, 1, 0], C[:, 1, 1] = X[:, 2], X[:, 3], X[:, 3], X[:, 4]
    C = np.where(used_in[:, None, None], C, np.nan)
    d2 = np.full(R, np.nan)
    flag = np.zeros(R, dtype=bool)
    if not M:
        z = np.zeros(0)
        return _Fused(np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0, np.int64), z, z, np.zeros(0, bool),
                      d2, flag, np.zeros(0, bool))
    fr = fuse_by_id(group[keyed], xy[keyed], C[keyed], confidence=confidence)
    fx, fP, nsrc = fr.xy_world_m.copy(), fr.cov_m2.copy(), fr.n_sources
    d2[keyed] = fr.source_d2
    flag[keyed] = fr.source_inconsistent
    # one usable estimate: pass it through bit for bit (the information form would round it)
    single = used_in & (group >= 0)
    single[single] = nsrc[group[single]] == 1
    fx[group[single]] = xy[single]
    fP[group[single]] = C[single]
    # outputs are checked too: a fused centre or covariance that is not finite is never "ok"
    overflow = (nsrc > 0) & ~(np.isfinite(fx).all(-1) & np.isfinite(fP).all((-2, -1)))
    if np.any(overflow):
        fx[overflow], fP[overflow] = np.nan, np.nan
        nsrc = np.where(overflow, 0, nsrc)
    return _Fused(fx, fP, nsrc, fr.chi2, fr.chi2_threshold, fr.consistent, d2, flag, overflow)


def _object_reasons(g: _Groups, f: _Fused, reason: np.ndarray) -> np.ndarray:
    """``ok``, or for objects without any usable row ``no usable estimate: <the first row's reason>``."""
    M, group, keyed, has = g.M, g.group, g.keyed, f.nsrc > 0
    obj_reason = np.full(M, "ok", dtype=object)
    if np.any(~has):
        first_reason = np.full(M, None, dtype=object)
        kr = np.flatnonzero(keyed)
        order = kr[np.argsort(group[kr], kind="stable")]
        g_sorted = group[order]
        firsts = order[np.r_[True, g_sorted[1:] != g_sorted[:-1]]] if order.size else order
        first_reason[group[firsts]] = reason[firsts]
        obj_reason[~has] = ["no usable estimate: " + str(r) for r in first_reason[~has]]
        obj_reason[f.overflow] = "fused result not finite (overflow)"
    return obj_reason


def _objects_table(key, g: _Groups, f: _Fused, used_in: np.ndarray, reason: np.ndarray, *,
                   ellipse_confidence: float | None, heading_offset_deg: float) -> pa.Table:
    """One row per object: fused centre, covariance, ellipse, consistency and V2X fields."""
    M, group, keyed, nsrc, fP = g.M, g.group, g.keyed, f.nsrc, f.fP
    n_rows = np.bincount(group[keyed], minlength=M)
    n_incons = np.bincount(group[keyed], weights=f.flag[keyed], minlength=M).astype(np.int64)
    max_d2 = np.full(M, np.nan)
    ok_d2 = keyed & np.isfinite(f.d2)
    if np.any(ok_d2):
        np.fmax.at(max_d2, group[ok_d2], f.d2[ok_d2])
    smaj, smin, ori = ellipse_axes(fP)
    v2x = {**cpm_fields(fP, heading_offset_deg), **j2735_fields(fP, heading_offset_deg)}
    has = nsrc > 0
    cols: dict[str, pa.Array] = {}
    for j, k in enumerate(key):
        cols[k] = g.kuniq[j].take(pa.array(g.groups[:, j])) if M else pa.array([], _key_type(k))
    cols["status"] = pa.array(np.where(has, "ok", "error").tolist(), pa.string())
    cols["reason"] = pa.array(_object_reasons(g, f, reason), pa.string())
    cols["n_cameras"] = pa.array(nsrc.astype(np.int32))
    cols["n_rows"] = pa.array(n_rows.astype(np.int32))
    cols["cameras"] = pa.array(_join_per_group(group, g.camc, g.cam_uniq, used_in, M), pa.string())
    for name, v in (("x_m", f.fx[:, 0]), ("y_m", f.fx[:, 1]), ("cov_xx_m2", fP[:, 0, 0]),
                    ("cov_xy_m2", 0.5 * (fP[:, 0, 1] + fP[:, 1, 0])), ("cov_yy_m2", fP[:, 1, 1]),
                    ("sigma_major_m", smaj), ("sigma_minor_m", smin), ("orientation_deg", ori)):
        cols[name] = pa.array(np.asarray(v, dtype=np.float64))
    if ellipse_confidence is not None:
        a, b, _ = ellipse_axes(fP, confidence=ellipse_confidence)
        cols["semi_major_m"] = pa.array(a)
        cols["semi_minor_m"] = pa.array(b)
    cols["chi2"] = pa.array(np.asarray(f.chi2, dtype=np.float64))
    cols["chi2_dof"] = pa.array((2 * np.maximum(nsrc - 1, 0)).astype(np.int32))
    cols["chi2_threshold"] = pa.array(np.asarray(f.chi2_thr, dtype=np.float64))
    cols["max_d2"] = pa.array(max_d2)
    cols["consistent"] = pa.array(np.asarray(f.cons, dtype=bool), mask=~has)
    cols["n_inconsistent"] = pa.array(n_incons.astype(np.int32))
    cols["inconsistent_cameras"] = pa.array(_join_per_group(group, g.camc, g.cam_uniq, f.flag, M), pa.string())
    for name in V2X_FIELDS:
        cols[name] = pa.array(np.asarray(v2x[name], dtype=np.int32))
    return pa.table(cols)


def _sources_table(parts: list[_Part], key, rows: _Rows, f: _Fused, used_in: np.ndarray,
                   reason: np.ndarray) -> pa.Table:
    """One row per input row: where it came from, whether it was used and why not, its d2."""
    names = pa.array([p.name for p in parts], pa.string())
    sc: dict[str, pa.Array] = {
        "input": pa.DictionaryArray.from_arrays(pa.array(rows.inp, pa.int32()), names),
        "source_row": pa.array(rows.srow),
        "camera_id": rows.cam,
    }
    for k in key:
        sc[k] = rows.keyvals[k]
    det_row = rows.det_row
    sc["detection_row"] = pa.array(np.where(np.isfinite(det_row), det_row, 0).astype(np.int64),
                                   mask=~np.isfinite(det_row))
    sc["used"] = pa.array(used_in)
    sc["reason"] = pa.array(reason, pa.string()).dictionary_encode()
    sc["d2"] = pa.array(f.d2)
    sc["inconsistent"] = pa.array(f.flag)
    return pa.table(sc)


def _fill_summary(summary: FuseSummary, parts: list[_Part], f: _Fused, used_in: np.ndarray,
                  reason: np.ndarray) -> None:
    """Row and object counts of the job into ``summary`` (rows by reason, objects by outcome)."""
    R, nsrc = used_in.shape[0], f.nsrc
    summary.rows_in = R
    if all(p.lines is not None for p in parts):
        summary.lines_in = int(sum(p.lines for p in parts))
    summary.rows_used = int(used_in.sum())
    summary.rows_rejected = R - summary.rows_used
    summary.objects_out = nsrc.shape[0]
    summary.objects_fused = int((nsrc >= 2).sum())
    summary.objects_single = int((nsrc == 1).sum())
    summary.objects_unavailable = int((nsrc == 0).sum())
    summary.objects_inconsistent = int(((nsrc >= 2) & ~np.asarray(f.cons, dtype=bool)).sum())
    summary.sources_inconsistent = int(f.flag.sum())
    rj = reason[~used_in]
    if rj.size:
        u, c = np.unique(rj.astype(str), return_counts=True)
        summary.reasons = dict(zip(u.tolist(), c.tolist(), strict=True))


def _fuse_parts(parts: list[_Part], key, *, confidence: float, ellipse_confidence: float | None,
                heading_offset_deg: float) -> FusedFootprints:
    """Stack the inputs, group rows by key, fuse each group, and tabulate objects, sources and summary."""
    t0 = time.perf_counter()
    key = tuple(key)
    thr2 = chi2_threshold(confidence, 2)  # validates confidence
    summary = FuseSummary()
    rows = _stack_parts(parts, key, summary)
    g = _associate(rows, key)
    used_in = (rows.reason == None) & g.keyed  # noqa: E711
    f = _fuse_groups(rows, g, used_in, confidence)
    reason = np.where(used_in, "ok", rows.reason).astype(object)
    objects = _objects_table(key, g, f, used_in, reason, ellipse_confidence=ellipse_confidence,
                             heading_offset_deg=heading_offset_deg)
    sources = _sources_table(parts, key, rows, f, used_in, reason)
    _fill_summary(summary, parts, f, used_in, reason)
    summary.info = {"key": list(key), "confidence": float(confidence), "d2_threshold": thr2,
                    "ellipse_confidence": ellipse_confidence, "heading_offset_deg": float(heading_offset_deg)}
    summary.elapsed_s = time.perf_counter() - t0
    return FusedFootprints(objects, sources, summary)


def _join_per_group(group: np.ndarray, camc: np.ndarray, cam_uniq: pa.Array, mask: np.ndarray, M: int) -> list:
    """Comma-joined sorted camera ids of the rows in ``mask``, per group (empty string if none).

    Vectorised with one bit per camera (``camc`` are codes into the sorted ``cam_uniq``); the
    strings are built once per distinct camera combination, not once per object.
    """
    sel = np.flatnonzero(mask & (group >= 0) & (camc >= 0))
    n_cam = len(cam_uniq)
    if not sel.size:
        return [""] * M
    words = (n_cam + 62) // 63
    bits = np.zeros((M, words), dtype=np.int64)
    for w in range(words):  # a handful of 63-camera words
        inw = sel[(camc[sel] // 63) == w]
        np.bitwise_or.at(bits[:, w], group[inw], np.left_shift(1, camc[inw] % 63).astype(np.int64))
    combos, inv = np.unique(bits, axis=0, return_inverse=True)
    cu = [str(v) for v in cam_uniq.to_pylist()]
    names = []
    for row in combos:  # one string per distinct combination of cameras
        ids = [w * 63 + b for w in range(words) for b in range(63) if (int(row[w]) >> b) & 1]
        names.append(",".join(cu[i] for i in ids))
    return np.asarray(names, dtype=object)[inv.reshape(-1)].tolist()


def _row_codes(codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unique rows of non-negative integer codes ``(R, k)``: ``(unique (M, k), inverse (R,))``, rows sorted."""
    R, k = codes.shape
    if R == 0:
        return np.zeros((0, k), np.int64), np.zeros(0, np.int64)
    span = codes.max(0).astype(np.float64) + 1.0
    if float(np.prod(span)) < 2.0**62:  # mixed radix into one int64: a 1-D unique (fast)
        radix = np.ones(k, np.int64)
        for j in range(k - 2, -1, -1):
            radix[j] = radix[j + 1] * int(span[j + 1])
        flat = codes @ radix
        u, inv = np.unique(flat, return_inverse=True)
        return np.stack([(u // radix[j]) % int(span[j]) for j in range(k)], 1), inv.reshape(-1)
    u, inv = np.unique(codes, axis=0, return_inverse=True)
    return u, inv.reshape(-1)


def _check_options(key, confidence, ellipse_confidence, heading_offset_deg):
    key = tuple(key)
    if not key or any(not isinstance(k, str) or not k for k in key) or len(set(key)) != len(key):
        raise InputError("key", key, "one or more distinct column names, e.g. frame,object_id")
    c = as_float("confidence", confidence)
    if not 0.0 < c < 1.0:
        raise InputError("confidence", confidence, "a probability in (0, 1), e.g. 0.99")
    if ellipse_confidence is not None:
        e = as_float("ellipse_confidence", ellipse_confidence)
        if not 0.0 < e < 1.0:
            raise InputError("ellipse_confidence", ellipse_confidence, "a probability in (0, 1), e.g. 0.95")
    as_float("heading_offset_deg", heading_offset_deg)
    return key


def fuse_footprints(tables, *, camera_ids=None, key=DEFAULT_KEY, confidence: float = 0.99,
                    ellipse_confidence: float | None = 0.95, heading_offset_deg: float = 0.0) -> FusedFootprints:
    """Fuse in-memory footprint tables (e.g. one :func:`~footprint_uq.batch.process_table` output per camera).

    Parameters
    ----------
    tables : sequence of pyarrow.Table, pandas.DataFrame or dict of columns
        Footprint rows with the key columns and ``x_m, y_m, cov_xx_m2, cov_xy_m2, cov_yy_m2``
        (``status``/``reason`` honoured when present).
    camera_ids : sequence of str, optional
        One camera id per table; None: each table's ``camera_id`` column.
    key : sequence of str
        Association columns (default ``("frame", "object_id")``).
    confidence : float
        Level of the chi-square consistency tests (default 0.99: d^2 > 9.21 is flagged).
    ellipse_confidence : float or None
        Probability of the ``semi_major_m``/``semi_minor_m`` ellipse (default 0.95); None: not written.
    heading_offset_deg : float
        Compass bearing of the world +y axis, for the V2X fields.

    Returns
    -------
    FusedFootprints
        ``objects`` (one row per key), ``sources`` (one row per input row, ``input`` is
        ``"table <i>"``, ``source_row`` the 0-based row) and the ``summary``.
    """
    key = _check_options(key, confidence, ellipse_confidence, heading_offset_deg)
    tables = list(tables)
    if camera_ids is not None:
        camera_ids = [str(c) for c in camera_ids]
        if len(camera_ids) != len(tables):
            raise InputError("camera_ids", camera_ids, f"one id per table ({len(tables)})")
    parts = []
    for i, obj in enumerate(tables):
        t = _as_table(obj)
        where = f"table {i}"
        _check_columns(t.column_names, key, camera_ids is None, where)
        keep = [c for c in dict.fromkeys(tuple(key) + ESTIMATE_COLUMNS + ("camera_id", "status", "reason", "row"))
                if c in t.column_names]
        t = t.select(keep)
        pre = [None] * t.num_rows
        t = _normalise(t, key, pre)
        parts.append(_Part(where, t, np.arange(t.num_rows, dtype=np.int64), pre, [],
                           None if camera_ids is None else camera_ids[i]))
    return _fuse_parts(parts, key, confidence=confidence, ellipse_confidence=ellipse_confidence,
                       heading_offset_deg=heading_offset_deg)


def _check_out_paths(inputs: list[Path], out, sources_out) -> Path:
    """Validate ``out`` and ``sources_out`` (formats, distinct, not an input); returns ``sources_out``."""
    fmt = detect_out_format(out)
    if fmt == "geojson":
        raise InputError("out", str(out), "a .parquet, .csv or .jsonl file (GeoJSON needs footprint polygons)")
    sources_out = sources_path(out) if sources_out is None else Path(sources_out)
    detect_out_format(sources_out)
    if Path(sources_out).absolute() == Path(out).absolute() or same_file(sources_out, out):
        raise InputError("sources_out", str(sources_out), "a different file from out")
    for p in inputs:
        if not p.is_file():
            raise InputError("INPUT", str(p), "an existing footprint file (.csv, .jsonl/.ndjson, .parquet/.pq)")
        for o in (out, sources_out, summary_path(out)):
            if same_file(p, o):
                raise InputError("out", str(o), f"a file that is not an input (it is the same file as {p})")
    return sources_out


def _resolve_camera_id_from(inputs: list[Path], camera_id_from: str | None) -> str:
    """``camera_id_from`` checked (None: "column" if every input has ``camera_id``, else "filename")."""
    if camera_id_from is None:
        has_col = all("camera_id" in open_detections(p).columns for p in inputs)
        camera_id_from = "column" if has_col else "filename"
    if camera_id_from not in CAMERA_ID_FROM:
        raise InputError("camera_id_from", camera_id_from, f"one of {CAMERA_ID_FROM}")
    if camera_id_from == "filename":
        stems = [p.stem for p in inputs]
        if len(inputs) < 2:
            raise InputError("INPUT", [str(p) for p in inputs],
                             "two or more files (one per camera), or one file with a camera_id column "
                             "and --camera-id-from column")
        dup = sorted({s for s in stems if stems.count(s) > 1})
        if dup:
            raise InputError("INPUT", f"camera id {dup[0]!r} from two file names",
                             "file names (without extension) that differ between cameras")
    return camera_id_from


def _write_tables(res: FusedFootprints, out, sources_out: Path, compression: str | None) -> None:
    """Both tables complete under temporary names, then renamed; the old summary removed first."""
    comp = compression or "none"
    writers = []
    try:
        for path, table in ((out, res.objects), (sources_out, res.sources)):
            kw = {"compression": comp} if detect_out_format(path) == "parquet" else {}
            w = open_writer(path, table.schema, **kw)
            writers.append(w)
            w.write(table)
        summary_path(out).unlink(missing_ok=True)
        for w in writers:
            w.close()
    except BaseException:
        for w in writers:
            w.abort()
        raise


def fuse_files(inputs, out, *, camera_id_from: str | None = None, key=DEFAULT_KEY, confidence: float = 0.99,
               ellipse_confidence: float | None = 0.95, heading_offset_deg: float = 0.0, sources_out=None,
               compression: str | None = "snappy", chunk_rows: int = 262_144) -> FuseSummary:
    """Fuse footprint files (one per camera, or files with a ``camera_id`` column) into ``out``.

    Parameters
    ----------
    inputs : sequence of paths
        ``.csv``, ``.jsonl``/``.ndjson`` or ``.parquet``/``.pq`` footprint files.
    out : path
        Fused objects, ``.parquet``, ``.csv`` or ``.jsonl``.
    camera_id_from : {"filename", "column"} or None
        Camera of a row: the input's file name without extension (ids must differ), or its
        ``camera_id`` column.  None: "column" if every input has that column, else "filename".
    sources_out : path, optional
        The per-row table (default :func:`sources_path` of ``out``: ``fused.sources.parquet``).
    key, confidence, ellipse_confidence, heading_offset_deg
        As :func:`fuse_footprints`.
    compression : Parquet compression (None: none).
    chunk_rows : rows read at a time (the fusion itself holds the estimate columns of all rows).

    Returns
    -------
    FuseSummary
        Also written to :func:`summary_path` of ``out`` (``<out>.summary.json``).
    """

    t0 = time.perf_counter()
    key = _check_options(key, confidence, ellipse_confidence, heading_offset_deg)
    inputs = [Path(p) for p in inputs]
    if not inputs:
        raise InputError("INPUT", [], "one or more footprint files")
    sources_out = _check_out_paths(inputs, out, sources_out)
    camera_id_from = _resolve_camera_id_from(inputs, camera_id_from)
    parts = [_read_footprints(p, key=key, camera_id_from=camera_id_from, chunk_rows=chunk_rows) for p in inputs]
    res = _fuse_parts(parts, key, confidence=confidence, ellipse_confidence=ellipse_confidence,
                      heading_offset_deg=heading_offset_deg)
    s = res.summary
    if not s.consistent:  # pragma: no cover - a bug, not bad input
        raise RuntimeError(f"row accounting broken: {s.text()} (lines in {s.lines_in})")
    _write_tables(res, out, sources_out, compression)
    s.elapsed_s = time.perf_counter() - t0
    s.info.update({"camera_id_from": camera_id_from, "out": str(out), "sources_out": str(sources_out)})
    atomic_write_text(summary_path(out), json.dumps(s.to_dict(), indent=2) + "\n")
    return s
