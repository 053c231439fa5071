"""Find a checkerboard target in LiDAR scans and place its inner corners in 3D.

The LiDAR sees the board as a flat rectangle of known size.  For each scan:

1. optionally crop to a user region (:class:`Box` or :class:`Sphere`, LiDAR frame)
   and drop the ground (points within ``ground_clearance_m`` of a fitted or given
   ground plane, and below it);
2. fit planes with a seeded RANSAC (:func:`fit_plane_ransac`), largest first, and
   split each plane's inliers into connected patches;
3. keep the patch whose in-plane rectangle (:func:`fit_rectangle`) matches the
   board's outer size (squares x square size + 2 margins): the orientation from
   the minimum-area rectangle, the position by sliding a window of the board's
   known size over the patch (so a stand or a hand below the board, coplanar with
   it, does not shift it), then the centre as the middle of the extents of the
   points inside the window (beam-sampling gaps shrink both extents alike, so the
   middle is unbiased);
4. place the inner-corner grid (:meth:`BoardDetection.corners_m`) -> ``(N, 3)``
   corners in the LiDAR frame.

A plain rectangle does not tell which end of the board is which: the grid can be
placed in 4 ways (8 for a square grid) that fit the cloud equally well.
:meth:`BoardDetection.corner_candidates` returns them all; the extrinsic solver
(:mod:`.extrinsics`) picks the one consistent with the camera.

The ground frame: :func:`fit_ground_plane` fits the ground in the (pooled)
scans and :func:`ground_frame_from_plane` builds ``T_ground_lidar`` (4x4): z up
along the plane normal, origin at the foot of the LiDAR origin on the plane, x
along the LiDAR's x axis projected onto the plane, y = z x x.

A scan in which no board is found gives a :class:`BoardDetection` with
``found=False`` and a ``reason``; it never raises for that, so the other frames go on.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .._checks import as_float
from ..errors import InputError
from .boards import Checkerboard, parse_board

__all__ = ["Box", "Sphere", "parse_region", "PlaneFit", "fit_plane_ransac", "fit_ground_plane",
           "ground_frame_from_plane", "Rectangle", "fit_rectangle", "BoardDetection", "detect_board",
           "transform_points"]


# ---------------------------------------------------------------------------------------------
# regions
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Box:
    """Axis-aligned box in the LiDAR frame: ``min_m <= xyz <= max_m`` (metres)."""

    min_m: tuple[float, float, float]
    max_m: tuple[float, float, float]

    def __post_init__(self):
        lo, hi = np.asarray(self.min_m, float), np.asarray(self.max_m, float)
        if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)):
            raise InputError("region box", (self.min_m, self.max_m), "min and max corners of 3 finite numbers")
        if np.any(hi <= lo):
            raise InputError("region box", (self.min_m, self.max_m), "max > min on every axis")

    def contains(self, xyz_m) -> np.ndarray:
        """Mask ``(...)`` of the points ``(..., 3)`` inside the box."""
        p = np.asarray(xyz_m, float)
        return np.all((p >= np.asarray(self.min_m)) & (p <= np.asarray(self.max_m)), axis=-1)

    def to_dict(self) -> dict:
        return {"box": {"min_m": list(map(float, self.min_m)), "max_m": list(map(float, self.max_m))}}


@dataclass(frozen=True)
class Sphere:
    """Ball in the LiDAR frame: ``|xyz - centre_m| <= radius_m``."""

    centre_m: tuple[float, float, float]
    radius_m: float

    def __post_init__(self):
        c = np.asarray(self.centre_m, float)
        if c.shape != (3,) or not np.all(np.isfinite(c)):
            raise InputError("region sphere centre_m", self.centre_m, "3 finite numbers (metres)")
        as_float("region sphere radius_m", self.radius_m, positive=True)

    def contains(self, xyz_m) -> np.ndarray:
        p = np.asarray(xyz_m, float)
        return np.sum((p - np.asarray(self.centre_m)) ** 2, axis=-1) <= float(self.radius_m) ** 2

    def to_dict(self) -> dict:
        return {"sphere": {"centre_m": list(map(float, self.centre_m)), "radius_m": float(self.radius_m)}}


_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_region(spec):
    """A region from ``"box:x0,y0,z0,x1,y1,z1"``, ``"sphere:cx,cy,cz,r"``, a mapping, a Box/Sphere or None."""
    if spec is None or isinstance(spec, (Box, Sphere)):
        return spec
    if isinstance(spec, dict):
        if "box" in spec:
            b = spec["box"]
            return Box(tuple(b["min_m"]), tuple(b["max_m"]))
        if "sphere" in spec:
            s = spec["sphere"]
            return Sphere(tuple(s["centre_m"]), float(s["radius_m"]))
        raise InputError("region", spec, "a mapping with 'box' (min_m, max_m) or 'sphere' (centre_m, radius_m)")
    s = str(spec).strip().lower()
    kind, _, rest = s.partition(":")
    nums = [float(v) for v in re.findall(_NUM, rest)]
    if kind == "box" and len(nums) == 6:
        return Box(tuple(nums[:3]), tuple(nums[3:]))
    if kind == "sphere" and len(nums) == 4:
        return Sphere(tuple(nums[:3]), nums[3])
    raise InputError("region", spec, "'box:xmin,ymin,zmin,xmax,ymax,zmax' or 'sphere:cx,cy,cz,radius' (metres, "
                     "LiDAR frame)")


# ---------------------------------------------------------------------------------------------
# planes
# ---------------------------------------------------------------------------------------------
@dataclass
class PlaneFit:
    """A plane ``normal . x + offset_m = 0`` (unit normal) fitted to points.

    ``inliers`` is a boolean mask over the points given, ``rms_m`` the RMS
    point-to-plane distance of the inliers.
    """

    normal: np.ndarray
    offset_m: float
    inliers: np.ndarray
    rms_m: float

    @property
    def n_inliers(self) -> int:
        return int(self.inliers.sum())

    def distance_m(self, xyz_m) -> np.ndarray:
        """Signed distances ``(...)`` of points ``(..., 3)`` to the plane."""
        return np.asarray(xyz_m) @ self.normal + self.offset_m


def _lsq_plane(p):
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c, full_matrices=False)
    n = vt[2]
    return n, -float(n @ c)


def fit_plane_ransac(xyz_m, *, threshold_m: float = 0.05, n_iter: int = 300, seed=0,
                     normal_hint=None, max_angle_deg: float | None = None, max_points: int = 40000) -> PlaneFit | None:
    """Seeded RANSAC plane fit followed by least-squares refinement on the inliers.

    Parameters
    ----------
    xyz_m : ndarray (N, 3)
    threshold_m : float
        Inlier distance.  About 3x the range noise.
    n_iter : int
        RANSAC hypotheses (evaluated in vectorised chunks).
    seed : int or numpy Generator
    normal_hint : array_like (3,), optional
        With ``max_angle_deg``: only planes whose normal is within that angle of
        ``+-normal_hint`` are accepted (e.g. the ground: ``(0, 0, 1)``).
    max_points : int
        Hypotheses are scored on a random subset of at most this many points.

    Returns
    -------
    PlaneFit or None
        None when there are fewer than 3 points or no hypothesis satisfies the constraint.
    """
    p = np.asarray(xyz_m, dtype=np.float64)
    n_pts = p.shape[0]
    if n_pts < 3:
        return None
    rng = np.random.default_rng(seed)
    sub = p if n_pts <= max_points else p[rng.choice(n_pts, max_points, replace=False)]
    tri = rng.integers(0, sub.shape[0], size=(int(n_iter), 3))
    a, b, c = sub[tri[:, 0]], sub[tri[:, 1]], sub[tri[:, 2]]
    nrm = np.cross(b - a, c - a)
    ln = np.linalg.norm(nrm, axis=1)
    ok = ln > 1e-9
    nrm[ok] /= ln[ok, None]
    if normal_hint is not None and max_angle_deg is not None:
        h = np.asarray(normal_hint, float)
        h = h / np.linalg.norm(h)
        ok &= np.abs(nrm @ h) >= np.cos(np.deg2rad(max_angle_deg))
    if not ok.any():
        return None
    nrm, a = nrm[ok], a[ok]
    d = -np.sum(nrm * a, axis=1)
    best, best_count = -1, -1
    c0 = sub.mean(axis=0)  # score in float32 about the centroid (ample for counting inliers at cm thresholds)
    sub32 = (sub - c0).astype(np.float32)
    nrm32 = nrm.astype(np.float32)
    d32 = (d + nrm @ c0).astype(np.float32)
    for s in range(0, nrm.shape[0], 64):
        cnt = (np.abs(sub32 @ nrm32[s:s + 64].T + d32[s:s + 64]) < threshold_m).sum(axis=0)
        k = int(np.argmax(cnt))
        if cnt[k] > best_count:
            best, best_count = s + k, int(cnt[k])
    n, off = nrm[best], float(d[best])
    inl = np.abs(p @ n + off) < threshold_m
    for _ in range(3):  # refine: least squares on the inliers, re-select
        if inl.sum() < 3:
            return None
        n, off = _lsq_plane(p[inl])
        new = np.abs(p @ n + off) < threshold_m
        if np.array_equal(new, inl):
            break
        inl = new
    if normal_hint is not None and max_angle_deg is not None:
        if abs(n @ h) < np.cos(np.deg2rad(max_angle_deg)):
            return None
    if inl.sum() < 3:
        return None
    rms = float(np.sqrt(np.mean((p[inl] @ n + off) ** 2)))
    return PlaneFit(n, off, inl, rms)


def fit_ground_plane(clouds, *, up_hint=(0.0, 0.0, 1.0), max_tilt_deg: float = 30.0, threshold_m: float = 0.05,
                     n_iter: int = 400, seed=0, max_points: int = 200000) -> PlaneFit:
    """Fit the ground plane in one or several scans of a static LiDAR.

    The scans are pooled (at most ``max_points``, randomly thinned), and the
    plane with most inliers whose normal is within ``max_tilt_deg`` of ``up_hint``
    (the LiDAR's approximate "up", in its own frame) is kept.  The normal is
    oriented so that the LiDAR origin is on its positive side (``offset_m > 0``).

    Raises
    ------
    InputError
        When no such plane is found.
    """
    rng = np.random.default_rng(seed)
    clouds = clouds if isinstance(clouds, (list, tuple)) else [clouds]
    pts = [np.asarray(getattr(c, "xyz_m", c), float) for c in clouds]
    p = np.concatenate(pts) if pts else np.zeros((0, 3))
    if p.shape[0] > max_points:
        p = p[rng.choice(p.shape[0], max_points, replace=False)]
    fit = fit_plane_ransac(p, threshold_m=threshold_m, n_iter=n_iter, seed=rng, normal_hint=up_hint,
                           max_angle_deg=max_tilt_deg)
    if fit is None or fit.n_inliers < 50:
        raise InputError("ground plane", f"{0 if fit is None else fit.n_inliers} inlier points",
                         f"a ground plane within {max_tilt_deg:g} deg of up={tuple(up_hint)} in the scans "
                         "(or give T_ground_lidar)")
    if fit.offset_m < 0:
        fit = PlaneFit(-fit.normal, -fit.offset_m, fit.inliers, fit.rms_m)
    return fit


def ground_frame_from_plane(plane: PlaneFit) -> np.ndarray:
    """``T_ground_lidar`` (4, 4): LiDAR -> ground frame (z up along the normal, origin below the LiDAR).

    x is the LiDAR's x axis projected onto the plane (its y axis if x is nearly vertical).
    """
    n = np.asarray(plane.normal, float)
    n = n / np.linalg.norm(n)
    if plane.offset_m < 0:
        n = -n
    origin = -abs(plane.offset_m) * n  # foot of the LiDAR origin on the plane
    ex = np.array([1.0, 0.0, 0.0])
    if abs(ex @ n) > 0.95:
        ex = np.array([0.0, 1.0, 0.0])
    x = ex - (ex @ n) * n
    x /= np.linalg.norm(x)
    y = np.cross(n, x)
    R = np.stack([x, y, n])  # rows: ground axes in LiDAR coordinates
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = -R @ origin
    return T


def transform_points(T, xyz) -> np.ndarray:
    """Apply a 4x4 transform to points ``(..., 3)``."""
    T = np.asarray(T, float)
    return np.asarray(xyz, float) @ T[:3, :3].T + T[:3, 3]


# ---------------------------------------------------------------------------------------------
# rectangle in the plane
# ---------------------------------------------------------------------------------------------
@dataclass
class Rectangle:
    """A rectangle in plane coordinates: centre ``(2,)``, unit axes ``axis_a``/``axis_b`` ``(2,)``,
    measured extents along them and the mask of the points inside."""

    centre: np.ndarray
    axis_a: np.ndarray
    axis_b: np.ndarray
    extent_m: tuple[float, float]
    inside: np.ndarray


def _window_centre(ab, size_ab, cell):
    """Centre of a window of size ``size_ab`` containing the most points (middle of the plateau)."""
    lo = ab.min(axis=0) - size_ab
    nb = np.ceil((ab.max(axis=0) - lo + size_ab) / cell).astype(int) + 1
    if np.prod(nb) > 4_000_000:  # a patch far larger than the board: coarser grid
        cell = float(cell * np.sqrt(np.prod(nb) / 4_000_000.0)) + 1e-9
        nb = np.ceil((ab.max(axis=0) - lo + size_ab) / cell).astype(int) + 1
    idx = np.floor((ab - lo) / cell).astype(int)
    H = np.zeros(nb, dtype=np.int64)
    np.add.at(H, (idx[:, 0], idx[:, 1]), 1)
    S = np.zeros((nb[0] + 1, nb[1] + 1), dtype=np.int64)
    S[1:, 1:] = H.cumsum(0).cumsum(1)
    wa, wb = max(1, int(round(size_ab[0] / cell))), max(1, int(round(size_ab[1] / cell)))
    wa, wb = min(wa, nb[0]), min(wb, nb[1])
    cnt = S[wa:, wb:] - S[:-wa, wb:] - S[wa:, :-wb] + S[:-wa, :-wb]  # window starting at cell (i, j)
    m = cnt.max()
    ii, jj = np.nonzero(cnt == m)
    start = np.array([(ii.min() + ii.max()) / 2.0, (jj.min() + jj.max()) / 2.0])
    return lo + start * cell + np.array([wa, wb]) * cell / 2.0, int(m)


def _robust_extents(ab, n_bins=(8, 6)):
    """Edges of a rectangle from points inside it: per strip across each axis, the min and max of the
    points; the edge is the median over the strips (a narrow protrusion such as a stand moves one strip only)."""
    lo, hi = ab.min(axis=0), ab.max(axis=0)
    out_lo, out_hi = lo.copy(), hi.copy()
    for k in range(2):
        other = 1 - k
        nb = n_bins[other]
        edges = np.linspace(lo[other], hi[other], nb + 1)
        idx = np.clip(np.searchsorted(edges, ab[:, other], side="right") - 1, 0, nb - 1)
        mins, maxs = [], []
        for b in range(1, nb - 1):  # skip the two outer strips (cut by the rectangle's corners when rotated)
            sel = ab[idx == b, k]
            if sel.size >= 2:
                mins.append(sel.min())
                maxs.append(sel.max())
        if len(mins) >= 3:
            out_lo[k], out_hi[k] = np.median(mins), np.median(maxs)
    return out_lo, out_hi


def fit_rectangle(uv_m, size_m=None, *, tolerance_m: float = 0.03, cell_m: float = 0.01,
                  angle_step_deg: float = 3.0) -> Rectangle:
    """Fit a rectangle to points ``(N, 2)`` lying in a plane.

    Without ``size_m``: the minimum-area rectangle of all points.  With
    ``size_m = (long, short)``: a window of that size (plus ``tolerance_m`` on each
    side) is turned in ``angle_step_deg`` steps and slid over the points; the
    orientation and position holding the most points win (the middle of the
    plateau of equally good ones), so that points outside the board (a stand, a
    hand) do not tilt or shift it.  The orientation is then refined by the
    minimum-area rectangle of the points inside, and the centre is the middle of
    their robust extents (:func:`_robust_extents`).  ``axis_a`` is along the long side.
    """

    uv = np.asarray(uv_m, float)
    centre = uv.mean(axis=0)
    rel = uv - centre
    if size_m is None:
        (_, _), (w, h), ang = cv2.minAreaRect(rel.astype(np.float32))
        t = np.deg2rad(ang)
        ax_a, ax_b = np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])
        if h > w:
            ax_a, ax_b = ax_b, -ax_a
        ab = rel @ np.stack([ax_a, ax_b], 1)
        lo, hi = ab.min(axis=0), ab.max(axis=0)
        centre = centre + np.stack([ax_a, ax_b], 1) @ ((lo + hi) / 2)
        return Rectangle(centre, ax_a, ax_b, (float(hi[0] - lo[0]), float(hi[1] - lo[1])), np.ones(len(uv), bool))
    size_ab = np.asarray(size_m, float)
    win = size_ab + 2 * tolerance_m
    angles = np.deg2rad(np.arange(0.0, 180.0, angle_step_deg))
    counts = np.empty(len(angles), dtype=np.int64)
    for k, t in enumerate(angles):
        A = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        counts[k] = _window_centre(rel @ A, win, max(cell_m, 0.03))[1]
    good = counts >= counts.max() - max(1, int(0.002 * len(uv)))
    ang0 = 0.5 * np.angle(np.sum(np.exp(2j * angles[good])))  # middle of the plateau (mod 180 deg)
    ax_a = np.array([np.cos(ang0), np.sin(ang0)])
    ax_b = np.array([-np.sin(ang0), np.cos(ang0)])
    inside = np.ones(len(uv), bool)
    for it in range(2):
        E = np.stack([ax_a, ax_b], 1)
        ab = rel @ E
        c_ab = _window_centre(ab, win, cell_m)[0]
        inside = np.all(np.abs(ab - c_ab) <= win / 2.0, axis=1)
        if inside.sum() < 3 or it == 1:
            break
        (_, _), (w, h), ang = cv2.minAreaRect(rel[inside].astype(np.float32))
        t = np.deg2rad(ang)
        cand = [np.array([np.cos(t), np.sin(t)]), np.array([-np.sin(t), np.cos(t)])]
        a_new = max(cand, key=lambda v: abs(v @ ax_a))
        if abs(a_new @ ax_a) > np.cos(np.deg2rad(2 * angle_step_deg)):  # refine only near the search result
            ax_a = a_new * np.sign(a_new @ ax_a)
            ax_b = np.array([-ax_a[1], ax_a[0]])
    E = np.stack([ax_a, ax_b], 1)
    ab = rel @ E
    lo, hi = _robust_extents(ab[inside]) if inside.sum() >= 10 else (ab.min(axis=0), ab.max(axis=0))
    centre = centre + E @ ((lo + hi) / 2.0)
    ext = hi - lo
    return Rectangle(centre, ax_a, ax_b, (float(ext[0]), float(ext[1])), inside)


# ---------------------------------------------------------------------------------------------
# board detection
# ---------------------------------------------------------------------------------------------
@dataclass
class BoardDetection:
    """The board found (or not) in one scan.

    Attributes
    ----------
    found : bool
    reason : str
        Why not found (empty when found).
    centre_m : ndarray (3,)
        Board centre (centre of the outer rectangle), LiDAR frame, metres.
    axis_long, axis_short, normal : ndarray (3,)
        Unit vectors of the fitted rectangle (long side, short side) and the plane
        normal (towards the LiDAR), LiDAR frame.
    extent_m : (float, float)
        Measured extents of the board points along the long and short axes.
    n_points : int
        Points on the board.
    plane_rms_m : float
        RMS distance of the board points to the plane.
    board_xyz_m : ndarray (n_points, 3)
        The board points (for figures and checks).
    """

    found: bool
    reason: str = ""
    board: Checkerboard | None = None
    centre_m: np.ndarray | None = None
    axis_long: np.ndarray | None = None
    axis_short: np.ndarray | None = None
    normal: np.ndarray | None = None
    extent_m: tuple[float, float] = (np.nan, np.nan)
    n_points: int = 0
    plane_rms_m: float = np.nan
    board_xyz_m: np.ndarray | None = field(default=None, repr=False)

    def corner_candidates(self) -> list[np.ndarray]:
        """All placements of the inner-corner grid consistent with the rectangle: ``[(N, 3), ...]``.

        4 for a non-square grid (the board's x axis along +-long side, y along
        +-short side), 8 for a square grid.  The first one has the board's x along
        ``+axis_long`` and z (x cross y) pointing away from the LiDAR, i.e. the
        face with the squares seen from the LiDAR.
        """
        if not self.found:
            return []
        b = self.board
        obj = b.object_points()
        c_b = np.array([(b.cols - 1) * b.square_m / 2.0, (b.rows - 1) * b.square_m / 2.0, 0.0])
        rel = obj - c_b
        long_is_x = b.cols >= b.rows
        axes = [(self.axis_long, self.axis_short)] if long_is_x else [(self.axis_short, self.axis_long)]
        if b.cols == b.rows:
            axes.append((self.axis_short, self.axis_long))
        out = []
        for ax_x0, ax_y0 in axes:
            # sign so that z = x cross y points away from the LiDAR (board face seen by the sensor)
            sy0 = 1.0 if np.cross(ax_x0, ax_y0) @ self.normal < 0 else -1.0
            for sx, sy in ((1.0, sy0), (-1.0, -sy0), (1.0, -sy0), (-1.0, sy0)):
                ax_x, ax_y = sx * ax_x0, sy * ax_y0
                out.append(self.centre_m + rel[:, :1] * ax_x + rel[:, 1:2] * ax_y)
        return out

    def corners_m(self, which: int = 0) -> np.ndarray:
        """Inner corners ``(N, 3)`` in the LiDAR frame, OpenCV order, for candidate ``which``."""
        c = self.corner_candidates()
        if not c:
            raise InputError("board detection", self.reason, "a scan in which the board was found")
        return c[which]

    def to_dict(self) -> dict:
        d = {"found": self.found, "reason": self.reason, "n_points": self.n_points}
        if self.found:
            d.update(centre_m=self.centre_m.tolist(), normal=self.normal.tolist(),
                     axis_long=self.axis_long.tolist(), extent_m=list(self.extent_m),
                     plane_rms_m=self.plane_rms_m)
        return d


def _search_points(cloud, region, max_range_m, ground, ground_clearance_m) -> np.ndarray:
    """The finite points ``(n, 3)`` m of ``cloud`` inside ``region`` and range, above the ground's clearance."""
    xyz = np.asarray(getattr(cloud, "xyz_m", cloud), dtype=np.float64)
    if xyz.ndim != 2 or xyz.shape[1] != 3:
        raise InputError("cloud", getattr(xyz, "shape", None), "points of shape (N, 3)")
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    region = parse_region(region)
    if region is not None:
        xyz = xyz[region.contains(xyz)]
    if max_range_m is not None:
        xyz = xyz[np.linalg.norm(xyz, axis=1) <= max_range_m]
    if ground is not None:
        xyz = xyz[ground.distance_m(xyz) * np.sign(ground.offset_m or 1.0) > ground_clearance_m]
    return xyz


def _patches(pts: np.ndarray, cluster_radius_m: float) -> tuple[np.ndarray, int]:
    """Connected patches of a plane's points: ``(label per point, number of patches)``.

    On a voxel grid of half the radius (bounded work however dense the plane is): voxels whose mean points
    are within ``cluster_radius_m`` are connected.
    """
    vox = np.floor(pts / (cluster_radius_m / 2.0)).astype(np.int64)
    _, first, inv = np.unique(vox, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    centres = np.zeros((len(first), 3))
    np.add.at(centres, inv, pts)
    centres /= np.bincount(inv, minlength=len(first))[:, None]
    pairs = cKDTree(centres).query_pairs(cluster_radius_m, output_type="ndarray")
    g = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(len(first), len(first)))
    n_comp, vlab = connected_components(g, directed=False)
    return vlab[inv], n_comp


def detect_board(cloud, board, *, region=None, ground: PlaneFit | None = None, ground_clearance_m: float = 0.15,
                 plane_threshold_m: float = 0.05, cluster_radius_m: float = 0.2, size_tolerance: float = 0.1,
                 max_planes: int = 8, min_points: int = 30, max_range_m: float | None = None,
                 seed=0) -> BoardDetection:
    """Find ``board`` in one scan (see the module docstring).

    Parameters
    ----------
    cloud : PointCloud or ndarray (N, 3)
        LiDAR frame, metres.
    board : Checkerboard or str
        With ``square_m`` and ``margin_m`` set: the outer size is
        ``((cols + 1) s + 2 margin, (rows + 1) s + 2 margin)``.
    region : Box, Sphere, str or None
        Search only inside this region (LiDAR frame).
    ground : PlaneFit, optional
        Ground plane (LiDAR frame); points below it or within ``ground_clearance_m``
        above it are ignored.  None: no ground removal (give a region then).
    plane_threshold_m : float
        RANSAC inlier distance (about 3x the range noise).
    cluster_radius_m : float
        Points of a plane closer than this are in one patch (larger than the
        spacing of the scan lines on the board).
    size_tolerance : float
        Accept a board whose measured extents are within ``size (1 - tol) - 0.1 m`` and
        ``size (1 + tol) + 2 plane_threshold_m`` (sparse scan lines make the measured
        extent smaller by up to one line spacing).
    seed : int
        RANSAC seed (detection is deterministic for a given seed).

    Returns
    -------
    BoardDetection
        ``found=False`` with a reason when no board-sized planar patch exists.
    """

    board = parse_board(board) if not isinstance(board, Checkerboard) else board
    xyz = _search_points(cloud, region, max_range_m, ground, ground_clearance_m)
    if xyz.shape[0] < min_points:
        return BoardDetection(False, f"only {xyz.shape[0]} points in the search region (after ground removal)",
                              board)
    size = np.array(sorted(board.size_m, reverse=True))
    rng = np.random.default_rng(seed)
    rest = xyz
    tried = []
    best = None
    for _ in range(max_planes):
        if rest.shape[0] < min_points:
            break
        fit = fit_plane_ransac(rest, threshold_m=plane_threshold_m, n_iter=300, seed=rng, max_points=15000)
        if fit is None or fit.n_inliers < min_points:
            break
        pts = rest[fit.inliers]
        rest = rest[~fit.inliers]
        lab, n_comp = _patches(pts, cluster_radius_m)
        counts = np.bincount(lab, minlength=n_comp)
        for comp in np.argsort(counts)[::-1]:
            if counts[comp] < min_points:
                break
            cand = _candidate(pts[lab == comp], fit, board, size, size_tolerance, plane_threshold_m)
            tried.append(cand[1])
            if cand[0] is not None and (best is None or cand[0].n_points > best.n_points):
                best = cand[0]
        if best is not None:
            break  # the largest board-sized patch of the largest plane holding one
    if best is None:
        why = "; ".join(tried[:4]) if tried else "no planar patch"
        return BoardDetection(False, f"no board-sized planar patch ({why})", board)
    return best


def _candidate(pts, fit, board, size, tol, thr):
    n, _ = _lsq_plane(pts)
    c0 = pts.mean(axis=0)
    if n @ (-c0) < 0:  # normal towards the LiDAR (origin)
        n = -n
    e1 = np.cross(n, [0.0, 0.0, 1.0])
    if np.linalg.norm(e1) < 1e-6:
        e1 = np.cross(n, [1.0, 0.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    uv = np.stack([(pts - c0) @ e1, (pts - c0) @ e2], 1)
    rect0 = fit_rectangle(uv)
    ext0 = np.array(rect0.extent_m)
    if ext0[1] > 2.0 * size[0] + 0.2 or ext0[0] > size[0] + 2.5:  # a board, even on a stand, is not that big
        return None, f"patch of {len(pts)} pts, {ext0[0]:.1f} x {ext0[1]:.1f} m much larger than the board"
    if np.any(ext0 < (1 - tol) * size - 0.1):
        return None, f"patch of {len(pts)} pts, {ext0[0]:.2f} x {ext0[1]:.2f} m smaller than the board"
    rect = fit_rectangle(uv, size, tolerance_m=max(thr, 0.02))
    ext = np.array(rect.extent_m)
    lo_ok = (1 - tol) * size - 0.1
    frac = rect.inside.mean()
    if frac < 0.6:
        return None, (f"patch of {len(pts)} pts, {ext0[0]:.2f} x {ext0[1]:.2f} m: only {100 * frac:.0f}% of it "
                      "in a board-sized window (a larger plane)")
    if np.any(ext < lo_ok) or np.any(ext > size * (1 + tol) + 2 * thr):
        return None, f"patch of {len(pts)} pts, {ext[0]:.2f} x {ext[1]:.2f} m vs board {size[0]:.2f} x {size[1]:.2f}"
    inside = pts[rect.inside]
    if inside.shape[0] < 10:
        return None, "too few points inside the board rectangle"
    # final plane on the board points only, and the rectangle re-expressed in 3D
    n2, off2 = _lsq_plane(inside)
    if n2 @ (-inside.mean(axis=0)) < 0:
        n2, off2 = -n2, -off2
    centre3 = c0 + rect.centre[0] * e1 + rect.centre[1] * e2
    centre3 = centre3 - (centre3 @ n2 + off2) * n2
    a3 = rect.axis_a[0] * e1 + rect.axis_a[1] * e2
    a3 = a3 - (a3 @ n2) * n2
    a3 /= np.linalg.norm(a3)
    b3 = np.cross(n2, a3)
    rms = float(np.sqrt(np.mean((inside @ n2 + off2) ** 2)))
    det = BoardDetection(True, "", board, centre3, a3, b3, n2, (float(ext[0]), float(ext[1])), int(inside.shape[0]),
                         rms, inside)
    return det, "board"
