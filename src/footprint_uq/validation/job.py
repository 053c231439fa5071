"""The validation job: chunks of labelled objects -> pairs -> coverage summary and per-object file, streamed.

:func:`validate` holds one chunk at a time (memory flat in the number of pairs); the per-object file is
written as the chunks go (``.csv`` or ``.parquet``) and moved into place at the end (atomic).
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
import pyarrow.parquet as pq

from ..errors import InputError
from ..io.atomic import commit, discard, temp_path
from ..uncertainty.budget import load_budget
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD
from .coverage import DEFAULT_RANGE_BANDS_M, LEVELS, CoverageAccumulator
from .motion import MotionScorer
from .pairs import GroupIndex, build_pairs, contact_model
from .readers import LabelChunk

__all__ = ["validate", "ValidationResult", "OBJECT_COLUMNS", "ObjectWriter"]

#: columns of the per-object file, in order
OBJECT_COLUMNS = ("source", "line", "group", "frame", "object_id", "class", "status", "reason",
                  "u_min_px", "v_min_px", "u_max_px", "v_max_px", "truth_x_m", "truth_y_m", "truth_z_m",
                  "x_m", "y_m", "residual_x_m", "residual_y_m", "error_m", "r_major_m", "r_minor_m",
                  "sigma_major_m", "sigma_minor_m", "orientation_deg", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2",
                  "nees", *(f"inside_{round(lv * 100)}" for lv in LEVELS), "range_m", "nonlinearity", "linear_ok")


@dataclass
class ValidationResult:
    """``summary`` (JSON-ready dict), the accumulator (figures use its sample), the output paths."""

    summary: dict
    accumulator: CoverageAccumulator
    objects_path: Path | None


def _text(a) -> pa.Array:
    try:  # str / None objects: converted by Arrow directly (no Python loop)
        return pa.array(a, type=pa.string(), from_pandas=True)
    except (pa.ArrowTypeError, pa.ArrowInvalid):
        return pa.array([None if v is None else str(v) for v in a], type=pa.string())


def _object_table(pairs, m, group_names) -> pa.Table:
    g = pairs.group
    gname = np.array([group_names[i] if i >= 0 else "" for i in g], dtype=object) if len(g) else g.astype(object)
    cols = {"source": _text(pairs.source), "line": pa.array(pairs.line, pa.int64()), "group": _text(gname),
            "frame": _text(pairs.frame), "object_id": _text(pairs.object_id), "class": _text(pairs.cls),
            "status": _text(pairs.status), "reason": _text(pairs.reason)}
    for j, c in enumerate(("u_min_px", "v_min_px", "u_max_px", "v_max_px")):
        cols[c] = pairs.box_xyxy_px[:, j]
    cols.update(truth_x_m=pairs.truth_xy_world_m[:, 0], truth_y_m=pairs.truth_xy_world_m[:, 1],
                truth_z_m=pairs.truth_z_m, x_m=pairs.xy_world_m[:, 0], y_m=pairs.xy_world_m[:, 1],
                residual_x_m=pairs.residual_m[:, 0], residual_y_m=pairs.residual_m[:, 1],
                error_m=np.hypot(pairs.residual_m[:, 0], pairs.residual_m[:, 1]))
    for k in ("r_major_m", "r_minor_m", "sigma_major_m", "sigma_minor_m", "orientation_deg"):
        cols[k] = m[k]
    cols.update(cov_xx_m2=pairs.cov_m2[:, 0, 0], cov_xy_m2=pairs.cov_m2[:, 0, 1], cov_yy_m2=pairs.cov_m2[:, 1, 1],
                nees=m["nees"])
    ok = pairs.usable & np.isfinite(m["nees"])
    for lv in LEVELS:
        k = f"inside_{round(lv * 100)}"
        cols[k] = pa.array(np.asarray(m[k], dtype=bool), mask=~ok)  # null where there is no residual
    cols.update(range_m=pairs.range_m, nonlinearity=pairs.nonlinearity,
                linear_ok=pa.array(np.asarray(pairs.linear_ok, dtype=bool)))
    # NaN -> null: an empty CSV field, as in the batch's outputs
    return pa.table({k: (v if isinstance(v, pa.Array) else pa.array(np.asarray(v, dtype=np.float64), from_pandas=True))
                     for k, v in cols.items()})


class ObjectWriter:
    """Per-object rows into ``.csv`` or ``.parquet``, written to a temporary file and renamed at :meth:`close`.

    Small tables (one per camera of a chunk) are gathered into blocks of at least ``block_rows`` rows before
    they are written: a Parquet file keeps metadata per row group in memory until it is closed, so one row
    group per small table would make memory grow with the number of pairs.
    """

    def __init__(self, path, *, fsync: bool = True, block_rows: int = 65_536):
        self.path = Path(path)
        suffix = self.path.suffix.lower()
        if suffix not in (".csv", ".parquet", ".pq"):
            raise InputError("objects output", str(path), "a file ending in .csv or .parquet")
        self.parquet = suffix != ".csv"
        self.tmp = temp_path(self.path)
        self.fsync = fsync
        self.writer = None
        self.rows = 0
        self.block_rows = int(block_rows)
        self.pending: list[pa.Table] = []
        self.pending_rows = 0

    def write(self, table: pa.Table) -> None:
        self.pending.append(table)
        self.pending_rows += table.num_rows
        self.rows += table.num_rows
        if self.pending_rows >= self.block_rows:
            self._flush()

    def _flush(self) -> None:
        if not self.pending:
            return
        table = pa.concat_tables(self.pending)
        self.pending, self.pending_rows = [], 0
        if self.writer is None:
            self.writer = (pq.ParquetWriter(self.tmp, table.schema) if self.parquet
                           else pcsv.CSVWriter(self.tmp, table.schema))
        self.writer.write_table(table)

    def close(self, *, ok: bool = True) -> None:
        if ok:
            self._flush()
        if self.writer is not None:
            self.writer.close()
        elif ok:  # no chunk at all: a header-only file
            empty = pa.table({c: pa.array([], pa.string()) for c in OBJECT_COLUMNS})
            (pq.write_table(empty, self.tmp) if self.parquet else pcsv.write_csv(empty, self.tmp))
        if ok:
            commit(self.tmp, self.path, fsync=self.fsync)
        else:
            discard(self.tmp)


def validate(chunks: Iterable[LabelChunk], budget, *, contact="bottom-centre", objects_out=None,
             range_bands_m=DEFAULT_RANGE_BANDS_M, alpha: float = 0.05, linear_threshold: float =
             DEFAULT_LINEAR_THRESHOLD, extra: dict | None = None, fsync: bool = True, progress=None,
             tracks=None, motion_options: dict | None = None, motion_out=None) -> ValidationResult:
    """Validate the uncertainty of every pair of a stream of chunks.

    Parameters
    ----------
    chunks : LabelChunk objects (any reader of :mod:`footprint_uq.validation.readers`)
    budget : error budget (preset name, file, mapping or ErrorBudget); a chunk's own budget wins
    contact : contact model name (:data:`footprint_uq.validation.pairs.CONTACT_MODELS`) or function
    objects_out : path of the per-object file (``.csv`` / ``.parquet``), or None
    range_bands_m : edges of the range bands
    alpha : significance of the NEES test and the bias test
    extra : entries added to the summary (e.g. the folder report)
    progress : callable(n_rows) called after every chunk, or None
    tracks : None, True or a :class:`~footprint_uq.tracking.table.TrackerConfig`
        Also track the detections (per camera, by ``object_id`` and ``time_s``) and score velocity and heading
        where the chunks carry a truth velocity (:mod:`footprint_uq.validation.motion`): the summary's
        ``motion`` entry.  True: the default tracker (a budget's motion section applies over it).
    motion_options : keyword arguments of :class:`~footprint_uq.validation.motion.MotionScorer` (``differences``,
        ``truth_sigma_m``, ``max_span_s``: truth velocities from consecutive labelled frames)
    motion_out : path of the per-row motion scores (``motion.csv``, with ``tracks``), or None

    Returns
    -------
    ValidationResult
    """
    t0 = time.perf_counter()
    fn = contact_model(contact)
    bud = load_budget(budget)
    acc = CoverageAccumulator(range_bands_m=range_bands_m, alpha=alpha)
    groups = GroupIndex()
    S_of: dict[int, np.ndarray] = {}
    writer = ObjectWriter(objects_out, fsync=fsync) if objects_out is not None else None
    scorer = None if tracks is None or tracks is False else MotionScorer(None if tracks is True else tracks,
                                                                          alpha=alpha, **(motion_options or {}))
    ok = False
    try:
        for ch in chunks:
            pairs = build_pairs(ch, bud, contact=fn, groups=groups, linear_threshold=linear_threshold)
            if ch.camera is not None and ch.camera_key in groups.keys:
                g = groups.keys[ch.camera_key]
                S_of.setdefault(g, load_budget(ch.budget if ch.budget is not None else bud).param_covariance())
            m = acc.add(pairs, S_of, groups.names())
            if scorer is not None:
                scorer.add(ch, pairs, bud)
            if writer is not None:
                writer.write(_object_table(pairs, m, groups.names()))
            if progress is not None:
                progress(len(pairs))
        ok = True
    finally:
        if writer is not None:
            writer.close(ok=ok)
    summary = acc.summary()
    summary.update({"budget": bud.name, "contact": contact if isinstance(contact, str) else getattr(
        contact, "__name__", "custom"), "levels": list(LEVELS), "range_bands_m": list(map(float, acc.edges)),
        "linear_threshold": linear_threshold, "n_groups": len(groups.keys), "elapsed_s": time.perf_counter() - t0})
    rows = summary["rows"]
    summary["unpaired"] = {"detections_without_truth": rows.get("no truth", 0),
                           "truth_without_detection": rows.get("no detection", 0),
                           "no_ground_point": rows.get("no ground point", 0), "error_rows": rows.get("error", 0)}
    if scorer is not None:
        summary["motion"] = scorer.summary()
        if motion_out is not None:
            scorer.write_rows(motion_out, fsync=fsync)
    if extra:
        summary.update(extra)
    return ValidationResult(summary, acc, Path(objects_out) if objects_out is not None else None)
