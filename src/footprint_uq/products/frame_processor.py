"""The per-frame fast path: :class:`FrameProcessor` prepares a camera and budget once and runs the fused
compiled kernel (:mod:`footprint_uq.fast.footprint_kernels`) per frame, with the numpy reference
(:mod:`.footprint_reference`) while the kernels compile.  Public through :mod:`footprint_uq.products.footprints`."""

from __future__ import annotations

import math
import threading
from typing import NamedTuple

import numpy as np
import pyarrow as pa

from .._checks import COV_PSD_RTOL, as_float, check_cov
from .._notices import before_kernels
from ..errors import InputError
from ..fast import footprint_kernels as fk
from ..fast import frame_columns as fc
from ..fast.buffers import thread_buffer
from ..fast.cov_checks import first_bad_cov2
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import ellipse_axes
from ..uncertainty.propagation import (
    DEFAULT_LINEAR_THRESHOLD,
)
from .footprint_estimate import BOX3D_COLUMNS, CONTACT_MODES, V2X_SAMPLES, FootprintEstimate, mark_overflow
from .footprint_flags import apply_v2x_policy, check_flag_options
from .footprint_geometry import (
    box2d_contact_points,
    box2d_contact_points_checked,
    box3d_bottom_corners,
    box_cov_to_corners,
)
from .footprint_reference import footprints_from_boxes3d, footprints_from_corners

# -- the per-frame fast path ---------------------------------------------------------------------
#: outputs of at least this many bytes come from pyarrow's memory pool (see :func:`empty_reusable`)
_POOL_MIN_BYTES = 1 << 20
_F64 = np.dtype(np.float64)  # (a dtype compared with a dtype: ~3x faster than with the type np.float64)
_N_V2X = fc.INT32_ROWS - 1  # (the V2X code rows of boxes2d_columns' int32 block, then centre_reason)
#: the settings :meth:`FrameProcessor.boxes2d_columns` reads from its packed constants
_PACKED_SETTINGS = frozenset({"allow_outside_image", "linearity", "linear_threshold", "v2x_policy"})


def empty_reusable(shape, dtype=np.float64) -> np.ndarray:
    """An uninitialised array whose memory is reused after it is freed.

    Large arrays come from pyarrow's default memory pool (mimalloc or jemalloc), which keeps
    freed pages for the next allocation; numpy's (and numba's) large allocations are fresh pages
    from the kernel every time, whose first touch costs ~40 % of the footprint kernel's time
    (measured on a 2-core VM).  Small arrays come from numpy.
    """
    dtype = np.dtype(dtype)
    n = math.prod(shape)
    if n * dtype.itemsize < _POOL_MIN_BYTES:
        return np.empty(shape, dtype=dtype)

    return np.frombuffer(pa.allocate_buffer(n * dtype.itemsize), dtype=dtype, count=n).reshape(shape)


def reusable_allocator(max_bytes: int):
    """:func:`empty_reusable`'s policy decided once for arrays of at most ``max_bytes`` each: ``np.empty``
    itself when even the largest is below the pool's threshold (what :func:`empty_reusable` would choose
    for every one of them; ~0.4 us per array less), else :func:`empty_reusable`."""
    return np.empty if max_bytes < _POOL_MIN_BYTES else empty_reusable


class FrameColumns(NamedTuple):
    """The columns of a frame of 2-D boxes that a service record writes (:meth:`FrameProcessor.boxes2d_columns`):
    the numbers of :meth:`FrameProcessor.boxes2d`'s estimate, not an estimate (no per-corner outputs, no
    ellipse, no V2X source: every centre's V2X fields encode its linear covariance).

    Every array is a view of one of the two blocks the compiled call fills (``floats``, ``ints32``); the two a
    record always reads are fields, the others properties (a view made only when read)."""

    #: (q, N) float64, C-contiguous (q = ``boxes2d_columns``' ``value_rows``, 5 by default): ``x_m, y_m, cov_xx_m2,
    #: cov_xy_m2, cov_yy_m2`` of each centre in the first five rows (``centre_xy_world_m``, ``centre_cov_m2``;
    #: :data:`footprint_uq.fast.frame_columns.COLUMN_ROWS`), the rest not written (the caller's)
    values: np.ndarray
    #: (7, N) int32, C-contiguous: ``v2x_codes`` transposed (rows :data:`.footprint_estimate.V2X_FIELDS`)
    v2x_rows: np.ndarray
    #: corners per object (1: the bottom centre, 2: the bottom corners)
    n_corners: int
    #: how many centres are valid (``centre_reason == 0``)
    n_valid: int
    #: (q + ``fast.frame_columns.TAIL_ROWS``, N) float64: ``values``, the fused kernel's per-object rows
    #: (:attr:`object_rows`), then :attr:`largest_index` and :attr:`centre_bad_corner` (int64 in a float64 row each)
    floats: np.ndarray
    #: (8, N) int32: ``v2x_rows``, then :attr:`centre_reason`
    ints32: np.ndarray
    #: with the processor's ``shared_jacobian`` (the tracker's processors; else None): the tracker's input as
    #: :meth:`FrameProcessor.boxes2d`'s estimate has it -- ``centre_xy_world_m`` (N, 2) m and ``centre_cov_m2``
    #: (N, 2, 2) m^2, views of :attr:`object_rows` with the estimate's strides, and ``centre_shared_m`` (N, 2, r),
    #: NaN rows where no centre
    centre_xy_world_m: np.ndarray | None = None
    centre_cov_m2: np.ndarray | None = None
    centre_shared_m: np.ndarray | None = None

    @property
    def object_rows(self) -> np.ndarray:
        """(len(OBJ_ROWS), N) float64: the fused kernel's per-object rows (``FootprintEstimate.object_rows``)."""
        t = self.floats.shape[0] - fc.TAIL_ROWS
        return self.floats[t:t + fc.N_OBJ_ROWS]

    @property
    def centre_reason(self) -> np.ndarray:
        """(N,) int32: as the estimate's ``centre_reason`` (0: a valid centre)."""
        return self.ints32[fc.INT32_ROWS - 1]

    @property
    def largest_index(self) -> np.ndarray:
        """(N,) int64: as the estimate's."""
        return self.floats[-2].view(np.int64)

    @property
    def centre_bad_corner(self) -> np.ndarray:
        """(N,) int64: as the estimate's."""
        return self.floats[-1].view(np.int64)


class FrameProcessor:
    """Reusable per-frame processor: the same results as the reference functions, fused in numba.

    Camera and budget constants (parameter vector, rotation and its derivatives, the
    non-zero entries of the 22x22 parameter covariance, the budget's pixel covariance)
    are prepared once; each call then runs one compiled kernel over the frame's
    detections (see :mod:`footprint_uq.fast.footprint_kernels`).  Results agree with
    :func:`footprints_from_corners` / :func:`footprints_from_boxes2d` /
    :func:`footprints_from_boxes3d` to 1e-9 relative.

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    heading_offset_deg : float
        Bearing of the world +y axis from true north (V2X fields).
    allow_outside_image : bool
        See :func:`footprints_from_corners`.
    joint_cov : bool
        Form the (N, 2K, 2K) joint corner covariance (default True).  Without it
        ``joint_cov_m2`` is None; corner and centre covariances are unchanged.
    linearity, linear_threshold, v2x_policy, v2x_samples, v2x_seed
        The linearity flag (computed in the kernel) and the V2X policy where the centre is not
        ``linear_ok``, as in :func:`footprints_from_corners`.
    shared_jacobian : bool
        Also return each centre's whitened parameter Jacobian ``centre_shared_m`` (N, 2, r), which splits
        its covariance into the camera-level part shared by every frame and the per-frame part (the tracker
        needs it, :mod:`footprint_uq.tracking`); default False (None).

    A processor keeps only read-only constants and the kernels release the GIL, so
    one processor may serve several threads at once (e.g. chunks of a batch).

    Examples
    --------
    >>> proc = FrameProcessor(camera, "basler1")          # once
    >>> est = proc.boxes3d(boxes_world)                   # every frame, (N, 7)
    >>> est.centre_cov_m2, est.largest_semi_major_m, est.v2x["cpm_x_confidence"]
    """

    def __init__(self, camera, budget, *, heading_offset_deg: float = 0.0, allow_outside_image: bool = False,
                 joint_cov: bool = True, linearity: bool = True, linear_threshold: float = DEFAULT_LINEAR_THRESHOLD,
                 v2x_policy: str = "sampled", v2x_samples: int = V2X_SAMPLES, v2x_seed: int = 0,
                 shared_jacobian: bool = False):
        self.shared_jacobian = bool(shared_jacobian)
        self.linear_threshold, self.v2x_samples = check_flag_options(linear_threshold, v2x_policy, v2x_samples)
        self.linearity = bool(linearity)
        self.v2x_policy = v2x_policy
        self.v2x_seed = int(v2x_seed)
        self.camera = camera
        self.budget = load_budget(budget)
        self.heading_offset_deg = as_float("heading_offset_deg", heading_offset_deg)
        self.allow_outside_image = bool(allow_outside_image)
        self.joint_cov = bool(joint_cov)
        self._fk = fk
        self._cam, self._dR = fk.camera_constants(camera)
        fac = self.budget.param_factor()
        self._Lr, self._Lc, self._Lv, self._r = fac.rowidx, fac.cols, fac.vals, fac.rank
        self._spx = np.ascontiguousarray(self.budget.pixel_covariance())
        h = np.deg2rad(self.heading_offset_deg)
        self._ch, self._sh = (1.0, 0.0) if h == 0.0 else (float(np.cos(h)), float(np.sin(h)))
        self._no_det = np.zeros((1, 1, 2, 2))
        self._no_cov = np.zeros((1, 2, 2))
        self._no_shared = np.zeros((0, 2, 0))
        self._no_extra = np.zeros((0, 0), dtype=np.int8)
        self._no_boxes = np.zeros((0, 7))
        #: whether per-corner coordinates and covariances (and the largest point's covariance) are
        #: formed at all; the batch sets False when it writes no corner columns (leaner, faster)
        self.corner_outputs = True
        self._pack_columns()
        self._kernels = False  # the compiled kernels run (footprint_uq._notices; asked until they do)
        self._last_scratch = (None, None)  # (thread id, its scratch) of the last frame (_scratch)

    def __setattr__(self, name: str, value) -> None:
        # a setting packed into boxes2d_columns' constants, set again after construction: packed again (reads of
        # every attribute stay plain; only these few writes pay)
        object.__setattr__(self, name, value)
        if name in _PACKED_SETTINGS and "_columns_consts" in self.__dict__:
            self._pack_columns()

    def _pack_columns(self) -> None:
        """:meth:`boxes2d_columns`' constants and settings in two arrays (:func:`~footprint_uq.fast.frame_columns.
        columns_constants`), packed at construction and again when a packed setting is set."""
        #: the constants and settings of boxes2d_columns' one call
        self._columns_consts = fc.columns_constants(
            self._cam, self._dR, self._Lr, self._Lc, self._Lv, self._r, self._spx,
            allow_outside=self.allow_outside_image, ch=self._ch, sh=self._sh, flag=self.linearity,
            threshold=self.linear_threshold, cov_tol=COV_PSD_RTOL, decline_flagged=self.v2x_policy != "linear")

    def _use_kernels(self) -> bool:
        """Whether this call runs the compiled kernel (else the numpy reference: a command line whose kernels
        are still compiling in the background, :class:`footprint_uq.products.warmup.KernelGate`)."""
        if not self._kernels:
            self._kernels = before_kernels("objects")
        return self._kernels

    def _reference(self, est: FootprintEstimate) -> FootprintEstimate:
        """A reference estimate shaped as this processor's: the kernel's per-object rows (the batch reads
        them), no joint covariance or centre Jacobian unless asked for."""
        est.object_rows = _object_rows(est)
        if not self.joint_cov:
            est.joint_cov_m2 = None
        if not self.shared_jacobian:
            est.centre_shared_m = None
        return est

    def _det(self, pixel_cov_px2, N: int, K: int):
        if pixel_cov_px2 is None:
            return self._no_det, 0
        c = np.asarray(pixel_cov_px2, dtype=np.float64)
        if c.shape == (N, 2, 2):
            return self._checked_cov2(c)[:, None], 1
        if c.shape == (N, K, 2, 2):
            return self._checked_cov2(c), 2
        if c.shape == (N, 2 * K, 2 * K):
            return np.ascontiguousarray(check_cov("pixel_cov_px2", c, 2 * K)[:, None]), 3
        raise InputError("pixel_cov_px2", c.shape, f"shape ({N}, 2, 2), ({N}, {K}, 2, 2) or ({N}, {2 * K}, {2 * K})")

    def _checked_cov2(self, c: np.ndarray) -> np.ndarray:
        """``c`` (..., 2, 2) C-contiguous, checked as :func:`check_cov` does: in one compiled pass when the kernels
        run (the numpy checks only for a frame that fails it, for their one-line error)."""
        c = np.ascontiguousarray(c)
        if self._use_kernels() and first_bad_cov2(c.reshape(-1, 2, 2), COV_PSD_RTOL) < 0:
            return c
        return check_cov("pixel_cov_px2", c, 2)

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_last_scratch"] = (None, None)  # (a thread's buffer is not part of a copy: pickled for a worker)
        return state

    def _scratch(self) -> np.ndarray:
        """The per-frame kernel's scratch: one per thread (fast.buffers; a fresh one every frame cost ~9 us of
        page touching), so one processor may serve several threads at once.  The last caller's thread and buffer
        are kept here: a frame of the same thread (the usual case) takes it without a call into ``fast/``
        (bench/frame_walk.py counts such calls)."""
        tid = threading.get_ident()
        last = self._last_scratch  # (one tuple, read and replaced whole: safe under threads)
        if last[0] == tid:
            return last[1]
        buf = thread_buffer("frame_scratch", fk.SCRATCH_SHAPE)
        self._last_scratch = (tid, buf)
        return buf

    def _flag_options(self) -> dict:
        return dict(linearity=self.linearity, linear_threshold=self.linear_threshold, v2x_policy=self.v2x_policy,
                    v2x_samples=self.v2x_samples, v2x_seed=self.v2x_seed)

    def _run(self, uv, extra, pixel_cov_px2) -> FootprintEstimate:
        N, K = uv.shape[0], uv.shape[1]
        det, mode = self._det(pixel_cov_px2, N, K)
        if K > self._fk.MAX_CORNERS or not self._use_kernels():  # (beyond the kernel's chunk layout)
            return self._reference(footprints_from_corners(
                self.camera, self.budget, uv, pixel_cov_px2=pixel_cov_px2, allow_outside_image=self.allow_outside_image,
                heading_offset_deg=self.heading_offset_deg, extra_reason=extra if extra.shape[0] == N else None,
                **self._flag_options()))
        r = self._r if self.shared_jacobian else None
        alloc = reusable_allocator(self._fk.outputs_max_bytes(N, K, joint=self.joint_cov, shared_rank=r))
        out = self._fk.alloc_outputs(N, K, joint=self.joint_cov, corners=self.corner_outputs, alloc=alloc,
                                     shared_rank=r)
        n_over = self._fk.process_corners(uv, extra, self._no_boxes, False, True, self._cam, self._dR, self._Lr,
                                          self._Lc, self._Lv, self._r, self._spx, det, mode, self.allow_outside_image,
                                          self._ch, self._sh, self.linearity, out, self._scratch())
        return self._pack(uv, out, lambda r: uv[r], det, mode, n_over)

    def _pack(self, uv, out, corners_of, det, mode, n_over) -> FootprintEstimate:
        xy, ccov, joint, reason, usable, li, lcov, creason, cbad, obj, v2x, cnl, shared = out
        row = self._fk.OBJ_ROW
        # views of the kernel's per-object rows (no copies): (N, 2) and (N, 2, 2) with strides across rows
        centre = obj[row["x_m"]:row["y_m"] + 1].T
        ccentre = obj[row["cov_xx_m2"]:row["cov_yy_m2"] + 1].T.reshape(obj.shape[1], 2, 2)
        flag = self.linearity
        est = FootprintEstimate(uv, xy, ccov, joint if self.joint_cov else None, reason, usable, li,
                                obj[row["largest_sigma_major_m"]], obj[row["largest_x_m"]:row["largest_y_m"] + 1].T,
                                lcov, centre, ccentre, creason == 0, creason, cbad, obj[row["area_m2"]], v2x.T,
                                self.heading_offset_deg, cnl if flag else None,
                                obj[row["nonlinearity"]] if flag else None,
                                obj[row["largest_nonlinearity"]] if flag else None, self.linear_threshold)
        est.object_rows = obj
        if self.shared_jacobian:
            shared[creason != 0] = np.nan
            est.centre_shared_m = shared
        K = reason.shape[1]
        if n_over:  # (the kernel counts what mark_overflow would find; almost always nothing)
            est = mark_overflow(est)
        return apply_v2x_policy(est, self.camera, self.budget, self.v2x_policy, self.v2x_samples,
                                 self.v2x_seed, corners_of=corners_of,
                                 det_of=lambda r: _det_joint_rows(det, mode, r, K))

    def point_shared_jacobian(self, uv_px) -> np.ndarray:
        """The whitened parameter Jacobian ``B`` (n, 2, r) of the ground points of pixels ``uv_px (n, 2)``, alone:
        :attr:`FootprintEstimate.centre_shared_m` of one-point footprints (pixels outside the image included), NaN
        where a pixel has no ground point.  One kernel pass without the rest of an estimate (the tracker evaluates
        ``B`` at every track's predicted position in every frame: ~4x less than :meth:`corners`)."""
        uv = np.ascontiguousarray(uv_px, dtype=np.float64).reshape(-1, 1, 2)
        if not self._use_kernels():
            return footprints_from_corners(self.camera, self.budget, uv, allow_outside_image=True, linearity=False,
                                           v2x_policy="linear").centre_shared_m
        return self._fk.point_shared_jacobian(uv, self._no_extra, self._no_boxes, False, True, self._cam, self._dR,
                                              self._Lr, self._Lc, self._Lv, self._r, self._spx, self._no_det, 0, True,
                                              self._ch, self._sh, False, self._scratch())

    def point_jacobian_kernel(self) -> tuple | None:
        """The compiled call behind :meth:`point_shared_jacobian`'s numbers, for a caller that runs it from its
        own hot path (the tracker, every frame, without a Python frame of this layer): ``(kernel, args)`` such
        that ``kernel(uv, *args, out, scratch)`` with ``uv (n, 2)`` float64 C-contiguous, ``out (n, 2, r)``
        float64 C-contiguous and ``scratch`` a float64 array of shape ``footprint_kernels.SCRATCH_SHAPE`` owned
        by the caller (one per thread) fills ``out`` with what :meth:`point_shared_jacobian` returns, to the bit
        (``footprint_kernels.point_jacobian_into``: only the stages that form ``B``).  None while the kernels are
        not ready (a command whose kernels compile in the background): call :meth:`point_shared_jacobian` then,
        and ask again later."""
        if not self._use_kernels():
            return None
        return self._fk.point_jacobian_into, (self._cam, self._dR, self._Lr, self._Lc, self._Lv)

    def corners(self, corners_px, *, pixel_cov_px2=None) -> FootprintEstimate:
        """Footprints from corners in pixels ``(N, K, 2)`` (see :func:`footprints_from_corners`)."""
        uv = np.ascontiguousarray(corners_px, dtype=np.float64)
        if uv.ndim != 3 or uv.shape[2] != 2 or uv.shape[1] < 1:
            raise InputError("corners_px", uv.shape, "an array of shape (N, K, 2) with K >= 1")
        return self._run(uv, self._no_extra, pixel_cov_px2)

    def boxes2d(self, boxes_px, *, contact: str = "bottom-centre", pixel_cov_px2=None,
                box_cov_px2=None, boxes_checked: bool = False) -> FootprintEstimate:
        """Footprints of image boxes ``(N, 4)`` (see :func:`footprints_from_boxes2d`).

        ``boxes_checked``: the caller has checked the boxes already -- a float64 array ``(N, 4)``, finite, corners
        in order (the service's value checks) -- and ``contact`` (:data:`CONTACT_MODES`); the contact pixels are then
        formed without the checks (the same numbers)."""
        if boxes_checked and box_cov_px2 is None and type(boxes_px) is np.ndarray and boxes_px.dtype == np.float64 \
                and boxes_px.ndim == 2 and boxes_px.shape[1] == 4:
            return self._run(box2d_contact_points_checked(boxes_px, contact), self._no_extra, pixel_cov_px2)
        corners, A = box2d_contact_points(boxes_px, contact)
        if box_cov_px2 is not None:
            if pixel_cov_px2 is not None:
                raise InputError("box_cov_px2", "given with pixel_cov_px2", "only one detector covariance")
            pixel_cov_px2 = box_cov_to_corners(box_cov_px2, A, corners.shape[0])
        return self._run(np.ascontiguousarray(corners), self._no_extra, pixel_cov_px2)

    def boxes2d_columns(self, boxes_px: np.ndarray, pixel_cov_px2: np.ndarray | None = None, *,
                        contact: str = "bottom-centre", value_rows: int = 5) -> FrameColumns | None:
        """:meth:`boxes2d` of checked boxes as the columns a service frame writes, in ONE compiled call
        (:func:`footprint_uq.fast.frame_columns.boxes2d_columns`: contact pixels, covariance check, the fused
        kernel, the V2X policy's test), without an estimate: the same numbers (``tests/test_service_columnar.py``).

        Parameters
        ----------
        boxes_px : (N, 4) float64
            ``u_min, v_min, u_max, v_max`` (px), checked by the caller: finite, corners in order (the service's value
            checks, as ``boxes2d(..., boxes_checked=True)``).
        pixel_cov_px2 : (N, 2, 2) float64, optional
            The detector's covariance per box (px^2); checked here (finite, symmetric, PSD).
        contact : {"bottom-centre", "bottom-corners"}
        value_rows : int
            Rows of :attr:`FrameColumns.values` (>= 5): the five of the centres, then rows left for the caller
            (10: the tracked record's motion columns, written after the tracker's step).

        Returns
        -------
        :class:`FrameColumns` (with the processor's ``shared_jacobian``: also ``centre_shared_m``, the tracker's
        input, as :meth:`boxes2d`'s estimate has it), or None where :meth:`boxes2d` is needed for this frame: the
        kernels are not ready (the numpy reference runs meanwhile), a covariance the check refuses (``boxes2d``
        names it), an output that overflowed (``mark_overflow``), a valid centre that is not ``linear_ok`` under a
        V2X policy other than ``"linear"`` (its fields are the policy's: sampled or unavailable), arrays of another
        type or shape.
        """
        N = boxes_px.shape[0]
        if contact not in CONTACT_MODES:
            raise InputError("contact", contact, f"one of {CONTACT_MODES}")
        has_cov = pixel_cov_px2 is not None
        if not self._use_kernels() or type(boxes_px) is not np.ndarray or boxes_px.dtype != _F64 or \
                boxes_px.shape != (N, 4) or (has_cov and (type(pixel_cov_px2) is not np.ndarray or
                                                          pixel_cov_px2.dtype != _F64 or
                                                          pixel_cov_px2.shape != (N, 2, 2))):
            return None
        if not boxes_px.flags.c_contiguous:  # (row-major always: one kernel signature)
            boxes_px = np.ascontiguousarray(boxes_px)
        if has_cov and not pixel_cov_px2.flags.c_contiguous:
            pixel_cov_px2 = np.ascontiguousarray(pixel_cov_px2)
        q = max(5, value_rows)
        floats, ints32 = np.empty((q + fc.TAIL_ROWS, N)), np.empty((fc.INT32_ROWS, N), np.int32)
        shared = np.empty((N, 2, self._r)) if self.shared_jacobian else self._no_shared
        cf, ci = self._columns_consts
        n_valid = fc.boxes2d_columns(boxes_px, contact == "bottom-corners", pixel_cov_px2 if has_cov else self._no_cov,
                                     has_cov, cf, ci, floats, ints32, shared, self._scratch())
        if n_valid < 0:
            return None
        K = 2 if contact == "bottom-corners" else 1
        if not self.shared_jacobian:
            return FrameColumns(floats[:q], ints32[:_N_V2X], K, n_valid, floats, ints32)
        obj, row = floats[q:], fk.OBJ_ROW  # (the views as _pack makes them: the tracker reads the estimate's arrays)
        centre, cov = obj[row["x_m"]:row["y_m"] + 1].T, obj[row["cov_xx_m2"]:row["cov_yy_m2"] + 1].T.reshape(N, 2, 2)
        return FrameColumns(floats[:q], ints32[:_N_V2X], K, n_valid, floats, ints32, centre, cov, shared)

    def boxes3d(self, boxes_world, *, yaw_unit: str = "rad", bottom_on_ground: bool = True,
                pixel_cov_px2=None) -> FootprintEstimate:
        """Footprints of 3D world boxes ``(N, 7)`` (see :func:`footprints_from_boxes3d`)."""
        # row-major always: a column-major table (the batch's) would be another kernel signature, i.e. a second
        # full compile of the per-frame kernel (~1 min) for a copy of 56 bytes per box (~1 % of the kernel's time)
        b = np.ascontiguousarray(boxes_world, dtype=np.float64)
        if b.ndim != 2 or b.shape[1] != 7:
            raise InputError("boxes_world", b.shape, f"an array of shape (N, 7): {', '.join(BOX3D_COLUMNS)}")
        if yaw_unit not in ("rad", "deg"):
            raise InputError("yaw_unit", yaw_unit, "'rad' (column yaw_rad) or 'deg' (column yaw_deg)")
        N = b.shape[0]
        det, mode = self._det(pixel_cov_px2, N, 4)
        if not self._use_kernels():
            return self._reference(footprints_from_boxes3d(
                self.camera, self.budget, b, yaw_unit=yaw_unit, bottom_on_ground=bottom_on_ground,
                pixel_cov_px2=pixel_cov_px2, allow_outside_image=self.allow_outside_image,
                heading_offset_deg=self.heading_offset_deg, **self._flag_options()))
        r = self._r if self.shared_jacobian else None
        alloc = reusable_allocator(self._fk.outputs_max_bytes(N, 4, joint=self.joint_cov, shared_rank=r))
        uv = alloc((N if self.corner_outputs else 0, 4, 2), np.float64)
        out = self._fk.alloc_outputs(N, 4, joint=self.joint_cov, corners=self.corner_outputs, alloc=alloc,
                                     shared_rank=r)
        bad, n_over = self._fk.process_boxes3d(b, yaw_unit == "deg", bool(bottom_on_ground), self._cam, self._dR,
                                               self._Lr, self._Lc, self._Lv, self._r, self._spx, det, mode,
                                               self.allow_outside_image, self._ch, self._sh, self.linearity, uv, out,
                                               self._scratch())
        if bad >= 0:
            raise InputError(f"boxes_world[{bad}] (length_m, width_m, height_m)", b[bad, 3:6].tolist(), "sizes >= 0")

        def corners_of(r):  # the flagged rows' pixels (the batch's lean mode keeps none)
            if uv.shape[0] == N:
                return uv[r]
            X = box3d_bottom_corners(b[r], yaw_unit=yaw_unit, bottom_on_ground=bottom_on_ground,
                                     ground_z_m=self.camera.ground_z_m)
            return self.camera.project(X).uv_px

        return self._pack(uv, out, corners_of, det, mode, n_over)


def _object_rows(est: FootprintEstimate) -> np.ndarray:
    """The fused kernel's per-object rows (:data:`footprint_uq.fast.footprint_kernels.OBJ_ROWS`, (R, N)) of a
    reference estimate: the centre, its covariance and 1-sigma ellipse, the largest point, the area, the flags."""
    row = fk.OBJ_ROW
    obj = np.full((len(fk.OBJ_ROWS), len(est)), np.nan)
    c = est.centre_cov_m2
    obj[row["x_m"]], obj[row["y_m"]] = est.centre_xy_world_m[:, 0], est.centre_xy_world_m[:, 1]
    obj[row["cov_xx_m2"]], obj[row["cov_xy_m2"]] = c[:, 0, 0], c[:, 0, 1]
    obj[row["cov_yx_m2"]], obj[row["cov_yy_m2"]] = c[:, 1, 0], c[:, 1, 1]
    obj[row["sigma_major_m"]], obj[row["sigma_minor_m"]], obj[row["orientation_deg"]] = ellipse_axes(c)
    obj[row["largest_sigma_major_m"]] = est.largest_semi_major_m
    obj[row["largest_x_m"]], obj[row["largest_y_m"]] = est.largest_xy_world_m[:, 0], est.largest_xy_world_m[:, 1]
    obj[row["area_m2"]] = est.area_m2
    if est.centre_nonlinearity is not None:
        obj[row["nonlinearity"]] = est.centre_nonlinearity
        obj[row["largest_nonlinearity"]] = est.largest_nonlinearity
    return obj


def _det_joint_rows(det, mode: int, rows, K: int):
    """The kernel's detector covariance (``FrameProcessor._det``) of ``rows`` as (r, 2K, 2K), or None."""
    if mode == 0:
        return None
    if mode == 3:
        return det[rows, 0]
    out = np.zeros((len(rows), 2 * K, 2 * K))
    for k in range(K):
        out[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = det[rows, 0] if mode == 1 else det[rows, k]
    return out
