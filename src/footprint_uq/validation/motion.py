"""Velocity and heading scored against labelled truth: the tracker's 95 % regions, checked as the positions are.

The detections of a validation job (their back-projected contact points, with the split covariance of
:mod:`footprint_uq.validation.pairs`: the calibration part ``dxy_dp Sigma_params dxy_dp^T`` and the per-object
part) are run, per camera, through the tracker of ``footprint-uq objects --tracks``
(:class:`~footprint_uq.tracking.classes.ClassTracks` with the budget's motion section, the consider-state filter),
frame by frame in time order.  Where a row carries a truth velocity (``truth_v_world_mps``), the tracker's
velocity and heading are scored:

* velocity: ``NEES_v = dv^T C_v^-1 dv`` (``dv = truth - track``, chi-square with 2 dof if the model is right);
  inside the ``p`` region when ``NEES_v <= -2 ln(1 - p)``;
* heading: ``z = (truth heading - track heading) / sigma_heading`` (wrapped to +-180 deg), ``NEES_h = z^2`` (1
  dof); inside when ``|z| <= Phi^-1((1 + p) / 2)``.  Only where the tracker states a heading sigma (speed large
  against the velocity's sigma: :mod:`footprint_uq.tracking.motion`) and the truth speed is not zero.

Rows without a truth velocity, without a time or an ``object_id``, and a track's first detection (no velocity
yet) are counted, never scored.  Consecutive estimates of one track are strongly correlated, so the verdict
treats each **track** as one cluster: ``mean NEES`` is compared with its expectation (2, resp. 1) with the
cluster-robust standard error across tracks; ``n_eff = var(chi2_k) / (N var(mean))`` is the number of independent
objects carrying the same information (docs/validation.md, "Velocity and heading").
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.csv as pcsv
from scipy.special import ndtr, ndtri

from .._checks import as_float
from ..io.atomic import commit, discard, temp_path
from ..tracking import SharedJacobianAt, TrackerConfig, object_motion
from ..tracking.classes import ClassTracks, tracker_configs
from ..uncertainty.budget import load_budget
from .coverage import LEVELS, nees_threshold, wilson_interval

__all__ = ["MotionScorer", "score_rows", "truth_differences", "MOTION_COLUMNS", "MOTION_ROW_COLUMNS"]

#: columns of the per-row file (``motion.csv``): where the row comes from, the truth velocity (W, m/s; its kind:
#: ``given``, ``differences`` or empty) and the scores (velocity in W, m/s; NaN where not scored)
MOTION_ROW_COLUMNS = ("source", "line", "camera", "frame", "object_id", "class", "time_s", "track_id",
                      "truth_velocity", "truth_v_x_mps", "truth_v_y_mps", "v_x_mps", "v_y_mps", "nees_v",
                      "heading_err_deg", "sigma_heading_deg", "nees_h")
#: per-row outputs of :func:`score_rows`
#: the spread between cameras enters the verdict's standard error from this many calibration groups on
MIN_CAMERAS = 5
MOTION_COLUMNS = ("track_id", "v_x_mps", "v_y_mps", "nees_v", "heading_err_deg", "sigma_heading_deg", "nees_h")


@dataclass
class _CameraRows:
    camera: object
    budget: object
    parts: list = field(default_factory=list)


def _z(level: float) -> float:
    return float(ndtri(0.5 + level / 2))


def score_rows(camera, budget, time_s, object_id, cls, xy_m, cov_object_m2, dxy_dp, truth_v_mps, *,
               config: TrackerConfig | None = None, truth_cov_v_m2ps2=None) -> dict:
    """Track one camera's detections and score them against the truth velocity.

    Parameters
    ----------
    camera : Camera;  budget : ErrorBudget (its ``motion`` section, if any, sets the model per class)
    time_s : (n,) s;  object_id, cls : (n,) object
    xy_m : (n, 2) contact points in W;  cov_object_m2 : (n, 2, 2) their per-object covariance, m^2
    dxy_dp : (n, 2, 22) their Jacobian w.r.t. the camera parameters
    truth_v_mps : (n, 2) truth velocity in W, m/s (NaN: none)
    config : the tracker's options (default :class:`~footprint_uq.tracking.table.TrackerConfig`)
    truth_cov_v_m2ps2 : (n, 2, 2), optional
        Covariance of the truth velocity (finite differences: :func:`truth_differences`), added to the tracker's
        in both scores; None: the truth is exact

    Returns
    -------
    dict of (n,) arrays: :data:`MOTION_COLUMNS` (NaN / -1 where not tracked or not scored), in input order
    """
    n = len(time_s)
    at = SharedJacobianAt(camera, budget)
    L = budget.param_factor().dense()  # (22, r): Sigma_params = L L^T
    B = np.einsum("nij,jk->nik", np.nan_to_num(dxy_dp), L)
    tracks = ClassTracks(*tracker_configs(getattr(budget, "motion", None), config), rank=at.rank, shared_at=at)
    out = {k: np.full(n, np.nan) for k in MOTION_COLUMNS}
    out["track_id"] = np.full(n, -1, np.int64)
    Ct = np.zeros((n, 2, 2)) if truth_cov_v_m2ps2 is None else np.nan_to_num(truth_cov_v_m2ps2)
    order = np.argsort(time_s, kind="stable")
    ts = time_s[order]
    starts = np.flatnonzero(np.r_[True, ts[1:] != ts[:-1]])
    for a, b in zip(starts, np.r_[starts[1:], n], strict=True):
        rows = order[a:b]
        ids = object_id[rows]  # (integer ids as an array: the tables' compiled look-up; others as a list)
        o = tracks.step(float(ts[a]), ids if ids.dtype.kind in "iu" else list(ids), list(cls[rows]), xy_m[rows],
                        cov_object_m2[rows], B[rows])
        mo = object_motion(o)
        out["track_id"][rows] = o.track_id
        out["v_x_mps"][rows], out["v_y_mps"][rows] = o.v_mps[:, 0], o.v_mps[:, 1]
        vt = truth_v_mps[rows]
        dv = vt - o.v_mps
        ok = np.isfinite(dv).all(1)
        if ok.any():
            d2 = np.full(len(rows), np.nan)
            d2[ok] = np.einsum("ni,nij,nj->n", dv[ok], np.linalg.inv(o.cov_v_m2ps2[ok] + Ct[rows][ok]), dv[ok])
            out["nees_v"][rows] = d2
        head = np.rad2deg(np.arctan2(vt[:, 0], vt[:, 1]))  # compass in W (+y as north), as object_motion's
        hok = ok & np.isfinite(mo.sigma_heading_deg) & (np.hypot(vt[:, 0], vt[:, 1]) > 0)
        dh = np.where(hok, np.mod(head - mo.heading_deg + 180.0, 360.0) - 180.0, np.nan)
        out["heading_err_deg"][rows] = dh
        g = np.stack([vt[:, 1], -vt[:, 0]], 1) / np.maximum(np.hypot(vt[:, 0], vt[:, 1]), 1e-300)[:, None] ** 2
        var_truth_deg2 = np.rad2deg(1.0) ** 2 * np.einsum("ni,nij,nj->n", g, Ct[rows], g)  # delta method
        sig = np.sqrt(mo.sigma_heading_deg ** 2 + np.where(hok, var_truth_deg2, 0.0))
        out["sigma_heading_deg"][rows] = np.where(hok, sig, np.nan)
        out["nees_h"][rows] = (dh / sig) ** 2
    return out


def truth_differences(object_id, time_s, truth_xy_m, *, sigma_m: float, accel_psd_m2ps3: float,
                      max_span_s: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """Truth velocities from consecutive labelled frames: central differences of one object's truth positions.

    Per row with a previous and a next row of the same ``object_id`` (in time) within ``max_span_s``:
    ``v = (x_next - x_prev) / D`` with ``D = t_next - t_prev``, and its covariance (per axis, independent)
    ``2 sigma_m^2 / D^2 + q D / 12``: the labels' position noise (``sigma_m`` per axis, independent between frames)
    and the difference between the mean velocity over the span and the velocity at its middle for a white-noise
    acceleration of density ``q`` (the motion model's).  Rows at a track's ends, with a gap longer than
    ``max_span_s``, or without a finite truth get NaN.

    Parameters
    ----------
    object_id : (n,) object;  time_s : (n,) s;  truth_xy_m : (n, 2) truth positions in W (NaN: none)

    Returns
    -------
    v_mps : (n, 2);  cov_v_m2ps2 : (n, 2, 2)
    """
    n = len(time_s)
    v, cov = np.full((n, 2), np.nan), np.full((n, 2, 2), np.nan)
    key = np.array([str(o) for o in object_id], dtype=object)
    order = np.lexsort((time_s, key))
    k, t, x = key[order], time_s[order], truth_xy_m[order]
    if n < 3:
        return v, cov
    same = (k[:-2] == k[2:]) & (k[:-2] == k[1:-1])
    D = t[2:] - t[:-2]
    ok = same & (D > 0) & (D <= max_span_s) & np.isfinite(x[2:]).all(1) & np.isfinite(x[:-2]).all(1)
    mid = order[1:-1][ok]
    v[mid] = (x[2:][ok] - x[:-2][ok]) / D[ok][:, None]
    var = 2.0 * sigma_m ** 2 / D[ok] ** 2 + accel_psd_m2ps3 * D[ok] / 12.0
    cov[mid] = var[:, None, None] * np.eye(2)
    return v, cov


def _cluster_var(nees: np.ndarray, cluster: np.ndarray, mean: float) -> tuple[float, int]:
    """Cluster-robust variance of the mean (CR1) and the number of clusters."""
    _, inv = np.unique(cluster, return_inverse=True)
    C = int(inv.max()) + 1
    s = np.bincount(inv, weights=nees - mean, minlength=C)
    return (float((s ** 2).sum()) / len(nees) ** 2 * (C / (C - 1)) if C > 1 else np.inf), C


def _clustered_test(nees: np.ndarray, track: np.ndarray, camera: np.ndarray, dof: int, alpha: float) -> dict:
    """Mean NEES against ``dof`` with a cluster-robust standard error: the larger of the spread between tracks and,
    with :data:`MIN_CAMERAS` calibration groups or more, between cameras (tracks of one camera share its
    calibration error)."""
    N = len(nees)
    if N == 0:
        return {"n": 0, "nees_mean": None, "n_tracks": 0, "n_cameras": 0, "n_eff": 0.0, "p_value": None,
                "verdict": None}
    mean = float(nees.mean())
    var_t, n_t = _cluster_var(nees, track, mean)
    var_c, n_c = _cluster_var(nees, camera, mean)
    var_mean = max(var_t, var_c if n_c >= MIN_CAMERAS else 0.0)
    n_eff = float(min(N, 2.0 * dof / var_mean)) if var_mean > 0 else float(N)
    se = float(np.sqrt(var_mean))
    if not np.isfinite(se) or se == 0:
        return {"n": N, "nees_mean": mean, "nees_expected": float(dof), "n_tracks": n_t, "n_cameras": n_c,
                "n_eff": 0.0, "p_value": None, "verdict": None}
    z = (mean - dof) / se
    p = float(2 * ndtr(-abs(z)))
    verdict = "consistent" if p >= alpha else ("over-confident" if z > 0 else "under-confident")
    return {"n": N, "nees_mean": mean, "nees_expected": float(dof), "n_tracks": n_t, "n_cameras": n_c,
            "se_mean": se, "n_eff": n_eff, "z": float(z), "p_value": p, "verdict": verdict,
            "evidence": "weak" if n_eff < 10 or n_t < 10 else "ok"}


def _coverage(inside_by_level: dict, n_eff: float, alpha: float) -> list:
    out = []
    for lv, inside in inside_by_level.items():
        N = len(inside)
        k = int(np.count_nonzero(inside))
        lo, hi = wilson_interval(k, N, 1 - alpha)
        ne = max(n_eff, 1.0)
        lo_e, hi_e = wilson_interval(k * (ne / N if N else 0), ne, 1 - alpha)
        out.append({"nominal": lv, "empirical": k / N if N else None, "inside": k, "n": N,
                    "interval": [float(lo), float(hi)], "interval_n_eff": [float(lo_e), float(hi_e)],
                    "se_n_eff": float(np.sqrt(lv * (1 - lv) / ne))})
    return out


def _block(nees: np.ndarray, cluster: np.ndarray, dof: int, alpha: float) -> dict:
    camera = np.array([c.rsplit("#", 1)[0] for c in cluster], dtype=object)
    test = _clustered_test(nees, cluster, camera, dof, alpha)
    if dof == 2:
        inside = {lv: nees <= nees_threshold(lv) for lv in LEVELS}
    else:
        inside = {lv: np.sqrt(nees) <= _z(lv) for lv in LEVELS}
    return {"test": test, "coverage": _coverage(inside, test["n_eff"], alpha), "verdict": test["verdict"]}


class MotionScorer:
    """Collects a validation job's detections per camera (:meth:`add`), tracks and scores them (:meth:`summary`).

    Parameters
    ----------
    config : TrackerConfig, optional (the budget's motion section, if any, is applied over it)
    alpha : significance of the tests
    differences : derive a truth velocity from consecutive labelled frames where none is given
        (:func:`truth_differences`, with ``truth_sigma_m`` the labels' position sigma per axis, m, and
        ``max_span_s``)
    """

    def __init__(self, config: TrackerConfig | None = None, *, alpha: float = 0.05, differences: bool = True,
                 truth_sigma_m: float = 0.1, max_span_s: float = 1.0):
        self.config = config or TrackerConfig()
        self.differences = bool(differences)
        self.truth_sigma_m = as_float("truth_sigma_m", truth_sigma_m, nonnegative=True)
        self.max_span_s = as_float("max_span_s", max_span_s, positive=True)
        self.alpha = float(alpha)
        self.cameras: dict[str, _CameraRows] = {}
        self.counts: dict[str, int] = defaultdict(int)
        #: per-row scores after :meth:`summary` (column -> (n,) array)
        self.rows: dict = {}

    def write_rows(self, path, *, fsync: bool = True) -> Path:
        """:attr:`rows` as a CSV file (:data:`MOTION_ROW_COLUMNS`), written atomically."""
        n = len(self.rows.get("line", ()))
        cols = {}
        for k in MOTION_ROW_COLUMNS:
            a = self.rows.get("cls" if k == "class" else k, np.zeros(0))
            if n == 0:
                cols[k] = pa.array([], pa.string())
            elif np.asarray(a).dtype == object:
                cols[k] = pa.array([None if v is None else str(v) for v in a], pa.string())
            else:
                cols[k] = pa.array(np.asarray(a), from_pandas=True)
        tmp = temp_path(Path(path))
        try:
            pcsv.write_csv(pa.table(cols), tmp)
        except BaseException:
            discard(tmp)
            raise
        commit(tmp, Path(path), fsync=fsync)
        return Path(path)

    def add(self, chunk, pairs, budget) -> None:
        """Keep the rows of one chunk that can be tracked (a detection with a ground point, a time and an id)."""
        n = len(chunk)
        tv = chunk.truth_v_world_mps if chunk.truth_v_world_mps is not None else np.full((n, 2), np.nan)
        t = chunk.time_s if chunk.time_s is not None else np.full(n, np.nan)
        has_tv = np.isfinite(tv).all(1) & (pairs.status != "error")
        self.counts["rows_with_truth_velocity"] += int(has_tv.sum())
        det = np.isin(pairs.status, ("ok", "no truth")) & np.isfinite(pairs.xy_world_m).all(1)
        keep = det & np.isfinite(t) & np.array([o is not None for o in chunk.object_id], dtype=bool)
        self.counts["truth_velocity_not_tracked"] += int((has_tv & ~keep).sum())
        self.counts["detections_without_truth_velocity"] += int((det & ~has_tv).sum())
        if not keep.any() or chunk.camera is None:
            return
        bud = load_budget(chunk.budget if chunk.budget is not None else budget)
        cam = self.cameras.setdefault(chunk.camera_key, _CameraRows(chunk.camera, bud))
        cam.parts.append(dict(time_s=t[keep], object_id=chunk.object_id[keep], cls=chunk.cls[keep],
                              xy_m=pairs.xy_world_m[keep], cov_object_m2=pairs.cov_object_m2[keep],
                              dxy_dp=pairs.dxy_dp[keep], truth_v_mps=tv[keep], line=pairs.line[keep],
                              source=pairs.source[keep], frame=chunk.frame[keep],
                              truth_xy_m=np.where((pairs.status[keep] == "ok")[:, None],
                                                  pairs.truth_xy_world_m[keep], np.nan)))

    def _camera_scores(self, key: str, cam: _CameraRows) -> dict:
        """Track one camera's rows and score them (truth velocity given, or from differences)."""
        rows = {k: np.concatenate([p[k] for p in cam.parts]) for k in cam.parts[0]}
        tv, ct = rows["truth_v_mps"], None
        use = np.zeros(len(tv), dtype=bool)
        if self.differences:
            dv, dc = truth_differences(rows["object_id"], rows["time_s"], rows["truth_xy_m"],
                                       sigma_m=self.truth_sigma_m, accel_psd_m2ps3=self.config.accel_psd_m2ps3,
                                       max_span_s=self.max_span_s)
            use = ~np.isfinite(tv).all(1) & np.isfinite(dv).all(1)
            tv = np.where(use[:, None], dv, tv)
            ct = np.where(use[:, None, None], dc, 0.0)
        sc = score_rows(cam.camera, cam.budget, rows["time_s"], rows["object_id"], rows["cls"], rows["xy_m"],
                        rows["cov_object_m2"], rows["dxy_dp"], tv, config=self.config, truth_cov_v_m2ps2=ct)
        truth_kind = np.where(use, "differences", np.where(np.isfinite(tv).all(1), "given", ""))
        return {"source": rows["source"], "line": rows["line"], "camera": np.full(len(tv), key, dtype=object),
                "frame": rows["frame"], "object_id": rows["object_id"], "cls": rows["cls"], "time_s": rows["time_s"],
                "truth_velocity": truth_kind.astype(object), "truth_v_x_mps": tv[:, 0], "truth_v_y_mps": tv[:, 1],
                **sc, "cluster": np.array([f"{key}#{i}" for i in sc["track_id"]], dtype=object)}

    def summary(self) -> dict | None:
        """The ``motion`` entry of the summary (None when no row carries a truth velocity); the per-row scores are
        then in :attr:`rows` (:data:`MOTION_ROW_COLUMNS`, one row per tracked detection, per camera in input
        order)."""
        parts = [self._camera_scores(key, cam) for key, cam in self.cameras.items()]
        c = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} if parts else {}
        self.rows = c
        derived = int(np.count_nonzero(c["truth_velocity"] == "differences")) if c else 0
        if self.counts["rows_with_truth_velocity"] + derived == 0:
            return None
        return self._summarise(c, derived)

    def _summarise(self, c: dict, derived: int) -> dict:
        counts = dict(self.counts)
        counts["truth_velocity_from_differences"] = derived
        counts["detections_without_truth_velocity"] = counts.get("detections_without_truth_velocity", 0) - derived
        if not c:
            counts.update(velocity_scored=0, heading_scored=0)
            return {"counts": counts, "velocity": _block(np.zeros(0), np.zeros(0), 2, self.alpha),
                    "heading": _block(np.zeros(0), np.zeros(0), 1, self.alpha), "by_class": {}}
        v_ok, h_ok = np.isfinite(c["nees_v"]), np.isfinite(c["nees_h"])
        has_tv = c["truth_velocity"] != ""
        counts.update(tracked_with_truth_velocity=int(has_tv.sum()),
                      first_detection=int((has_tv & (c["track_id"] >= 0) & ~v_ok).sum()),
                      not_tracked=int((has_tv & (c["track_id"] < 0)).sum()),
                      velocity_scored=int(v_ok.sum()), heading_scored=int(h_ok.sum()),
                      heading_unavailable=int((v_ok & ~h_ok).sum()))
        out = {"counts": counts, "velocity": _block(c["nees_v"][v_ok], c["cluster"][v_ok], 2, self.alpha),
               "heading": _block(c["nees_h"][h_ok], c["cluster"][h_ok], 1, self.alpha), "by_class": {}}
        cls = np.array(["" if v is None else str(v) for v in c["cls"]], dtype=object)
        for name in sorted(set(cls[v_ok])):
            mv, mh = v_ok & (cls == name), h_ok & (cls == name)
            out["by_class"][name] = {"velocity": _block(c["nees_v"][mv], c["cluster"][mv], 2, self.alpha),
                                     "heading": _block(c["nees_h"][mh], c["cluster"][mh], 1, self.alpha)}
        return out
