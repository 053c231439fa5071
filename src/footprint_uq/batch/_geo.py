"""Local world frame W -> WGS84 for the batch outputs (lat/lon columns, GeoJSON).

W is tied to the map by a geodetic origin (the WGS84 latitude/longitude of W's
origin, on the ellipsoid) and ``heading_offset_deg``, the compass bearing of W's +y
axis (the convention of :mod:`footprint_uq.v2x`).  W is rotated into true
east/north, ``E = cos h x + sin h y``, ``N = -sin h x + cos h y``, and (E, N) are
read as coordinates of the azimuthal equidistant projection centred on the origin
(pyproj ``+proj=aeqd``), whose distances and bearings from the origin are exact:
within a few kilometres of the origin it agrees with the local tangent plane to
well under a centimetre.
"""

from __future__ import annotations

import numpy as np

from .._checks import as_float
from ..errors import ConfigError

__all__ = ["LocalToWGS84"]


class LocalToWGS84:
    """Vectorised converter of W coordinates (m) to (lat_deg, lon_deg).

    Parameters
    ----------
    origin_lat_deg, origin_lon_deg : float
        WGS84 position of W's origin.
    heading_offset_deg : float
        Compass bearing of W's +y axis (0: +y is true north).
    """

    def __init__(self, origin_lat_deg: float, origin_lon_deg: float, heading_offset_deg: float = 0.0):
        self.origin_lat_deg = as_float("origin_lat_deg", origin_lat_deg, lo=-90.0, hi=90.0)
        self.origin_lon_deg = as_float("origin_lon_deg", origin_lon_deg, lo=-180.0, hi=180.0)
        self.heading_offset_deg = as_float("heading_offset_deg", heading_offset_deg)
        try:
            from pyproj import Transformer
        except ImportError:  # pragma: no cover - depends on the environment
            raise ConfigError("origin_lat_deg/origin_lon_deg", "given",
                              "the optional dependency pyproj (pip install 'footprint-uq[geo]')") from None
        proj = (f"+proj=aeqd +lat_0={self.origin_lat_deg!r} +lon_0={self.origin_lon_deg!r} "
                "+x_0=0 +y_0=0 +ellps=WGS84 +units=m +no_defs")
        self._tr = Transformer.from_crs(proj, "EPSG:4326", always_xy=True)
        h = np.deg2rad(self.heading_offset_deg)
        self._c, self._s = float(np.cos(h)), float(np.sin(h))

    def __call__(self, x_m, y_m) -> tuple[np.ndarray, np.ndarray]:
        """``(lat_deg, lon_deg)`` arrays of the shape of ``x_m`` (NaN stays NaN)."""
        x = np.asarray(x_m, dtype=np.float64)
        y = np.asarray(y_m, dtype=np.float64)
        e = self._c * x + self._s * y
        n = -self._s * x + self._c * y
        lon, lat = self._tr.transform(e, n)
        lat = np.where(np.isfinite(e) & np.isfinite(n), lat, np.nan)
        lon = np.where(np.isfinite(e) & np.isfinite(n), lon, np.nan)
        return np.asarray(lat, dtype=np.float64).reshape(x.shape), np.asarray(lon, dtype=np.float64).reshape(x.shape)

    def to_dict(self) -> dict:
        return {"origin_lat_deg": self.origin_lat_deg, "origin_lon_deg": self.origin_lon_deg,
                "heading_offset_deg": self.heading_offset_deg}
