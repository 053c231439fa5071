"""The sliding contact of a 2-D box: a velocity error of extended objects, carried in the velocity covariance.

With 2-D boxes the tracker follows the ground point of the box's bottom-edge centre (``--contact bottom-centre``).
On a vehicle that point is not a fixed point of the vehicle: the box's lowest row is the image of the footprint
corner nearest the camera and its middle column the middle of the 8 projected corners, so the back-projected
point sits at an offset from the footprint centre that depends on where the vehicle is in the view (the angle
between its heading and the line of sight, its range, the box's top).  A vehicle driving straight at ``v``
moves its contact at ``(dg/dc) v``, not ``v``: the tracker's velocity is off by the *slide*

    u = (dg/dc - I) v,        g(c) = backproject(bottom_centre(render(c, size, yaw = course of v)))

(docs/motion-fit.md, section 6).  ``dg/dc`` is closed form: the rendered box's edge derivatives
(:func:`~footprint_uq.products.contact.rendered_bottom_centre`) through the back-projection's ``d(x, y)/d(u, v)``.
It is the contact's offset differentiated along the path, i.e. its derivative w.r.t. the angle of the line of
sight times that angle's rate (cross-range speed / range), with the camera's own model (lens, pose) and the box's
top corners (parametric cameras: a homography camera cannot render a box, :meth:`ContactSlide.for_camera`).

On line (:func:`slide_moments`, :class:`ContactSlide`) the closed form runs compiled
(:func:`footprint_uq.fast.slide_kernels.slide_moments`): per size node one render of the box, the bottom-centre
pixel's derivative along the path only (every corner moves by the same vector) and the back-projection's
derivative at that pixel, seven renders per object (the mean size for the centre, then the six nodes) -- the same
numbers as the numpy closed form (:func:`slide_moments_reference`) to rounding.  The kernels run columnar (the
renders of 64 objects at a time, each step one vectorised pass over them): ~5 us per frame of 100 tracked objects
for a pinhole camera (was ~54 us object by object), ~23 us with a distorting lens (was ~137 us object by object);
:meth:`ContactSlide.apply` -- one compiled call, the term added to the tracker's ``cov_v`` -- ~7 us with its
Python (``bench/bench_slide.py``; docs/motion-fit.md, section 6).
:func:`slide_along_path` (a central difference of the rendered contact along the path, the earlier on-line form)
stays as a check.

The size is not known per object: the term is the second moment of ``u`` over the six unscented nodes of the
class's size prior (``mean +- sqrt(3) sigma`` per axis, :mod:`footprint_uq.products.contact`), added to the
tracker's ``cov_v`` after its step (:meth:`ContactSlide.apply`) -- it is a bias of the contact, not a noise of
the filter, so it is not fed back into the track.  A turning vehicle's yaw rate adds a slide not modelled here.
"""

from __future__ import annotations

import threading

import numpy as np

from .. import params as P
from ..cameras.rotation import R_W_C
from ..errors import InputError
from ..fast import slide_kernels
from ..products.contact import class_size_priors, load_size_priors, rendered_bottom_centre
from .table import TrackOutput

__all__ = ["contact_point", "slide_velocity", "slide_along_path", "slide_covariance", "slide_moments",
           "slide_moments_reference", "ContactSlide", "SIZE_NODES", "PATH_STEP_S"]

#: the time step of :func:`slide_along_path`'s central difference, s (1 cm at 10 m/s)
PATH_STEP_S = 1e-3
#: the unscented nodes of a Gaussian size (length, width, height): ``mean + sigma * SIZE_NODES[k]``, weight 1/6
SIZE_NODES = np.sqrt(3.0) * np.vstack([np.eye(3), -np.eye(3)])
_NODES = SIZE_NODES.copy()   # (the kernel's argument: a private copy, C-contiguous float64)
#: distinct class names a :class:`ContactSlide` remembers the prior of (then it starts afresh)
CLASS_CACHE_SIZE = 1024


def contact_point(camera, centre_xy_m, sizes_m, yaw_rad) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The bottom-centre ground contact of cuboids standing on the ground.

    Parameters
    ----------
    camera : Camera (a parametric model)
    centre_xy_m : (..., 2)   footprint centres, frame W, metres
    sizes_m : (..., 3)       length, width, height, metres
    yaw_rad : (...)          yaw, radians counter-clockwise from W's x axis

    Returns
    -------
    xy_contact_m : (..., 2)          the back-projected bottom-centre pixel, frame W (NaN: no ground point)
    dxy_dc : (..., 2, 2)             its derivative w.r.t. the centre (dimensionless)
    valid : (...) bool
    """
    uv, duv_dc, ok = rendered_bottom_centre(camera, centre_xy_m, sizes_m, yaw_rad)
    shape = uv.shape[:-1]
    bp = camera.backproject(uv.reshape(-1, 2), get_gradients=True)
    xy = bp.xy_world_m.reshape(shape + (2,))
    dxy_dc = bp.dxy_duv.reshape(shape + (2, 2)) @ duv_dc
    return xy, dxy_dc, ok & bp.valid.reshape(shape)


def slide_velocity(camera, centre_xy_m, v_mps, sizes_m) -> tuple[np.ndarray, np.ndarray]:
    """The slide ``u = (dg/dc - I) v`` (..., 2), m/s, of the contact of cuboids driving straight at ``v_mps``
    (..., 2) (yaw: the course of ``v``); and ``valid`` (...).  Module doc."""
    v = np.asarray(v_mps, dtype=np.float64)
    yaw = np.arctan2(v[..., 1], v[..., 0])
    _, J, ok = contact_point(camera, centre_xy_m, sizes_m, yaw)
    u = np.einsum("...ij,...j->...i", J, v) - v
    return u, ok & np.isfinite(u).all(-1)


def slide_along_path(camera, centre_xy_m, v_mps, sizes_m, *, step_s: float = PATH_STEP_S) -> tuple[np.ndarray,
                                                                                                 np.ndarray]:
    """:func:`slide_velocity` by a central difference of the rendered contact along the path, ``(g(c + v h) -
    g(c - v h)) / 2h - v``: two renders without derivatives (a twentieth of the work of the closed form, whose
    projection derivatives cover all 22 camera parameters; the tests hold the two equal).  Returns ``u`` (..., 2)
    m/s and ``valid`` (...)."""
    c = np.asarray(centre_xy_m, dtype=np.float64)
    v = np.asarray(v_mps, dtype=np.float64)
    sizes = np.asarray(sizes_m, dtype=np.float64)
    yaw = np.arctan2(v[..., 1], v[..., 0])
    shape = np.broadcast_shapes(c.shape[:-1], v.shape[:-1], sizes.shape[:-1])
    c, v = np.broadcast_to(c, shape + (2,)), np.broadcast_to(v, shape + (2,))
    sizes, yaw = np.broadcast_to(sizes, shape + (3,)), np.broadcast_to(yaw, shape)
    uv, _, valid = rendered_bottom_centre(camera, np.stack([c + step_s * v, c - step_s * v]),
                                          np.stack([sizes, sizes]), np.stack([yaw, yaw]), gradients=False)
    bp = camera.backproject(uv.reshape(-1, 2))
    g = bp.xy_world_m.reshape((2,) + shape + (2,))
    ok = (valid & bp.valid.reshape((2,) + shape)).all(0)
    u = (g[0] - g[1]) / (2.0 * step_s) - v
    return u, ok & np.isfinite(u).all(-1)


def slide_covariance(camera, xy_contact_m, v_mps, size_mean_m, size_sigma_m) -> np.ndarray:
    """The velocity covariance term ``E[u u^T]`` (n, 2, 2), m^2/s^2, of tracks of contacts ``xy_contact_m``
    (n, 2) moving at ``v_mps`` (n, 2), over the unscented nodes of their size priors ``size_mean_m``,
    ``size_sigma_m`` (n, 3) (:func:`slide_moments`' second moment)."""
    return slide_moments(camera, xy_contact_m, v_mps, size_mean_m, size_sigma_m)[1]


def _rows_of(a, width: int) -> np.ndarray:
    """``a`` as writeable C-contiguous float64 (n, width) (copied only when it is not one: a read-only array is
    another numba type, a second compilation of the kernel)."""
    r = np.ascontiguousarray(np.asarray(a, dtype=np.float64).reshape(-1, width))
    return r if r.flags.writeable else r.copy()


def _moment_inputs(xy_contact_m, v_mps, size_mean_m, size_sigma_m):
    """The four inputs (n, 2), (n, 2), (n, 3), (n, 3), one row per contact (:func:`_rows_of`)."""
    x, v = _rows_of(xy_contact_m, 2), _rows_of(v_mps, 2)
    mean, sig = _rows_of(size_mean_m, 3), _rows_of(size_sigma_m, 3)
    n = x.shape[0]
    if v.shape[0] != n or mean.shape[0] != n or sig.shape[0] != n:
        raise InputError("v_mps/size_mean_m/size_sigma_m", (v.shape, mean.shape, sig.shape),
                         f"{n} rows, one per contact")
    return x, v, mean, sig


def kernel_camera(camera) -> tuple:
    """The camera as :func:`footprint_uq.fast.slide_kernels.slide_moments` takes it: ``(prm (22,), R_W_C (3, 3),
    packed lens domain, has_dist)`` (writeable C-contiguous float64 arrays: one numba signature)."""
    p = np.array(camera.params, dtype=np.float64, order="C")
    R = np.array(R_W_C(p[P.PAN], p[P.TILT], p[P.ROLL]), dtype=np.float64, order="C")
    return p, R, np.array(camera.lens_domain.packed, dtype=np.float64, order="C"), bool(np.any(p[P.DIST_SLICE]))


def slide_moments(camera, xy_contact_m, v_mps, size_mean_m, size_sigma_m, *,
                  constants=None) -> tuple[np.ndarray, np.ndarray]:
    """The mean ``E[u]`` (n, 2), m/s, and second moment ``E[u u^T]`` (n, 2, 2), m^2/s^2, of the slide of tracks
    of contacts ``xy_contact_m`` (n, 2) moving at ``v_mps`` (n, 2) over the unscented nodes of their size priors
    ``size_mean_m``, ``size_sigma_m`` (n, 3).  The footprint centre is found from the contact by one fixed-point
    step (``c = x - (g(x) - x)``, its error second order in the offset's change over the offset); at each node the
    slide is the closed form ``(dg/dc - I) v``.  Nodes whose box does not render are left out; NaN where none
    renders (the velocity is then not reported with a covariance).

    Compiled (:func:`footprint_uq.fast.slide_kernels.slide_moments`); :func:`slide_moments_reference` is its numpy
    form, the same numbers to rounding.  ``constants``: :func:`kernel_camera` of ``camera`` (computed when None).
    """
    x, v, mean, sig = _moment_inputs(xy_contact_m, v_mps, size_mean_m, size_sigma_m)
    m, M = np.empty((x.shape[0], 2)), np.empty((x.shape[0], 2, 2))
    slide_kernels.slide_moments(*(constants or kernel_camera(camera)), x, v, mean, sig, _NODES, m, M)
    return m, M


def slide_moments_reference(camera, xy_contact_m, v_mps, size_mean_m, size_sigma_m, *,
                            along_path: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """:func:`slide_moments` in numpy: the centre by the same fixed-point step, the slide at each node by
    :func:`slide_velocity` (closed form) or, with ``along_path``, by :func:`slide_along_path` (a central difference
    along the path: within 1e-6 m^2/s^2 of the closed form at the tests' points)."""
    x, v, mean, sig = _moment_inputs(xy_contact_m, v_mps, size_mean_m, size_sigma_m)
    yaw = np.arctan2(v[:, 1], v[:, 0])
    uv0, _, _ = rendered_bottom_centre(camera, x, mean, yaw, gradients=False)
    g0 = camera.backproject(uv0).xy_world_m
    c = 2.0 * x - g0                                        # the centre whose contact is x (one step)
    sizes = np.clip(mean[:, None, :] + SIZE_NODES[None] * sig[:, None, :], 0.02, None)   # (n, 6, 3)
    slide = slide_along_path if along_path else slide_velocity
    u, ok = slide(camera, np.repeat(c[:, None], 6, 1), np.repeat(v[:, None], 6, 1), sizes)
    u = np.where(ok[..., None], u, 0.0)
    k = ok.sum(1)
    with np.errstate(invalid="ignore", divide="ignore"):
        M = np.einsum("nki,nkj->nij", u, u) / k[:, None, None]
        m = u.sum(1) / k[:, None]
    M[k == 0], m[k == 0] = np.nan, np.nan
    return m, M


class ContactSlide:
    """The slide term of one camera's tracks of 2-D box contacts (:func:`slide_covariance`), applied to the
    tracker's output after its step.

    Parameters
    ----------
    camera : Camera (a parametric model: ``params``, ``lens_domain``)
    size_priors : path or :func:`~footprint_uq.products.contact.load_size_priors` result, optional
        Per-class length, width, height (default: the shipped priors); objects without a class or of an unknown
        class get the fallback prior ('other': 2 +- 1.5 m long).
    """

    def __init__(self, camera, size_priors=None):
        self.camera = camera
        self.size_priors = size_priors if isinstance(size_priors, tuple) else load_size_priors(size_priors)
        self._constants = None            # kernel_camera(camera) less has_dist, on first use
        self._kernel = None               # its compiled entries (slide_kernels.MOMENTS_KERNELS, ADDED_KERNELS),
        self._added = None                # on first use
        self._rows: dict = {}             # class name -> row of the prior tables
        self._lock = threading.Lock()
        self._mean, self._sigma = np.empty((0, 3)), np.empty((0, 3))
        self._last = ((None, -1), None)   # the last one-class frame's (class, n) and its prior rows (kept: read only)

    @classmethod
    def for_camera(cls, camera, size_priors=None) -> ContactSlide | None:
        """The term of a parametric camera; None for one that cannot render a box (a homography camera: its
        tracks of 2-D boxes are reported without the term, docs/motion-fit.md, section 6)."""
        ok = hasattr(camera, "lens_domain") and np.shape(getattr(camera, "params", None)) == (P.N_PARAMS,)
        return cls(camera, size_priors) if ok else None

    def covariance(self, out: TrackOutput, classes) -> np.ndarray:
        """The term (n, 2, 2) of a frame's tracked objects (zero where no velocity is reported).

        :func:`slide_moments` with the camera's compiled entry called from here (looked up once: a frame does not
        climb back up from ``fast/``, ``bench/frame_walk.py``); the tracker's rows as they come (C-contiguous
        float64 of the frame's shape, :meth:`~footprint_uq.tracking.table.TrackTable.step`'s outputs) or copied
        as such (:func:`_frame_rows`)."""
        n = out.track_id.shape[0]
        mean, sig = self._priors(classes, n)
        if self._kernel is None:
            self._load_kernels()
        x, v = _frame_rows(out.xy_m, "out.xy_m", (n, 2)), _frame_rows(out.v_mps, "out.v_mps", (n, 2))
        m, M = np.empty((n, 2)), np.empty((n, 2, 2))
        self._kernel(*self._constants, x, v, mean, sig, _NODES, m, M)
        nan = np.isnan(M[:, 0, 0])   # (where no node renders; a row without a velocity or position is such a row)
        if nan.any():
            rows = np.flatnonzero(nan)
            M[rows[~(np.isfinite(v[rows]).all(1) & np.isfinite(x[rows]).all(1))]] = 0.0
        return M

    def _load_kernels(self) -> None:
        """The camera's constants and its two compiled entries (``MOMENTS_KERNELS``, ``ADDED_KERNELS``)."""
        prm, R, dom, has_dist = kernel_camera(self.camera)
        self._constants = (prm, R, dom)
        self._kernel, self._added = slide_kernels.MOMENTS_KERNELS[has_dist], slide_kernels.ADDED_KERNELS[has_dist]

    def _priors(self, classes, n: int) -> tuple[np.ndarray, np.ndarray]:
        """Per object, its class's size prior ``(mean_m (n, 3), sigma_m (n, 3))``; a class seen first is looked up
        once (:func:`~footprint_uq.products.contact.class_size_priors`: the fallback for None and unknowns); a
        frame of one class gets the rows of the last such frame when its class and size are the same (the kernel
        only reads them)."""
        names = [None] * n if classes is None else classes if isinstance(classes, list) else list(classes)
        if len(names) != n:
            raise InputError("classes", f"{len(names)} names", f"one class name (or None) per object ({n})")
        one = n > 0 and names.count(names[0]) == n  # (a frame of one class, the common case: one look-up)
        with self._lock:  # (the service may run frames of one camera in several threads)
            if one and self._last[0] == (names[0], n):
                return self._last[1]
            new = [c for c in ({names[0]} if one else set(names)) if c not in self._rows]
            if new:
                if len(self._rows) + len(new) > CLASS_CACHE_SIZE:
                    self._rows, self._mean, self._sigma = {}, np.empty((0, 3)), np.empty((0, 3))
                    new = list(set(names))
                mean, sig = class_size_priors(["" if c is None else c for c in new], len(new), self.size_priors)
                self._rows.update({c: len(self._rows) + k for k, c in enumerate(new)})
                self._mean, self._sigma = np.vstack([self._mean, mean]), np.vstack([self._sigma, sig])
            if not one:
                rows = np.fromiter(map(self._rows.__getitem__, names), dtype=np.intp, count=n)
                return self._mean[rows], self._sigma[rows]
            r = self._rows[names[0]]
            self._last = ((names[0], n), (np.repeat(self._mean[r:r + 1], n, 0), np.repeat(self._sigma[r:r + 1], n, 0)))
            return self._last[1]

    def apply(self, out: TrackOutput, classes) -> TrackOutput:
        """``out`` with the term added to ``cov_v_m2ps2`` (the track's own state is not changed): a new
        ``cov_v_m2ps2`` array, every other field ``out``'s own.

        One compiled call (``slide_kernels.ADDED_KERNELS``: the moments, the zero term of a row without a velocity
        or position, the sum): ``out.cov_v_m2ps2 + self.covariance(out, classes)`` -- the same bytes where the
        term is zero or NaN, to rounding elsewhere (~3e-14 relative: the two kernels are compiled apart, with FMA
        contraction allowed; ``tests/test_contact_slide.py``)."""
        n = out.track_id.shape[0]
        mean, sig = self._priors(classes, n)
        if self._added is None:
            self._load_kernels()
        cov = np.empty((n, 2, 2))
        self._added(*self._constants, _frame_rows(out.xy_m, "out.xy_m", (n, 2)),
                    _frame_rows(out.v_mps, "out.v_mps", (n, 2)), mean, sig, _NODES,
                    _frame_rows(out.cov_v_m2ps2, "out.cov_v_m2ps2", (n, 2, 2)), cov)
        return TrackOutput(*out[:_COV_V], cov)


#: the position of ``cov_v_m2ps2`` in :class:`~footprint_uq.tracking.table.TrackOutput` (its last field: ``apply``
#: builds the new output from the others and the new array, ~0.3 us less than ``_replace``)
_COV_V = TrackOutput._fields.index("cov_v_m2ps2")
if _COV_V != len(TrackOutput._fields) - 1:  # pragma: no cover - a change of TrackOutput's fields
    raise ImportError("TrackOutput's last field is not cov_v_m2ps2: ContactSlide.apply builds it positionally")
_F64 = np.dtype(np.float64)


def _frame_rows(a, field: str, shape: tuple) -> np.ndarray:
    """``a`` as the kernels take it: writeable C-contiguous float64 of exactly ``shape`` (the tracker's outputs
    are such arrays: taken as they are; anything else is copied as such, a read-only array being another numba
    type, a second compilation).  Another shape: InputError naming ``field`` (the kernels read one row per
    object)."""
    if type(a) is np.ndarray and a.dtype is _F64 and a.flags.carray and a.shape == shape:
        return a
    r = np.ascontiguousarray(np.asarray(a, dtype=np.float64))
    if r.shape != shape:
        raise InputError(field, r.shape, f"shape {shape}, one row per object of the frame")
    return r if r.flags.writeable else r.copy()
