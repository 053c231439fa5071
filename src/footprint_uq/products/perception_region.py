"""Where a camera's positions are good enough: its perception region, from the uncertainty model itself.

A receiver of a Collective Perception Message (ETSI TS 103 324) learns from the Sensor Information and the
Perception Region containers *where* the sender perceives, so that the absence of an object there means absence.
For a camera, "perceives" depends on how precisely it places an object: this module computes the ground region in
which the camera's 95 % position ellipse has a semi-major axis at most ``max_semi_major_m`` (default 1 m), for the
camera's calibration and error budget, and simplifies it to the polygon a CPM can carry (``PolygonalShape``: 3 to
16 vertices).

How
---
1. A coarse scan of the image (``covariance_points`` on a pixel grid) bounds the region on the ground.
2. A ground grid of ``cell_m`` cells over that bound is projected into the image (``project_ground``); every cell
   centre seen by the camera gets its covariance (``covariance_points``) and its 95 % semi-major axis; the mask is
   the cells where it is at most the limit (the largest connected part is kept).
3. The mask's outline is simplified (Douglas-Peucker, ``cv2.approxPolyDP``) to at most ``max_vertices`` vertices,
   after eroding the mask by ``r`` cells, ``r = 1, 2, ...``, until the polygon is **inside** the region: every grid
   cell whose centre lies in the polygon is in the mask, and points along every edge (every ``cell_m / 2``),
   evaluated afresh, have a semi-major axis at most the limit.  The polygon is conservative: a point inside it
   satisfies the limit; the region's cells it leaves out are counted (``coverage``).

The polygon is in the world frame W (metres, counter-clockwise in W's x-y plane); :func:`polygon_east_north_cm`
gives the CPM's offsets from a reference position.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from matplotlib.path import Path as _Path

from .._checks import as_float, as_int
from ..errors import InputError
from ..uncertainty.budget import load_budget
from ..uncertainty.ellipse import ellipse_axes
from .covariance import covariance_points

__all__ = ["PerceptionRegion", "perception_region", "semi_major_at", "polygon_east_north_cm"]

#: the CDD's PolygonalShape: ``SequenceOfCartesianPosition3d (SIZE(3..16,...))``
CPM_MAX_POLYGON_VERTICES = 16


@dataclass(frozen=True)
class PerceptionRegion:
    """A camera's perception region (see the module doc).

    Attributes
    ----------
    polygon_xy_world_m : ndarray (M, 2)
        Vertices in the world frame W (m), counter-clockwise, not repeated at the end; 3 <= M <= max_vertices.
    max_semi_major_m, confidence : float
        The limit on the ellipse's semi-major axis (m) and the ellipse's probability.
    cell_m : float
        The ground grid's cell size (m).
    area_m2, region_area_m2 : float
        The polygon's area, and the area of the grid cells where the limit holds (the largest connected part).
    coverage : float
        ``area_m2 / region_area_m2`` (<= 1 up to a cell along the outline): how much of the region the polygon
        keeps.
    erosion_cells : int
        How many cells the mask was eroded by before its simplified outline was inside the region.
    max_semi_major_inside_m : float
        The largest semi-major axis found inside the polygon (grid cells and edge samples): <= the limit.
    outside_gap_m : float
        How far the region reaches beyond the polygon: the largest distance from a region cell's centre outside
        the polygon to the polygon (m); beyond it (plus a cell) every point is outside the region.
    """

    polygon_xy_world_m: np.ndarray
    max_semi_major_m: float
    confidence: float
    cell_m: float
    area_m2: float
    region_area_m2: float
    coverage: float
    erosion_cells: int
    max_semi_major_inside_m: float
    outside_gap_m: float


def semi_major_at(camera, budget, xy_world_m, *, confidence: float = 0.95) -> np.ndarray:
    """Semi-major axis (m) of the ``confidence`` ellipse of a point seen at ground points ``(..., 2)``.

    ``inf`` where the camera does not see the point (behind it, outside the image, beyond the horizon).
    """
    xy = np.asarray(xy_world_m, dtype=np.float64)
    lead = xy.shape[:-1]
    flat = xy.reshape(-1, 2)
    out = np.full(flat.shape[0], np.inf)
    pr = camera.project_ground(flat)
    W, H = camera.image_size_px
    uv = pr.uv_px
    seen = pr.valid & np.all(np.isfinite(uv), axis=-1)
    seen &= (uv[:, 0] >= 0) & (uv[:, 0] <= W) & (uv[:, 1] >= 0) & (uv[:, 1] <= H)
    if np.any(seen):
        _, cov, valid = covariance_points(camera, budget, uv[seen])
        a, _, _ = ellipse_axes(cov, confidence=confidence)
        out[np.flatnonzero(seen)] = np.where(valid & np.isfinite(a), a, np.inf)
    return out.reshape(lead)


def _ground_bounds(camera, budget, limit_m: float, confidence: float, n: int = 48):
    """Bounding box (x0, y0, x1, y1) of the ground points of a pixel scan whose semi-major is within 1.5 x the
    limit, or None where no pixel meets the limit."""
    W, H = camera.image_size_px
    u, v = np.meshgrid(np.linspace(0.0, W, n + 1), np.linspace(0.0, H, n + 1))
    xy, cov, valid = covariance_points(camera, budget, np.stack([u, v], -1).reshape(-1, 2))
    a, _, _ = ellipse_axes(cov, confidence=confidence)
    ok = valid & np.isfinite(a)
    if not np.any(ok & (a <= limit_m)):
        return None
    near = xy[ok & (a <= 1.5 * limit_m)]
    lo, hi = near.min(axis=0), near.max(axis=0)
    pad = 0.05 * float(np.max(hi - lo)) + 1e-6
    return lo[0] - pad, lo[1] - pad, hi[0] + pad, hi[1] + pad


def _largest_part(mask: np.ndarray) -> np.ndarray:
    n, labels, stats, _ = cv2.connectedComponentsWithStats(mask.astype(np.uint8), connectivity=4)
    if n <= 1:
        return np.zeros_like(mask)
    best = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
    return labels == best


def _outline(mask: np.ndarray, max_vertices: int) -> np.ndarray | None:
    """The simplified outer outline (K, 2) in grid (col, row) units of the largest part of ``mask``."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return None
    c = max(contours, key=cv2.contourArea)
    if len(c) < 3:
        return None
    eps = 0.5
    while True:
        poly = cv2.approxPolyDP(c, eps, True).reshape(-1, 2).astype(np.float64)
        if 3 <= len(poly) <= max_vertices:
            return poly
        if len(poly) < 3:
            return None
        eps *= 1.25


def _signed_area(p: np.ndarray) -> float:
    x, y = p[:, 0], p[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def _edge_samples(poly: np.ndarray, step_m: float) -> np.ndarray:
    pts = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        k = max(2, int(np.ceil(np.linalg.norm(b - a) / step_m)) + 1)
        t = np.linspace(0.0, 1.0, k)[:, None]
        pts.append(a + t * (b - a))
    return np.concatenate(pts)


def _distance_to_polygon(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Distance (m) of points ``(N, 2)`` to the closed polyline ``poly`` ``(M, 2)``."""
    a, b = poly, np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.einsum("nmk,mk->nm", points[:, None, :] - a[None], ab) / np.maximum(np.einsum("mk,mk->m", ab, ab), 1e-300)
    foot = a[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.min(np.linalg.norm(points[:, None, :] - foot, axis=-1), axis=1)


def _check_args(max_semi_major_m, confidence, cell_m, max_vertices):
    limit = as_float("max_semi_major_m", max_semi_major_m, positive=True)
    conf = as_float("confidence", confidence, lo=0.0, hi=1.0)
    if not 0.0 < conf < 1.0:
        raise InputError("confidence", confidence, "a probability in (0, 1)")
    if cell_m is not None:
        cell_m = as_float("cell_m", cell_m, positive=True)
    nv = as_int("max_vertices", max_vertices, minimum=3, expected="an integer >= 3 (vertices)")
    return limit, conf, cell_m, nv


def perception_region(camera, budget, *, max_semi_major_m: float = 1.0, confidence: float = 0.95,
                      cell_m: float | None = None, max_vertices: int = CPM_MAX_POLYGON_VERTICES,
                      max_cells: int = 400) -> PerceptionRegion | None:
    """The ground region where the camera's ``confidence`` ellipse has semi-major <= ``max_semi_major_m``.

    Parameters
    ----------
    camera : Camera
    budget : ErrorBudget, preset name, path or mapping
    max_semi_major_m : float
        The limit (m) on the semi-major axis of the position ellipse.
    confidence : float
        The ellipse's probability (2-D), 0.95 as in the CPM's confidence fields.
    cell_m : float, optional
        The ground grid's cell (m); default: the region's bound / ``max_cells``.
    max_vertices : int
        At most this many vertices (the CPM's ``PolygonalShape`` takes 16).

    Returns
    -------
    PerceptionRegion, or None where no point of the image meets the limit.
    """
    limit, conf, cell_m, nv = _check_args(max_semi_major_m, confidence, cell_m, max_vertices)
    budget = load_budget(budget)
    bounds = _ground_bounds(camera, budget, limit, conf)
    if bounds is None:
        return None
    x0, y0, x1, y1 = bounds
    if cell_m is None:
        cell_m = max(x1 - x0, y1 - y0) / max_cells
    nx, ny = int(np.ceil((x1 - x0) / cell_m)) + 1, int(np.ceil((y1 - y0) / cell_m)) + 1
    gx, gy = np.meshgrid(x0 + cell_m * np.arange(nx), y0 + cell_m * np.arange(ny))
    centres = np.stack([gx, gy], -1)                       # (ny, nx, 2): row j ~ y, column i ~ x
    semi = semi_major_at(camera, budget, centres, confidence=conf)
    mask = _largest_part(semi <= limit)
    if not np.any(mask):
        return None
    return _fit_polygon(camera, budget, mask, semi, centres, (x0, y0, cell_m), limit, conf, nv)


def _fit_polygon(camera, budget, mask, semi, centres, grid, limit, conf, nv) -> PerceptionRegion | None:
    x0, y0, cell_m = grid
    kernel = np.ones((3, 3), np.uint8)
    region_area = float(mask.sum()) * cell_m ** 2
    for r in range(1, 64):
        m = cv2.erode(mask.astype(np.uint8), kernel, iterations=r).astype(bool)
        if not np.any(m):
            return None
        outline = _outline(m, nv)
        if outline is None:
            return None
        poly = np.column_stack([x0 + cell_m * outline[:, 0], y0 + cell_m * outline[:, 1]])
        if _signed_area(poly) < 0:
            poly = poly[::-1]
        inside = _Path(poly).contains_points(centres.reshape(-1, 2)).reshape(mask.shape)
        if np.any(inside & ~mask):
            continue
        edge = semi_major_at(camera, budget, _edge_samples(poly, 0.5 * cell_m), confidence=conf)
        if np.all(edge <= limit):
            worst = max(float(np.max(edge)), float(np.max(semi[inside], initial=0.0)))
            left_out = centres[mask & ~inside]
            gap = float(np.max(_distance_to_polygon(left_out, poly), initial=0.0)) if len(left_out) else 0.0
            area = _signed_area(poly)
            return PerceptionRegion(poly, limit, conf, cell_m, area, region_area, area / region_area, r, worst, gap)
    return None


def polygon_east_north_cm(polygon_xy_world_m, reference_xy_world_m, heading_offset_deg: float = 0.0) -> np.ndarray:
    """Polygon vertices as the CPM's offsets from its reference position: ``(M, 2)`` int, 0.01 m east, north.

    ``heading_offset_deg`` is the compass bearing of W's +y axis, as in :mod:`footprint_uq.products.v2x`
    (0: W is already east/north).  Vertices are rounded to the nearest centimetre.
    """
    p = np.asarray(polygon_xy_world_m, dtype=np.float64) - np.asarray(reference_xy_world_m, dtype=np.float64)
    h = np.deg2rad(as_float("heading_offset_deg", heading_offset_deg))
    ch, sh = np.cos(h), np.sin(h)
    east = ch * p[:, 0] + sh * p[:, 1]
    north = -sh * p[:, 0] + ch * p[:, 1]
    return np.rint(np.column_stack([east, north]) * 100.0).astype(np.int64)
