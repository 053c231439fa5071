"""Batch footprints: one table of detections in, one table of footprints out, every row accounted for.

:class:`BatchProcessor` holds a camera, a budget and the options, and turns a
:class:`pyarrow.Table` (or a dict of arrays) of detections into a footprint table
(:func:`footprint_uq.batch.schema.output_schema`).  It is the single per-chunk /
per-partition implementation used by :func:`process_table`, by
:func:`process_file` (streaming, chunk by chunk) and by the Dask fleet path
(:mod:`footprint_uq.batch.fleet`).

Row accounting
--------------
Every input row gives exactly one output row, with its 0-based input index in
``row`` and a ``status``:

* ``ok`` -- the footprint centre and its covariance were computed;
* ``partial`` -- the centre is not computable (a corner outside the image or above
  the horizon, a degenerate polygon) but at least one corner is usable: the largest
  point and the usable corners are given, ``reason`` says what is missing;
* ``error`` -- nothing could be computed: a missing/NaN/non-numeric field, a negative
  size, an inverted 2D box, a pixel covariance that is not positive semi-definite,
  or no usable corner (e.g. the whole object above the horizon); ``reason`` says which.

Bad rows never stop the batch.  Errors that concern the whole job (unknown box type,
missing columns, bad options) raise :class:`~footprint_uq.errors.InputError`.
"""

from __future__ import annotations

import json
import os
import queue
import sys
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from concurrent.futures import ThreadPoolExecutor as _Pool
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
from tqdm import tqdm

from .. import status as st
from .._checks import as_float
from ..errors import InputError
from ..fast import footprint_kernels as fk
from ..fast.footprint_kernels import OBJ_ROWS
from ..io.atomic import atomic_write_text, same_file
from ..products.detection_columns import MAX_PIXEL_VAR_PX2
from ..products.footprints import CONTACT_MODES, DEGENERATE, V2X_FIELDS, FrameProcessor
from ..products.geo import GeoReference
from ..tracking import SharedJacobianAt, TrackerConfig, TrackOutput, object_motion
from ..tracking.classes import ClassTracks, tracker_configs
from ..tracking.contact_slide import ContactSlide
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import chi2_scale
from . import schema as S
from .formats import open_reader
from .writers import detect_out_format, open_writer

__all__ = ["prefetch", "BatchProcessor", "process_table", "process_file", "process_chunk", "Summary", "summary_path",
           "Reasons", "PSD_TOL"]

#: relative tolerance of the per-row PSD test of the detector pixel covariance (a little
#: stricter than footprint_uq._checks.check_cov's 1e-12 so that accepted rows always pass it)
PSD_TOL = 0.5e-12
#: row of each output column in the kernel's per-object block
_OBJ = {name: i for i, name in enumerate(OBJ_ROWS)}
#: kernel rows that must be finite in an "ok" row (centre and covariance) / a "partial" row (largest point)
_CENTRE_ROWS = [_OBJ[c] for c in ("x_m", "y_m", "cov_xx_m2", "cov_xy_m2", "cov_yy_m2", "sigma_major_m")]
_LARGEST_ROWS = [_OBJ[c] for c in ("largest_sigma_major_m", "largest_x_m", "largest_y_m")]
#: reason of a row whose numbers overflowed (inputs finite but absurd, e.g. a box at 1e300 px)
OVERFLOW_REASON = "result is not finite (overflow: input values far out of range)"
#: below this many rows a chunk is processed in one thread
_MIN_ROWS_PER_THREAD = 20_000
#: the motion columns of ``tracks=True`` (docs/batch.md), after the other columns; track_id is null where untracked
TRACK_COLUMNS = ("track_id", "v_east_mps", "v_north_mps", "cov_v_ee_m2ps2", "cov_v_en_m2ps2", "cov_v_nn_m2ps2",
                 "speed_mps", "sigma_speed_mps", "heading_deg", "sigma_heading_deg", "yaw_deg", "sigma_yaw_deg",
                 "age_s")


class Reasons:
    """Registry of reason strings -> small integer ids (stable over a whole job)."""

    def __init__(self):

        self.texts: list[str] = []
        self._ids: dict[str, int] = {}
        self._lock = threading.Lock()

    def id(self, text: str) -> int:
        i = self._ids.get(text)
        if i is None:
            with self._lock:
                i = self._ids.get(text)
                if i is None:
                    self.texts.append(text)
                    i = self._ids[text] = len(self.texts) - 1
        return i

    def dictionary(self) -> pa.Array:
        return pa.array(self.texts, type=pa.string())


def _kernel_releases_gil() -> bool:

    opts = getattr(fk.process_corners, "targetoptions", {}) or {}
    return bool(opts.get("nogil", False))


def _column_float(table: pa.Table, name: str) -> np.ndarray:
    """A numeric column as float64 numpy (nulls -> NaN)."""
    col = table.column(name)
    if not pa.types.is_float64(col.type):
        col = pc.cast(col, pa.float64())
    col = col.combine_chunks() if isinstance(col, pa.ChunkedArray) else col
    return col.to_numpy(zero_copy_only=False)


@dataclass
class _Result:
    """Per-row numbers of a chunk (full length; NaN / defaults on error rows)."""

    n: int
    K: int
    reason_id: np.ndarray
    status_id: np.ndarray
    obj: np.ndarray = field(default=None)  # (len(OBJ_ROWS), n) rows footprint_kernels.OBJ_ROWS
    largest_index: np.ndarray = field(default=None)
    v2x: np.ndarray = field(default=None)  # (7, n) rows V2X_FIELDS
    corners_px: np.ndarray = field(default=None)
    corners_xy: np.ndarray = field(default=None)
    corners_cov: np.ndarray = field(default=None)
    corner_reason: np.ndarray = field(default=None)
    corners_nl: np.ndarray = field(default=None)
    shared: np.ndarray = field(default=None)  # (n, 2, r) the centre's whitened parameter Jacobian (tracks)
    motion: dict = field(default=None)  # TRACK_COLUMNS -> (n,) arrays (tracks)


class BatchProcessor:
    """Turns tables of detections into footprint tables (see the module doc).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    box_type : {"2d", "3d", "corners"} or None
        None: detected from the columns of the first table.
    contact : {"bottom-centre", "bottom-corners"}
        Ground contact of 2D boxes (:func:`footprint_uq.products.footprints.box2d_contact_points`).
    confidence : float, optional
        Also write ``semi_major_m``/``semi_minor_m``, the ellipse at this probability (2-D).
    heading_offset_deg : float
        Compass bearing of W's +y axis (V2X fields, lat/lon).
    origin_lat_deg, origin_lon_deg : float, optional
        WGS84 position of W's origin: adds ``lat_deg``/``lon_deg`` (needs pyproj).
    corners : bool
        Add the per-corner columns ``c{k}_*``.
    allow_outside_image : bool
        Let corners outside the image enter the centre and the largest point.
    bottom_on_ground : bool
        3D boxes: put the bottom face on the ground (see :func:`footprints_from_boxes3d`).
    linearity : bool
        Compute the centre's linearity flag and write its columns (``nonlinearity``, ``linear_ok``,
        ``c{k}_nonlinearity``); False: no flag, the columns are absent and every V2X field is the
        linear one (``v2x_policy`` has nothing to act on).
    linear_threshold : float
        ``linear_ok = nonlinearity <= linear_threshold`` (default 0.05).
    v2x_policy : {"sampled", "unavailable", "linear"}
        The V2X fields of rows whose centre is not ``linear_ok`` (see
        :class:`~footprint_uq.footprints.FrameProcessor`, docs/batch.md).
    threads : int, optional
        Threads for the numeric kernel on large chunks (default: up to 2; used only
        when the compiled kernel releases the GIL).
    tracks : bool
        Track objects across frames (:mod:`footprint_uq.tracking`; needs the columns ``timestamp_s`` and
        ``object_id``; one track table per ``camera_id``) and add :data:`TRACK_COLUMNS`.  A frame is a run of
        consecutive rows with the same camera and time; each camera's frames must come in time order (rows of an
        earlier time than the camera's previous frame are not tracked).  Chunks then run in one thread.
    tracker : TrackerConfig, optional
        The tracker's options.
    """

    def __init__(self, camera, budget, *, box_type: str | None = None, contact: str = "bottom-centre",
                 confidence: float | None = None, heading_offset_deg: float = 0.0,
                 origin_lat_deg: float | None = None, origin_lon_deg: float | None = None, corners: bool = False,
                 allow_outside_image: bool = False, bottom_on_ground: bool = True,
                 linearity: bool = True, linear_threshold: float = 0.05, v2x_policy: str = "sampled",
                 threads: int | None = None, tracks: bool = False, tracker: TrackerConfig | None = None):
        if box_type is not None and box_type not in S.BOX_TYPES:
            raise InputError("box_type", box_type, f"one of {S.BOX_TYPES}")
        if contact not in CONTACT_MODES:
            raise InputError("contact", contact, f"one of {CONTACT_MODES}")
        self.camera = camera
        self.budget = load_budget(budget)
        self.box_type = box_type
        self.contact = contact
        self.confidence = None if confidence is None else float(confidence)
        self._k_conf = None if confidence is None else chi2_scale(confidence)
        self.heading_offset_deg = as_float("heading_offset_deg", heading_offset_deg)
        if (origin_lat_deg is None) != (origin_lon_deg is None):
            raise InputError("origin_lat_deg/origin_lon_deg", (origin_lat_deg, origin_lon_deg),
                             "both the latitude and the longitude of the origin, or neither")
        self.geo = None
        if origin_lat_deg is not None:

            self.geo = GeoReference(self.heading_offset_deg, origin_lat_deg, origin_lon_deg)
        self.corners = bool(corners)
        self.allow_outside_image = bool(allow_outside_image)
        self.bottom_on_ground = bool(bottom_on_ground)
        self.threads = max(1, min(2, os.cpu_count() or 1)) if threads is None else max(1, int(threads))
        self._parallel = self.threads > 1 and _kernel_releases_gil()
        self.proc = FrameProcessor(camera, self.budget, heading_offset_deg=self.heading_offset_deg,
                                   allow_outside_image=self.allow_outside_image, joint_cov=False,
                                   linearity=linearity, linear_threshold=linear_threshold, v2x_policy=v2x_policy)
        self.linearity = self.proc.linearity
        self.linear_threshold = self.proc.linear_threshold
        self.v2x_policy = v2x_policy
        # kernel outputs (FrameProcessor: pyarrow-pool memory, reused from chunk to chunk) become the
        # output columns without a copy; per-corner coordinates and covariances only when written
        self.proc.corner_outputs = self.corners or self.geo is not None
        self.reasons = Reasons()
        self._status_dict = pa.array(list(S.STATUSES), type=pa.string())
        self._pool = None
        self._layout = None  # (box_type, box columns, cov columns, id fields, K) fixed by the first table
        self.tracks = bool(tracks)
        self.tracker = tracker or TrackerConfig()
        #: the motion model per class: the budget's motion section over ``tracker`` (docs/motion-fit.md)
        self._track_configs = tracker_configs(getattr(self.budget, "motion", None), self.tracker)
        self._track_tables: dict = {}  # camera_id -> ClassTracks
        #: called after each frame's tracking step with ``(camera_id, time_s, classes, TrackOutput, xy_m (n, 2),
        #: cov_frame_m2 (n, 2, 2), shared_m (n, 2, r))`` (``calibrate motion`` feeds its likelihood bank from it)
        self.track_observer = None
        if self.tracks:
            self.proc.shared_jacobian = True
            self._shared_at = SharedJacobianAt(camera, self.budget)
            self._slide = ContactSlide.for_camera(camera)  # 2-D boxes' sliding contact (tracking/contact_slide.py)

    # -- layout -----------------------------------------------------------------------------------
    def resolve(self, names, id_fields: list[pa.Field] | None = None):
        """Fix the input layout from column names (first table); returns the output schema."""
        names = list(names)
        bt = self.box_type or S.detect_box_type(names)
        if bt is None:
            raise InputError("detections columns", sorted(names)[:12],
                             "exactly one complete box family: 2D (u_min_px, v_min_px, u_max_px, v_max_px), 3D "
                             "(x_m, y_m, z_m, length_m, width_m, height_m, yaw_rad|yaw_deg) or corners (u0_px, v0_px, "
                             "...) -- or give box_type")
        cols = S.box_columns(bt, names)
        missing = [c for c in cols if c not in names]
        if bt == "corners" and not cols:
            raise InputError("detections columns", sorted(names)[:12], "corner columns u0_px, v0_px, u1_px, ...")
        if bt == "3d" and not any(y in names for y in S.YAW_COLUMNS):
            missing = [c for c in missing if c != "yaw_deg"] + ["yaw_rad or yaw_deg"]
        if missing:
            raise InputError("detections columns", f"missing {missing}", f"the {bt} box columns {list(cols)}")
        cov = tuple(c for c in S.COV_COLUMNS if c in names)
        if cov and len(cov) != 3:
            raise InputError("detections columns", f"only {list(cov)}",
                             f"all three pixel covariance columns {list(S.COV_COLUMNS)} or none")
        if bt == "2d":
            K = 1 if self.contact == "bottom-centre" else 2
        elif bt == "3d":
            K = 4
        else:
            K = len(cols) // 2
        if id_fields is None:
            id_fields = [pa.field(c, S.ID_TYPES[c]) for c in S.ID_COLUMNS if c in names]
        self.box_type = bt
        self._layout = (bt, cols, cov, list(id_fields), K)
        self.schema = S.output_schema(list(id_fields), K, confidence=self._k_conf is not None,
                                      geo=self.geo is not None, corners=self.corners, linearity=self.linearity)
        if self.tracks:
            need = [c for c in ("timestamp_s", "object_id") if c not in names]
            if need:
                raise InputError("detections columns", f"missing {need}", "timestamp_s and object_id for tracks")
            for name in TRACK_COLUMNS:
                self.schema = self.schema.append(pa.field(name, pa.int64() if name == "track_id" else pa.float64()))
        return self.schema

    @property
    def n_corners(self) -> int:
        return self._layout[4]

    # -- validation ---------------------------------------------------------------------------------
    def _validate(self, X: np.ndarray, cov: np.ndarray | None, reason_id: np.ndarray) -> None:
        """Set ``reason_id`` (in place, -1 = fine) of rows that cannot be processed."""
        bt, cols, covcols, _, _ = self._layout
        fin = np.isfinite(X)
        if not fin.all():
            for j, name in enumerate(cols):
                bad = ~fin[:, j] & (reason_id < 0)
                if bad.any():
                    reason_id[bad] = self.reasons.id(f"missing or non-finite field {name}")
        if bt == "2d":
            with np.errstate(invalid="ignore"):
                for lo, hi in ((0, 2), (1, 3)):
                    bad = (X[:, hi] < X[:, lo]) & (reason_id < 0)
                    if bad.any():
                        reason_id[bad] = self.reasons.id(f"inverted box: {cols[hi]} < {cols[lo]}")
        elif bt == "3d":
            with np.errstate(invalid="ignore"):
                for j in (3, 4, 5):
                    bad = (X[:, j] < 0) & (reason_id < 0)
                    if bad.any():
                        reason_id[bad] = self.reasons.id(f"negative size {cols[j]} (expected >= 0)")
        if cov is not None:
            a, b, d = cov[:, 0], cov[:, 1], cov[:, 2]
            nan = np.isnan(cov)
            none = nan.all(1)
            part = nan.any(1) & ~none & (reason_id < 0)
            if part.any():
                reason_id[part] = self.reasons.id("incomplete pixel covariance: give cov_uu_px2, cov_uv_px2 and "
                                                  "cov_vv_px2, or none of them")
            inf = ~none & ~nan.any(1) & ~np.isfinite(cov).all(1) & (reason_id < 0)
            if inf.any():
                reason_id[inf] = self.reasons.id("pixel covariance is not finite")
            with np.errstate(invalid="ignore"):
                scale = np.maximum(np.maximum(np.abs(a), np.abs(d)), np.abs(b))
                lmin = 0.5 * (a + d) - np.hypot(0.5 * (a - d), b)
                bad = ~(lmin >= -PSD_TOL * scale) & ~nan.any(1) & np.isfinite(cov).all(1) & (reason_id < 0)
            if bad.any():
                reason_id[bad] = self.reasons.id("pixel covariance (cov_uu_px2, cov_uv_px2, cov_vv_px2) is not "
                                                 "positive semi-definite")
            with np.errstate(invalid="ignore"):
                big = (scale > MAX_PIXEL_VAR_PX2) & (reason_id < 0)
            if big.any():
                reason_id[big] = self.reasons.id(f"pixel covariance out of range (entries above "
                                                 f"{MAX_PIXEL_VAR_PX2:g} px^2)")

    # -- the kernel --------------------------------------------------------------------------------
    def _kernel(self, X: np.ndarray, P: np.ndarray | None):
        bt = self._layout[0]
        if bt == "2d":  # the contact points of box2d_contact_points, formed here without a matrix product
            if self.contact == "bottom-centre":
                uv = np.empty((X.shape[0], 1, 2))
                uv[:, 0, 0] = 0.5 * X[:, 0] + 0.5 * X[:, 2]
                uv[:, 0, 1] = X[:, 3]
            else:
                uv = np.empty((X.shape[0], 2, 2))
                uv[:, 0, 0], uv[:, 1, 0] = X[:, 0], X[:, 2]
                uv[:, 0, 1] = uv[:, 1, 1] = X[:, 3]
            return self.proc.corners(uv, pixel_cov_px2=P)
        if bt == "3d":
            yaw_unit = "deg" if self._layout[1][-1] == "yaw_deg" else "rad"
            return self.proc.boxes3d(X, yaw_unit=yaw_unit, bottom_on_ground=self.bottom_on_ground, pixel_cov_px2=P)
        return self.proc.corners(X.reshape(X.shape[0], -1, 2), pixel_cov_px2=P)

    def compute(self, X: np.ndarray, cov: np.ndarray | None, reason_id: np.ndarray) -> _Result:
        """Numbers of one chunk: ``X`` (n, m) box columns, ``cov`` (n, 3) or None, ``reason_id`` (n,) pre-errors."""
        n = X.shape[0]
        self._validate(X, cov, reason_id)
        good = reason_id < 0
        all_good = bool(good.all())
        Xg = X if all_good else X[good]
        P = None
        if cov is not None:
            cg = cov if all_good else cov[good]
            cg = np.where(np.isnan(cg).all(1, keepdims=True), 0.0, cg)  # no detector covariance: budget only
            if np.any(cg):
                P = np.empty((cg.shape[0], 2, 2))
                P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = cg[:, 0], cg[:, 1], cg[:, 1], cg[:, 2]
        res = _Result(n=n, K=self.n_corners, reason_id=reason_id, status_id=np.full(n, 2, dtype=np.int32))
        est = self._kernel(Xg, P) if Xg.shape[0] else None
        creason, cbad, corner_reason = self._gather(res, est, good, all_good)
        partial, failed = self._set_status(res, good, creason, corner_reason, reason_id)
        for mask, prefix in ((partial, "no centre: "), (failed, "no usable corner: ")):
            if mask.any():
                reason_id[mask] = self._failure_reason_ids(prefix, creason[mask], cbad[mask], corner_reason[mask])
        return res

    def _gather(self, res: _Result, est, good: np.ndarray, all_good: bool):
        """The kernel's results for the ``good`` rows spread into ``res`` (n rows, fills elsewhere).

        Returns ``(centre reason, centre's bad corner, corner reasons)`` of every row.
        """
        n, K = res.n, res.K

        def gather(attr, shape_tail, fill, dtype=np.float64):
            if est is not None and all_good:
                return getattr(est, attr)
            out = np.full((n,) + shape_tail, fill, dtype=dtype)
            if est is not None:
                out[good] = getattr(est, attr)
            return out

        def gather_rows(block, nrows, fill, dtype):  # (nrows, n) blocks of the kernel's per-object rows
            if est is not None and all_good:
                return block
            out = np.full((nrows, n), fill, dtype=dtype)
            if est is not None:
                out[:, good] = block
            return out

        res.obj = gather_rows(est.object_rows if est is not None else None, len(OBJ_ROWS), np.nan, np.float64)
        res.largest_index = gather("largest_index", (), -1, np.int64)
        res.v2x = gather_rows(est.v2x_codes.T if est is not None else None, len(V2X_FIELDS), 0, np.int32)
        if not all_good:
            unavailable = np.array([S.V2X_UNAVAILABLE[f] for f in V2X_FIELDS], dtype=np.int32)
            res.v2x[:, ~good] = unavailable[:, None]
        creason = gather("centre_reason", (), -1, np.int32)
        cbad = gather("centre_bad_corner", (), -1, np.int64)
        corner_reason = gather("corner_reason", (K,), st.NOT_FINITE, np.int8)
        if self.corners or self.geo is not None:
            res.corners_px = gather("corners_px", (K, 2), np.nan)
            res.corners_xy = gather("corners_xy_world_m", (K, 2), np.nan)
            res.corners_cov = gather("corners_cov_m2", (K, 2, 2), np.nan)
            if self.linearity:
                res.corners_nl = gather("corners_nonlinearity", (K,), np.nan)
            res.corner_reason = corner_reason
        if self.tracks:
            res.shared = gather("centre_shared_m", (2, self._shared_at.rank), np.nan)
        return creason, cbad, corner_reason

    def _set_status(self, res: _Result, good, creason, corner_reason, reason_id) -> tuple[np.ndarray, np.ndarray]:
        """Status and reason of the processed rows (``ok``, ``partial``, overflow); returns the masks of the
        partial and the failed rows, whose reasons :meth:`_failure_reason_ids` gives."""
        # outputs are checked too: a centre, covariance or largest point that overflowed (absurd but finite
        # inputs) is never "ok"/"partial"
        n = res.n
        o = res.obj
        with np.errstate(invalid="ignore"):
            centre_fin = np.isfinite(o[_CENTRE_ROWS]).all(0) if n else np.zeros(0, bool)
            largest_fin = np.isfinite(o[_LARGEST_ROWS]).all(0) if n else np.zeros(0, bool)
        centre_ok = good & (creason == st.OK)
        ok = centre_ok & centre_fin
        partial = good & ~centre_ok & (res.largest_index >= 0) & largest_fin
        overflow = (centre_ok & ~centre_fin) | (good & ~centre_ok & (res.largest_index >= 0) & ~largest_fin)
        # the frame processor's own output check (OVERFLOW codes) leaving nothing usable: an overflow too
        overflow |= good & ~ok & ~partial & ((creason == st.OVERFLOW) | (corner_reason == st.OVERFLOW).any(1))
        failed = good & ~ok & ~partial & ~overflow
        res.status_id[ok] = 0
        res.status_id[partial] = 1
        if ok.any():
            reason_id[ok] = self.reasons.id("ok")
        if overflow.any():
            reason_id[overflow] = self.reasons.id(OVERFLOW_REASON)
            res.obj = o = np.array(o, copy=True) if o is not None and not o.flags.writeable else o
            o[:, overflow] = np.nan
            res.largest_index = np.where(overflow, -1, res.largest_index)
            unavailable = np.array([S.V2X_UNAVAILABLE[f] for f in V2X_FIELDS], dtype=np.int32)
            res.v2x = np.array(res.v2x, copy=True) if not res.v2x.flags.writeable else res.v2x
            res.v2x[:, overflow] = unavailable[:, None]
        return partial, failed

    def _failure_reason_ids(self, prefix: str, creason, cbad, corner_reason) -> np.ndarray:
        """Reason ids of rows without a centre (``prefix`` "no centre: ") or without any usable corner
        ("no usable corner: "; summarised when every corner has the same code); one text per distinct case."""
        K = self.n_corners
        key = creason.astype(np.int64) * 64 + (cbad + 1)
        if prefix == "no usable corner: ":  # summarise: every corner's code the same?
            same = (corner_reason == corner_reason[:, :1]).all(1)
            key = np.where(same, -1 - corner_reason[:, 0].astype(np.int64), key)
        uk, inv = np.unique(key, return_inverse=True)
        ids = np.empty(uk.size, dtype=np.int32)
        for i, k in enumerate(uk.tolist()):
            if k < 0:
                text = f"all {K} corners: {st.REASONS[-1 - k]}" if K > 1 else st.REASONS[-1 - k]
            else:
                code, bad = divmod(k, 64)
                if code == DEGENERATE:
                    text = st.REASONS[DEGENERATE]
                else:
                    text = f"corner {bad - 1} of {K}: {st.REASONS[code]}"
            ids[i] = self.reasons.id(prefix + text)
        return ids[inv]

    # -- tables -----------------------------------------------------------------------------------
    def inputs_from_table(self, table: pa.Table):
        """``(X, cov)`` float64 arrays of a table's box and covariance columns (nulls -> NaN)."""
        _, cols, covcols, _, _ = self._layout
        X = np.empty((len(cols), table.num_rows)).T  # column-major: each column is one contiguous copy
        for j, c in enumerate(cols):
            X[:, j] = _column_float(table, c)
        cov = None
        if covcols:
            cov = np.empty((table.num_rows, 3))
            for j, c in enumerate(covcols):
                cov[:, j] = _column_float(table, c)
        return X, cov

    def process(self, table, *, rows=None, pre_errors=None) -> pa.Table:
        """Footprints of one table of detections.

        Parameters
        ----------
        table : pyarrow.Table or dict of arrays
            Detections (columns: :mod:`footprint_uq.batch.schema`).
        rows : array_like (n,) of int, optional
            Input row index of each table row (default ``0 .. n-1``).
        pre_errors : sequence (n,) of str or None, optional
            Rows already known to be bad (e.g. a value that is not a number), with the reason.

        Returns
        -------
        pyarrow.Table with :attr:`schema`, one row per input row, in the same order.
        """
        if not isinstance(table, pa.Table):
            table = pa.table({k: np.asarray(v) if not isinstance(v, pa.Array | pa.ChunkedArray) else v
                              for k, v in dict(table).items()})
        if self._layout is None:
            self.resolve(table.column_names)
        n = table.num_rows
        rows = np.arange(n, dtype=np.int64) if rows is None else np.asarray(rows, dtype=np.int64)
        if rows.shape != (n,):
            raise InputError("rows", rows.shape, f"one row index per table row ({n},)")
        reason_id = np.full(n, -1, dtype=np.int32)
        if pre_errors is not None:
            for i, text in enumerate(pre_errors):
                if text is not None:
                    reason_id[i] = self.reasons.id(text)
        if not self._parallel or n < 2 * _MIN_ROWS_PER_THREAD or self.tracks:
            return self._process_part(table, rows, reason_id)
        # large chunk: contiguous parts in threads (the kernel releases the GIL), then one table
        edges = [n * i // self.threads for i in range(self.threads + 1)]
        if self._pool is None:
            self._pool = ThreadPoolExecutor(self.threads, thread_name_prefix="footprint-uq-batch")
        futs = [self._pool.submit(self._process_part, table.slice(a, b - a), rows[a:b], reason_id[a:b])
                for a, b in zip(edges[:-1], edges[1:], strict=True)]
        parts = [f.result() for f in futs]
        # the reason ids are global; give every part the final dictionary
        d = self.reasons.dictionary()
        j = self.schema.get_field_index("reason")
        parts = [p.set_column(j, self.schema.field(j), pa.chunked_array(
            [pa.DictionaryArray.from_arrays(c.indices, d) for c in p.column(j).chunks], type=S.REASON_TYPE))
            for p in parts]
        return pa.concat_tables(parts)

    def _process_part(self, table: pa.Table, rows: np.ndarray, reason_id: np.ndarray) -> pa.Table:
        X, cov = self.inputs_from_table(table)
        res = self.compute(X, cov, reason_id)
        if self.tracks:
            res.motion = self._track(res, table, X)
        return self.to_table(res, table, rows)

    def _track(self, res: _Result, table: pa.Table, X: np.ndarray) -> dict:
        """The motion columns of a chunk: its frames (runs of rows with the same camera and time) in order,
        each through its camera's tracks (:class:`~footprint_uq.tracking.classes.ClassTracks`: a
        :class:`~footprint_uq.tracking.table.TrackTable` per motion model of the budget's motion section)."""
        n = res.n
        t = _column_float(table, "timestamp_s")
        ids = _track_ids(table.column("object_id"))
        cams = table.column("camera_id").to_pylist() if "camera_id" in table.column_names else [None] * n
        classes = table.column("class").to_pylist() if "class" in table.column_names else [None] * n
        o = res.obj
        xy = np.ascontiguousarray(o[[_OBJ["x_m"], _OBJ["y_m"]]].T)
        cov = o[[_OBJ["cov_xx_m2"], _OBJ["cov_xy_m2"], _OBJ["cov_yx_m2"], _OBJ["cov_yy_m2"]]].T.reshape(n, 2, 2)
        B = res.shared
        cov_frame = cov - B @ np.swapaxes(B, -1, -2)
        cam_arr = np.array(cams, dtype=object)
        cut = np.flatnonzero((t[1:] != t[:-1]) | (cam_arr[1:] != cam_arr[:-1])) + 1 if n else np.zeros(0, np.int64)
        pieces = []
        for a, b in zip(np.r_[0, cut].tolist(), np.r_[cut, n].tolist(), strict=True):
            table_c = self._track_tables.get(cams[a])
            if table_c is None:
                table_c = self._track_tables[cams[a]] = ClassTracks(*self._track_configs, rank=self._shared_at.rank,
                                                                    shared_at=self._shared_at)
            if not np.isfinite(t[a]):  # no time: not tracked
                pieces.append(TrackOutput.untracked(b - a))
                continue
            pieces.append(table_c.step(t[a], ids[a:b], classes[a:b], xy[a:b], cov_frame[a:b], B[a:b]))
            if self.track_observer is not None:
                self.track_observer(cams[a], t[a], classes[a:b], pieces[-1], xy[a:b], cov_frame[a:b], B[a:b])
        tout = TrackOutput(*[np.concatenate(f) for f in zip(*pieces, strict=True)]) if pieces else None
        yaw = None
        if self.box_type == "3d" and n:
            yaw = X[:, 6] if self._layout[1][-1] == "yaw_rad" else np.deg2rad(X[:, 6])
        if tout is None:
            return {name: np.zeros(0, np.int64 if name == "track_id" else np.float64) for name in TRACK_COLUMNS}
        if self.box_type == "2d" and self._slide is not None:
            tout = self._slide.apply(tout, classes)
        m = object_motion(tout, heading_offset_deg=self.heading_offset_deg, yaw_rad=yaw)
        c = m.cov_v_m2ps2
        return dict(zip(TRACK_COLUMNS, (tout.track_id, m.v_east_mps, m.v_north_mps, c[:, 0, 0], c[:, 0, 1], c[:, 1, 1],
                                        m.speed_mps, m.sigma_speed_mps, m.heading_deg, m.sigma_heading_deg, m.yaw_deg,
                                        m.sigma_yaw_deg, m.age_s), strict=True))

    def to_table(self, res: _Result, table: pa.Table, rows: np.ndarray) -> pa.Table:
        """Assemble the output table of :meth:`compute`'s numbers."""
        _, _, _, id_fields, K = self._layout
        n = res.n
        cols: dict[str, object] = {"row": pa.array(rows, type=pa.int64())}
        for f in id_fields:
            if f.name in table.column_names:
                col = table.column(f.name)
                cols[f.name] = col if col.type == f.type else pc.cast(col, f.type)
            else:
                cols[f.name] = pa.nulls(n, type=f.type)
        cols["status"] = pa.DictionaryArray.from_arrays(pa.array(res.status_id, type=pa.int32()), self._status_dict)
        cols["reason"] = pa.DictionaryArray.from_arrays(pa.array(res.reason_id, type=pa.int32()),
                                                        self.reasons.dictionary())
        obj = res.obj  # rows OBJ_ROWS, each one contiguous: the columns need no copy
        for name in S.CENTRE_COLUMNS:
            cols[name] = obj[_OBJ[name]]
        if self._k_conf is not None:
            cols["semi_major_m"] = self._k_conf * obj[_OBJ["sigma_major_m"]]
            cols["semi_minor_m"] = self._k_conf * obj[_OBJ["sigma_minor_m"]]
        if self.linearity:
            nl = obj[_OBJ["nonlinearity"]]
            cols["nonlinearity"] = nl
            with np.errstate(invalid="ignore"):
                cols["linear_ok"] = nl <= self.linear_threshold  # NaN (no centre) -> False
        cols["largest_index"] = res.largest_index.astype(np.int8)
        for name in ("largest_sigma_major_m", "largest_x_m", "largest_y_m", "area_m2"):
            cols[name] = obj[_OBJ[name]]
        for j, name in enumerate(V2X_FIELDS):
            cols[name] = res.v2x[j]
        if self.geo is not None:
            cols["lat_deg"], cols["lon_deg"] = self.geo.to_wgs84(np.ascontiguousarray(obj[0:2].T))
        if self.corners:
            if self.geo is not None:
                clat, clon = self.geo.to_wgs84(res.corners_xy)
            for k in range(K):
                cols[f"c{k}_u_px"], cols[f"c{k}_v_px"] = res.corners_px[:, k, 0], res.corners_px[:, k, 1]
                cols[f"c{k}_x_m"], cols[f"c{k}_y_m"] = res.corners_xy[:, k, 0], res.corners_xy[:, k, 1]
                cc = res.corners_cov[:, k]
                cols[f"c{k}_cov_xx_m2"], cols[f"c{k}_cov_xy_m2"], cols[f"c{k}_cov_yy_m2"] = (cc[:, 0, 0], cc[:, 0, 1],
                                                                                           cc[:, 1, 1])
                if self.linearity:
                    cols[f"c{k}_nonlinearity"] = res.corners_nl[:, k]
                cols[f"c{k}_reason"] = res.corner_reason[:, k].astype(np.int8)
                if self.geo is not None:
                    cols[f"c{k}_lat_deg"], cols[f"c{k}_lon_deg"] = clat[:, k], clon[:, k]
        if self.tracks:
            mo = res.motion if res.motion is not None else {  # (the malformed rows' table: never tracked)
                name: np.full(n, -1 if name == "track_id" else np.nan) for name in TRACK_COLUMNS}
            cols.update(mo)
            cols["track_id"] = pa.array(mo["track_id"].astype(np.int64), type=pa.int64(), mask=mo["track_id"] < 0)
        arrays = []
        for f in self.schema:
            v = cols[f.name]
            if isinstance(v, np.ndarray):
                v = pa.array(np.ascontiguousarray(v), type=f.type)
            arrays.append(v)
        return pa.Table.from_arrays(arrays, schema=self.schema)

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown()
            self._pool = None


def process_table(camera, budget, table, **options) -> pa.Table:
    """Footprints of one table of detections (a frame, a chunk, a partition).

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    table : pyarrow.Table or dict of arrays
        Detections; columns in :mod:`footprint_uq.batch.schema` / ``docs/batch.md``.
    **options
        ``rows``, ``pre_errors`` (see :meth:`BatchProcessor.process`) and the keyword
        arguments of :class:`BatchProcessor` (``box_type``, ``contact``, ``confidence``,
        ``heading_offset_deg``, ``origin_lat_deg``, ``origin_lon_deg``, ``corners``,
        ``allow_outside_image``, ``bottom_on_ground``, ``threads``).

    Returns
    -------
    pyarrow.Table
        One row per input row (same order), columns :func:`footprint_uq.batch.schema.output_schema`.

    Examples
    --------
    >>> out = process_table(cam, "basler1", {"u_min_px": [900.0], "v_min_px": [500.0],
    ...                                      "u_max_px": [980.0], "v_max_px": [560.0]})
    >>> out.column("x_m"), out.column("cov_xx_m2"), out.column("status")
    """
    rows = options.pop("rows", None)
    pre_errors = options.pop("pre_errors", None)
    bp = BatchProcessor(camera, budget, **options)
    try:
        return bp.process(table, rows=rows, pre_errors=pre_errors)
    finally:
        bp.close()


# -- files ---------------------------------------------------------------------------------------------
@dataclass
class Summary:
    """Row accounting of a batch job (``rows_in == rows_out == rows_ok + rows_partial + rows_error``).

    ``reasons`` counts the rows of every reason other than "ok".  ``to_dict()`` is what the
    JSON summary file holds; ``text()`` the line printed on stderr.
    """

    rows_in: int = 0
    rows_out: int = 0
    rows_ok: int = 0
    rows_partial: int = 0
    rows_error: int = 0
    reasons: dict = field(default_factory=dict)
    elapsed_s: float = 0.0
    info: dict = field(default_factory=dict)
    #: physical lines of a CSV (after the header) or JSON Lines input, counted apart from the parser
    lines_in: int | None = None

    @property
    def rows_with_errors(self) -> int:
        return self.rows_error

    def add_table(self, out: pa.Table, rows_in: int) -> None:
        """Count one output table (``rows_in`` input rows gave it)."""
        self.rows_in += int(rows_in)
        self.rows_out += out.num_rows
        per = _value_counts(out.column("status"))
        unknown = set(per) - set(S.STATUSES)
        if unknown:  # pragma: no cover - a bug
            raise RuntimeError(f"unknown status {sorted(unknown)}")
        self.rows_ok += per.get(S.STATUS_OK, 0)
        self.rows_partial += per.get(S.STATUS_PARTIAL, 0)
        self.rows_error += per.get(S.STATUS_ERROR, 0)
        for text, c in _value_counts(out.column("reason")).items():
            if text != "ok":
                self.reasons[text] = self.reasons.get(text, 0) + c

    def merge(self, other: Summary) -> None:
        for name in ("rows_in", "rows_out", "rows_ok", "rows_partial", "rows_error"):
            setattr(self, name, getattr(self, name) + getattr(other, name))
        for k, v in other.reasons.items():
            self.reasons[k] = self.reasons.get(k, 0) + v

    @property
    def consistent(self) -> bool:
        lines_ok = self.lines_in is None or self.lines_in == self.rows_in
        return lines_ok and self.rows_in == self.rows_out == self.rows_ok + self.rows_partial + self.rows_error

    def to_dict(self) -> dict:
        lines = {} if self.lines_in is None else {"lines_in": self.lines_in}
        return {**lines, "rows_in": self.rows_in, "rows_out": self.rows_out, "rows_ok": self.rows_ok,
                "rows_partial": self.rows_partial, "rows_error": self.rows_error,
                "rows_with_errors": self.rows_error, "consistent": self.consistent,
                "reasons": dict(sorted(self.reasons.items(), key=lambda kv: -kv[1])),
                "elapsed_s": round(self.elapsed_s, 6),
                "rows_per_s": (round(self.rows_in / self.elapsed_s, 1) if self.elapsed_s > 0 else None),
                **self.info}

    def text(self) -> str:
        return (f"rows in {self.rows_in}, rows out {self.rows_out} (ok {self.rows_ok}, partial {self.rows_partial}), "
                f"rows with errors {self.rows_error}")


def _value_counts(col) -> dict[str, int]:
    """Counts of the values of a (chunked) string or dictionary column."""
    counts: dict[str, int] = {}
    chunks = col.chunks if isinstance(col, pa.ChunkedArray) else [col]
    for c in chunks:
        if not pa.types.is_dictionary(c.type):
            c = pc.dictionary_encode(c)
        texts = c.dictionary.to_pylist()
        for i, k in enumerate(np.bincount(c.indices.to_numpy(zero_copy_only=False), minlength=len(texts)).tolist()):
            if k:
                counts[texts[i]] = counts.get(texts[i], 0) + k
    return counts


def summary_path(out) -> Path:
    """Where :func:`process_file` writes the JSON summary: next to the output, ``<out>.summary.json``."""
    out = Path(out)
    return out.with_name(out.name + ".summary.json")


def prefetch(iterable, depth: int = 1):
    """Iterate ``iterable`` in a background thread, ``depth`` items ahead (pyarrow decodes without the GIL)."""

    q: queue.Queue = queue.Queue(maxsize=max(1, depth))
    done = object()
    stop = threading.Event()

    def run():
        try:
            for item in iterable:
                if stop.is_set():
                    return
                q.put((item, None))
            q.put((done, None))
        except BaseException as e:  # noqa: BLE001 - re-raised in the consumer
            q.put((done, e))

    th = threading.Thread(target=run, name="footprint-uq-reader", daemon=True)
    th.start()
    try:
        while True:
            item, err = q.get()
            if item is done:
                if err is not None:
                    raise err
                return
            yield item
    finally:
        stop.set()
        while th.is_alive():  # unblock the producer
            try:
                q.get_nowait()
            except queue.Empty:
                th.join(0.05)


def _malformed_table(bp: BatchProcessor, malformed: list) -> pa.Table:
    """Error rows for unparseable input lines (no values, only row number and reason)."""
    n = len(malformed)
    rows = np.array([m[0] for m in malformed], dtype=np.int64)
    reason_id = np.array([bp.reasons.id(m[1]) for m in malformed], dtype=np.int32)
    X = np.full((n, len(bp._layout[1])), np.nan)
    res = bp.compute(X, None, reason_id)
    return bp.to_table(res, pa.table({}), rows)


def process_chunk(bp: BatchProcessor, chunk) -> pa.Table:
    """Output table of one :class:`~footprint_uq.batch.readers.Chunk` (rows in input order)."""
    out = bp.process(chunk.table, rows=chunk.rows, pre_errors=chunk.pre_errors)
    if chunk.malformed:
        out = pa.concat_tables([out, _malformed_table(bp, chunk.malformed)])
        out = out.take(pc.sort_indices(out.column("row")))
    return out


def _check_out_file(out, detections) -> None:
    """``out`` (and its summary) must be a file path other than the detections."""
    for p in (out, summary_path(out)):
        if same_file(p, detections):
            raise InputError("out", str(p), "a file other than the detections (this is the same file)")
    if Path(out).is_dir():
        raise InputError("out", str(out), "a file path (this is a folder)")


def _stream_to_file(reader, bp, out, schema, bar, *, fmt_out: str, compression, fsync: bool,
                    summary: bool, writer_factory=None) -> Summary:
    """Process every chunk of ``reader`` into ``out`` (read ahead, one write in flight in a background
    thread); the file is committed only when every row is accounted for."""
    summ = Summary()
    pool = _Pool(1, thread_name_prefix="footprint-uq-writer")
    pending = None
    writer = None
    try:
        writer = open_writer(out, schema, format=fmt_out, compression=compression, fsync=fsync, georef=bp.geo,
                             ellipse_confidence=bp.confidence or 0.95) \
            if writer_factory is None else writer_factory(out, schema, fsync=fsync)
        for chunk in prefetch(iter(reader), 1):
            table = process_chunk(bp, chunk)
            summ.add_table(table, chunk.table.num_rows + len(chunk.malformed))
            if pending is not None:
                pending.result()
            pending = pool.submit(writer.write, table)
            bar.update(chunk.progress)
        if pending is not None:
            pending.result()
        summ.lines_in = reader.lines
        if not summ.consistent:  # pragma: no cover - a bug, not bad input
            raise RuntimeError(f"row accounting broken: {summ.text()} (lines in {summ.lines_in})")
        # the previous summary goes first: a summary never stands beside another output than its own
        writer.before_commit = (lambda: summary_path(out).unlink(missing_ok=True)) if summary else None
        writer.close()
        summ.info.update(writer.info())
    except BaseException:
        pool.shutdown(wait=True)  # an in-flight write finishes before its file is dropped
        if writer is not None:
            writer.abort()
        raise
    finally:
        pool.shutdown()
    return summ


def _file_info(detections, out, reader, fmt_out: str, bp, fsync: bool, info: dict | None) -> dict:
    """The ``info`` entries of a file job's summary (inputs, formats, options, origin, budget)."""
    names = getattr(reader, "names", None)
    return {"detections": str(detections), "out": str(out), "format_in": reader.format, "format_out": fmt_out,
            "class_names": getattr(names, "source", None),
            "box_type": bp.box_type, "contact": bp.contact if bp.box_type == "2d" else None,
            "n_corners": bp.n_corners, "confidence": bp.confidence, "heading_offset_deg": bp.heading_offset_deg,
            "origin": None if bp.geo is None else {
                "origin_lat_deg": bp.geo.origin_lat_deg, "origin_lon_deg": bp.geo.origin_lon_deg,
                "heading_offset_deg": bp.geo.heading_offset_deg}, "chunk_rows": reader.chunk_rows,
            "budget": bp.budget.name if hasattr(bp.budget, "name") else None, "fsync": bool(fsync), **(info or {})}


def process_file(camera, budget, detections, out, *, chunk_rows: int = S.DEFAULT_CHUNK_ROWS,
                 format_in: str | None = None, format_out: str | None = None, progress: bool | None = None,
                 summary: bool = True, compression: str | None = "auto", info: dict | None = None,
                 fsync: bool = True, reader=None, writer_factory=None, class_names=None, unknown_class: str = "error",
                 **options) -> Summary:
    """Stream a detection file through the footprint pipeline, chunk by chunk.

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    detections : path
        CSV (``.csv``), JSON Lines (``.jsonl``/``.ndjson``) or Parquet (``.parquet``/``.pq``), or a detector
        format (:mod:`footprint_uq.batch.formats`: YOLO labels, YOLOv5 CSV, COCO results, MOTChallenge).
    out : path
        ``.parquet``/``.pq``, ``.csv``, ``.jsonl``/``.ndjson`` or ``.geojson`` (needs an origin).
    chunk_rows : int
        Rows per chunk; memory use is proportional to it, not to the file size
        (peak about 0.35 GB + 0.8 kB x chunk_rows, see docs/batch.md).
    progress : bool, optional
        tqdm progress bar on stderr (default: only when stderr is a terminal).
    summary : bool
        Write the JSON summary to :func:`summary_path` (``<out>.summary.json``).
    compression : str or None
        Parquet compression: "auto" (snappy, the small-integer code columns uncompressed: see
        :func:`footprint_uq.batch.writers.parquet_options`), or one codec for every column
        ("snappy", "zstd", "lz4", "gzip"; None or "none": uncompressed).
    info : dict, optional
        Extra entries of the summary (e.g. the camera and budget files of the CLI).
    fsync : bool
        Make the output durable: every chunk is flushed to the disk as it is written and the file and its
        folder are fsynced before the rename (default).  False only renames: the output is still never
        partial under its name for a killed job, but a power loss or an operating-system crash may leave
        it empty or missing (scratch outputs, tmpfs; saves the disk write on the job's critical path).
    format_in : str, optional
        One of :data:`footprint_uq.batch.formats.INPUT_FORMATS` (default: detected from the file).
    class_names, unknown_class
        Integer class ids -> names (:func:`footprint_uq.batch.formats.open_reader`).  Normalised boxes are
        scaled to the camera's image size; a file stating another image size is refused.
    reader : optional
        A reader of another source than a detection file (the interface of
        :class:`~footprint_uq.batch.readers.DetectionReader`: ``columns``, ``family_columns``, ``id_fields``,
        ``select``, iteration over :class:`~footprint_uq.batch.readers.Chunk`; e.g. a ROS 2 bag's,
        :mod:`footprint_uq.integrations.ros2.bag_reader`); ``detections`` then only names it.
    writer_factory : callable, optional
        ``(out, schema, fsync=) -> FootprintWriter`` for another output than the file formats (e.g. a ROS 2 bag,
        :func:`footprint_uq.integrations.ros2.bag_writer.bag_writer_factory`); its ``info()`` joins the summary.
    **options
        Keyword arguments of :class:`BatchProcessor`.

    Returns
    -------
    Summary
    """

    t0 = time.perf_counter()
    fmt_out = detect_out_format(out, format_out) if writer_factory is None else \
        getattr(writer_factory, "format", "custom")
    if fmt_out == "geojson":
        if options.get("origin_lat_deg") is None:
            raise InputError("out", str(out), "an origin (--origin-lat/--origin-lon) for GeoJSON output: GeoJSON "
                             "coordinates are WGS84 longitude/latitude")
        options["corners"] = True  # the polygon
    if reader is None:
        reader = open_reader(detections, chunk_rows=chunk_rows, format=format_in, class_names=class_names,
                             unknown_class=unknown_class, image_size_px=camera.image_size_px)
    bp = BatchProcessor(camera, budget, **options)
    names = reader.columns if bp.box_type is not None else reader.family_columns  # JSON Lines: one rule per family
    schema = bp.resolve(names, reader.id_fields)
    reader.select(S.numeric_input_columns(bp.box_type, names))
    if writer_factory is None:
        _check_out_file(out, detections)
    elif same_file(out, detections):
        raise InputError("out", str(out), "another path than the detections (this is the same)")
    show = sys.stderr.isatty() if progress is None else bool(progress)
    bar = tqdm(total=reader.total, unit=reader.unit, unit_scale=True, disable=not show, file=sys.stderr,
               desc="footprints", leave=False)
    try:
        summ = _stream_to_file(reader, bp, out, schema, bar, fmt_out=fmt_out, compression=compression,
                               fsync=fsync, summary=summary, writer_factory=writer_factory)
    finally:
        bar.close()
        bp.close()
    summ.elapsed_s = time.perf_counter() - t0
    summ.info = {**_file_info(detections, out, reader, fmt_out, bp, fsync, info), **summ.info}
    if summary:
        atomic_write_text(summary_path(out), json.dumps(summ.to_dict(), indent=2) + "\n", fsync=fsync)
    return summ


def _track_ids(column: pa.ChunkedArray):
    """A chunk's object ids for the tracker: an integer column without nulls as one int64 array (each frame's
    slice of it goes to the table's compiled id look-up as it is, not a list made an array again frame by frame),
    anything else -- text, nulls (not tracked), uint64 beyond int64 -- as Python values."""
    t = column.type
    if not pa.types.is_integer(t) or column.null_count:
        return column.to_pylist()
    if pa.types.is_uint64(t) and len(column) and pc.max(column).as_py() > 2 ** 63 - 1:
        return column.to_pylist()
    return np.array(column.to_numpy(), dtype=np.int64)
