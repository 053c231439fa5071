"""The service's small compiled passes over a frame's columns (kept apart from :mod:`.core`, whose edits then
leave numba's cache of every kernel valid: the package's cache key covers every file that holds a kernel)."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .messages.cpm import COORD_GUARD_CM, COORD_MAX, COORD_MIN
from .messages.sdsm import OFFSET_MAX

__all__ = ["worst_usable", "cm_dm"]


@njit(cache=True, nogil=True)
def worst_usable(nl, usable, threshold, worst, ok):  # pragma: no cover - compiled
    """Per row of ``nl (N, K)``: the largest finite value among the ``usable`` ones into ``worst`` (NaN if none)
    and ``ok`` = that <= ``threshold`` (False if none): :meth:`.core.Service._linearity` in one pass."""
    for i in range(nl.shape[0]):
        w = -math.inf
        found = False
        for k in range(nl.shape[1]):
            v = nl[i, k]
            if usable[i, k] and math.isfinite(v):
                found = True
                w = max(w, v)
        worst[i] = w if found else math.nan
        ok[i] = found and w <= threshold


@njit(cache=True, nogil=True)
def _cm_dm_kernel(en, rows, cm_min, cm_max, dm_max, cm_guard):  # pragma: no cover - compiled
    out = np.empty((4, rows.shape[0]), np.int64)
    for j in range(rows.shape[0]):
        for a in range(2):
            v = en[rows[j], a]
            if v != v:  # NaN -> 0, as numpy.nan_to_num (only from absurd coordinates: inf - inf)
                v = 0.0
            c = np.ceil(v * 100.0 - cm_guard)  # CartesianCoordinateLarge: (n-1) x 0.01 < v <= n x 0.01
            d = np.rint(v * 10.0)
            out[a, j] = int(min(max(c, cm_min), cm_max))
            out[2 + a, j] = int(min(max(d, -dm_max), dm_max))
    return out


def cm_dm(en: np.ndarray, rows: np.ndarray):
    """:func:`~.messages.cpm.coordinate_cm` and :func:`~.messages.sdsm.offset_dm` of the east/north metres
    ``en[rows]``: x cm, y cm, x dm, y dm (the same numbers in one compiled pass)."""
    return _cm_dm_kernel(np.ascontiguousarray(en, dtype=np.float64), np.asarray(rows, dtype=np.int64),
                         float(COORD_MIN), float(COORD_MAX), float(OFFSET_MAX), COORD_GUARD_CM)
