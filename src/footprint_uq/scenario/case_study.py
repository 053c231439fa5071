"""The paper's case study: a left turn seen by two roadside cameras of three types.

Pipeline::

    config = CaseStudyConfig.from_dict({...})      # or load_config(path), or CaseStudyConfig()
    scene = build_scene(config)                    # intersection, trajectory, cameras
    result = analyse(scene, config.camera_types)   # per camera x type x frame
    result.table                                   # pandas DataFrame, one row per frame
    result.summary()                               # per camera x type numbers
    result.statements()                            # the paper's claims, tested on the data

A :class:`Scene` can also come from a CARLA recording
(:func:`footprint_uq.integrations.carla.bridge.read_recording`); :func:`analyse` does not care.

Per frame and camera, the vehicle's 3-D box is known in the world (ground truth, as the
paper captured it in CARLA).  Its bottom corners are projected into the image and
back-projected with uncertainty by :func:`footprint_uq.products.footprints.footprints_from_boxes3d`
(the camera-level errors are shared by the corners); from that come the largest-point
and footprint-centre uncertainties.  Per-source contributions to the footprint-centre
covariance are the same linear propagation split by source (they add up to the total).

Axes used to compare with the paper's "X" and "Y"
------------------------------------------------
The paper's earth frame has its origin at the camera, X and Y horizontal, and the camera
panned by alpha from X; it does not say how X is tied to the road.  We report three
readings and test the paper's statements in each:

* ``world``: X = east (x of W), Y = north (y of W);
* ``north-east``: X = north, Y = east -- the paper's frame with alpha a compass heading
  (as :mod:`footprint_uq.cameras.pantilt` reads it);
* ``camera``: X = along the camera's pan direction (ground projection of the boresight),
  Y = across it (to the right) -- the paper's frame with alpha = 0.

and, to explain the results, the range / cross-range components (along and across the
horizontal line of sight from the camera's foot to the footprint centre).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .. import params as P
from .. import status
from .._checks import as_float
from .._parse import load_yaml_or_json
from ..errors import ConfigError
from ..products.footprints import footprint_centre, footprints_from_boxes3d
from ..uncertainty import presets
from ..uncertainty.budget import SHARED_SOURCES, ErrorBudget, load_budget
from ..uncertainty.ellipse import chi2_scale, ellipse_axes
from ..uncertainty.propagation import DEFAULT_LINEAR_THRESHOLD, nonlinearity
from .cameras import CAMERA_TYPES, CameraSpec, default_camera_specs
from .intersection import Intersection, RoadLayout, cfg_float
from .trajectory import SEGMENTS, Vehicle, box_corners, left_turn_path, sample_trajectory

__all__ = ["CaseStudyConfig", "Scene", "CaseStudyResult", "FootprintHeatmap", "load_config", "build_scene", "analyse",
           "footprint_heatmap",
           "centre_contributions", "axis_components", "AXIS_SYSTEMS", "camera_type_label"]

#: axis systems in which the paper's X/Y statements are tested (see module doc)
AXIS_SYSTEMS = {
    "world": ("east (x of W)", "north (y of W)"),
    "north-east": ("north", "east"),
    "camera": ("along the camera pan", "across the camera pan"),
}


def camera_type_label(name: str) -> str:
    """Display name of a camera type (``"bw-cube1"`` -> ``"BW-Cube1"``)."""
    return presets.DISPLAY_NAMES.get(str(name).lower(), str(name))


# -- configuration -------------------------------------------------------------------------
_CONFIG_KEYS = {"intersection", "vehicle", "trajectory", "cameras", "camera_types", "confidence", "heatmap"}
_TRAJ_KEYS = {"approach", "entry_lane", "exit_lane", "lead_in_m", "lead_out_m", "turn_radius_m", "speed_mps",
              "turn_speed_mps", "accel_mps2", "frame_rate_hz"}
_HEAT_KEYS = {"step_m", "margin_m", "yaw_deg"}


@dataclass
class CaseStudyConfig:
    """Everything the case study needs; every field has a default (the paper-like set-up).

    ``camera_types`` maps a label to a budget spec (preset name, budget file path or mapping).
    The YAML/JSON file has the keys ``intersection``, ``vehicle``, ``trajectory``,
    ``cameras`` (list), ``camera_types`` (list of preset names, or mapping label -> budget),
    ``confidence`` and ``heatmap`` (``step_m``, ``margin_m``, ``yaw_deg``); see
    ``docs/case-study.md``.
    """

    intersection: Intersection = field(default_factory=Intersection)
    vehicle: Vehicle = field(default_factory=Vehicle)
    trajectory: dict = field(default_factory=lambda: {
        "approach": "south", "entry_lane": 0, "exit_lane": 0, "lead_in_m": 35.0, "lead_out_m": 35.0,
        "turn_radius_m": None, "speed_mps": 8.0, "turn_speed_mps": 4.5, "accel_mps2": 2.0,
        "frame_rate_hz": 10.0})
    cameras: list = field(default_factory=list)
    camera_types: dict = field(default_factory=lambda: {k: k for k in CAMERA_TYPES})
    confidence: float = 0.95
    heatmap: dict = field(default_factory=lambda: {"step_m": 1.0, "margin_m": 2.0, "yaw_deg": None})

    def __post_init__(self):
        if not self.cameras:
            self.cameras = default_camera_specs(self.intersection)
        c = cfg_float("confidence", self.confidence)
        if not 0 < c < 1:
            raise ConfigError("confidence", self.confidence, "a probability in (0, 1), e.g. 0.95")

    @classmethod
    def from_dict(cls, d: dict | None, *, where: str = "config") -> CaseStudyConfig:
        d = dict(d or {})
        unknown = sorted(set(d) - _CONFIG_KEYS)
        if unknown:
            raise ConfigError(f"{where}: {unknown[0]}", d[unknown[0]], f"one of {sorted(_CONFIG_KEYS)}")
        inter = Intersection.from_dict(d.get("intersection"))
        kw: dict = {"intersection": inter, "vehicle": Vehicle.from_dict(d.get("vehicle"))}
        traj = cls().trajectory
        t = d.get("trajectory") or {}
        bad = sorted(set(t) - _TRAJ_KEYS)
        if bad:
            raise ConfigError(f"{where}: trajectory.{bad[0]}", t[bad[0]], f"one of {sorted(_TRAJ_KEYS)}")
        traj.update(t)
        kw["trajectory"] = traj
        if d.get("cameras") is not None:
            cams = d["cameras"]
            if not isinstance(cams, list) or not cams:
                raise ConfigError(f"{where}: cameras", cams, "a non-empty list of camera mappings")
            specs = [CameraSpec.from_dict(c, where=f"{where}: cameras[{i}]") for i, c in enumerate(cams)]
            names = [s.name for s in specs]
            if len(set(names)) != len(names):
                raise ConfigError(f"{where}: cameras.name", names, "unique camera names")
            kw["cameras"] = specs
        if d.get("camera_types") is not None:
            ct = d["camera_types"]
            if isinstance(ct, list):
                ct = {str(k): k for k in ct}
            if not isinstance(ct, dict) or not ct:
                raise ConfigError(f"{where}: camera_types", ct, "a list of preset names or a mapping label -> budget")
            for v in ct.values():
                load_budget(v)  # validate now, with the budget's own message
            kw["camera_types"] = dict(ct)
        if "confidence" in d:
            kw["confidence"] = d["confidence"]
        heat = cls().heatmap
        h = d.get("heatmap") or {}
        bad = sorted(set(h) - _HEAT_KEYS)
        if bad:
            raise ConfigError(f"{where}: heatmap.{bad[0]}", h[bad[0]], f"one of {sorted(_HEAT_KEYS)}")
        heat.update(h)
        cfg_float(f"{where}: heatmap.step_m", heat["step_m"], positive=True)
        kw["heatmap"] = heat
        return cls(**kw)

    def to_dict(self) -> dict:
        """The settings as a plain mapping (what :meth:`from_dict` reads back)."""
        ct = {k: (v if isinstance(v, str) else load_budget(v).to_dict()) for k, v in self.camera_types.items()}
        return {"intersection": self.intersection.to_dict(), "vehicle": self.vehicle.to_dict(),
                "trajectory": dict(self.trajectory), "cameras": [c.to_dict() for c in self.cameras],
                "camera_types": ct, "confidence": self.confidence, "heatmap": dict(self.heatmap)}

    def budgets(self) -> dict[str, ErrorBudget]:
        return {k: load_budget(v) for k, v in self.camera_types.items()}


def load_config(path) -> CaseStudyConfig:
    """A :class:`CaseStudyConfig` from a YAML or JSON file."""
    p = Path(path)
    if not p.exists():
        raise ConfigError("config", str(path), "an existing YAML or JSON file")
    text = p.read_text()
    try:
        data = load_yaml_or_json(text, str(p), is_json=p.suffix.lower() == ".json")
    except ConfigError:  # alias bomb, duplicate key, too large: already named
        raise
    except ValueError as e:
        raise ConfigError(str(p), type(e).__name__, f"valid YAML/JSON ({str(e).splitlines()[0]})") from None
    except Exception as e:  # yaml.YAMLError has no common base with ValueError
        raise ConfigError(str(p), type(e).__name__, f"valid YAML/JSON ({str(e).splitlines()[0]})") from None
    if data is not None and not isinstance(data, dict):
        raise ConfigError(str(p), type(data).__name__, "a mapping of case-study settings")
    return CaseStudyConfig.from_dict(data, where=str(p))


# -- the scene ---------------------------------------------------------------------------------
@dataclass
class Scene:
    """Cameras, road layout and one vehicle's frames: the input of :func:`analyse`.

    Attributes
    ----------
    layout : RoadLayout
    cameras : dict[str, Camera]
    frame : (N,) int       frame numbers
    t_s : (N,) float       timestamps, s
    boxes_world : (N, 7)   x, y, z, length, width, height, yaw_rad (W)
    segment : (N,) int8    0 entry / 1 turn / 2 exit
    source : str           where the scene comes from (shown in the report)
    camera_settings : dict[str, dict]   per camera, the settings shown in the report
    """

    layout: RoadLayout
    cameras: dict
    frame: np.ndarray
    t_s: np.ndarray
    boxes_world: np.ndarray
    segment: np.ndarray
    source: str = "footprint-uq scenario generator"
    camera_settings: dict = field(default_factory=dict)
    extra: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def build_scene(config: CaseStudyConfig | None = None) -> Scene:
    """The synthetic scene of ``config`` (defaults: the paper-like set-up)."""
    config = config or CaseStudyConfig()
    t = config.trajectory
    path = left_turn_path(config.intersection, approach=t["approach"], entry_lane=int(t["entry_lane"]),
                          exit_lane=int(t["exit_lane"]), lead_in_m=t["lead_in_m"], lead_out_m=t["lead_out_m"],
                          turn_radius_m=t["turn_radius_m"])
    tr = sample_trajectory(path, config.vehicle, speed_mps=t["speed_mps"], frame_rate_hz=t["frame_rate_hz"],
                           turn_speed_mps=t["turn_speed_mps"], accel_mps2=t["accel_mps2"])
    cams = {}
    settings = {}
    for spec in config.cameras:
        cams[spec.name] = spec.build()
        settings[spec.name] = spec.to_dict()
    return Scene(config.intersection.layout(), cams, np.arange(len(tr)), tr.t_s, tr.boxes_world, tr.segment,
                 camera_settings=settings, extra={"path": path.to_dict(), "turn_radius_m": path.radius_m,
                                                  "speed_mps": tr.speed_mps})


# -- axes -----------------------------------------------------------------------------------------
def _unit_axes(system: str, camera, xy_world_m=None) -> tuple[np.ndarray, np.ndarray]:
    if system == "world":
        return np.array([1.0, 0.0]), np.array([0.0, 1.0])
    if system == "north-east":
        return np.array([0.0, 1.0]), np.array([1.0, 0.0])
    if system == "camera":
        pan = camera.params[P.PAN]
        along = np.array([np.sin(pan), np.cos(pan)])
        return along, np.array([along[1], -along[0]])
    if system == "range":
        d = np.asarray(xy_world_m, dtype=np.float64) - camera.position_world_m[:2]
        n = np.linalg.norm(d, axis=-1, keepdims=True)
        with np.errstate(invalid="ignore", divide="ignore"):
            e = d / n
        return e, np.stack([e[..., 1], -e[..., 0]], -1)
    raise ConfigError("axes", system, f"one of {list(AXIS_SYSTEMS) + ['range']}")


def axis_components(cov_m2, system: str, camera, xy_world_m=None) -> tuple[np.ndarray, np.ndarray]:
    """Standard deviations ``(sigma_X, sigma_Y)`` of ``(..., 2, 2)`` covariances along the axes of ``system``.

    ``system``: ``"world"``, ``"north-east"``, ``"camera"`` (see module doc) or ``"range"``
    (X along the horizontal line of sight from the camera foot to ``xy_world_m``, Y across it).
    """
    c = np.asarray(cov_m2, dtype=np.float64)
    ex, ey = _unit_axes(system, camera, xy_world_m)
    vx = np.einsum("...i,...ij,...j->...", ex, c, ex)
    vy = np.einsum("...i,...ij,...j->...", ey, c, ey)
    return np.sqrt(vx), np.sqrt(vy)


# -- per-source contributions ------------------------------------------------------------------------
def centre_contributions(camera, budget, fp) -> dict[str, np.ndarray]:
    """Per-source covariance ``(N, 2, 2)`` of the footprint centres of ``fp`` (a FootprintEstimate).

    The centre is a function of the corners, ``C = C(p_0, ..., p_{K-1})``, with the
    Jacobian ``G`` of :func:`footprint_uq.products.footprints.footprint_centre`; a camera-level
    source ``s`` with parameter block ``Sigma_s`` contributes ``G J_s Sigma_s J_s^T G^T``
    (``J_s`` stacks the corners' ``dxy/dp_s``), a per-point source ``G Juv (I x S) Juv^T G^T``.
    Correlations between sources, if the budget has any, are in ``"cross_terms"``.  The
    contributions add up to ``fp.centre_cov_m2``; NaN where the centre is invalid.
    """
    budget = load_budget(budget)
    uv = fp.corners_px
    N, K = uv.shape[:2]
    ok = fp.centre_valid
    uv_ok = np.where(ok[:, None, None], uv, camera.principal_point_px if hasattr(camera, "principal_point_px")
                     else camera.params[[P.CX, P.CY]])
    bp = camera.backproject(uv_ok, get_gradients=True)
    xy = np.where(ok[:, None, None], fp.corners_xy_world_m, bp.xy_world_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        _, _, G = footprint_centre(xy, get_gradients=True)
    G = np.nan_to_num(G)
    out: dict[str, np.ndarray] = {}
    total = np.zeros((N, 2, 2))
    for name, (idx, block) in budget.shared_source_covariances().items():
        J = bp.dxy_dp[..., idx].reshape(N, 2 * K, idx.size)
        GJ = G @ J
        out[name] = GJ @ block @ np.swapaxes(GJ, -1, -2)
        total = total + out[name]
    Juv = np.zeros((N, 2 * K, 2 * K))
    for k in range(K):
        Juv[:, 2 * k:2 * k + 2, 2 * k:2 * k + 2] = bp.dxy_duv[:, k]
    GJuv = G @ Juv
    for src in ("imaging", "resolution"):
        S = budget.pixel_covariance((src,))
        if np.any(S):
            out[src] = GJuv @ np.kron(np.eye(K), S) @ np.swapaxes(GJuv, -1, -2)
            total = total + out[src]
    Sp = budget.param_covariance()
    used = np.flatnonzero(np.any(Sp != 0, axis=0))
    GJp = G @ bp.dxy_dp[..., used].reshape(N, 2 * K, used.size)
    shared_full = GJp @ Sp[np.ix_(used, used)] @ np.swapaxes(GJp, -1, -2)
    shared_sum = sum((v for k, v in out.items() if k in SHARED_SOURCES), np.zeros((N, 2, 2)))
    cross = shared_full - shared_sum
    scale = np.abs(shared_full[ok]).max(initial=0.0) if ok.any() else 0.0
    if ok.any() and np.any(np.abs(cross[ok]) > 1e-12 * max(scale, 1e-300)):
        out["cross_terms"] = cross
    for k in out:
        out[k] = np.where(ok[:, None, None], out[k], np.nan)
    return out


# -- analysis ------------------------------------------------------------------------------------------
@dataclass
class CaseStudyResult:
    """Everything computed by :func:`analyse`.

    Attributes
    ----------
    scene : Scene
    budgets : dict[str, ErrorBudget]      camera types
    confidence : float
    table : pandas.DataFrame              one row per (camera, camera_type, frame); columns in docs/case-study.md
    footprints : dict[(camera, type), FootprintEstimate]
    contributions : dict[(camera, type), dict[source, (N, 2, 2)]]
    """

    scene: Scene
    budgets: dict
    confidence: float
    table: object
    footprints: dict
    contributions: dict

    @property
    def camera_names(self) -> list[str]:
        return list(self.scene.cameras)

    @property
    def type_names(self) -> list[str]:
        return list(self.budgets)

    def rows(self, camera: str, camera_type: str):
        t = self.table
        return t[(t["camera"] == camera) & (t["camera_type"] == camera_type)].reset_index(drop=True)

    def crossings(self, camera: str, camera_type: str, system: str, quantity: str = "centre") -> list[dict]:
        """Where sigma_X - sigma_Y changes sign between consecutive usable frames (linear interpolation)."""
        r = self.rows(camera, camera_type)
        sx = r[f"{quantity}_sigma_X_{system}_m"].to_numpy()
        sy = r[f"{quantity}_sigma_Y_{system}_m"].to_numpy()
        return _crossings(r, sx - sy, self.scene.layout)

    def statements(self, quantity: str = "centre") -> list[dict]:
        """The paper's X/Y statement tested per camera, camera type and axis system (see docs/case-study.md)."""
        out = []
        for cam in self.camera_names:
            for ct in self.type_names:
                r = self.rows(cam, ct)
                for system in AXIS_SYSTEMS:
                    out.append(_xy_statement(r, cam, ct, system, quantity, self.scene.layout))
        return out

    def summary(self) -> list[dict]:
        """Per camera and camera type: visibility and the size of the uncertainties."""
        lane = self.scene.layout.lane_width_m
        k95 = chi2_scale(self.confidence)
        out = []
        for cam in self.camera_names:
            for ct in self.type_names:
                r = self.rows(cam, ct)
                ok = r["centre_valid"].to_numpy(bool)
                a = r["centre_semi_major_m"].to_numpy()[ok]
                lp = r["largest_semi_major_m"].to_numpy()[r["largest_index"].to_numpy() >= 0]
                jb = self.scene.layout.junction_box_m
                inj = ok & _in_junction(r, jb)
                aj = r["centre_semi_major_m"].to_numpy()[inj]
                row = {
                    "camera": cam, "camera_type": ct, "frames": int(len(r)), "frames_centre_valid": int(ok.sum()),
                    "centre_sigma_major_median_m": _stat(np.median, a),
                    "centre_sigma_major_max_m": _stat(np.max, a),
                    "centre_semi_major_95_max_m": _stat(np.max, a) * k95 if a.size else float("nan"),
                    "centre_semi_major_95_junction_median_m": _stat(np.median, aj) * k95 if aj.size else float("nan"),
                    "centre_axis_95_junction_median_over_lane": (_stat(np.median, aj) * 2 * k95 / lane
                                                                 if aj.size else float("nan")),
                    "largest_sigma_major_max_m": _stat(np.max, lp),
                    "frames_centre_95_over_half_lane": int(np.sum(a * k95 > lane / 2)),
                    "frames_not_linear_ok": int(np.sum(ok & ~r["footprint_linear_ok"].to_numpy(bool))),
                }
                out.append(row)
        return out

    def lane_width_statements(self, factor: float = 1.5) -> list[dict]:
        """The paper: "the uncertainty in BW-Cube cameras being almost equivalent to the lane width".

        The paper does not say which size it compares, so three are measured, each the median
        over the frames in the intersection box (then the median over the cameras) of the
        footprint-centre ellipse: the 1-sigma semi-major axis, the 95 % semi-major axis
        (``chi2_scale(0.95) = 2.4477`` sigma) and the full 95 % major axis (twice that).
        "Close" means within a factor ``factor`` of the lane width.  One row per camera type
        and measure, with ``is_largest_type`` (the type with the largest uncertainty).
        """
        lane = self.scene.layout.lane_width_m
        k = chi2_scale(self.confidence)
        pct = f"{100 * self.confidence:g} %"
        measures = (("1-sigma semi-major", 1.0), (f"{pct} semi-major", k), (f"{pct} major axis (full)", 2 * k))
        jb = self.scene.layout.junction_box_m
        med = {}
        for ct in self.type_names:
            per_cam = []
            for cam in self.camera_names:
                r = self.rows(cam, ct)
                ok = r["centre_valid"].to_numpy(bool) & _in_junction(r, jb)
                a = r["centre_semi_major_m"].to_numpy()[ok]
                per_cam.append(float(np.median(a)) if a.size else float("nan"))
            pc = np.array(per_cam)
            med[ct] = (float(np.median(pc[np.isfinite(pc)])) if np.isfinite(pc).any() else float("nan"), per_cam)
        largest = max(med, key=lambda c: med[c][0] if np.isfinite(med[c][0]) else -np.inf)
        out = []
        for ct in self.type_names:
            for label, scale in measures:
                v = med[ct][0] * scale
                out.append({"camera_type": ct, "measure": label, "value_m": v, "lane_width_m": lane,
                            "ratio_to_lane_width": v / lane,
                            "per_camera_m": {c: x * scale for c, x in zip(self.camera_names, med[ct][1], strict=True)},
                            "close": bool(np.isfinite(v) and 1 / factor <= v / lane <= factor),
                            "is_largest_type": ct == largest})
        return out


def _stat(fn, a) -> float:
    return float(fn(a)) if np.size(a) else float("nan")


def _in_box(x, y, box, margin: float = 0.0):
    if box is None:
        return np.zeros(np.shape(x), bool)
    x0, y0, x1, y1 = box
    return (x >= x0 - margin) & (x <= x1 + margin) & (y >= y0 - margin) & (y <= y1 + margin)


def _in_junction(r, box) -> np.ndarray:
    """Frames whose box centre is in the junction box (the turn frames if the layout has no box)."""
    if box is None:
        return r["segment"].to_numpy() == 1
    return _in_box(r["box_x_m"].to_numpy(), r["box_y_m"].to_numpy(), box)


def _crossings(r, diff, layout) -> list[dict]:
    t = r["t_s"].to_numpy()
    x = r["box_x_m"].to_numpy()
    y = r["box_y_m"].to_numpy()
    seg = r["segment"].to_numpy()
    idx = np.flatnonzero(np.isfinite(diff))
    out = []
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        if b != a + 1:  # do not interpolate across frames where the centre is not available
            continue
        if diff[a] == 0 or np.sign(diff[a]) != np.sign(diff[b]):
            w = diff[a] / (diff[a] - diff[b]) if diff[a] != diff[b] else 0.0
            xc, yc = x[a] + w * (x[b] - x[a]), y[a] + w * (y[b] - y[a])
            sc = int(seg[a if w < 0.5 else b])
            in_j = _in_box(xc, yc, layout.junction_box_m) if layout.junction_box_m is not None else sc == 1
            out.append({"t_s": float(t[a] + w * (t[b] - t[a])), "x_m": float(xc), "y_m": float(yc),
                        "segment": SEGMENTS[sc], "in_junction": bool(in_j),
                        "direction": "X>Y to Y>X" if diff[a] > 0 else "Y>X to X>Y"})
    return out


def _xy_statement(r, cam, ct, system, quantity, layout, majority: float = 0.8) -> dict:
    sx = r[f"{quantity}_sigma_X_{system}_m"].to_numpy()
    sy = r[f"{quantity}_sigma_Y_{system}_m"].to_numpy()
    seg = r["segment"].to_numpy()
    ok = np.isfinite(sx) & np.isfinite(sy)
    ent, ext, trn = ok & (seg == 0), ok & (seg == 2), ok & (seg == 1)
    f_entry = float(np.mean(sx[ent] > sy[ent])) if ent.any() else float("nan")
    f_exit = float(np.mean(sy[ext] > sx[ext])) if ext.any() else float("nan")
    cr = _crossings(r, sx - sy, layout)
    main = [c for c in cr if c["direction"] == "X>Y to Y>X"]
    mid = [c for c in main if c["in_junction"] or c["segment"] == "turn"]
    holds = bool(ent.any() and ext.any() and f_entry >= majority and f_exit >= majority and len(mid) >= 1)
    ratio_entry = float(np.median(sx[ent] / sy[ent])) if ent.any() else float("nan")
    ratio_turn = float(np.median(sx[trn] / sy[trn])) if trn.any() else float("nan")
    ratio_exit = float(np.median(sx[ext] / sy[ext])) if ext.any() else float("nan")
    return {"camera": cam, "camera_type": ct, "axes": system, "X": AXIS_SYSTEMS[system][0],
            "Y": AXIS_SYSTEMS[system][1], "frames_entry": int(ent.sum()), "frames_turn": int(trn.sum()),
            "frames_exit": int(ext.sum()), "share_X_gt_Y_entry": f_entry, "share_Y_gt_X_exit": f_exit,
            "median_X_over_Y_entry": ratio_entry, "median_X_over_Y_turn": ratio_turn,
            "median_X_over_Y_exit": ratio_exit, "crossings": len(cr),
            "first_X_to_Y_crossing_t_s": main[0]["t_s"] if main else float("nan"),
            "first_X_to_Y_crossing_xy_m": (main[0]["x_m"], main[0]["y_m"]) if main else None,
            "crossing_in_junction": bool(mid), "holds": holds}


def _camera_columns(scene: Scene, cam_name: str, cam, boxes: np.ndarray, corners3d: np.ndarray) -> dict:
    """Per-frame columns of one camera that do not depend on the camera type: the box in the world and
    camera frames, its image bounding box and corners (px), whether all corners are in the image."""
    N = boxes.shape[0]
    T = cam.T_cam_world
    c_cam = corners3d @ T[:3, :3].T + T[:3, 3]  # (N, 8, 3) OpenCV camera frame
    ctr_cam = boxes[:, :3] @ T[:3, :3].T + T[:3, 3]
    pr = cam.project(corners3d)
    uv8 = np.where(pr.valid[..., None], pr.uv_px, np.nan)
    in_img = pr.valid & cam.in_image(np.nan_to_num(pr.uv_px, nan=-1e9))
    base = {"camera": cam_name, "frame": scene.frame, "t_s": scene.t_s, "segment": scene.segment,
            "segment_name": np.array(SEGMENTS)[scene.segment]}
    for j, nm in enumerate(("x", "y", "z", "length", "width", "height")):
        base[f"box_{nm}_m"] = boxes[:, j]
    base["box_yaw_rad"] = boxes[:, 6]
    for j, nm in enumerate("xyz"):
        base[f"box_cam_{nm}_m"] = ctr_cam[:, j]
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all corners behind the camera: NaN box
        base["bbox_u_min_px"] = np.nanmin(uv8[..., 0], 1) if N else np.zeros(0)
        base["bbox_v_min_px"] = np.nanmin(uv8[..., 1], 1) if N else np.zeros(0)
        base["bbox_u_max_px"] = np.nanmax(uv8[..., 0], 1) if N else np.zeros(0)
        base["bbox_v_max_px"] = np.nanmax(uv8[..., 1], 1) if N else np.zeros(0)
    base["box_in_view"] = in_img.all(1)
    for k in range(8):
        for j, nm in enumerate("xyz"):
            base[f"box_corner{k}_cam_{nm}_m"] = c_cam[:, k, j]
        base[f"box_corner{k}_u_px"] = uv8[:, k, 0]
        base[f"box_corner{k}_v_px"] = uv8[:, k, 1]
    return base


def _corner_columns(fp, corner_nl: np.ndarray, row: dict) -> None:
    """Each footprint corner's pixel, ground position, sigmas, reason and nonlinearity into ``row``."""
    N = fp.corners_px.shape[0]
    for k in range(fp.n_corners):
        row[f"corner{k}_u_px"] = fp.corners_px[:, k, 0]
        row[f"corner{k}_v_px"] = fp.corners_px[:, k, 1]
        row[f"corner{k}_x_m"] = fp.corners_xy_world_m[:, k, 0]
        row[f"corner{k}_y_m"] = fp.corners_xy_world_m[:, k, 1]
        row[f"corner{k}_sigma_x_m"] = np.sqrt(fp.corners_cov_m2[:, k, 0, 0])
        row[f"corner{k}_sigma_y_m"] = np.sqrt(fp.corners_cov_m2[:, k, 1, 1])
        row[f"corner{k}_cov_xy_m2"] = fp.corners_cov_m2[:, k, 0, 1]
        row[f"corner{k}_reason"] = fp.corner_reason[:, k]
        row[f"corner{k}_nonlinearity"] = corner_nl[:, k]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all corners invalid: NaN
        row["footprint_nonlinearity_max"] = np.nanmax(corner_nl, axis=1) if N else np.zeros(0)
    row["footprint_linear_ok"] = fp.centre_valid & np.all(corner_nl <= DEFAULT_LINEAR_THRESHOLD, axis=1)


def _point_columns(fp, cam, confidence: float, k_conf: float, row: dict) -> None:
    """The largest-uncertainty corner's and the centre's position, sigmas and ellipse (in every axis
    system) into ``row``."""
    for q, cov, xy in (("largest", fp.largest_cov_m2, fp.largest_xy_world_m),
                       ("centre", fp.centre_cov_m2, fp.centre_xy_world_m)):
        a, b, th = ellipse_axes(cov)
        row[f"{q}_x_m"] = xy[:, 0]
        row[f"{q}_y_m"] = xy[:, 1]
        row[f"{q}_sigma_x_m"] = np.sqrt(cov[:, 0, 0])
        row[f"{q}_sigma_y_m"] = np.sqrt(cov[:, 1, 1])
        row[f"{q}_cov_xy_m2"] = cov[:, 0, 1]
        row[f"{q}_semi_major_m"] = a
        row[f"{q}_semi_minor_m"] = b
        row[f"{q}_orientation_deg"] = th
        row[f"{q}_semi_major_{int(round(confidence * 100))}_m"] = a * k_conf
        for system in (*AXIS_SYSTEMS, "range"):
            sX, sY = axis_components(cov, system, cam, xy)
            row[f"{q}_sigma_X_{system}_m"] = sX
            row[f"{q}_sigma_Y_{system}_m"] = sY


def _type_rows(cam, budget, boxes: np.ndarray, base: dict, ct: str, confidence: float, k_conf: float):
    """Footprints of the boxes for one camera and camera type: ``(rows as a DataFrame, footprints, contributions)``."""
    fp = footprints_from_boxes3d(cam, budget, boxes)
    contrib = centre_contributions(cam, budget, fp)
    with np.errstate(invalid="ignore"):
        corner_nl = nonlinearity(cam, budget, np.nan_to_num(fp.corners_px, nan=-1e6))
    corner_nl = np.where(np.isfinite(fp.corners_xy_world_m).all(-1), corner_nl, np.nan)
    row = dict(base)
    row["camera_type"] = ct
    _corner_columns(fp, corner_nl, row)
    _point_columns(fp, cam, confidence, k_conf, row)
    row["largest_index"] = fp.largest_index
    row["centre_valid"] = fp.centre_valid
    row["centre_reason"] = fp.centre_reason
    row["centre_reason_text"] = fp.centre_reason_text()
    for src, cov in contrib.items():
        row[f"contrib_{src}_m2"] = cov[:, 0, 0] + cov[:, 1, 1]
    for name, v in fp.v2x.items():
        row[f"v2x_{name}"] = v
    return pd.DataFrame(row), fp, contrib


def analyse(scene: Scene, camera_types=None, *, confidence: float = 0.95):
    """Run the case study on a scene: per camera, camera type and frame.

    Parameters
    ----------
    scene : Scene
    camera_types : dict label -> budget spec, or list of preset names; default the paper's three
    confidence : float   for the ``*_95`` columns (2-D chi-square scale)

    Returns
    -------
    CaseStudyResult
    """

    if camera_types is None:
        camera_types = {k: k for k in CAMERA_TYPES}
    if isinstance(camera_types, list | tuple):
        camera_types = {str(k): k for k in camera_types}
    budgets = {k: load_budget(v) for k, v in camera_types.items()}
    k_conf = chi2_scale(confidence)
    boxes = np.asarray(scene.boxes_world, dtype=np.float64)
    corners3d = box_corners(boxes)  # (N, 8, 3)
    frames = []
    footprints = {}
    contributions = {}
    for cam_name, cam in scene.cameras.items():
        base = _camera_columns(scene, cam_name, cam, boxes, corners3d)
        for ct, budget in budgets.items():
            df, fp, contrib = _type_rows(cam, budget, boxes, base, ct, confidence, k_conf)
            footprints[(cam_name, ct)] = fp
            contributions[(cam_name, ct)] = contrib
            frames.append(df)
    table = pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()
    lead = ["camera", "camera_type", "frame", "t_s", "segment", "segment_name"]
    table = table[lead + [c for c in table.columns if c not in lead]]
    contrib_cols = [c for c in table.columns if c.startswith("contrib_")]
    table[contrib_cols] = table[contrib_cols].astype(float)
    return CaseStudyResult(scene, budgets, float(confidence), table, footprints, contributions)


def reason_names(codes) -> list[str]:
    """Short names of status codes (for tables)."""
    return [status.REASONS.get(int(c), str(c)) for c in np.ravel(codes)]


@dataclass
class FootprintHeatmap:
    """Footprint-centre uncertainty of a vehicle placed at every node of a ground grid.

    Attributes
    ----------
    x_m : (nx,), y_m : (ny,)    grid coordinates in W, metres
    semi_major_m : (ny, nx)     1-sigma semi-major axis of the footprint centre (NaN: not fully in view)
    confidence : float
    yaw_rad : (ny, nx)          heading of the vehicle placed at each node
    """

    x_m: np.ndarray
    y_m: np.ndarray
    semi_major_m: np.ndarray
    confidence: float
    yaw_rad: np.ndarray

    @property
    def semi_major_conf_m(self) -> np.ndarray:
        return self.semi_major_m * chi2_scale(self.confidence)


def footprint_heatmap(camera, budget, extent_m, *, vehicle_lwh_m=(4.8, 1.9, 1.5), step_m: float = 1.0,
                      yaw_deg: float | None = None, confidence: float = 0.95,
                      road_centre_xy_m=(0.0, 0.0)) -> FootprintHeatmap:
    """Footprint-centre uncertainty of a vehicle box centred on each node of a ground grid.

    Parameters
    ----------
    camera : Camera
    budget : budget spec
    extent_m : (x_min, y_min, x_max, y_max)
    vehicle_lwh_m : (length, width, height), metres
    step_m : float   grid step
    yaw_deg : float, optional
        Heading (ccw from east) of every placed vehicle; default: along the road of the
        intersection -- north-south where ``|x - x_c| < |y - y_c|``, east-west elsewhere, with
        ``(x_c, y_c) = road_centre_xy_m`` the intersection centre.
    confidence : float
    road_centre_xy_m : (float, float)

    Nodes where any footprint corner is outside the image or beyond the horizon are NaN.
    """
    step = as_float("step_m", step_m, positive=True)
    x0, y0, x1, y1 = (float(v) for v in extent_m)
    xs = np.arange(x0, x1 + 1e-9, step)
    ys = np.arange(y0, y1 + 1e-9, step)
    if xs.size * ys.size > 250_000:
        raise ConfigError("heatmap.step_m", step, f"a step giving at most 250000 nodes (got {xs.size * ys.size})")
    X, Y = np.meshgrid(xs, ys)
    if yaw_deg is None:
        xc, yc = (float(v) for v in road_centre_xy_m)
        yaw = np.where(np.abs(X - xc) < np.abs(Y - yc), np.pi / 2, 0.0)
    else:
        yaw = np.full(X.shape, np.deg2rad(as_float("yaw_deg", yaw_deg)))
    l, w, h = (float(v) for v in vehicle_lwh_m)
    boxes = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, h / 2), np.full(X.size, l), np.full(X.size, w),
                             np.full(X.size, h), yaw.ravel()])
    fp = footprints_from_boxes3d(camera, budget, boxes)
    a, _, _ = ellipse_axes(fp.centre_cov_m2)
    a = np.where(fp.centre_valid, a, np.nan).reshape(X.shape)
    return FootprintHeatmap(xs, ys, a, float(confidence), yaw)
