"""The lens's valid domain: where OpenCV's distortion model can be inverted.

OpenCV's radial polynomial ``r_d = r (1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + ...)``
rises from the optical axis, and for a barrel lens (k1 < 0) it reaches a maximum and folds
back: past that radius two different rays land on the same pixel, and a pixel farther out
than the maximum has no ray at all.  Newton's method started in the wrong place happily
returns the other root (a ray on the far side of the fold, hundreds of metres off on the
ground), so the domain is made explicit, once per camera:

* the **principal region** ``U`` (undistorted normalised coordinates): the points ``x`` such
  that along the segment from the optical axis to ``x`` the distortion Jacobian's
  determinant, the radial factor and its denominator stay positive, and the model's local
  stretch (Frobenius norm of its Jacobian) stays below 20 (near a rational model's pole it
  grows without bound and no root can be resolved in double precision).  It is star-shaped; its
  boundary radius ``r_fold(phi)`` is found per direction by a scan and bisection
  (:func:`footprint_uq.fast.core.fold_radius`), capped at :data:`R_MAX` (87 deg off-axis, in
  undistorted and in distorted coordinates).  With a tangential term it can jump between two
  neighbouring directions (the determinant turns negative over a range of angles only); the solver
  slides along such walls (:func:`footprint_uq.fast.core.undistort_point`).  A fold thinner than the
  scan's grid is found by a search at each sampled dip of the determinant
  (:func:`~footprint_uq.fast.core.fold_radius`); one confined to an angular range narrower than a bin
  of the table can still fall between two;
* the **valid domain** ``D = distort(U)`` (distorted normalised coordinates, i.e. pixels):
  the pixels whose root lies in ``U``.  Membership is decided by the solver itself
  (:func:`footprint_uq.fast.core.undistort_point`: its answer is accepted only in ``U``), so
  every path applies the same test; pixels beyond the largest distorted radius of ``U``'s
  boundary (plus 1 %) are rejected at once.

A pixel outside ``D`` is :data:`footprint_uq.status.UNDISTORT_FAILED`; a world point projects
only from inside ``U``.  ``U``'s boundary table is shrunk by a relative :data:`MARGIN` and read
conservatively (the smaller of two neighbouring entries).

Without distortion the domain is unlimited.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from ..fast import core

__all__ = ["LensDomain", "lens_domain", "R_MAX", "N_BINS", "MARGIN"]

#: largest undistorted (and distorted) normalised radius considered (tan 87 deg)
R_MAX = core.R_CAP
#: angular bins of the boundary tables
N_BINS = 512
#: relative shrink of the boundary tables
MARGIN = 1e-7
_N_GRID = 4096


class LensDomain(NamedTuple):
    """Valid domain of one lens (see the module docstring).

    Attributes
    ----------
    dist : ndarray (8,)
        The distortion coefficients it was built for (k1, k2, p1, p2, k3, k4, k5, k6).
    packed : ndarray
        The float64 vector the compiled code reads (layout :data:`footprint_uq.fast.core.DOM_M` ...).
    r_fold : ndarray (N_BINS + 1,)
        Undistorted normalised boundary radius at angles ``angles_rad`` (inf without distortion).
    r_max_distorted : ndarray (N_BINS + 1,)
        Distorted normalised radius of the image of each boundary point ``r_fold``
        (for a radial-only lens: the largest distorted radius with a ray).
    angles_rad : ndarray (N_BINS + 1,)
        Uniform angles from -pi to pi.
    star_shaped : bool
        Whether the domain's boundary in the distorted plane is star-shaped around the axis
        (information only: membership is decided by the solver, not by a polar table).
    """

    dist: np.ndarray
    packed: np.ndarray
    r_fold: np.ndarray
    r_max_distorted: np.ndarray
    angles_rad: np.ndarray
    star_shaped: bool

    @property
    def limited(self) -> bool:
        """True where the lens model restricts the usable pixels at all."""
        return bool(np.isfinite(self.packed[core.DOM_RD_OUT2]))

    def contains_distorted(self, xy_d) -> np.ndarray:
        """``(..., 2)`` distorted normalised points -> bool ``(...)``: inside the valid domain.

        By definition where the scalar core's undistortion answers (its root lies in the
        principal region); the same test every path applies.
        """
        a = np.asarray(xy_d, dtype=np.float64)
        flat = np.ascontiguousarray(a.reshape(-1, 2))
        n = flat.shape[0]
        out, ok, minv = np.empty((n, 2)), np.empty(n, dtype=np.bool_), np.empty((n, 4))
        k = np.repeat(np.asarray(self.dist, dtype=np.float64)[None], n, 0)  # (one array type for the kernel)
        core.undistort_many(self.packed, k, flat, out, ok, minv)
        return ok.reshape(a.shape[:-1])

    def contains_undistorted(self, xy_n) -> np.ndarray:
        """``(..., 2)`` undistorted normalised points -> bool ``(...)``: inside the principal region."""
        a = np.asarray(xy_n, dtype=np.float64)
        flat = np.ascontiguousarray(a.reshape(-1, 2))
        out = np.empty(flat.shape[0], dtype=np.bool_)
        core.contains_many(self.packed, flat, out)
        return out.reshape(a.shape[:-1])


def _unlimited(dist: np.ndarray) -> LensDomain:
    ang = np.linspace(-np.pi, np.pi, N_BINS + 1)
    inf = np.full(N_BINS + 1, np.inf)
    packed = np.concatenate([[N_BINS, np.inf, np.inf, np.inf, np.inf], inf, inf])
    for a in (dist, packed, inf, ang):  # read-only as :func:`_build`'s: one array type for the compiled kernels
        a.setflags(write=False)
    return LensDomain(dist, packed, inf, inf, ang, True)


@functools.lru_cache(maxsize=256)
def _build(key: tuple) -> LensDomain:
    k = np.array(key, dtype=np.float64)
    if not np.any(k):
        return _unlimited(k)
    ang = np.linspace(-np.pi, np.pi, N_BINS + 1)
    c, s = np.cos(ang), np.sin(ang)
    if k[2] == 0.0 and k[3] == 0.0:  # radial only: one radius for every direction
        r_u = np.full(ang.size, core.fold_radius(k, 1.0, 0.0, R_MAX, _N_GRID))
    else:
        r_u = np.array([core.fold_radius(k, c[i], s[i], R_MAX, _N_GRID) for i in range(ang.size)])
        r_u[-1] = r_u[0]  # -pi and pi are one direction
    r_u = r_u * (1.0 - MARGIN)
    # image of the boundary in the distorted plane: its largest radius (+1 %) is the quick outer filter
    xb, yb = r_u * c, r_u * s
    r2 = xb * xb + yb * yb
    num = 1.0 + r2 * (k[0] + r2 * (k[1] + r2 * k[4]))
    den = 1.0 + r2 * (k[5] + r2 * (k[6] + r2 * k[7]))
    rad = num / den
    xd = xb * rad + 2.0 * k[2] * xb * yb + k[3] * (r2 + 2.0 * xb * xb)
    yd = yb * rad + k[2] * (r2 + 2.0 * yb * yb) + 2.0 * k[3] * xb * yb
    r_d = np.hypot(xd, yd)
    psi = np.unwrap(np.arctan2(yd, xd))
    star = bool(np.all(np.diff(psi) > 0) and abs(psi[-1] - psi[0] - 2 * np.pi) < 1e-9)
    packed = np.concatenate([[N_BINS, r_d.min() ** 2, (1.01 * r_d.max()) ** 2, r_u.min() ** 2, r_u.max() ** 2],
                             r_d, r_u])
    for a in (k, packed, r_u, r_d, ang):
        a.setflags(write=False)
    return LensDomain(k, packed, r_u, r_d, ang, star)


def lens_domain(dist) -> LensDomain:
    """The valid domain of the lens with distortion ``dist`` (8,) (cached per coefficient set).

    Parameters
    ----------
    dist : array_like, shape (8,)
        k1, k2, p1, p2, k3, k4, k5, k6 (OpenCV order), finite.

    Returns
    -------
    LensDomain
    """
    k = np.asarray(dist, dtype=np.float64)
    if k.shape != (8,) or not np.all(np.isfinite(k)):
        raise InputError("dist", dist, "8 finite distortion coefficients (k1, k2, p1, p2, k3, k4, k5, k6)")
    return _build(tuple(float(v) for v in k))
