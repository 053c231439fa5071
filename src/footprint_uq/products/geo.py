"""Tie the camera's world frame to the map: true north, WGS84 and GeoJSON.

The world frame W (x, y in metres, z up) of a camera set-up is tied to the map by

* ``heading_offset_deg`` -- the compass bearing (degrees clockwise from true north) of
  the world +y axis (0: W is east/north already), and
* an optional geodetic origin ``(origin_lat_deg, origin_lon_deg)`` on WGS84 and the
  world point ``origin_world_m`` that sits there (default (0, 0)).

World -> true east/north (ENU) is the rotation ``E = x' cos h + y' sin h``,
``N = -x' sin h + y' cos h`` of ``(x', y') = xy_world_m - origin_world_m``.
East/north metres -> latitude/longitude uses an azimuthal-equidistant projection
centred on the origin (pyproj ``+proj=aeqd``, WGS84 ellipsoid): it is a local
tangent-plane map whose distances and bearings from the origin are exact, with a
scale error below 1e-6 within 1 km of the origin, far below any camera
uncertainty.  Covariances rotate with ``R C R^T``; the ellipse's orientation is
reported as a bearing from true north.

pyproj is the optional extra ``geo`` (``pip install 'footprint-uq[geo]'``); it is
imported only when latitude/longitude are needed.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import status
from .._checks import as_float, as_points
from ..errors import InputError
from ..io.atomic import atomic_write_text
from ..uncertainty.ellipse import ellipse_axes, ellipse_ring
from .v2x import cpm_fields, j2735_fields, rotate_to_true_north

__all__ = ["GeoReference", "footprints_geojson", "write_geojson"]


def _pyproj():
    try:
        import pyproj
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("WGS84 output needs pyproj: pip install 'footprint-uq[geo]' (or pip install pyproj)") from e
    return pyproj


@dataclass
class GeoReference:
    """How the world frame W sits on the map (see the module doc).

    Parameters
    ----------
    heading_offset_deg : float
        Bearing of the world +y axis from true north, degrees clockwise.
    origin_lat_deg, origin_lon_deg : float, optional
        WGS84 latitude/longitude of ``origin_world_m``; needed for :meth:`to_wgs84`.
    origin_world_m : (float, float)
        The world point at the geodetic origin.
    """

    heading_offset_deg: float = 0.0
    origin_lat_deg: float | None = None
    origin_lon_deg: float | None = None
    origin_world_m: tuple[float, float] = (0.0, 0.0)
    _transformer: object = field(default=None, init=False, repr=False, compare=False)

    def __post_init__(self):
        self.heading_offset_deg = as_float("heading_offset_deg", self.heading_offset_deg, lo=-360.0, hi=360.0)
        if (self.origin_lat_deg is None) != (self.origin_lon_deg is None):
            raise InputError("origin_lat_deg/origin_lon_deg", (self.origin_lat_deg, self.origin_lon_deg),
                             "both or neither")
        if self.origin_lat_deg is not None:
            self.origin_lat_deg = as_float("origin_lat_deg", self.origin_lat_deg, lo=-90.0, hi=90.0)
            self.origin_lon_deg = as_float("origin_lon_deg", self.origin_lon_deg, lo=-180.0, hi=180.0)
        try:
            ox, oy = (float(v) for v in self.origin_world_m)
        except (TypeError, ValueError):
            raise InputError("origin_world_m", self.origin_world_m, "[x, y] in metres") from None
        self.origin_world_m = (as_float("origin_world_m[0]", ox), as_float("origin_world_m[1]", oy))

    @property
    def has_origin(self) -> bool:
        return self.origin_lat_deg is not None

    @property
    def R_enu_world(self) -> np.ndarray:
        """2x2 rotation from world x/y to true east/north."""
        h = np.deg2rad(self.heading_offset_deg)
        c, s = np.cos(h), np.sin(h)
        return np.array([[c, s], [-s, c]])

    def world_to_enu(self, xy_world_m) -> np.ndarray:
        """World points ``(..., 2)`` -> east/north metres from the geodetic origin ``(..., 2)``."""
        xy = as_points("xy_world_m", xy_world_m, 2) - np.asarray(self.origin_world_m)
        return xy @ self.R_enu_world.T

    def enu_to_world(self, en_m) -> np.ndarray:
        """Inverse of :meth:`world_to_enu`."""
        en = as_points("en_m", en_m, 2)
        return en @ self.R_enu_world + np.asarray(self.origin_world_m)

    def cov_to_enu(self, cov_m2) -> np.ndarray:
        """World covariances ``(..., 2, 2)`` -> east/north."""
        return rotate_to_true_north(cov_m2, self.heading_offset_deg)

    def bearing_deg(self, orientation_world_deg) -> np.ndarray:
        """Axis orientation (deg ccw from world +x) -> bearing from true north in [0, 180)."""
        return np.mod(90.0 - np.asarray(orientation_world_deg, dtype=np.float64) + self.heading_offset_deg, 180.0)

    def _proj(self):
        if not self.has_origin:
            raise InputError("GeoReference", "no geodetic origin", "origin_lat_deg and origin_lon_deg for WGS84")
        if self._transformer is None:
            pyproj = _pyproj()
            local = pyproj.CRS.from_proj4(f"+proj=aeqd +lat_0={self.origin_lat_deg!r} +lon_0={self.origin_lon_deg!r} "
                                          "+x_0=0 +y_0=0 +datum=WGS84 +units=m +no_defs")
            self._transformer = (pyproj.Transformer.from_crs(local, "EPSG:4326", always_xy=True),
                                 pyproj.Transformer.from_crs("EPSG:4326", local, always_xy=True))
        return self._transformer

    def to_wgs84(self, xy_world_m):
        """World points ``(..., 2)`` -> ``(lat_deg, lon_deg)``, each ``(...)`` (NaN stays NaN)."""
        en = self.world_to_enu(xy_world_m)
        fwd, _ = self._proj()
        lon, lat = fwd.transform(en[..., 0], en[..., 1])
        lon, lat = np.asarray(lon, dtype=np.float64), np.asarray(lat, dtype=np.float64)
        bad = ~np.isfinite(en).all(-1)
        return np.where(bad, np.nan, lat), np.where(bad, np.nan, lon)

    def from_wgs84(self, lat_deg, lon_deg) -> np.ndarray:
        """``(lat_deg, lon_deg)`` -> world points ``(..., 2)``."""
        _, inv = self._proj()
        e, n = inv.transform(np.asarray(lon_deg, dtype=np.float64), np.asarray(lat_deg, dtype=np.float64))
        return self.enu_to_world(np.stack([np.asarray(e), np.asarray(n)], -1))


def _num(x):
    x = float(x)
    return x if np.isfinite(x) else None


def footprints_geojson(estimate, georef: GeoReference, *, object_ids=None, properties=None,
                       centroid_points: bool = True, confidence: float = 0.95, ellipse_polygons: bool = True,
                       ellipse_vertices: int = 64) -> dict:
    """GeoJSON FeatureCollection (RFC 7946, lon/lat WGS84) of a frame's footprints.

    One ``Polygon`` feature per object (the footprint, exterior ring counter-clockwise;
    a ``LineString`` for two contact points, a ``Point`` for one; ``null`` geometry when
    a corner could not be computed, with the reasons in the properties), and with
    ``centroid_points`` one ``Point`` feature per object at its centre, and with ``ellipse_polygons``
    one ``Polygon`` feature per object with a centre covariance (``"role": "ellipse"``): the
    ``confidence`` ellipse as a closed counter-clockwise ring of ``ellipse_vertices`` vertices
    (:func:`~footprint_uq.uncertainty.ellipse.ellipse_ring` in the world frame, put on WGS84), so
    that a GIS draws it.  Properties:
    ``object_id``, ``role`` ("footprint"/"centroid"), centre lat/lon, centre ellipse at
    1 sigma and at ``confidence`` (semi-axes in m, ``orientation_deg_from_north``), the
    largest-point bound, the CPM and J2735 fields (computed for the georeference's heading
    offset), per-corner reason texts and the centre reason.

    Parameters
    ----------
    estimate : FootprintEstimate
    georef : GeoReference   (with a geodetic origin)
    object_ids : sequence (N,), optional    default 0..N-1
    properties : sequence of dict (N,), optional    merged into each object's properties
    """
    N = len(estimate)
    ids = list(range(N)) if object_ids is None else list(object_ids)
    if len(ids) != N:
        raise InputError("object_ids", len(ids), f"{N} ids (one per object)")
    if properties is not None and len(properties) != N:
        raise InputError("properties", len(properties), f"{N} mappings (one per object)")
    lat_c, lon_c = georef.to_wgs84(estimate.corners_xy_world_m)
    lat_m, lon_m = georef.to_wgs84(estimate.centre_xy_world_m)
    cov_enu = georef.cov_to_enu(estimate.centre_cov_m2)
    a1, b1, _ = ellipse_axes(cov_enu)
    ak, bk, ang = ellipse_axes(cov_enu, confidence=confidence)
    bearing = np.mod(90.0 - ang, 180.0)
    v2x = {**cpm_fields(estimate.centre_cov_m2, georef.heading_offset_deg),
           **j2735_fields(estimate.centre_cov_m2, georef.heading_offset_deg)}
    reasons = estimate.centre_reason_text()
    conf_pct = f"{100 * confidence:g}"
    rings = _ellipse_rings(estimate, georef, confidence, ellipse_vertices) if ellipse_polygons else [None] * N
    feats = []
    for i in range(N):
        geom = _footprint_geometry(lon_c[i], lat_c[i])
        props = {
            "object_id": ids[i].item() if hasattr(ids[i], "item") else ids[i],
            "role": "footprint",
            "centre_lat_deg": _num(lat_m[i]), "centre_lon_deg": _num(lon_m[i]),
            "centre_valid": bool(estimate.centre_valid[i]), "centre_reason": str(reasons[i]),
            "semi_major_1sigma_m": _num(a1[i]), "semi_minor_1sigma_m": _num(b1[i]),
            f"semi_major_{conf_pct}pct_m": _num(ak[i]), f"semi_minor_{conf_pct}pct_m": _num(bk[i]),
            "orientation_deg_from_north": _num(bearing[i]),
            "largest_point_index": int(estimate.largest_index[i]),
            "largest_point_semi_major_1sigma_m": _num(estimate.largest_semi_major_m[i]),
            "corner_reasons": [status.REASONS[int(c)] for c in estimate.corner_reason[i]],
            "heading_offset_deg": georef.heading_offset_deg,
        }
        props.update({k: int(v[i]) for k, v in v2x.items()})
        if properties is not None:
            props.update(dict(properties[i]))
        feats.append({"type": "Feature", "geometry": geom, "properties": props})
        if centroid_points:
            cg = None
            if estimate.centre_valid[i]:
                cg = {"type": "Point", "coordinates": [float(lon_m[i]), float(lat_m[i])]}
            feats.append({"type": "Feature", "geometry": cg, "properties": {**props, "role": "centroid"}})
        if rings[i] is not None:
            feats.append({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [rings[i]]},
                          "properties": {**props, "role": "ellipse", "ellipse_confidence": confidence}})
    return {"type": "FeatureCollection", "features": feats}


def _footprint_geometry(lon, lat) -> dict | None:
    """GeoJSON geometry of one footprint's K corners (``lon``, ``lat`` (K,)): a Point (K = 1), a LineString
    (K = 2), a counter-clockwise Polygon (K >= 3), or None when a corner is missing."""
    if not (np.isfinite(lat).all() and np.isfinite(lon).all()):
        return None
    ring = [[float(x), float(y)] for x, y in zip(lon, lat, strict=True)]
    if len(ring) == 1:
        return {"type": "Point", "coordinates": ring[0]}
    if len(ring) == 2:
        return {"type": "LineString", "coordinates": ring}
    if 0.5 * np.sum(lon * np.roll(lat, -1) - np.roll(lon, -1) * lat) < 0:
        ring = ring[::-1]
    return {"type": "Polygon", "coordinates": [ring + [ring[0]]]}


def _ellipse_rings(estimate, georef: GeoReference, confidence: float, n: int) -> list:
    """Per object: the ``confidence`` ellipse's closed ``[lon, lat]`` ring, or None (no centre covariance)."""
    centre, cov = estimate.centre_xy_world_m, estimate.centre_cov_m2
    _, b, _ = ellipse_axes(cov)
    with np.errstate(invalid="ignore"):
        ok = np.asarray(estimate.centre_valid, bool) & np.isfinite(centre).all(-1) & np.isfinite(cov).all((-1, -2)) \
            & (b > 0)
    out: list = [None] * len(ok)
    if ok.any():
        lat, lon = georef.to_wgs84(ellipse_ring(centre[ok], cov[ok], confidence=confidence, n=n))
        for j, i in enumerate(np.flatnonzero(ok).tolist()):
            ring = np.stack([lon[j], lat[j]], -1).tolist()
            ring[-1] = ring[0]
            out[i] = ring
    return out


def write_geojson(path, feature_collection: dict) -> Path:
    """Write a FeatureCollection (``allow_nan=False``: missing numbers are already ``null``)."""
    p = Path(path)

    atomic_write_text(p, json.dumps(feature_collection, allow_nan=False, indent=1))
    return p
