"""One-line input checks used at the entry of public functions."""

from __future__ import annotations

import math

import numpy as np

from .errors import InputError

__all__ = ["as_points", "check_finite", "check_positive", "check_cov", "cov2_faults", "as_float"]


def as_points(name: str, a, last: int) -> np.ndarray:
    """Return ``a`` as a float64 array of shape ``(..., last)`` or raise InputError."""
    try:
        arr = np.asarray(a, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(name, a, f"numbers in an array of shape (..., {last})") from None
    if arr.ndim == 0 or arr.shape[-1] != last:
        raise InputError(name, getattr(a, "shape", a) if arr.ndim else a,
                         f"an array of shape (..., {last})")
    return arr


def as_float(name: str, value, *, positive: bool = False, nonnegative: bool = False,
             lo: float | None = None, hi: float | None = None) -> float:
    """Return ``value`` as a finite float, checking the requested bounds."""
    if isinstance(value, bool | np.bool_):
        raise InputError(name, value, "a number, not a boolean")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(name, value, "a number") from None
    if not math.isfinite(x):  # (numpy's isfinite on one float costs ~10x more)
        raise InputError(name, value, "a finite number")
    if positive and not x > 0:
        raise InputError(name, value, "a finite number > 0")
    if nonnegative and not x >= 0:
        raise InputError(name, value, "a finite number >= 0")
    if lo is not None and x < lo:
        raise InputError(name, value, f"a number >= {lo}")
    if hi is not None and x > hi:
        raise InputError(name, value, f"a number <= {hi}")
    return x


def as_int(name: str, value, *, minimum: int, expected: str) -> int:
    """Return ``value`` as an int equal to it and ``>= minimum``, else :class:`InputError` with ``expected``
    ("a positive integer"); infinities and NaN included."""
    try:
        n = int(value)
    except (TypeError, ValueError, OverflowError):
        raise InputError(name, value, expected) from None
    if n != value or n < minimum:
        raise InputError(name, value, expected)
    return n


def check_finite(name: str, a: np.ndarray) -> np.ndarray:
    if not np.all(np.isfinite(a)):
        bad = np.argwhere(~np.isfinite(a))[0]
        raise InputError(f"{name}[{', '.join(map(str, bad))}]", a[tuple(bad)], "a finite number")
    return a


def check_positive(name: str, a: np.ndarray) -> np.ndarray:
    if not np.all(a > 0):
        bad = np.argwhere(~(a > 0))[0]
        raise InputError(f"{name}[{', '.join(map(str, bad))}]", a[tuple(bad)], "a number > 0")
    return a


#: check_cov's default tolerance: an eigenvalue may be this far below 0, relative to the matrix's largest entry
COV_PSD_RTOL = 1e-12


def check_cov(name: str, cov, n: int, *, tol: float = COV_PSD_RTOL) -> np.ndarray:
    """Check a symmetric positive semi-definite ``(..., n, n)`` covariance."""
    c = np.asarray(cov, dtype=np.float64)
    if c.ndim < 2 or c.shape[-2:] != (n, n):
        raise InputError(name, getattr(cov, "shape", cov), f"a covariance of shape (..., {n}, {n})")
    check_finite(name, c)
    if n == 2:  # the per-frame case (a detector's pixel covariances): closed form, no LAPACK call per matrix
        return _check_cov_2x2(name, c, tol)
    return _check_cov_eig(name, c, tol)


def _check_cov_eig(name: str, c: np.ndarray, tol: float) -> np.ndarray:
    """:func:`check_cov` of finite (..., n, n) matrices by their eigenvalues (LAPACK)."""
    scale = np.maximum(np.abs(c).max(axis=(-2, -1), keepdims=True), 1e-300)
    asym = np.any(np.abs(c - np.swapaxes(c, -1, -2)) > 1e-9 * scale, axis=(-2, -1))
    if np.any(asym):
        raise InputError(_at(name, asym), "non-symmetric matrix", "a symmetric covariance matrix")
    w = np.linalg.eigvalsh(c)
    neg = np.any(w < -tol * scale[..., 0], axis=-1)
    if np.any(neg):
        raise InputError(_at(name, neg), f"min eigenvalue {w.min():.3g}",
                         "a positive semi-definite covariance matrix")
    return c


def cov2_faults(c: np.ndarray, tol: float = COV_PSD_RTOL) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per finite ``(..., 2, 2)`` matrix: ``(asym, neg, w_min)`` -- not symmetric (beyond 1e-9 of its largest
    entry), not positive semi-definite (smallest eigenvalue below ``-tol`` times that scale), and the smaller
    eigenvalue of ``[[a, b], [c, d]]`` as ``(a + d) / 2 - hypot((a - d) / 2, c)`` in closed form (its rounding
    error, ~1e-16 of the scale, is far below the tolerance).  The tests of :func:`check_cov`, row by row (the
    service reports each bad detection, not only the first)."""
    a, b, b2, d = c[..., 0, 0], c[..., 0, 1], c[..., 1, 0], c[..., 1, 1]
    scale = np.maximum(np.maximum(np.maximum(np.abs(a), np.abs(d)), np.maximum(np.abs(b), np.abs(b2))), 1e-300)
    asym = np.abs(b - b2) > 1e-9 * scale
    w_min = 0.5 * (a + d) - np.hypot(0.5 * (a - d), b2)  # the lower triangle, as eigvalsh reads it
    return asym, w_min < -tol * scale, w_min


def _check_cov_2x2(name: str, c: np.ndarray, tol: float) -> np.ndarray:
    """:func:`check_cov` of finite (..., 2, 2) matrices: the same tests and messages (:func:`cov2_faults`)."""
    asym, neg, w_min = cov2_faults(c, tol)
    if asym.any():
        raise InputError(_at(name, asym), "non-symmetric matrix", "a symmetric covariance matrix")
    if neg.any():
        raise InputError(_at(name, neg), f"min eigenvalue {w_min.min():.3g}",
                         "a positive semi-definite covariance matrix")
    return c


def _at(name: str, bad: np.ndarray) -> str:
    """``name`` with the index of the first True entry of ``bad`` (the offending matrix of a batch)."""
    if np.ndim(bad) == 0:
        return name
    return f"{name}[{', '.join(map(str, np.argwhere(bad)[0]))}]"
