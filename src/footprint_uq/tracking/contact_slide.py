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

On line, ``u`` is taken by a central difference of the rendered contact along the path (:func:`slide_along_path`,
held equal to the closed form by the tests): the closed form's projection derivatives w.r.t. all 22 camera
parameters cost 60 x the render.

The size is not known per object: the term is the second moment of ``u`` over the six unscented nodes of the
class's size prior (``mean +- sqrt(3) sigma`` per axis, :mod:`footprint_uq.products.contact`), added to the
tracker's ``cov_v`` after its step (:meth:`ContactSlide.apply`) -- it is a bias of the contact, not a noise of
the filter, so it is not fed back into the track.  A turning vehicle's yaw rate adds a slide not modelled here.
"""

from __future__ import annotations

import numpy as np

from .. import params as P
from ..errors import InputError
from ..products.contact import class_size_priors, load_size_priors, rendered_bottom_centre
from .table import TrackOutput

__all__ = ["contact_point", "slide_velocity", "slide_along_path", "slide_covariance", "slide_moments", "ContactSlide",
           "SIZE_NODES", "PATH_STEP_S"]

#: the time step of :func:`slide_along_path`'s central difference, s (1 cm at 10 m/s)
PATH_STEP_S = 1e-3
#: the unscented nodes of a Gaussian size (length, width, height): ``mean + sigma * SIZE_NODES[k]``, weight 1/6
SIZE_NODES = np.sqrt(3.0) * np.vstack([np.eye(3), -np.eye(3)])


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


def slide_moments(camera, xy_contact_m, v_mps, size_mean_m, size_sigma_m) -> tuple[np.ndarray, np.ndarray]:
    """The mean ``E[u]`` (n, 2), m/s, and second moment ``E[u u^T]`` (n, 2, 2), m^2/s^2, of the slide of tracks
    of contacts ``xy_contact_m`` (n, 2) moving at ``v_mps`` (n, 2) over the unscented nodes of their size priors
    ``size_mean_m``, ``size_sigma_m`` (n, 3).  The footprint centre is found from the contact by one fixed-point
    step (``c = x - (g(x) - x)``, its error second order in the offset's change over the offset).  Nodes whose
    box does not render are left out; NaN where none renders (the velocity is then not reported with a
    covariance)."""
    x = np.asarray(xy_contact_m, dtype=np.float64).reshape(-1, 2)
    v = np.asarray(v_mps, dtype=np.float64).reshape(-1, 2)
    mean = np.asarray(size_mean_m, dtype=np.float64).reshape(-1, 3)
    sig = np.asarray(size_sigma_m, dtype=np.float64).reshape(-1, 3)
    n = x.shape[0]
    if v.shape[0] != n or mean.shape[0] != n or sig.shape[0] != n:
        raise InputError("v_mps/size_mean_m/size_sigma_m", (v.shape, mean.shape, sig.shape),
                         f"{n} rows, one per contact")
    yaw = np.arctan2(v[:, 1], v[:, 0])
    uv0, _, _ = rendered_bottom_centre(camera, x, mean, yaw, gradients=False)
    g0 = camera.backproject(uv0).xy_world_m
    c = 2.0 * x - g0                                        # the centre whose contact is x (one step)
    sizes = np.clip(mean[:, None, :] + SIZE_NODES[None] * sig[:, None, :], 0.02, None)   # (n, 6, 3)
    u, ok = slide_along_path(camera, np.repeat(c[:, None], 6, 1), np.repeat(v[:, None], 6, 1), sizes)
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

    @classmethod
    def for_camera(cls, camera, size_priors=None) -> ContactSlide | None:
        """The term of a parametric camera; None for one that cannot render a box (a homography camera: its
        tracks of 2-D boxes are reported without the term, docs/motion-fit.md, section 6)."""
        ok = hasattr(camera, "lens_domain") and np.shape(getattr(camera, "params", None)) == (P.N_PARAMS,)
        return cls(camera, size_priors) if ok else None

    def covariance(self, out: TrackOutput, classes) -> np.ndarray:
        """The term (n, 2, 2) of a frame's tracked objects (zero where no velocity is reported)."""
        n = out.track_id.shape[0]
        names = ["" if c is None else c for c in (classes if classes is not None else [None] * n)]
        term = np.zeros((n, 2, 2))
        sel = np.flatnonzero(np.isfinite(out.v_mps).all(1) & np.isfinite(out.xy_m).all(1))
        if sel.size:
            mean, sig = class_size_priors([names[i] for i in sel.tolist()], sel.size, self.size_priors)
            term[sel] = slide_covariance(self.camera, out.xy_m[sel], out.v_mps[sel], mean, sig)
        return term

    def apply(self, out: TrackOutput, classes) -> TrackOutput:
        """``out`` with the term added to ``cov_v_m2ps2`` (the track's own state is not changed)."""
        return out._replace(cov_v_m2ps2=out.cov_v_m2ps2 + self.covariance(out, classes))
