"""Per-pixel uncertainty maps: ground point, 2x2 covariance, ellipse and ground sampling distance.

:func:`uncertainty_map` evaluates every ``step_px``-th pixel of an image and
returns an :class:`UncertaintyMap`: where each pixel lands on the ground, the
covariance of that ground point under an error budget (camera-level sources and
per-point pixel noise, first order), its 1-sigma ellipse and the ground
sampling distance (GSD).

Ground sampling distance (definition used throughout footprint-uq)
------------------------------------------------------------------
A pixel is a unit square in the image.  To first order its footprint on the
ground is the parallelogram spanned by the columns of ``dxy_duv`` (metres per
pixel): ``a = dxy/du`` (one step to the right) and ``b = dxy/dv`` (one step
down).  Let ``e_range`` be the horizontal unit vector from the camera's foot
point to the ground point and ``e_cross`` the unit vector 90 deg counter-clockwise
from it (``e_cross = z x e_range``).  Then

* ``gsd_range_m = |a . e_range| + |b . e_range|``: the length of the
  footprint projected on the range direction (metres covered by one pixel
  along the line of sight);
* ``gsd_cross_m = |a . e_cross| + |b . e_cross|``: the same across it.

For a camera with no roll these are, near the image centre line, the ground
length of one image row step and the ground width of one column step.  Where
the ground point is (within 1 mm) below the camera the range direction is
undefined and the boresight heading is used instead.  ``footprint_area_m2 =
|det dxy_duv|`` is the ground area of one pixel.

Validity: a pixel whose ray does not meet the ground, whose input is not finite
or whose lens model cannot be inverted is NaN with ``valid`` False and the
:mod:`footprint_uq.status` code in ``reason``.  With ``max_range_m``, pixels
that land farther than that from the camera foot point are masked the same
way with :data:`footprint_uq.status.BEYOND_RANGE`.

Linearity: ``nonlinearity`` is the predicted relative error of the linear 1-sigma
semi-major axis of every pixel (docs/uncertainty-model.md, "The linearity flag"),
computed in the same kernel pass; ``linear_ok`` masks the pixels where it is at most
``linear_threshold`` (default 0.05).  Where ``linear_ok`` is False the covariance
under-estimates the spread (near the horizon): the figures hatch that region and draw
the threshold's contour.
"""

from __future__ import annotations

import json
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import params as P
from .. import status
from .._checks import as_float, as_int
from .._notices import before_kernels
from ..cameras.distortion import undistort
from ..cameras.ground import intersect_ground
from ..cameras.pinhole import pixel_to_normalised
from ..io import camera_from_dict, camera_to_dict
from ..io.atomic import atomic_path
from ..uncertainty.budget import ErrorBudget, load_budget
from ..uncertainty.ellipse import chi2_scale, ellipse_axes
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD, check_linear_threshold, propagate
from .covariance import covariance_map

__all__ = ["UncertaintyMap", "uncertainty_map", "ground_sampling_distance", "pixel_jacobian", "GSD_DEFINITION",
           "SUMMARY_RANGES_M"]

#: ranges (metres from the camera foot point) of the summary's ``within_range`` figures: the reach of a
#: roadside camera's detections (an unmasked map's maximum comes from pixels just below the horizon)
SUMMARY_RANGES_M = (50.0, 100.0, 200.0)

#: one-line definition stored with every saved map
GSD_DEFINITION = ("gsd_range_m = |dxy/du . e_range| + |dxy/dv . e_range|, gsd_cross_m = the same with "
                  "e_cross = z x e_range; e_range = horizontal unit vector from the camera foot point to the "
                  "ground point (metres covered by one pixel along and across the line of sight)")

_BEYOND_RANGE = getattr(status, "BEYOND_RANGE", None)

# pixels per block of the reference (numpy) path; bounds memory to ~100 MB
_BLOCK_PX = 65_536


@dataclass
class UncertaintyMap:
    """Per-pixel results on a regular pixel grid of ``H x W`` samples.

    Attributes
    ----------
    uv_px : ndarray (H, W, 2)
        Pixel centres sampled (u right, v down, origin at the centre of the top-left pixel).
    xy_world_m : ndarray (H, W, 2)
        Ground point in the world frame W (x east, y north), metres; NaN where invalid.
    cov_m2 : ndarray (H, W, 2, 2)
        Covariance of the ground point, m^2 (x, y order of W); NaN where invalid.
    valid : ndarray of bool (H, W)
    reason : ndarray of int8 (H, W)
        :mod:`footprint_uq.status` code (0 = ok).
    semi_major_m, semi_minor_m : ndarray (H, W)
        1-sigma semi-axes of the ellipse of ``cov_m2``, metres.
    orientation_deg : ndarray (H, W)
        Major-axis angle, degrees counter-clockwise from +x (east), in (-90, 90].
    gsd_range_m, gsd_cross_m : ndarray (H, W)
        Ground sampling distance along and across the line of sight, metres per pixel
        (see the module docstring for the exact definition).
    footprint_area_m2 : ndarray (H, W)
        Ground area covered by one pixel, ``|det dxy_duv|``, m^2.
    range_m : ndarray (H, W)
        Horizontal distance from the camera foot point to the ground point, metres.
    step_px : int
        Grid step in pixels.
    camera, budget
        The inputs (kept for figures and reports; not stored in the ``.npz`` arrays).
    max_range_m : float or None
    nonlinearity : ndarray (H, W) or None
        Predicted relative error of the linear 1-sigma semi-major axis (0.05 = 5 %); NaN where
        not valid; None when not computed (``linearity=False``).
    linear_threshold : float
        Threshold of :attr:`linear_ok`.
    """

    uv_px: np.ndarray
    xy_world_m: np.ndarray
    cov_m2: np.ndarray
    valid: np.ndarray
    reason: np.ndarray
    semi_major_m: np.ndarray
    semi_minor_m: np.ndarray
    orientation_deg: np.ndarray
    gsd_range_m: np.ndarray
    gsd_cross_m: np.ndarray
    footprint_area_m2: np.ndarray
    range_m: np.ndarray
    step_px: int = 1
    camera: object = field(default=None, repr=False)
    budget: ErrorBudget | None = field(default=None, repr=False)
    max_range_m: float | None = None
    nonlinearity: np.ndarray | None = None
    linear_threshold: float = DEFAULT_LINEAR_THRESHOLD

    @property
    def linear_ok(self) -> np.ndarray | None:
        """(H, W) bool: valid and ``nonlinearity <= linear_threshold`` (None without the layer)."""
        if self.nonlinearity is None:
            return None
        with np.errstate(invalid="ignore"):
            return self.valid & (self.nonlinearity <= self.linear_threshold)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)`` of the grid."""
        return self.valid.shape

    def semi_axes(self, confidence: float | None = None):
        """``(semi_major_m, semi_minor_m)`` scaled to ``confidence`` (2-D chi-square); 1 sigma if None."""
        k = 1.0 if confidence is None else chi2_scale(confidence)
        return k * self.semi_major_m, k * self.semi_minor_m

    def summary(self, thresholds_m=(0.1, 0.25, 0.5, 1.0, 2.0), confidence: float | None = None) -> dict:
        """Headline numbers for planners (JSON-serialisable).

        For each threshold ``t``: the ground area (m^2) and the farthest range (m) of
        valid pixels whose semi-major axis (1 sigma, or at ``confidence``) is below ``t``.
        The area sums the pixel footprints ``|det dxy_duv|`` (times ``step_px^2``).

        Without ``max_range_m`` the maximum (``semi_major_m_max``, ``range_m_max``) comes from the pixels
        just below the horizon (10^5..10^6 m): use the percentiles (``semi_major_m_p90/p95/p99``,
        ``range_m_p95``) and, with the linearity flag, ``semi_major_m_max_linear_ok`` / ``range_m_max_linear_ok``
        (the largest over the pixels whose linear covariance holds), or ``within_range``: the 95th
        percentile and the maximum of the valid pixels within each of :data:`SUMMARY_RANGES_M` of the
        camera foot point.
        """
        a, _ = self.semi_axes(confidence)
        v = self.valid & np.isfinite(a)
        n = int(self.valid.size)
        out = {
            "image_size_px": list(getattr(self.camera, "image_size_px", ())) or None,
            "step_px": int(self.step_px),
            "grid_shape": list(self.shape),
            "budget": getattr(self.budget, "name", None),
            "confidence": confidence,
            "semi_axis_scale": 1.0 if confidence is None else chi2_scale(confidence),
            "max_range_m": self.max_range_m,
            "fraction_valid": float(v.sum() / n) if n else 0.0,
            "reason_counts": {status.REASONS.get(int(c), str(int(c))): int((self.reason == c).sum())
                              for c in np.unique(self.reason)},
        }
        if v.any():
            av = a[v]
            out.update({
                "semi_major_m_min": float(av.min()),
                "semi_major_m_median": float(np.median(av)),
                "semi_major_m_p90": float(np.percentile(av, 90)),
                "semi_major_m_p95": float(np.percentile(av, 95)),
                "semi_major_m_p99": float(np.percentile(av, 99)),
                "semi_major_m_max": float(av.max()),
                "range_m_p95": float(np.percentile(self.range_m[v], 95)),
                "range_m_max": float(self.range_m[v].max()),
                "gsd_range_m_median": float(np.median(self.gsd_range_m[v])),
                "gsd_cross_m_median": float(np.median(self.gsd_cross_m[v])),
            })
        else:
            out.update({k: None for k in ("semi_major_m_min", "semi_major_m_median", "semi_major_m_p90",
                                          "semi_major_m_p95", "semi_major_m_p99", "semi_major_m_max", "range_m_p95",
                                          "range_m_max", "gsd_range_m_median", "gsd_cross_m_median")})
        out.update(self._linearity_summary(v))
        ok = v & self.linear_ok if self.nonlinearity is not None else None
        has_ok = ok is not None and bool(ok.any())
        out["semi_major_m_max_linear_ok"] = float(a[ok].max()) if has_ok else None
        out["range_m_max_linear_ok"] = float(self.range_m[ok].max()) if has_ok else None
        out["within_range"] = []
        for r in SUMMARY_RANGES_M:
            m = v & (self.range_m <= r)
            out["within_range"].append({
                "range_m": float(r), "fraction_of_valid": float(m.sum() / max(int(v.sum()), 1)),
                "semi_major_m_p95": float(np.percentile(a[m], 95)) if m.any() else None,
                "semi_major_m_max": float(a[m].max()) if m.any() else None})
        area = self.footprint_area_m2 * float(self.step_px) ** 2
        out["below_threshold"] = []
        for t in thresholds_m:
            m = v & (a < t)
            out["below_threshold"].append({
                "semi_major_below_m": float(t),
                "ground_area_m2": float(area[m].sum()) if m.any() else 0.0,
                "max_range_m": float(self.range_m[m].max()) if m.any() else None,
                "fraction_of_image": float(m.sum() / n) if n else 0.0,
            })
        return out

    def _linearity_summary(self, v) -> dict:
        """The flag's headline numbers: share of valid pixels that are ``linear_ok`` and the nearest
        range where a pixel is not (None if none)."""
        if self.nonlinearity is None:
            return {"linear_threshold": None, "fraction_linear_ok": None, "nonlinearity_max": None,
                    "range_m_min_not_linear_ok": None}
        ok = self.linear_ok
        bad = v & ~ok
        nl = self.nonlinearity[v]
        return {"linear_threshold": float(self.linear_threshold),
                "fraction_linear_ok": float(ok[v].mean()) if v.any() else None,
                "nonlinearity_max": float(np.nanmax(nl)) if np.isfinite(nl).any() else None,
                "range_m_min_not_linear_ok": float(self.range_m[bad].min()) if bad.any() else None}

    def save_npz(self, path) -> Path:
        """Write every array to a compressed ``.npz`` file, plus a ``metadata_json`` string.

        The metadata holds the camera and budget (as their file dictionaries), the
        grid step, the GSD definition and the reason-code table.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        meta = {
            "format": "footprint-uq uncertainty map",
            "version": 1,
            "step_px": int(self.step_px),
            "max_range_m": self.max_range_m,
            "camera": _camera_dict(self.camera),
            "budget": self.budget.to_dict() if isinstance(self.budget, ErrorBudget) else None,
            "gsd_definition": GSD_DEFINITION,
            "orientation_convention": "degrees counter-clockwise from +x (east), in (-90, 90]",
            "semi_axes": "1 sigma; multiply by chi2_scale(p) (2.4477 for 95 %) for a p-confidence ellipse",
            "reasons": {str(k): v for k, v in status.REASONS.items()},
            "linear_threshold": float(self.linear_threshold),
            "nonlinearity": "predicted relative error of the linear 1-sigma semi-major axis; linear_ok = valid and "
                            "nonlinearity <= linear_threshold (docs/uncertainty-model.md)",
        }
        with atomic_path(path) as tmp:
            self._savez(tmp, meta)
        return Path(path)

    def _savez(self, path, meta) -> None:
        with open(path, "wb") as f:  # a file object: numpy appends no ".npz" to the temporary name
            self._savez_to(f, meta)

    def _savez_to(self, f, meta) -> None:
        flag = {} if self.nonlinearity is None else {"nonlinearity": self.nonlinearity, "linear_ok": self.linear_ok}
        np.savez_compressed(
            f, uv_px=self.uv_px, xy_world_m=self.xy_world_m, cov_m2=self.cov_m2, valid=self.valid,
            reason=self.reason, semi_major_m=self.semi_major_m, semi_minor_m=self.semi_minor_m,
            orientation_deg=self.orientation_deg, gsd_range_m=self.gsd_range_m, gsd_cross_m=self.gsd_cross_m,
            footprint_area_m2=self.footprint_area_m2, range_m=self.range_m, **flag,
            metadata_json=np.array(json.dumps(meta, default=_json_default)),
        )

    @classmethod
    def load_npz(cls, path) -> UncertaintyMap:
        """Read a file written by :meth:`save_npz` (camera and budget are rebuilt when possible)."""
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files if k not in ("metadata_json", "linear_ok")}  # linear_ok: derived
            meta = json.loads(str(z["metadata_json"])) if "metadata_json" in z.files else {}
        camera = None
        if meta.get("camera"):

            camera = camera_from_dict(meta["camera"], where=str(path))
        budget = ErrorBudget.from_dict(meta["budget"]) if meta.get("budget") else None
        return cls(**arrays, step_px=int(meta.get("step_px", 1)), camera=camera, budget=budget,
                   max_range_m=meta.get("max_range_m"),
                   linear_threshold=float(meta.get("linear_threshold", DEFAULT_LINEAR_THRESHOLD)))


def _camera_dict(camera):
    """The camera-file mapping (exact round trip through :func:`footprint_uq.io.camera_from_dict`)."""
    if camera is None:
        return None

    return camera_to_dict(camera)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _heading_unit(camera) -> np.ndarray:
    """Horizontal unit vector of the boresight heading in W (x east, y north)."""
    pan = camera.params[P.PAN]
    return np.array([np.sin(pan), np.cos(pan)])


def ground_sampling_distance(camera, xy_world_m, dxy_duv):
    """GSD along and across the line of sight from the pixel Jacobian.

    Parameters
    ----------
    camera : Camera
        Supplies the foot point (``x_m``, ``y_m``) and, for points right below it, the heading.
    xy_world_m : array_like (..., 2)
        Ground points in W, metres.
    dxy_duv : array_like (..., 2, 2)
        ``d(x, y)/d(u, v)``, metres per pixel.

    Returns
    -------
    gsd_range_m, gsd_cross_m, footprint_area_m2, range_m : ndarray (...)
        See the module docstring; NaN where the inputs are NaN.
    """
    xy = np.asarray(xy_world_m, dtype=np.float64)
    J = np.asarray(dxy_duv, dtype=np.float64)
    d = xy - camera.params[P.XM:P.YM + 1]
    rng = np.hypot(d[..., 0], d[..., 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        e_r = d / rng[..., None]
    near = rng < 1e-3
    if np.any(near):
        e_r = np.where(near[..., None], _heading_unit(camera), e_r)
    e_c = np.stack([-e_r[..., 1], e_r[..., 0]], -1)
    a, b = J[..., :, 0], J[..., :, 1]
    gsd_r = np.abs((a * e_r).sum(-1)) + np.abs((b * e_r).sum(-1))
    gsd_c = np.abs((a * e_c).sum(-1)) + np.abs((b * e_c).sum(-1))
    area = np.abs(J[..., 0, 0] * J[..., 1, 1] - J[..., 0, 1] * J[..., 1, 0])
    return gsd_r, gsd_c, area, rng


def pixel_jacobian(camera, uv_px, *, full: bool = False):
    """``dxy_duv (..., 2, 2)`` (metres per pixel) and ``valid``, without the 22 parameter columns.

    The same chain as :func:`footprint_uq.cameras.general.backproject` (pixel ->
    normalised -> undistorted -> ray -> ground) restricted to the pixel
    derivatives, several times cheaper than ``backproject(get_gradients=True)``
    for whole images; ``tests/test_maps.py`` checks that both agree.  NaN where
    the point is invalid.  With ``full``, returns ``(xy_world_m, dxy_duv, valid,
    reason)`` (the back-projection itself from the same single undistortion).
    """

    p = camera.params
    uv = np.asarray(uv_px, dtype=np.float64)
    xd, dxd_duv, _ = pixel_to_normalised(uv, p[P.FX], p[P.FY], p[P.CX], p[P.CY], p[P.SKEW], get_gradients=True)
    dist = p[P.DIST_SLICE]
    if np.any(dist):
        xn, conv, dxn_dxd, _ = undistort(xd, dist, get_gradients=True)
        dxn_duv = dxn_dxd @ dxd_duv
    else:
        xn, conv, dxn_duv = xd, np.ones(xd.shape[:-1], dtype=bool), dxd_duv
    R = camera.R_world_cam
    ray_w = xn @ R[:, :2].T + R[:, 2]
    xy, vg, _, dxy_dray, _ = intersect_ground(p[P.XM:P.HM + 1], ray_w, p[P.GDZ:P.GSY + 1], get_gradients=True)
    J = dxy_dray @ R[:, :2] @ dxn_duv
    finite = np.isfinite(uv).all(-1)
    valid = vg & conv & finite
    J = np.where(valid[..., None, None], J, np.nan)
    if not full:
        return J, valid
    xy = np.where(valid[..., None], xy, np.nan)
    return xy, J, valid, status.backprojection_reason(vg, conv, finite)


def _kernel_disagreement(camera, budget, uv, xy, cov, valid, xy_ref, valid_ref, m_per_px, *, n_check: int = 256,
                         rtol: float = 1e-6, nonlinearity=None) -> str:
    """Cheap guard on the fused kernel: '' if it agrees with the reference path, else what differs.

    Checks validity and ground points everywhere, finiteness of every valid
    covariance, and the covariance itself against :func:`propagate` at up to
    ``n_check`` pixels spread over the image plus the farthest ones.
    ``m_per_px`` (n,) is the ground motion per pixel (conditioning of the ground point).
    """
    if not np.array_equal(valid, valid_ref):
        return f"validity differs at {int((valid != valid_ref).sum())} pixels"
    if not valid.any():
        return ""
    with np.errstate(invalid="ignore"):
        d = np.abs(xy - xy_ref).max(-1)
        # 1e-9 relative, plus 1e-8 px worth of ground motion: near the horizon the ground point is
        # ill-conditioned (metres per pixel grow like range^2) and round-off differs between the two paths
        bad = valid & ~(d <= 1e-9 * (1.0 + np.abs(xy_ref).max(-1)) + 1e-8 * m_per_px)
    if bad.any():
        return f"ground points differ at {int(bad.sum())} pixels (max {np.nanmax(d[bad]):.3g} m)"
    bad = valid & ~np.isfinite(cov).all((-1, -2))
    if bad.any():
        return f"non-finite covariance at {int(bad.sum())} valid pixels"
    v = np.flatnonzero(valid)
    rng = np.hypot(xy[v, 0] - camera.params[P.XM], xy[v, 1] - camera.params[P.YM])
    k = min(32, v.size)
    far = v[np.argpartition(rng, v.size - k)[v.size - k:]]
    pick = np.unique(np.concatenate([v[np.linspace(0, v.size - 1, min(n_check, v.size)).astype(np.intp)], far]))
    est = propagate(camera, budget, uv[pick])
    ref = est.cov_m2
    scale = np.abs(ref).max(axis=(-2, -1))
    err = np.abs(cov[pick] - ref).max(axis=(-2, -1)) / scale
    if np.any(~(err <= rtol)):
        return f"covariance differs by up to {np.nanmax(err):.3g} (relative) at {int((~(err <= rtol)).sum())} " \
               f"of {pick.size} checked pixels"
    if nonlinearity is not None:
        with np.errstate(invalid="ignore"):
            err = np.abs(nonlinearity[pick] - est.nonlinearity) / np.maximum(np.abs(est.nonlinearity), 1e-12)
        if np.any(~(err <= rtol)):
            return f"nonlinearity differs by up to {np.nanmax(err):.3g} (relative) at {int((~(err <= rtol)).sum())} " \
                   f"of {pick.size} checked pixels"
    return ""




def uncertainty_map(camera, budget, step_px: int = 1, *, max_range_m: float | None = None,
                    use_kernel: bool = True, linearity: bool = True,
                    linear_threshold: float = DEFAULT_LINEAR_THRESHOLD) -> UncertaintyMap:
    """Ground point, covariance, ellipse and GSD of every ``step_px``-th pixel of the image.

    Parameters
    ----------
    camera : Camera
        :class:`~footprint_uq.PanTiltCamera` or :class:`~footprint_uq.OpenCVCamera`.
    budget : ErrorBudget, preset name, path or mapping
        Error budget (:func:`footprint_uq.uncertainty.budget.load_budget`).
    step_px : int
        Grid step; the grid is ``camera.pixel_grid(step_px)`` (pixel centres 0, step, 2 step, ...).
    max_range_m : float, optional
        Mask pixels whose ground point is farther than this from the camera foot point
        (reason :data:`footprint_uq.status.BEYOND_RANGE`).  Near the horizon the
        ground range grows without bound; this keeps maps and figures readable.
    use_kernel : bool
        Use the fused ``footprint_uq.products.covariance.covariance_map`` when it is available;
        False forces the reference path (:func:`footprint_uq.uncertainty.propagation.propagate`).
    linearity : bool
        Also compute the ``nonlinearity`` layer (in the same kernel pass) and the ``linear_ok`` mask.
    linear_threshold : float
        ``linear_ok = valid and nonlinearity <= linear_threshold`` (default 0.05).

    Returns
    -------
    UncertaintyMap
        Arrays of shape ``(H, W, ...)`` with ``H = ceil(height / step_px)``,
        ``W = ceil(width / step_px)``.
    """
    step = as_int("step_px", step_px, minimum=1, expected="a positive integer")
    if max_range_m is not None:
        max_range_m = as_float("max_range_m", max_range_m, positive=True)
    thr = check_linear_threshold(linear_threshold)
    budget = load_budget(budget)
    uv = camera.pixel_grid(step)
    H, W = uv.shape[:2]
    flat = uv.reshape(-1, 2)
    n = flat.shape[0]
    reason = np.empty(n, dtype=np.int8)
    xy_ref = np.empty((n, 2))
    gsd_r, gsd_c, area, rng = (np.empty(n) for _ in range(4))

    # (a command line whose map kernels still compile in the background takes the reference path: _notices)
    use_kernel = use_kernel and before_kernels("map")
    if use_kernel:
        xy, cov, valid, nl = _kernel_layers(camera, budget, step, (H, W), linearity)
    else:
        xy, cov, valid = np.empty((n, 2)), np.empty((n, 2, 2)), np.empty(n, dtype=bool)
        nl = np.full(n, np.nan) if linearity else None
    for s in range(0, n, _BLOCK_PX):
        blk = slice(s, min(n, s + _BLOCK_PX))
        xy_b, J_b, _, reason[blk] = pixel_jacobian(camera, flat[blk], full=True)
        xy_ref[blk] = xy_b
        gsd_r[blk], gsd_c[blk], area[blk], rng[blk] = ground_sampling_distance(camera, xy_b, J_b)
        if not use_kernel:
            _reference_block(camera, budget, flat, blk, linearity, xy, cov, valid, nl)
    if use_kernel:
        problem = _kernel_disagreement(camera, budget, flat, xy, cov, valid, xy_ref, reason == status.OK,
                                       gsd_r + gsd_c, nonlinearity=nl)
        if problem:
            warnings.warn(f"products.covariance.covariance_map disagrees with the reference path ({problem}); "
                          "using uncertainty.propagation.propagate for this map", RuntimeWarning, stacklevel=2)
            for s in range(0, n, _BLOCK_PX):
                _reference_block(camera, budget, flat, slice(s, min(n, s + _BLOCK_PX)), linearity, xy, cov, valid,
                                 nl)
    return _finished_map(camera, budget, uv, step, max_range_m, thr, xy, cov, valid, reason, nl, gsd_r, gsd_c, area,
                         rng)


def _finished_map(camera, budget, uv, step: int, max_range_m, thr: float, xy, cov, valid, reason, nl, gsd_r, gsd_c,
                  area, rng) -> UncertaintyMap:
    """The flat per-pixel layers of :func:`uncertainty_map` masked (invalid and beyond ``max_range_m``: NaN), their
    ellipses, and the map of shape ``uv.shape[:2]``."""
    linearity = nl is not None
    H, W = uv.shape[:2]
    if max_range_m is not None:
        far = valid & (rng > max_range_m)
        valid &= ~far
        if _BEYOND_RANGE is None:  # pragma: no cover - status without the code
            raise RuntimeError("footprint_uq.status.BEYOND_RANGE is missing")
        reason[far] = _BEYOND_RANGE
    inv = ~valid
    xy[inv] = np.nan
    cov[inv] = np.nan
    for a in (gsd_r, gsd_c, area, rng) + ((nl,) if linearity else ()):
        a[inv] = np.nan
    a_m, b_m, ang = ellipse_axes(cov)
    sh = (H, W)
    return UncertaintyMap(
        uv_px=uv, xy_world_m=xy.reshape(sh + (2,)), cov_m2=cov.reshape(sh + (2, 2)), valid=valid.reshape(sh),
        reason=reason.reshape(sh), semi_major_m=a_m.reshape(sh), semi_minor_m=b_m.reshape(sh),
        orientation_deg=ang.reshape(sh), gsd_range_m=gsd_r.reshape(sh), gsd_cross_m=gsd_c.reshape(sh),
        footprint_area_m2=area.reshape(sh), range_m=rng.reshape(sh), step_px=step, camera=camera,
        budget=budget, max_range_m=max_range_m, nonlinearity=None if nl is None else nl.reshape(sh),
        linear_threshold=thr,
    )


def _kernel_layers(camera, budget, step: int, hw: tuple[int, int], linearity: bool):
    """The fused kernel's ground points (n, 2), covariances (n, 2, 2), validity (n,) and nonlinearity (n,) (None
    without ``linearity``), flattened; its shapes checked against the grid ``hw``."""
    H, W = hw
    res = covariance_map(camera, budget, step, get_nonlinearity=True) if linearity else \
        covariance_map(camera, budget, step)
    kxy, kcov, kvalid = (np.asarray(a) for a in res[:3])
    if kxy.shape != (H, W, 2) or kcov.shape != (H, W, 2, 2) or kvalid.shape != (H, W):
        raise RuntimeError(f"kernels.covariance_map returned shapes {kxy.shape}, {kcov.shape}, "
                           f"{kvalid.shape}; expected ({H}, {W}, 2), ({H}, {W}, 2, 2), ({H}, {W})")
    nl = np.array(res[3], dtype=float).reshape(-1) if linearity else None
    return (np.array(kxy, dtype=float).reshape(-1, 2), np.array(kcov, dtype=float).reshape(-1, 2, 2),
            np.array(kvalid, dtype=bool).reshape(-1), nl)


def _reference_block(camera, budget, flat, blk: slice, linearity: bool, xy, cov, valid, nl) -> None:
    """Fill block ``blk`` of the layers with the reference path (:func:`propagate`), in place."""
    est = propagate(camera, budget, flat[blk], linearity=linearity)
    xy[blk], cov[blk], valid[blk] = est.xy_world_m, est.cov_m2, est.valid
    if linearity:
        nl[blk] = est.nonlinearity
