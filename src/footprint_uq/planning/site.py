"""The site file of the planner: what must be seen, how well, and from where it can be seen.

A site file (YAML or JSON) has these sections (``docs/planning.md`` has a complete example)::

    name: Example intersection          # optional
    resolution_m: 0.5                   # ground sample spacing (default 0.5)
    origin: {lat_deg: 48.15, lon_deg: 11.57, heading_offset_deg: 0}   # only for lat/lon input
    zones:                              # the region of interest, each with its own requirement
      - name: lanes
        polygon_m: [[x, y], ...]        # or polygon_latlon: [[lat, lon], ...]
        max_semi_major_m: 1.75          # 95 % semi-major axis (at `confidence`) must not exceed this
        weight: 1.0                     # optional (default 1)
    occluders:                          # optional: buildings, walls (prisms standing on the ground)
      - {name: depot, polygon_m: [...], height_m: 12}
    mounts:                             # candidate poles
      - name: ne
        position_m: [x, y]              # or position_latlon: [lat, lon]
        height_m: [6, 10]               # allowed range (or one number)
        existing: true                  # optional (default false)
        cost: 0                         # optional (default 0): the cost of using this mount
    cameras:                            # candidate camera types
      - name: hd
        image_size_px: [1920, 1080]
        lenses:                         # one or more lens choices
          - {name: wide, focal_px: 1000, dist: [-0.2, 0.05, 0, 0, 0]}
        budget: basler1                 # preset, budget file (relative to the site file) or a mapping
        cost: 1                         # optional (default 0)
    search:                             # optional: the candidate grid and the constraints
      pan_step_deg: 30                  # pans 0, 30, ..., 330
      tilts_deg: [15, 25, 40]
      heights_per_mount: 2              # heights sampled evenly in each mount's range
      max_cameras: 4
      max_cost: null
      confidence: 0.95

Every error is a one-line :class:`~footprint_uq.errors.ConfigError` naming the file and the field
(``site.yaml: zones[1].max_semi_major_m``), the value and what was expected.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ConfigError, InputError
from ..io._common import as_image_size, as_number, as_vector, label, parse_mapping, read_text, suggest_key
from ..products.geo import GeoReference
from ..uncertainty.budget import ErrorBudget, load_budget

__all__ = ["Zone", "Occluder", "Mount", "Lens", "CameraType", "SearchGrid", "Site", "load_site", "site_from_dict"]


@dataclass(frozen=True)
class Zone:
    """A ground polygon ``polygon_m (N, 2)`` (x east, y north) whose points must have a 95 % semi-major
    axis of at most ``max_semi_major_m``; ``weight`` scales its area in the objective."""

    name: str
    polygon_m: np.ndarray
    max_semi_major_m: float
    weight: float = 1.0


@dataclass(frozen=True)
class Occluder:
    """A vertical prism (a building): footprint ``polygon_m (N, 2)``, top at ``height_m`` above the ground."""

    name: str
    polygon_m: np.ndarray
    height_m: float


@dataclass(frozen=True)
class Mount:
    """A candidate pole: foot point ``position_m`` (x, y), allowed camera heights, cost of using it."""

    name: str
    position_m: tuple[float, float]
    height_range_m: tuple[float, float]
    existing: bool = False
    cost: float = 0.0


@dataclass(frozen=True)
class Lens:
    """A lens choice: focal length (px) and OpenCV distortion ``(k1, k2, p1, p2, k3[, k4, k5, k6])``."""

    name: str
    focal_px: float
    dist: tuple[float, ...] = ()


@dataclass(frozen=True)
class CameraType:
    """A candidate camera: sensor size, lens choices, error budget, cost."""

    name: str
    image_size_px: tuple[int, int]
    lenses: tuple[Lens, ...]
    budget: ErrorBudget
    cost: float = 0.0
    budget_spec: object = None


@dataclass(frozen=True)
class SearchGrid:
    """The discrete candidate grid and the constraints of the plan."""

    pan_step_deg: float = 30.0
    tilts_deg: tuple[float, ...] = (15.0, 25.0, 40.0)
    heights_per_mount: int = 2
    max_cameras: int = 4
    max_cost: float | None = None
    confidence: float = 0.95

    def pans_deg(self) -> np.ndarray:
        return np.arange(0.0, 360.0 - 1e-9, self.pan_step_deg)

    def heights_m(self, mount: Mount) -> np.ndarray:
        lo, hi = mount.height_range_m
        if hi <= lo or self.heights_per_mount == 1:
            return np.array([hi])
        return np.linspace(lo, hi, self.heights_per_mount)


@dataclass
class Site:
    """Everything a site file holds (see the module docstring)."""

    zones: list[Zone]
    mounts: list[Mount]
    cameras: list[CameraType]
    occluders: list[Occluder] = field(default_factory=list)
    search: SearchGrid = field(default_factory=SearchGrid)
    resolution_m: float = 0.5
    name: str = "site"
    path: Path | None = None

    def mount(self, name: str) -> Mount:
        for m in self.mounts:
            if m.name == name:
                return m
        raise InputError("mount", name, f"one of the site's mounts {[m.name for m in self.mounts]}")

    def camera_type(self, name: str) -> CameraType:
        for c in self.cameras:
            if c.name == name:
                return c
        raise InputError("camera_type", name, f"one of the site's cameras {[c.name for c in self.cameras]}")

    def bounds_m(self, margin_m: float = 0.0) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of zones, occluders and mounts, plus ``margin_m``."""
        pts = [z.polygon_m for z in self.zones] + [o.polygon_m for o in self.occluders]
        pts.append(np.array([m.position_m for m in self.mounts]).reshape(-1, 2))
        a = np.concatenate(pts, 0)
        return (float(a[:, 0].min() - margin_m), float(a[:, 1].min() - margin_m),
                float(a[:, 0].max() + margin_m), float(a[:, 1].max() + margin_m))


# -- reading -----------------------------------------------------------------------------------------------------
#: largest coordinate of a polygon or mount (metres in the site's local frame)
MAX_COORD_M = 1e6
#: largest number of raster cells over the site's bounds (the ground samples' grid)
MAX_CELLS = 20_000_000
#: largest candidate grid (mounts x heights x lenses x tilts x pans)
MAX_CANDIDATES = 200_000

_TOP = {"name", "resolution_m", "origin", "zones", "occluders", "mounts", "cameras", "search"}
_ZONE = {"name", "polygon_m", "polygon_latlon", "max_semi_major_m", "weight"}
_OCC = {"name", "polygon_m", "polygon_latlon", "height_m"}
_MOUNT = {"name", "position_m", "position_latlon", "height_m", "existing", "cost"}
_CAM = {"name", "image_size_px", "lenses", "budget", "cost"}
_LENS = {"name", "focal_px", "dist"}
_SEARCH = {"pan_step_deg", "tilts_deg", "heights_per_mount", "max_cameras", "max_cost", "confidence"}
_ORIGIN = {"lat_deg", "lon_deg", "heading_offset_deg"}


def _mapping(where, fld, d, allowed, required=()):
    if not isinstance(d, dict):
        raise ConfigError(label(where, fld), d, "a mapping of keys")
    for k in d:
        if k not in allowed:
            raise ConfigError(label(where, f"{fld}.{k}" if fld else str(k)), d[k], suggest_key(str(k), sorted(allowed)))
    for k in required:
        if k not in d:
            raise ConfigError(label(where, f"{fld}.{k}" if fld else k), "missing", "a value (required)")
    return d


def _list(where, fld, v, *, min_len=1):
    if not isinstance(v, list) or len(v) < min_len:
        raise ConfigError(label(where, fld), v if not isinstance(v, list) else f"{len(v)} entries",
                          f"a list of at least {min_len} entries")
    return v


def _name(where, fld, d, default, seen):
    n = d.get("name", default)
    if not isinstance(n, str) or not n.strip():
        raise ConfigError(label(where, f"{fld}.name"), n, "a non-empty string")
    if n in seen:
        raise ConfigError(label(where, f"{fld}.name"), n, "a name not used by another entry of the list")
    seen.add(n)
    return n


def _latlon_to_world(where, fld, georef, lat, lon):
    if georef is None:
        raise ConfigError(label(where, fld), "lat/lon given", "an `origin: {lat_deg, lon_deg}` section in the site "
                          "file (or metres: the _m form of the field)")
    lat, lon = np.asarray(lat, dtype=np.float64), np.asarray(lon, dtype=np.float64)
    if np.any(np.abs(lat) > 90) or np.any(np.abs(lon) > 180):
        raise ConfigError(label(where, fld), [float(np.max(np.abs(lat))), float(np.max(np.abs(lon)))],
                          "latitudes in [-90, 90] and longitudes in [-180, 180] degrees")
    return georef.from_wgs84(lat, lon)


def _polygon(where, fld, d, georef):
    if ("polygon_m" in d) == ("polygon_latlon" in d):
        raise ConfigError(label(where, f"{fld}.polygon_m"), "both or neither of polygon_m, polygon_latlon",
                          "exactly one of them")
    key = "polygon_m" if "polygon_m" in d else "polygon_latlon"
    try:
        a = np.asarray(d[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(label(where, f"{fld}.{key}"), d[key], "a list of [x, y] pairs") from None
    if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 3 or not np.all(np.isfinite(a)):
        raise ConfigError(label(where, f"{fld}.{key}"), f"shape {a.shape}" if a.ndim else d[key],
                          "at least 3 finite [x, y] (or [lat, lon]) pairs")
    if np.abs(a).max() > MAX_COORD_M:
        raise ConfigError(label(where, f"{fld}.{key}"), float(np.abs(a).max()),
                          f"coordinates of magnitude <= {MAX_COORD_M:g} (a local frame, metres)")
    if key == "polygon_latlon":
        a = _latlon_to_world(where, f"{fld}.{key}", georef, a[:, 0], a[:, 1])
    area = 0.5 * abs(np.sum(a[:, 0] * np.roll(a[:, 1], -1) - np.roll(a[:, 0], -1) * a[:, 1]))
    if not area > 0:
        raise ConfigError(label(where, f"{fld}.{key}"), "zero area", "a polygon enclosing some ground")
    return a


def _origin(where, d):
    if d is None:
        return None
    _mapping(where, "origin", d, _ORIGIN, ("lat_deg", "lon_deg"))
    try:
        return GeoReference(heading_offset_deg=d.get("heading_offset_deg", 0.0), origin_lat_deg=d["lat_deg"],
                            origin_lon_deg=d["lon_deg"])
    except InputError as e:
        raise ConfigError(label(where, f"origin.{e.field}"), e.value, e.expected) from None


def _zones(where, v, georef):
    seen, out = set(), []
    for i, d in enumerate(_list(where, "zones", v)):
        fld = f"zones[{i}]"
        _mapping(where, fld, d, _ZONE, ("max_semi_major_m",))
        out.append(Zone(_name(where, fld, d, f"zone{i}", seen), _polygon(where, fld, d, georef),
                        as_number(where, f"{fld}.max_semi_major_m", d["max_semi_major_m"], positive=True, unit=" (m)"),
                        as_number(where, f"{fld}.weight", d.get("weight", 1.0), positive=True)))
    return out


def _occluders(where, v, georef):
    seen, out = set(), []
    for i, d in enumerate(_list(where, "occluders", v, min_len=0)):
        fld = f"occluders[{i}]"
        _mapping(where, fld, d, _OCC, ("height_m",))
        out.append(Occluder(_name(where, fld, d, f"occluder{i}", seen), _polygon(where, fld, d, georef),
                            as_number(where, f"{fld}.height_m", d["height_m"], positive=True, unit=" (m)")))
    return out


def _mount(where, fld, d, georef, seen):
    _mapping(where, fld, d, _MOUNT, ("height_m",))
    if ("position_m" in d) == ("position_latlon" in d):
        raise ConfigError(label(where, f"{fld}.position_m"), "both or neither of position_m, position_latlon",
                          "exactly one of them")
    if "position_m" in d:
        xy = as_vector(where, f"{fld}.position_m", d["position_m"], 2, "numbers (x east, y north, metres)")
    else:
        ll = as_vector(where, f"{fld}.position_latlon", d["position_latlon"], 2, "numbers (lat, lon, degrees)")
        xy = _latlon_to_world(where, f"{fld}.position_latlon", georef, ll[0], ll[1])
    h = d["height_m"]
    hr = as_vector(where, f"{fld}.height_m", h if isinstance(h, list) else [h, h], 2,
                   "numbers: [min, max] metres (or one number)")
    if not 0 < hr[0] <= hr[1]:
        raise ConfigError(label(where, f"{fld}.height_m"), h, "heights > 0 m with min <= max")
    ex = d.get("existing", False)
    if not isinstance(ex, bool):
        raise ConfigError(label(where, f"{fld}.existing"), ex, "true or false")
    return Mount(_name(where, fld, d, f"mount{len(seen)}", seen), (float(xy[0]), float(xy[1])),
                 (float(hr[0]), float(hr[1])), ex, as_number(where, f"{fld}.cost", d.get("cost", 0.0), lo=0))


def _lens(where, fld, d, seen):
    _mapping(where, fld, d, _LENS, ("focal_px",))
    dist = d.get("dist", [])
    dist = () if dist in ([], None) else tuple(as_vector(where, f"{fld}.dist", dist, (4, 5, 8),
                                                         "OpenCV distortion coefficients (k1, k2, p1, p2[, k3...])"))
    return Lens(_name(where, fld, d, f"lens{len(seen)}", seen),
                as_number(where, f"{fld}.focal_px", d["focal_px"], positive=True, unit=" (px)"), dist)


def _budget(where, fld, spec, base: Path | None):
    if isinstance(spec, str) and base is not None and (base / spec).exists():
        spec = str(base / spec)
    try:
        return load_budget(spec)
    except InputError as e:
        raise ConfigError(label(where, fld), spec if not isinstance(spec, dict) else f"{e.field}: {e.value!r}",
                          e.expected) from None


def _camera(where, fld, d, base, seen):
    _mapping(where, fld, d, _CAM, ("image_size_px", "lenses", "budget"))
    lseen: set = set()
    lenses = tuple(_lens(where, f"{fld}.lenses[{j}]", x, lseen)
                   for j, x in enumerate(_list(where, f"{fld}.lenses", d["lenses"])))
    spec = d["budget"]
    if isinstance(spec, str) and base is not None and (base / spec).exists():
        spec = str((base / spec).resolve())
    return CameraType(_name(where, fld, d, f"camera{len(seen)}", seen),
                      as_image_size(where, f"{fld}.image_size_px", d["image_size_px"]), lenses,
                      _budget(where, f"{fld}.budget", spec, base),
                      as_number(where, f"{fld}.cost", d.get("cost", 0.0), lo=0), spec)


def _int(where, fld, v, lo):
    if isinstance(v, bool) or not isinstance(v, int | float) or v != int(v) or v < lo:
        raise ConfigError(label(where, fld), v, f"an integer >= {lo}")
    return int(v)


def _search(where, d):
    d = _mapping(where, "search", d or {}, _SEARCH)
    step = as_number(where, "search.pan_step_deg", d.get("pan_step_deg", 30.0), lo=1.0, hi=360.0, unit=" (deg)")
    tilts = d.get("tilts_deg", [15.0, 25.0, 40.0])
    tilts = _list(where, "search.tilts_deg", tilts if isinstance(tilts, list) else [tilts])
    tilts = tuple(as_number(where, f"search.tilts_deg[{i}]", t, lo=0.5, hi=89.5, unit=" (deg, down)")
                  for i, t in enumerate(tilts))
    mc = d.get("max_cost")
    conf = as_number(where, "search.confidence", d.get("confidence", 0.95), positive=True, hi=0.999999)
    return SearchGrid(step, tilts, _int(where, "search.heights_per_mount", d.get("heights_per_mount", 2), 1),
                      _int(where, "search.max_cameras", d.get("max_cameras", 4), 1),
                      None if mc is None else as_number(where, "search.max_cost", mc, lo=0), conf)


def site_from_dict(d: dict, *, where: str = "", base_dir=None) -> Site:
    """A :class:`Site` from the mapping of a site file (``base_dir``: where relative budget files are)."""
    _mapping(where, "", d, _TOP, ("zones", "mounts", "cameras"))
    georef = _origin(where, d.get("origin"))
    base = None if base_dir is None else Path(base_dir)
    mseen: set = set()
    mounts = [_mount(where, f"mounts[{i}]", m, georef, mseen)
              for i, m in enumerate(_list(where, "mounts", d["mounts"]))]
    cseen: set = set()
    cams = [_camera(where, f"cameras[{i}]", c, base, cseen)
            for i, c in enumerate(_list(where, "cameras", d["cameras"]))]
    name = d.get("name", "site")
    if not isinstance(name, str):
        raise ConfigError(label(where, "name"), name, "a string")
    site = Site(_zones(where, d["zones"], georef), mounts, cams, _occluders(where, d.get("occluders", []), georef),
                _search(where, d.get("search")),
                as_number(where, "resolution_m", d.get("resolution_m", 0.5), positive=True, unit=" (m)"), name)
    x0, y0, x1, y1 = site.bounds_m(site.resolution_m)
    cells = ((x1 - x0) / site.resolution_m) * ((y1 - y0) / site.resolution_m)
    if cells > MAX_CELLS:
        raise ConfigError(label(where, "resolution_m"), site.resolution_m,
                          f"a grid of at most {MAX_CELLS:g} cells over the site ({x1 - x0:.3g} m x {y1 - y0:.3g} m "
                          f"needs {cells:.3g}): a coarser resolution or a smaller site")
    g = site.search
    n = len(g.pans_deg()) * len(g.tilts_deg) * sum(len(c.lenses) for c in site.cameras) * \
        sum(len(g.heights_m(m)) for m in site.mounts)
    if n > MAX_CANDIDATES:
        raise ConfigError(label(where, "search"), f"{n} candidates", f"a candidate grid of at most {MAX_CANDIDATES} "
                          "(mounts x heights x lenses x tilts x pans): a coarser pan step, fewer tilts or heights")
    return site


def load_site(path) -> Site:
    """Read and validate a site file (YAML or JSON; see the module docstring)."""
    p, text = read_text(path)
    site = site_from_dict(parse_mapping(text, p, what="site file"), where=str(p), base_dir=p.parent)
    site.path = p
    return site
