"""A frame's 2x2 pixel covariances checked in one compiled pass (the per-frame path of
:class:`footprint_uq.products.footprints.FrameProcessor`).

:func:`first_bad_cov2` applies the tests of :func:`footprint_uq._checks.check_cov` for ``n = 2`` -- finite,
symmetric to 1e-9 of the matrix's largest entry, smaller eigenvalue ``(a + d) / 2 - hypot((a - d) / 2, c)`` of
``[[a, b], [c, d]]`` not below ``-tol`` times that entry -- and returns the first matrix that fails (-1: none).
The caller then runs :func:`~footprint_uq._checks.check_cov` itself for the one-line error, so the messages
stay those of the numpy checks; this only spares a clean frame its ~20 numpy calls (~50-80 us per frame of
100 detections on the 2026-11-26 VM, against ~1 us here).
"""

from __future__ import annotations

import math

import numba as nb

__all__ = ["first_bad_cov2"]


@nb.njit(cache=True, nogil=True)
def first_bad_cov2(c, tol):  # pragma: no cover - compiled
    """Index of the first of the (M, 2, 2) matrices ``c`` (C-contiguous float64) that is not a finite symmetric
    positive semi-definite covariance within ``tol`` (relative), or -1."""
    for i in range(c.shape[0]):
        a, b, b2, d = c[i, 0, 0], c[i, 0, 1], c[i, 1, 0], c[i, 1, 1]
        if not (math.isfinite(a) and math.isfinite(b) and math.isfinite(b2) and math.isfinite(d)):
            return i
        scale = max(max(abs(a), abs(d)), max(max(abs(b), abs(b2)), 1e-300))
        if abs(b - b2) > 1e-9 * scale:
            return i
        if 0.5 * (a + d) - math.hypot(0.5 * (a - d), b2) < -tol * scale:
            return i
    return -1
