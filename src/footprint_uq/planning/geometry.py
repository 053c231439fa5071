"""Plane geometry of the planner: points in polygons, the ground samples of a site, occlusion by prisms.

Occlusion test (geometric, exact for straight-walled prisms on a flat ground): the sight line from a
ground point ``p`` (height 0) to the camera centre ``c`` (height ``h``) rises linearly,
``z(s) = s h`` at the horizontal fraction ``s`` of the way from ``p`` to the foot point of ``c``.  It is
blocked by a prism of height ``H`` if ``p`` lies inside the prism's footprint (the ground there is
under the building) or if it crosses a wall of the footprint at some ``s`` with ``s h < H`` (it
passes the wall below its top).  A sight line that only grazes a wall's top edge (``s h == H``) is
not blocked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._checks import as_points

__all__ = ["points_in_polygon", "GroundSamples", "ground_samples", "occluded"]


def points_in_polygon(xy_m, polygon_m) -> np.ndarray:
    """Even-odd test: which points ``(..., 2)`` lie inside the polygon ``(N, 2)`` (closed implicitly).

    Returns a bool array ``(...)``; points exactly on an edge may fall either way.
    """
    xy = as_points("xy_m", xy_m, 2)
    poly = np.asarray(polygon_m, dtype=np.float64)
    x, y = xy[..., 0], xy[..., 1]
    inside = np.zeros(xy.shape[:-1], dtype=bool)
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    for a, b, c, d in zip(x0, y0, x1, y1, strict=True):  # loop over the few edges, vectorised over points
        crosses = (b > y) != (d > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xc = a + (y - b) * (c - a) / (d - b)
        inside ^= crosses & (x < xc)
    return inside


@dataclass
class GroundSamples:
    """The ground samples of a site: cell centres of a regular grid inside each zone.

    A point inside two zones is sampled once per zone (each zone is scored on its own requirement).

    Attributes
    ----------
    xy_world_m : (S, 2)        sample points, metres
    zone : (S,) int            index of the zone each sample belongs to
    area_m2 : float            ground area of one sample (resolution squared)
    cell : (S, 2) int          (row, column) of each sample in the raster ``grid_x_m`` x ``grid_y_m``
    grid_x_m, grid_y_m : (W,), (H,)   cell centres of the raster covering the site
    """

    xy_world_m: np.ndarray
    zone: np.ndarray
    area_m2: float
    cell: np.ndarray
    grid_x_m: np.ndarray
    grid_y_m: np.ndarray

    def __len__(self) -> int:
        return int(self.zone.shape[0])

    def thinned(self, step: int) -> GroundSamples:
        """Every ``step``-th cell in both directions (``area_m2`` scaled by ``step^2``): a coarser grid
        for screening the candidates."""
        if step == 1:
            return self
        keep = (self.cell[:, 0] % step == 0) & (self.cell[:, 1] % step == 0)
        return GroundSamples(self.xy_world_m[keep], self.zone[keep], self.area_m2 * step * step, self.cell[keep],
                             self.grid_x_m, self.grid_y_m)


def ground_samples(site) -> GroundSamples:
    """Sample every zone of ``site`` on a grid of ``site.resolution_m`` aligned with the site's bounds."""
    r = site.resolution_m
    x0, y0, x1, y1 = site.bounds_m(r)
    gx = x0 + r * (0.5 + np.arange(int(np.ceil((x1 - x0) / r))))
    gy = y0 + r * (0.5 + np.arange(int(np.ceil((y1 - y0) / r))))
    xx, yy = np.meshgrid(gx, gy)
    pts = np.stack([xx, yy], -1)
    rows, cols = np.indices(xx.shape)
    xy, zone, cell = [], [], []
    for k, z in enumerate(site.zones):
        m = points_in_polygon(pts, z.polygon_m)
        xy.append(pts[m])
        zone.append(np.full(int(m.sum()), k))
        cell.append(np.stack([rows[m], cols[m]], -1))
    return GroundSamples(np.concatenate(xy, 0), np.concatenate(zone), r * r, np.concatenate(cell, 0), gx, gy)


def occluded(xy_world_m, camera_xyz_m, occluders) -> np.ndarray:
    """Which ground points ``(S, 2)`` the camera centre ``(x, y, height above ground)`` cannot see.

    ``occluders`` are objects with ``polygon_m (N, 2)`` and ``height_m`` (see the module docstring for
    the test).  Returns ``(S,)`` bool.
    """
    p = as_points("xy_world_m", xy_world_m, 2)
    c = np.asarray(camera_xyz_m, dtype=np.float64)
    blocked = np.zeros(p.shape[:-1], dtype=bool)
    d = c[:2] - p  # p + s d, s in [0, 1]
    for occ in occluders:
        poly = np.asarray(occ.polygon_m, dtype=np.float64)
        lo, hi = poly.min(0), poly.max(0)
        # only points whose sight line's bounding box meets the footprint's
        near = (np.minimum(p[:, 0], c[0]) <= hi[0]) & (np.maximum(p[:, 0], c[0]) >= lo[0]) & \
               (np.minimum(p[:, 1], c[1]) <= hi[1]) & (np.maximum(p[:, 1], c[1]) >= lo[1]) & ~blocked
        idx = np.flatnonzero(near)
        if idx.size == 0:
            continue
        blocked[idx] |= points_in_polygon(p[idx], poly)
        s_max = min(1.0, occ.height_m / c[2]) if c[2] > 0 else 1.0
        pi, di = p[idx], d[idx]
        for a, b in zip(poly, np.roll(poly, -1, 0), strict=True):
            e = b - a
            den = di[:, 0] * e[1] - di[:, 1] * e[0]
            with np.errstate(divide="ignore", invalid="ignore"):
                s = ((a[0] - pi[:, 0]) * e[1] - (a[1] - pi[:, 1]) * e[0]) / den
                t = ((a[0] - pi[:, 0]) * di[:, 1] - (a[1] - pi[:, 1]) * di[:, 0]) / den
            hit = (den != 0) & (s >= 0) & (s < s_max) & (t >= 0) & (t <= 1)
            blocked[idx] |= hit
    return blocked
