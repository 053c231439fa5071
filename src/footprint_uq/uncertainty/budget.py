"""Error budgets: named standard deviations (or a full covariance) of every error source.

Sources are grouped as in the paper's Table 1.  **Camera-level** sources
(intrinsic and extrinsic calibration, ground plane) are shared by every point of
an image; **per-point** sources (imaging and resolution noise, and a detector's
own pixel covariance) are independent from point to point.  Footprints depend on
that distinction: the corners of one object share the calibration error.

Budget-file keys (YAML or JSON; a missing key means zero; units in the names):

==================  ===========  =============================================
key                 shape        meaning (1-sigma)
==================  ===========  =============================================
focal_px            scalar       focal length; applied to fx and fy together
principal_point_px  [c, r]       principal point column / row
distortion          [5]          k1, k2, p1, p2, k3 (dimensionless)
position_m          [x, y]       camera position along world x (east), y (north)
height_m            scalar       camera height
pan_deg             scalar       pan (heading)
tilt_deg            scalar       tilt (pitch)
roll_deg            scalar       roll
ground_height_m     scalar       ground-plane height offset
ground_slope_deg    scalar       terrain slope, each horizontal direction
imaging_px          [c, r]       imaging noise (per point)
resolution_px       [c, r]       resolution noise (per point)
covariance          mapping      optional full covariance: ``names`` (from
                                 PARAM_NAMES, or pan_deg/tilt_deg/roll_deg) and
                                 ``matrix``; replaces the sigmas of those names
==================  ===========  =============================================

plus optional ``name``, ``description`` and ``motion`` (the tracker's manoeuvre noise per object class, written by
``calibrate motion``: :mod:`footprint_uq.uncertainty.motion_section`, docs/motion-fit.md).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .. import params as P
from .._checks import check_cov
from .._files import read_input_text
from .._parse import load_yaml_or_json
from ..errors import ConfigError, InputError
from . import presets
from .motion_section import parse_motion_section

__all__ = ["ErrorBudget", "SHARED_SOURCES", "POINT_SOURCES", "TERM_GROUPS", "SparseFactor", "load_budget",
           "psd_factor"]

#: camera-level sources -> parameters they act on
SHARED_SOURCES: dict[str, tuple[str, ...]] = {
    "focal": ("fx_px", "fy_px"),
    "principal_point": ("cx_px", "cy_px"),
    "skew": ("skew_px",),
    "distortion": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"),
    "position": ("x_m", "y_m"),
    "height": ("height_m",),
    "pan": ("pan_rad",),
    "tilt": ("tilt_rad",),
    "roll": ("roll_rad",),
    "ground_height": ("ground_dz_m",),
    "ground_slope": ("ground_slope_x", "ground_slope_y"),
}
#: groups of camera-level parameters a complete budget has some error on (:meth:`ErrorBudget.missing_terms`):
#: a budget with none on one group (e.g. the one ``calibrate intrinsics`` writes: no pose, no ground error)
#: gives the covariance of the other sources only, far smaller than a deployed camera's
TERM_GROUPS: dict[str, tuple[str, ...]] = {
    "extrinsic": ("x_m", "y_m", "height_m", "pan_rad", "tilt_rad", "roll_rad"),
    "ground": ("ground_dz_m", "ground_slope_x", "ground_slope_y"),
}
#: per-point sources (act on the pixel)
POINT_SOURCES = ("imaging", "resolution", "detector")

_PAIR_KEYS = ("principal_point_px", "position_m", "imaging_px", "resolution_px")
_SCALAR_KEYS = ("focal_px", "height_m", "pan_deg", "tilt_deg", "roll_deg", "ground_height_m",
                "ground_slope_deg")
_ALLOWED = set(_PAIR_KEYS) | set(_SCALAR_KEYS) | {"distortion", "covariance", "name", "description", "motion"}
_DEG_ALIASES = {"pan_deg": "pan_rad", "tilt_deg": "tilt_rad", "roll_deg": "roll_rad"}
#: largest standard deviation accepted, in the key's unit (beyond it products overflow; issue 11)
MAX_SIGMA = 1e6


def _sigma(field_name: str, value, n: int | None, where: str):
    label = f"{where}: {field_name}" if where else field_name
    if isinstance(value, bool | np.bool_) or (isinstance(value, list | tuple) and any(
            isinstance(v, bool | np.bool_) for v in value)):
        raise ConfigError(label, value, "a standard deviation (number >= 0), not a boolean")
    if n is None:
        try:
            x = float(value)
        except (TypeError, ValueError, OverflowError):
            raise ConfigError(label, value, "a standard deviation (number >= 0)") from None
        if not np.isfinite(x) or x < 0 or x > MAX_SIGMA:
            raise ConfigError(label, value, f"a finite standard deviation >= 0 and <= {MAX_SIGMA:g}")
        return x
    if np.ndim(value) == 0:
        value = [value] * n if n == 2 else value
    try:
        arr = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(label, value, f"a list of {n} standard deviations") from None
    if arr.size != n:
        raise ConfigError(label, value, f"a list of {n} standard deviations")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0) or np.any(arr > MAX_SIGMA):
        raise ConfigError(label, value, f"finite standard deviations >= 0 and <= {MAX_SIGMA:g}")
    return tuple(float(a) for a in arr)


@dataclass(frozen=True)
class ErrorBudget:
    """Standard deviations of every error source (units in the field names).

    Use :meth:`preset`, :meth:`from_dict` or :func:`load_budget` to build one.
    """

    focal_px: float = 0.0
    principal_point_px: tuple[float, float] = (0.0, 0.0)
    distortion: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    position_m: tuple[float, float] = (0.0, 0.0)
    height_m: float = 0.0
    pan_deg: float = 0.0
    tilt_deg: float = 0.0
    roll_deg: float = 0.0
    ground_height_m: float = 0.0
    ground_slope_deg: float = 0.0
    imaging_px: tuple[float, float] = (0.0, 0.0)
    resolution_px: tuple[float, float] = (0.0, 0.0)
    covariance_names: tuple[str, ...] = ()
    covariance_matrix: np.ndarray | None = field(default=None, compare=False, repr=False)
    name: str = "custom"
    description: str = ""
    #: the ``motion`` section (:func:`~footprint_uq.uncertainty.motion_section.parse_motion_section`), or None
    motion: dict | None = field(default=None, compare=False, repr=False)

    def __post_init__(self):
        # direct construction is validated like a budget file (from_dict gives checked values)
        for k in _SCALAR_KEYS:
            _sigma(k, getattr(self, k), None, "")
        for k in _PAIR_KEYS:
            _sigma(k, getattr(self, k), 2, "")
        _sigma("distortion", self.distortion, 5, "")
        if self.covariance_matrix is not None:
            m = np.asarray(self.covariance_matrix)
            n = len(self.covariance_names)
            if m.shape != (n, n) or any(name not in P.IDX for name in self.covariance_names):
                raise ConfigError("covariance_matrix", f"shape {m.shape}, names {list(self.covariance_names)}",
                                  "a square matrix over PARAM_NAMES entries (use from_dict for deg aliases)")
        elif self.covariance_names:
            raise ConfigError("covariance_names", self.covariance_names, "no names without a covariance_matrix")

    def __eq__(self, other):
        # the generated __eq__ would skip the covariance matrix (an array cannot be compared with ==)
        if other.__class__ is not self.__class__:
            return NotImplemented
        fields = [f.name for f in self.__dataclass_fields__.values() if f.name != "covariance_matrix"]
        if any(getattr(self, f) != getattr(other, f) for f in fields):
            return False
        a, b = self.covariance_matrix, other.covariance_matrix
        return (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))

    # -- construction ----------------------------------------------------------------
    @classmethod
    def preset(cls, name: str) -> ErrorBudget:
        """One of :data:`footprint_uq.uncertainty.presets.PRESET_NAMES` (case-insensitive).

        Table 3's angular errors are read as printed (10^-3 deg); append ``@deg``
        (``"basler1@deg"``) to read them as degrees (:mod:`footprint_uq.uncertainty.presets`).
        Table 3's sigma X (north) and sigma Y (east) become ``position_m = (sigma_Y, sigma_X)``
        (world east, north).
        """
        if presets.parse_preset_name(name) is None:
            raise ConfigError("budget preset", name, f"one of {_preset_choices()}{_did_you_mean(name)}")
        return cls.from_dict(presets.preset_dict(str(name)))

    @classmethod
    def from_dict(cls, d: dict, *, where: str = "") -> ErrorBudget:
        """Validate a budget-file mapping; unknown keys, negative or NaN sigmas raise ConfigError."""
        if not isinstance(d, dict):
            raise ConfigError(where or "budget", type(d).__name__, "a mapping of budget keys")
        unknown = sorted(set(d) - _ALLOWED)
        if unknown:
            raise ConfigError(f"{where}: {unknown[0]}" if where else unknown[0], d[unknown[0]],
                              f"one of the budget keys {sorted(_ALLOWED)} (units in the key names)")
        kw: dict = {}
        for k in _SCALAR_KEYS:
            if k in d and d[k] is not None:
                kw[k] = _sigma(k, d[k], None, where)
        for k in _PAIR_KEYS:
            if k in d and d[k] is not None:
                kw[k] = _sigma(k, d[k], 2, where)
        if d.get("distortion") is not None:
            kw["distortion"] = _sigma("distortion", d["distortion"], 5, where)
        if d.get("covariance") is not None:
            names, mat = _parse_covariance(d["covariance"], where)
            kw["covariance_names"], kw["covariance_matrix"] = names, mat
        kw["name"] = str(d.get("name", "custom"))
        kw["description"] = str(d.get("description", ""))
        if d.get("motion") is not None:
            kw["motion"] = parse_motion_section(d["motion"], f"{where}: motion" if where else "motion")
        return cls(**kw)

    def to_dict(self) -> dict:
        out = {"name": self.name}
        if self.description:
            out["description"] = self.description
        out.update({
            "focal_px": self.focal_px, "principal_point_px": list(self.principal_point_px),
            "distortion": list(self.distortion), "position_m": list(self.position_m),
            "height_m": self.height_m, "pan_deg": self.pan_deg, "tilt_deg": self.tilt_deg,
            "roll_deg": self.roll_deg, "ground_height_m": self.ground_height_m,
            "ground_slope_deg": self.ground_slope_deg, "imaging_px": list(self.imaging_px),
            "resolution_px": list(self.resolution_px),
        })
        if self.covariance_matrix is not None:
            out["covariance"] = {"names": list(self.covariance_names),
                                 "matrix": np.asarray(self.covariance_matrix).tolist()}
        if self.motion is not None:
            out["motion"] = self.motion
        return out

    def replace(self, **changes) -> ErrorBudget:
        d = self.to_dict()
        d.update(changes)
        return ErrorBudget.from_dict(d)

    def scaled(self, factor: float) -> ErrorBudget:
        """All standard deviations multiplied by ``factor`` (covariance by factor^2)."""
        d = self.to_dict()
        for k in _SCALAR_KEYS:
            d[k] = d[k] * factor
        for k in (*_PAIR_KEYS, "distortion"):
            d[k] = [v * factor for v in d[k]]
        if "covariance" in d:
            d["covariance"]["matrix"] = (np.asarray(d["covariance"]["matrix"]) * factor**2).tolist()
        d["name"] = f"{self.name} x{factor:g}"
        return ErrorBudget.from_dict(d)

    # -- covariances -------------------------------------------------------------------
    def param_covariance(self) -> np.ndarray:
        """Covariance (22, 22) of the shared camera parameters, in :data:`PARAM_NAMES` units."""
        S = np.zeros((P.N_PARAMS, P.N_PARAMS))
        I = P.IDX
        f2 = self.focal_px**2
        S[I["fx_px"], I["fx_px"]] = S[I["fy_px"], I["fy_px"]] = f2
        S[I["fx_px"], I["fy_px"]] = S[I["fy_px"], I["fx_px"]] = f2  # one focal error moves both
        diag = {
            "cx_px": self.principal_point_px[0], "cy_px": self.principal_point_px[1],
            "k1": self.distortion[0], "k2": self.distortion[1], "p1": self.distortion[2],
            "p2": self.distortion[3], "k3": self.distortion[4],
            "x_m": self.position_m[0], "y_m": self.position_m[1], "height_m": self.height_m,
            "pan_rad": np.deg2rad(self.pan_deg), "tilt_rad": np.deg2rad(self.tilt_deg),
            "roll_rad": np.deg2rad(self.roll_deg), "ground_dz_m": self.ground_height_m,
            "ground_slope_x": np.tan(np.deg2rad(self.ground_slope_deg)),
            "ground_slope_y": np.tan(np.deg2rad(self.ground_slope_deg)),
        }
        for k, s in diag.items():
            S[I[k], I[k]] = s * s
        if self.covariance_matrix is not None:
            idx = P.param_index(self.covariance_names)
            S[idx, :] = 0.0
            S[:, idx] = 0.0
            S[np.ix_(idx, idx)] = self.covariance_matrix
        return S

    def pixel_covariance(self, sources=("imaging", "resolution")) -> np.ndarray:
        """Per-point pixel covariance (2, 2), px^2, from the imaging and resolution errors."""
        s2 = np.zeros(2)
        if "imaging" in sources:
            s2 += np.square(self.imaging_px)
        if "resolution" in sources:
            s2 += np.square(self.resolution_px)
        return np.diag(s2)

    def param_factor(self) -> SparseFactor:
        """The one factorisation of :meth:`param_covariance` every kernel uses (:func:`psd_factor`).

        Computed once per budget (the budget is frozen; a covariance matrix changed in place is noticed by
        its bytes): the eigen-decomposition cost ~0.15 ms of every small ``covariance_points`` call and is
        the only LAPACK call on that path (OpenBLAS may wake its threads for it).
        """
        key = None if self.covariance_matrix is None else np.asarray(self.covariance_matrix).tobytes()
        cached = self.__dict__.get("_factor")
        if cached is not None and cached[0] == key:
            return cached[1]
        f = psd_factor(self.param_covariance())  # writable arrays: a read-only one is another type to numba
        object.__setattr__(self, "_factor", (key, f))
        return f

    def shared_source_covariances(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Per shared source: ``(param indices, covariance block)``, only non-zero sources."""
        S = self.param_covariance()
        out = {}
        for name, names in SHARED_SOURCES.items():
            idx = P.param_index(names)
            block = S[np.ix_(idx, idx)]
            if np.any(block):
                out[name] = (idx, block)
        return out

    def missing_terms(self) -> tuple[str, ...]:
        """The groups of :data:`TERM_GROUPS` (``"extrinsic"``, ``"ground"``) this budget has no error on at all.

        Empty for a complete budget (every preset).  A budget without extrinsic terms -- the one
        ``calibrate intrinsics`` writes, say -- gives the covariance of the intrinsics (and pixel noise)
        alone: tens of times smaller than that of a deployed camera, whose pose is never exact.
        """
        S = self.param_covariance()
        return tuple(name for name, names in TERM_GROUPS.items()
                     if not np.any(S[np.ix_(P.param_index(names), P.param_index(names))]))

    def table_row(self) -> dict:
        """Flat dictionary for tables (the `presets` command, reports)."""
        return {
            "name": self.name, "focal_px": self.focal_px,
            "pp_c_px": self.principal_point_px[0], "pp_r_px": self.principal_point_px[1],
            "k1": self.distortion[0], "k2": self.distortion[1], "p1": self.distortion[2],
            "p2": self.distortion[3], "k3": self.distortion[4],
            "x_m": self.position_m[0], "y_m": self.position_m[1], "height_m": self.height_m,
            "pan_deg": self.pan_deg, "tilt_deg": self.tilt_deg, "roll_deg": self.roll_deg,
            "ground_height_m": self.ground_height_m, "ground_slope_deg": self.ground_slope_deg,
            "imaging_px": self.imaging_px[0], "resolution_px": self.resolution_px[0],
        }


def _preset_choices() -> str:
    return (f"{', '.join(presets.PRESET_NAMES)} (angles as printed, 1e-3 deg), "
            f"or one of them with '@deg' (angles read as degrees)")


def _did_you_mean(name) -> str:
    close = presets.suggest_preset(name)
    return f"; did you mean '{close}'?" if close else ""


def _parse_covariance(c, where):
    label = f"{where}: covariance" if where else "covariance"
    if not isinstance(c, dict) or "names" not in c or "matrix" not in c:
        raise ConfigError(label, c, "a mapping with 'names' and 'matrix'")
    if not isinstance(c["names"], list | tuple):
        raise ConfigError(f"{label}.names", c["names"], "a list of parameter names")
    names = [str(n) for n in c["names"]]
    try:
        mat = np.asarray(c["matrix"], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{label}.matrix", c["matrix"], "a numeric square matrix") from None
    big = np.abs(mat[np.isfinite(mat)])
    if big.size and big.max() > MAX_SIGMA**2:
        raise ConfigError(f"{label}.matrix", f"an entry of magnitude {big.max():g}",
                          f"entries of magnitude <= {MAX_SIGMA**2:g} (variances in the parameters' units)")
    n = len(names)
    if mat.shape != (n, n):
        raise ConfigError(f"{label}.matrix", f"shape {mat.shape}", f"a {n}x{n} matrix matching 'names'")
    scale = np.ones(n)
    out_names = []
    for i, name in enumerate(names):
        if name in _DEG_ALIASES:
            scale[i] = np.pi / 180.0
            name = _DEG_ALIASES[name]
        if name not in P.IDX:
            raise ConfigError(f"{label}.names", name, f"one of {list(P.PARAM_NAMES) + list(_DEG_ALIASES)}")
        out_names.append(name)
    if len(set(out_names)) != n:  # after the aliases: pan_deg and pan_rad are the same parameter
        raise ConfigError(f"{label}.names", names, "unique parameters (pan_deg and pan_rad are the same one)")
    try:
        mat = check_cov(f"{label}.matrix", mat, n)
    except InputError as e:  # re-raise as a config error with the same text
        raise ConfigError(e.field, e.value, e.expected) from None
    mat = mat * np.outer(scale, scale)
    return tuple(out_names), mat


class SparseFactor(NamedTuple):
    """A sparse factor ``L`` (n x r) with ``L L^T = S``, stored by columns (CSC).

    Attributes
    ----------
    colptr : ndarray of int64 (r + 1,)
        Column ``j`` holds entries ``colptr[j]:colptr[j + 1]``.
    rowidx : ndarray of int64
        Row (parameter index) of each stored entry.
    vals : ndarray of float64
        The entries.
    """

    colptr: np.ndarray
    rowidx: np.ndarray
    vals: np.ndarray

    @property
    def rank(self) -> int:
        return self.colptr.size - 1

    @property
    def cols(self) -> np.ndarray:
        """Column of each stored entry (int64)."""
        return np.repeat(np.arange(self.rank, dtype=np.int64), np.diff(self.colptr))

    def dense(self, n: int = P.N_PARAMS) -> np.ndarray:
        """``L`` as a dense (n, r) array."""
        L = np.zeros((n, self.rank))
        L[self.rowidx, self.cols] = self.vals
        return L


def psd_factor(S, *, rtol: float = 1e-14) -> SparseFactor:
    """Sparse factor of a positive semi-definite covariance: ``S = L L^T``.

    ``S`` is scaled to a correlation matrix (so that parameters in px^2 and in rad^2 keep
    their relative precision), factored by diagonal-pivoted Cholesky -- pivoting stops when
    the largest remaining diagonal is below ``rtol`` (the numerical rank) -- and scaled back.
    A diagonal ``S`` gives a diagonal ``L``; fully correlated parameters (one focal error
    moving fx and fy) share one column; zero-variance parameters appear in none.

    Parameters
    ----------
    S : array_like, shape (n, n)
        Symmetric PSD (checked by the budget that built it).
    rtol : float
        Rank threshold, relative to a correlation matrix's unit diagonal.

    Returns
    -------
    SparseFactor
    """
    S = np.asarray(S, dtype=np.float64)
    d = np.sqrt(np.clip(np.diag(S), 0.0, None))
    used = np.flatnonzero(d > 0)
    A = S[np.ix_(used, used)] / np.outer(d[used], d[used])
    m = used.size
    L = np.zeros((m, m))
    r = 0
    while r < m:
        diag = np.diag(A)
        p = int(np.argmax(diag))
        if not diag[p] > rtol:
            break
        col = A[:, p] / np.sqrt(diag[p])
        L[:, r] = col
        A = A - np.outer(col, col)
        A[p, :] = 0.0
        A[:, p] = 0.0
        r += 1
    L = L[:, :r] * d[used][:, None]
    cols, rows = np.nonzero(L.T)  # sorted by column: the kernels form one factor column at a time
    colptr = np.zeros(r + 1, dtype=np.int64)
    np.cumsum(np.bincount(cols, minlength=r), out=colptr[1:])
    vals = np.ascontiguousarray(L[rows, cols])
    return SparseFactor(colptr, used[rows].astype(np.int64), vals)


@functools.lru_cache(maxsize=64)
def _preset(name: str) -> ErrorBudget:
    return ErrorBudget.preset(name)


def load_budget(spec) -> ErrorBudget:
    """A budget from a preset name, a YAML/JSON file path, a mapping or an ErrorBudget.

    Preset names are case-insensitive; ``NAME@deg`` reads Table 3's angular errors as
    degrees instead of the printed 10^-3 deg (see :mod:`footprint_uq.uncertainty.presets`).
    """
    if isinstance(spec, ErrorBudget):
        return spec
    if isinstance(spec, dict):
        return ErrorBudget.from_dict(spec)
    s = str(spec)
    if presets.parse_preset_name(s) is not None:
        return _preset(s)  # one (frozen) object per name: its factor is computed once, not on every call
    path = Path(s)
    if not path.exists():
        raise ConfigError("budget", s, f"a preset ({_preset_choices()}) or an existing file{_did_you_mean(s)}")
    try:
        text = read_input_text(path, "budget")  # a FIFO: a stream; a device: refused
    except (OSError, UnicodeDecodeError) as e:
        raise ConfigError(str(path), type(e).__name__, f"a readable UTF-8 budget file ({e})") from None
    try:
        data = load_yaml_or_json(text, str(path), is_json=path.suffix.lower() == ".json")
    except ConfigError:  # alias bomb, duplicate key, too large: already named
        raise
    except Exception as e:
        raise ConfigError(str(path), type(e).__name__, f"valid YAML/JSON ({str(e).splitlines()[0]})") from None
    return ErrorBudget.from_dict(data, where=str(path))
