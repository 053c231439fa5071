"""Uncertainty ellipses of 2x2 covariances.

Scale factors: a 2-D Gaussian's ellipse containing probability ``p`` has
semi-axes ``k sqrt(lambda_i)`` with ``k = sqrt(chi2_2(p)) = sqrt(-2 ln(1 - p))``:
95 % is k = 2.4477, not the 1-D 1.96.  Orientation is the angle of the major
axis in the world frame W, degrees counter-clockwise from +x (east), in
(-90, 90].  :func:`heading_deg` converts to a compass bearing (clockwise from
north, [0, 180)).
"""

from __future__ import annotations

import numpy as np
from scipy.special import chdtri

from .._checks import as_float
from ..errors import InputError

__all__ = ["chi2_scale", "ellipse_axes", "ellipse_points", "ellipse_ring", "heading_deg"]


def chi2_scale(confidence: float, dof: int = 2) -> float:
    """Sigma multiplier ``k`` of the ``confidence`` region of a ``dof``-D Gaussian."""
    p = as_float("confidence", confidence)
    if not 0.0 < p < 1.0:
        raise InputError("confidence", confidence, "a probability in (0, 1), e.g. 0.95")
    if dof == 2:
        return float(np.sqrt(-2.0 * np.log1p(-p)))
    return float(np.sqrt(chdtri(dof, 1.0 - p)))  # the chi-square quantile (scipy.stats is slow to import)


def ellipse_axes(cov_m2, *, confidence: float | None = None):
    """Semi-axes and orientation of ``(..., 2, 2)`` covariances.

    Parameters
    ----------
    cov_m2 : array_like, shape (..., 2, 2)
    confidence : float, optional
        If given, axes are scaled to that probability (2-D chi-square); else 1 sigma.

    Returns
    -------
    semi_major_m, semi_minor_m, orientation_deg : ndarray, shape (...)
        NaN where the covariance is NaN.
    """
    c = np.asarray(cov_m2, dtype=np.float64)
    a, b, d = c[..., 0, 0], 0.5 * (c[..., 0, 1] + c[..., 1, 0]), c[..., 1, 1]
    mean = 0.5 * (a + d)
    rad = np.hypot(0.5 * (a - d), b)
    l1 = mean + rad
    l2 = np.maximum(mean - rad, 0.0)
    k = 1.0 if confidence is None else chi2_scale(confidence)
    ang = 0.5 * np.degrees(np.arctan2(2.0 * b, a - d))
    ang = np.where(ang <= -90.0, ang + 180.0, ang)
    return k * np.sqrt(l1), k * np.sqrt(l2), ang


def heading_deg(orientation_deg):
    """Orientation (ccw from east) -> axis bearing clockwise from north in [0, 180)."""
    return np.mod(90.0 - np.asarray(orientation_deg, dtype=np.float64), 180.0)


def ellipse_points(center_m, cov_m2, *, confidence: float | None = None, n: int = 64):
    """Boundary polygons ``(..., n, 2)`` of the ellipses of ``(..., 2)`` means and ``(..., 2, 2)`` covariances."""
    c = np.asarray(cov_m2, dtype=np.float64)
    m = np.asarray(center_m, dtype=np.float64)
    w, V = np.linalg.eigh(c)
    k = 1.0 if confidence is None else chi2_scale(confidence)
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=True)
    circle = np.stack([np.cos(t), np.sin(t)], -1)  # (n, 2)
    A = V * (k * np.sqrt(np.maximum(w, 0.0)))[..., None, :]  # (..., 2, 2)
    return m[..., None, :] + np.einsum("...ij,nj->...ni", A, circle)


def ellipse_ring(center_m, cov_m2, *, confidence: float = 0.95, n: int = 64):
    """Closed counter-clockwise rings ``(..., n + 1, 2)`` of the ``confidence`` ellipses (GeoJSON polygons).

    Vertex ``j`` is ``c + a cos t_j e_major + b sin t_j e_minor`` with ``t_j = 2 pi j / n``, the semi-axes
    ``a, b`` and the major axis ``e_major`` of :func:`ellipse_axes` (``e_minor`` = ``e_major`` turned 90 deg
    counter-clockwise), so every vertex lies on the ellipse and the ring runs counter-clockwise in a
    right-handed x-y frame (RFC 7946's exterior rings); the last vertex is the first one again (closed).

    Parameters
    ----------
    center_m : (..., 2) centres; cov_m2 : (..., 2, 2) covariances (m^2)
    confidence : probability inside the ellipse (2-D chi-square), default 0.95
    n : vertices before the closing one (>= 8)

    Returns
    -------
    ndarray (..., n + 1, 2): NaN where the covariance or the centre is NaN
    """
    if int(n) < 8:
        raise InputError("n", n, "at least 8 vertices")
    a, b, ang = ellipse_axes(cov_m2, confidence=confidence)
    th = np.radians(ang)[..., None]
    t = 2.0 * np.pi * np.arange(int(n)) / int(n)
    ca, sa = a[..., None] * np.cos(t), b[..., None] * np.sin(t)
    m = np.asarray(center_m, dtype=np.float64)
    x = m[..., 0:1] + ca * np.cos(th) - sa * np.sin(th)
    y = m[..., 1:2] + ca * np.sin(th) + sa * np.cos(th)
    ring = np.stack([x, y], -1)
    return np.concatenate([ring, ring[..., :1, :]], -2)
