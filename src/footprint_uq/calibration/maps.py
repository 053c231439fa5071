"""The paper's two calibration maps on a grid of square image cells.

1. **Coverage** (:func:`coverage_map`): for every board used in the calibration,
   the convex hull of the board in the image; each grid cell whose **centre**
   lies inside the hull counts one.  The result is the number of boards seen by
   every cell (the paper uses 5 px cells).  The hull is taken over the detected
   inner corners (``hull="corners"``, what was actually measured) or over the
   outer edge of the squares projected with the calibrated pose and lens
   (``hull="squares"``, the whole printed pattern).
2. **Reprojection error** (:func:`reprojection_error_map`): every detected corner
   falls in one cell (by its detected position); the map is the mean, over the
   corners in a cell, of the reprojection-error magnitude ``|detected -
   reprojected|`` (px); NaN where a cell holds no corner.  The mean residual
   *vector* per cell is kept too: a systematic error left over by the lens model
   shows as coherent vectors, noise as vectors that average out.

Asymmetry (:func:`error_asymmetry`) -- the paper looks for error that radial and
tangential distortion do not explain.  Those models are (nearly) point-symmetric
about the principal point, so we compare the mean error of each cell with that
of its **point reflection through the principal point** ``p' = 2 c - p``, on a
coarser grid (default 40 px, so that most cells hold corners):

* ``reflection_map[cell] = E(p) - E(p')`` (px), NaN where either cell is empty;
* ``reflection_index = sum |E(p) - E(p')| / sum (E(p) + E(p'))`` over all
  pairs, in [0, 1]: 0 is perfectly point-symmetric;
* ``left_right = (Ē_right - Ē_left) / (Ē_right + Ē_left)`` with Ē the mean
  error of all corners right (u > cx) or left of the principal point, in
  [-1, 1]; ``top_bottom`` likewise with bottom (v > cy) minus top;
* a yardstick for noise: the same reflection index after randomly permuting the
  error magnitudes among the corners (``n_permutations``, seeded), which
  destroys any spatial structure.  ``reflection_index_null_p95`` is its 95th
  percentile and ``reflection_p_value`` the fraction of permutations reaching
  the observed index; an index well above the null points to a real,
  position-dependent error.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from .._checks import as_float, as_points
from ..errors import InputError

__all__ = ["grid_shape", "cell_centres", "coverage_map", "reprojection_error_map", "error_asymmetry",
           "CoverageMap", "ErrorMap"]


def _check_size(image_size_px):
    try:
        w, h = (int(v) for v in image_size_px)
    except (TypeError, ValueError):
        raise InputError("image_size_px", image_size_px, "(width, height) in pixels") from None
    if w <= 0 or h <= 0:
        raise InputError("image_size_px", image_size_px, "two positive integers (width, height)")
    return w, h


def grid_shape(image_size_px, cell_px: float) -> tuple[int, int]:
    """``(ny, nx)`` cells covering an image of ``(width, height)`` px with square cells of ``cell_px``."""
    w, h = _check_size(image_size_px)
    c = as_float("grid_px", cell_px, positive=True)
    return int(np.ceil(h / c)), int(np.ceil(w / c))


def cell_centres(image_size_px, cell_px: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell-centre pixel coordinates ``(u (nx,), v (ny,))``; pixel centres are integers, cell 0 starts at -0.5."""
    ny, nx = grid_shape(image_size_px, cell_px)
    return (np.arange(nx) + 0.5) * cell_px - 0.5, (np.arange(ny) + 0.5) * cell_px - 0.5


def _cell_index(uv: np.ndarray, image_size_px, cell_px: float):
    ny, nx = grid_shape(image_size_px, cell_px)
    ix = np.floor((uv[:, 0] + 0.5) / cell_px).astype(np.int64)
    iy = np.floor((uv[:, 1] + 0.5) / cell_px).astype(np.int64)
    inside = (ix >= 0) & (ix < nx) & (iy >= 0) & (iy < ny) & np.isfinite(uv).all(-1)
    return iy, ix, inside


@dataclass
class CoverageMap:
    """Number of boards covering each cell: ``count (ny, nx)``; cells of ``cell_px``."""

    count: np.ndarray
    cell_px: float
    image_size_px: tuple[int, int]
    n_boards: int

    def summary(self) -> dict:
        c = self.count
        ny, nx = c.shape
        k = max(1, int(round(0.1 * min(nx, ny))))  # 10 % corner patches
        corners = np.concatenate([c[:k, :k].ravel(), c[:k, -k:].ravel(), c[-k:, :k].ravel(), c[-k:, -k:].ravel()])
        return {
            "cell_px": float(self.cell_px), "n_boards": int(self.n_boards),
            "covered_fraction": float(np.mean(c > 0)),
            "max_boards_per_cell": int(c.max()) if c.size else 0,
            "mean_boards_per_cell": float(c.mean()) if c.size else 0.0,
            "image_corner_patches_covered_fraction": float(np.mean(corners > 0)),
        }


def coverage_map(outlines_px, image_size_px, cell_px: float = 5.0) -> CoverageMap:
    """Count, per grid cell, the boards whose convex hull contains the cell centre.

    Parameters
    ----------
    outlines_px : sequence of array_like (M_i, 2)
        Per board, image points (px) whose convex hull is the board's footprint
        in the image (its detected corners, or its projected outline).
    image_size_px : (int, int)
        ``(width, height)``.
    cell_px : float
        Side of a grid cell in pixels (the paper: 5).

    Returns
    -------
    CoverageMap
        ``count`` has shape ``(ny, nx) = grid_shape(image_size_px, cell_px)``.
    """

    ny, nx = grid_shape(image_size_px, cell_px)
    uc, vc = cell_centres(image_size_px, cell_px)
    count = np.zeros((ny, nx), dtype=np.int32)
    n = 0
    for i, pts in enumerate(outlines_px):
        p = as_points(f"outlines_px[{i}]", pts, 2).reshape(-1, 2)
        p = p[np.isfinite(p).all(-1)]
        if len(p) < 3:
            continue
        hull = cv2.convexHull(p.astype(np.float32)).reshape(-1, 2).astype(np.float64)
        n += 1
        if len(hull) < 3:
            continue
        jx = np.nonzero((uc >= hull[:, 0].min()) & (uc <= hull[:, 0].max()))[0]
        jy = np.nonzero((vc >= hull[:, 1].min()) & (vc <= hull[:, 1].max()))[0]
        if jx.size == 0 or jy.size == 0:
            continue
        U, V = np.meshgrid(uc[jx], vc[jy])
        a, b = hull, np.roll(hull, -1, axis=0)
        cross = ((b[:, 0] - a[:, 0])[:, None, None] * (V[None] - a[:, 1, None, None])
                 - (b[:, 1] - a[:, 1])[:, None, None] * (U[None] - a[:, 0, None, None]))
        inside = np.all(cross >= 0, axis=0) | np.all(cross <= 0, axis=0)
        count[np.ix_(jy, jx)] += inside
    return CoverageMap(count, float(cell_px), _check_size(image_size_px), n)


@dataclass
class ErrorMap:
    """Per-cell reprojection error statistics on a grid of ``cell_px`` cells.

    Attributes
    ----------
    mean_error_px : ndarray (ny, nx)
        Mean of ``|residual|`` over the corners in the cell, px; NaN where empty.
    count : ndarray (ny, nx) of int
        Corners per cell.
    mean_residual_px : ndarray (ny, nx, 2)
        Mean residual vector ``detected - reprojected`` (du, dv), px; NaN where empty.
    """

    mean_error_px: np.ndarray
    count: np.ndarray
    mean_residual_px: np.ndarray
    cell_px: float
    image_size_px: tuple[int, int]

    def summary(self) -> dict:
        e = self.mean_error_px
        ok = np.isfinite(e)
        if not ok.any():
            return {"cell_px": float(self.cell_px), "cells_with_corners": 0}
        iy, ix = np.unravel_index(np.nanargmax(e), e.shape)
        return {
            "cell_px": float(self.cell_px), "cells_with_corners": int(ok.sum()),
            "max_cell_mean_error_px": float(e[iy, ix]),
            "max_cell_centre_px": [float((ix + 0.5) * self.cell_px - 0.5), float((iy + 0.5) * self.cell_px - 0.5)],
            "max_cell_corners": int(self.count[iy, ix]),
            "median_cell_mean_error_px": float(np.nanmedian(e)),
        }


def reprojection_error_map(points_px, residuals_px, image_size_px, cell_px: float = 5.0) -> ErrorMap:
    """Mean reprojection error per grid cell.

    Parameters
    ----------
    points_px : array_like (N, 2)
        Detected corner positions (bin positions), px.
    residuals_px : array_like (N, 2)
        ``detected - reprojected``, px.
    image_size_px : (int, int)
    cell_px : float

    Returns
    -------
    ErrorMap
    """
    p = as_points("points_px", points_px, 2).reshape(-1, 2)
    r = as_points("residuals_px", residuals_px, 2).reshape(-1, 2)
    if p.shape != r.shape:
        raise InputError("residuals_px", f"shape {r.shape}", f"the shape of points_px {p.shape}")
    ny, nx = grid_shape(image_size_px, cell_px)
    iy, ix, inside = _cell_index(p, image_size_px, cell_px)
    inside &= np.isfinite(r).all(-1)
    flat = iy[inside] * nx + ix[inside]
    rr = r[inside]
    n = np.bincount(flat, minlength=nx * ny)
    s = np.bincount(flat, weights=np.linalg.norm(rr, axis=-1), minlength=nx * ny)
    su = np.bincount(flat, weights=rr[:, 0], minlength=nx * ny)
    sv = np.bincount(flat, weights=rr[:, 1], minlength=nx * ny)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, s / n, np.nan).reshape(ny, nx)
        mres = np.stack([np.where(n > 0, su / n, np.nan), np.where(n > 0, sv / n, np.nan)], -1).reshape(ny, nx, 2)
    return ErrorMap(mean, n.reshape(ny, nx).astype(np.int32), mres, float(cell_px), _check_size(image_size_px))


def _reflection(err: np.ndarray, iy, ix, principal_point_px, image_size_px, cell_px):
    ny, nx = grid_shape(image_size_px, cell_px)
    flat = iy * nx + ix
    n = np.bincount(flat, minlength=nx * ny)
    s = np.bincount(flat, weights=err, minlength=nx * ny)
    with np.errstate(invalid="ignore", divide="ignore"):
        E = np.where(n > 0, s / n, np.nan).reshape(ny, nx)
    uc, vc = cell_centres(image_size_px, cell_px)
    U, V = np.meshgrid(uc, vc)
    pr = np.stack([2 * principal_point_px[0] - U, 2 * principal_point_px[1] - V], -1).reshape(-1, 2)
    jy, jx, ok = _cell_index(pr, image_size_px, cell_px)
    Er = np.full(ny * nx, np.nan)
    Er[ok] = E.ravel()[jy[ok] * nx + jx[ok]]
    Er = Er.reshape(ny, nx)
    D = E - Er
    pair = np.isfinite(D)
    denom = np.sum((E + Er)[pair])
    index = float(np.sum(np.abs(D[pair])) / denom) if denom > 0 else float("nan")
    return D, index, int(pair.sum())


def error_asymmetry(points_px, residuals_px, principal_point_px, image_size_px, *, cell_px: float = 40.0,
                    n_permutations: int = 200, seed: int = 0) -> dict:
    """Asymmetry of the reprojection error about the principal point (definitions in the module docstring).

    Parameters
    ----------
    points_px, residuals_px : array_like (N, 2)
        Detected corners and their residuals (px).
    principal_point_px : (float, float)
        ``(cx, cy)``.
    image_size_px : (int, int)
    cell_px : float
        Cell size of the reflection comparison (coarser than the display map).
    n_permutations : int
        Permutations for the noise yardstick (0 to skip).
    seed : int

    Returns
    -------
    dict
        ``reflection_map_px (ny, nx)`` (array) and JSON-ready scalars:
        ``reflection_index``, ``reflection_pairs``, ``reflection_index_null_mean``,
        ``reflection_index_null_p95``, ``reflection_p_value``, ``left_right``,
        ``top_bottom``, ``mean_error_left_px``, ``mean_error_right_px``,
        ``mean_error_top_px``, ``mean_error_bottom_px``, ``residual_coherence``.
    """
    p = as_points("points_px", points_px, 2).reshape(-1, 2)
    r = as_points("residuals_px", residuals_px, 2).reshape(-1, 2)
    cx, cy = (float(v) for v in principal_point_px)
    iy, ix, inside = _cell_index(p, image_size_px, cell_px)
    inside &= np.isfinite(r).all(-1)
    p, r, iy, ix = p[inside], r[inside], iy[inside], ix[inside]
    err = np.linalg.norm(r, axis=-1)
    D, index, pairs = _reflection(err, iy, ix, (cx, cy), image_size_px, cell_px)
    out: dict = {"cell_px": float(cell_px), "reflection_map_px": D, "reflection_index": index,
                 "reflection_pairs": pairs}
    if n_permutations > 0 and err.size > 1:
        rng = np.random.default_rng(seed)
        null = np.array([_reflection(rng.permutation(err), iy, ix, (cx, cy), image_size_px, cell_px)[1]
                         for _ in range(int(n_permutations))])
        out["reflection_index_null_mean"] = float(np.nanmean(null))
        out["reflection_index_null_p95"] = float(np.nanpercentile(null, 95))
        out["reflection_p_value"] = float((1 + np.sum(null >= index)) / (1 + null.size))
        out["n_permutations"] = int(n_permutations)

    def _imb(a, b):
        if a.size == 0 or b.size == 0:
            return float("nan"), float("nan"), float("nan")
        ma, mb = float(a.mean()), float(b.mean())
        return ma, mb, (mb - ma) / (ma + mb) if ma + mb > 0 else float("nan")

    out["mean_error_left_px"], out["mean_error_right_px"], out["left_right"] = _imb(err[p[:, 0] < cx],
                                                                                   err[p[:, 0] > cx])
    out["mean_error_top_px"], out["mean_error_bottom_px"], out["top_bottom"] = _imb(err[p[:, 1] < cy],
                                                                                   err[p[:, 1] > cy])
    # coherence: |mean residual vector| / mean |residual| per coarse cell, corner-weighted average
    ny, nx = grid_shape(image_size_px, cell_px)
    flat = iy * nx + ix
    n = np.bincount(flat, minlength=nx * ny)
    su = np.bincount(flat, weights=r[:, 0], minlength=nx * ny)
    sv = np.bincount(flat, weights=r[:, 1], minlength=nx * ny)
    sm = np.bincount(flat, weights=err, minlength=nx * ny)
    ok = (n > 1) & (sm > 0)
    coh = np.hypot(su[ok], sv[ok]) / sm[ok]
    out["residual_coherence"] = float(np.sum(coh * n[ok]) / np.sum(n[ok])) if ok.any() else float("nan")
    return out
