"""Intrinsic calibration (Zhang's method through OpenCV) and its error sizes.

Pipeline (:func:`calibrate_intrinsics`): detect the board in every frame
(:mod:`.detect`), calibrate with :func:`cv2.calibrateCameraExtended` (fx, fy,
cx, cy, k1, k2, p1, p2, k3; zero skew; OpenCV's default flags), filter frames as
the paper does, and measure the variability of the intrinsics three ways:

* ``opencv``: the standard deviations reported by ``calibrateCameraExtended``
  (first-order, from the Jacobian of the final solve; they depend on the OpenCV
  version, recorded with the results);
* ``jacobian``: our own first-order covariance from the same Jacobian (the full
  9x9 intrinsic block, with the per-view poses eliminated by a Schur
  complement and the corner noise variance estimated from the residuals with
  ``2 N - n_params`` degrees of freedom).  Its diagonal reproduces OpenCV's
  numbers in OpenCV versions that use the same convention, and it gives the
  correlations OpenCV does not return;
* ``bootstrap``: resample the used views with replacement, recalibrate
  (seeded), and take the standard deviation over resamples.  It captures
  frame-to-frame effects (board pose distribution, detection bias, lens model
  misfit) that the first-order formula, which assumes independent identically
  distributed corner noise, does not.

**Frame filter** (``max_mean_reproj_px``): calibrate, drop every frame whose
mean reprojection error (mean over its corners of ``|detected - reprojected|``,
px) exceeds the threshold, recalibrate, and repeat until no frame exceeds it.
Each dropped frame is reported with the round and its error at that round.

**Paper table** (Table 2): sigma fx, fy, f, c, r, k1, k2, p1, p2, k3 with
``sigma_f = sqrt(sigma_fx^2 + sigma_fy^2)`` (the paper's root-sum-square;
0.1992 and 0.1923 give 0.2768) and c, r the principal point column and row.

The budget (:meth:`IntrinsicCalibration.to_budget`) follows the paper:
``focal_px = sigma_f`` (applied to fx and fy together by the core),
``principal_point_px = [sigma_cx, sigma_cy]``, ``distortion = [sigma_k1 ..
sigma_k3]``; optionally the full 9x9 covariance (``full_covariance=True``),
which the core then uses instead of those sigmas.
"""

from __future__ import annotations

import csv
import json
import math
import os
import time
import warnings
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml
from tqdm.auto import tqdm

from ..cameras.opencv import OpenCVCamera
from ..errors import InputError
from ..io.atomic import atomic_path, atomic_write_text, commit, discard, temp_path
from ..params import INTRINSIC_NAMES, PAPER_COLUMNS
from ..uncertainty.budget import ErrorBudget
from ..viz.calibration import save_calibration_figures, write_calibration_html
from .boards import Checkerboard, parse_board
from .detect import Detection, FrameSource, detect_frames, mp_context
from .maps import coverage_map, error_asymmetry, reprojection_error_map

__all__ = ["INTRINSIC_NAMES", "PAPER_COLUMNS", "IntrinsicCalibration", "BootstrapResult", "FilterRound",
           "calibrate_intrinsics", "calibrate_detections", "calibrate_corners", "intrinsic_covariance",
           "bootstrap_intrinsics", "paper_sigmas", "compare_sigmas"]

#: where a standard deviation of the intrinsics can come from
SIGMA_SOURCES = ("opencv", "jacobian", "bootstrap", "max")


def paper_sigmas(std9) -> dict:
    """The paper's Table-2 row from the nine standard deviations (fx, fy, cx, cy, k1, k2, p1, p2, k3).

    ``sigma_f_px`` is the root-sum-square of ``sigma_fx_px`` and ``sigma_fy_px``.
    """
    s = np.asarray(std9, dtype=np.float64).ravel()
    if s.size != 9:
        raise InputError("std9", s.tolist(), "9 standard deviations (fx, fy, cx, cy, k1, k2, p1, p2, k3)")
    return {"sigma_fx_px": float(s[0]), "sigma_fy_px": float(s[1]), "sigma_f_px": float(math.hypot(s[0], s[1])),
            "sigma_c_px": float(s[2]), "sigma_r_px": float(s[3]), "sigma_k1": float(s[4]),
            "sigma_k2": float(s[5]), "sigma_p1": float(s[6]), "sigma_p2": float(s[7]), "sigma_k3": float(s[8])}


# ------------------------------------------------------------------------------------------ solves
@dataclass
class _Fit:
    rms_px: float
    K: np.ndarray
    dist: np.ndarray  # (5,)
    rvecs: np.ndarray  # (n, 3)
    tvecs: np.ndarray  # (n, 3)
    std9: np.ndarray  # (9,)
    per_view_rms_px: np.ndarray  # (n,)


def _calibrate(obj: np.ndarray, imgs: list[np.ndarray], image_size_px, flags: int = 0,
               K0=None, d0=None, criteria=None) -> _Fit:

    objs = [obj.astype(np.float32)] * len(imgs)
    ips = [np.asarray(c, dtype=np.float32).reshape(-1, 1, 2) for c in imgs]
    K_in = None if K0 is None else np.array(K0, dtype=np.float64)
    d_in = None if d0 is None else np.array(d0, dtype=np.float64).reshape(1, -1)
    if criteria is None:
        criteria = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    try:
        rms, K, d, rv, tv, sdi, _sde, pve = cv2.calibrateCameraExtended(
            objs, ips, tuple(int(v) for v in image_size_px), K_in, d_in, flags=flags, criteria=criteria)
    except cv2.error as e:
        raise InputError("calibration", str(e).strip().splitlines()[-1][:200],
                         "views OpenCV can calibrate from (non-degenerate board poses)") from None
    d = np.asarray(d, dtype=np.float64).ravel()
    d5 = np.zeros(5)
    d5[:min(5, d.size)] = d[:5]
    sdi = np.asarray(sdi, dtype=np.float64).ravel()
    return _Fit(float(rms), np.asarray(K, dtype=np.float64), d5,
                np.asarray(rv, dtype=np.float64).reshape(-1, 3), np.asarray(tv, dtype=np.float64).reshape(-1, 3),
                sdi[:9].copy(), np.asarray(pve, dtype=np.float64).ravel())


def _project(obj, rvec, tvec, K, dist, jacobian=False):

    pts, J = cv2.projectPoints(obj.astype(np.float64), np.asarray(rvec, dtype=np.float64),
                               np.asarray(tvec, dtype=np.float64), K, np.asarray(dist, dtype=np.float64))
    return (pts.reshape(-1, 2), J) if jacobian else pts.reshape(-1, 2)


def intrinsic_covariance(obj, imgs, K, dist, rvecs, tvecs) -> tuple[np.ndarray, float, int]:
    """First-order covariance of the nine intrinsics from the reprojection Jacobian.

    Parameters
    ----------
    obj : ndarray (N, 3)
        Board corners, board frame, metres.
    imgs : sequence of ndarray (N, 2)
        Detected corners per view, px.
    K, dist : calibrated intrinsics (dist: k1, k2, p1, p2, k3).
    rvecs, tvecs : ndarray (n_views, 3)

    Returns
    -------
    cov : ndarray (9, 9)
        In :data:`INTRINSIC_NAMES` order and units (px, dimensionless).
    sigma_px : float
        Estimated per-coordinate corner noise, ``sqrt(sum r^2 / (2 N_total - n_params))``.
    dof : int
        ``2 N_total - (9 + 6 n_views)``.

    Notes
    -----
    Normal matrix ``J^T J`` over (9 intrinsics, 6 pose parameters per view); the
    poses are eliminated by the Schur complement
    ``S = A - sum_i B_i C_i^-1 B_i^T`` and ``cov = sigma^2 S^-1``.
    """
    A = np.zeros((9, 9))
    S = np.zeros((9, 9))
    ss = 0.0
    n_tot = 0
    for c, rv, tv in zip(imgs, rvecs, tvecs, strict=True):
        proj, J = _project(obj, rv, tv, K, dist, jacobian=True)
        r = (np.asarray(c, dtype=np.float64).reshape(-1, 2) - proj).ravel()
        ss += float(r @ r)
        n_tot += r.size
        E = J[:, :6]
        Ji = J[:, 6:15]
        Ai = Ji.T @ Ji
        B = Ji.T @ E
        C = E.T @ E
        A += Ai
        S += B @ np.linalg.solve(C, B.T)
    n_params = 9 + 6 * len(imgs)
    dof = n_tot - n_params
    if dof <= 0:
        raise InputError("views", len(imgs), f"more corner coordinates ({n_tot}) than parameters ({n_params})")
    sigma2 = ss / dof
    Sc = A - S
    Sc = 0.5 * (Sc + Sc.T)
    cov = sigma2 * np.linalg.inv(Sc)
    return 0.5 * (cov + cov.T), float(np.sqrt(sigma2)), int(dof)


@dataclass
class BootstrapResult:
    """Bootstrap over views: ``samples (n_ok, 9)`` in :data:`INTRINSIC_NAMES` order."""

    samples: np.ndarray
    n_requested: int
    n_failed: int
    seed: int

    @property
    def std(self) -> np.ndarray:
        return np.std(self.samples, axis=0, ddof=1) if len(self.samples) > 1 else np.full(9, np.nan)

    @property
    def robust_std(self) -> np.ndarray:
        """1.4826 x median absolute deviation (insensitive to a few wild resamples)."""
        if len(self.samples) < 2:
            return np.full(9, np.nan)
        med = np.median(self.samples, axis=0)
        return 1.4826 * np.median(np.abs(self.samples - med), axis=0)

    @property
    def cov(self) -> np.ndarray:
        return np.cov(self.samples, rowvar=False) if len(self.samples) > 1 else np.full((9, 9), np.nan)


def _boot_fit(args):

    obj, imgs, idx_list, image_size_px, K0, d0, flags = args
    cv2.setNumThreads(1)
    out = []
    for idx in idx_list:
        try:
            f = _calibrate(obj, [imgs[i] for i in idx], image_size_px, flags | cv2.CALIB_USE_INTRINSIC_GUESS, K0, d0)
        except InputError:
            out.append(None)
            continue
        v = np.array([f.K[0, 0], f.K[1, 1], f.K[0, 2], f.K[1, 2], *f.dist[:5]])
        out.append(v if np.all(np.isfinite(v)) else None)
    return out


def bootstrap_intrinsics(obj, imgs, image_size_px, K0, d0, n: int, *, seed: int = 0, min_views: int = 3,
                         flags: int = 0, workers: int = 1, progress: bool = False) -> BootstrapResult:
    """Resample views with replacement ``n`` times and recalibrate (seeded).

    Each resample starts from the full-data solution (``CALIB_USE_INTRINSIC_GUESS``).
    Resamples with fewer than ``min_views`` distinct views are redrawn; resamples
    OpenCV cannot solve are counted in ``n_failed``.  The resamples are drawn
    up front, so the result does not depend on ``workers``.
    """


    n = int(n)
    rng = np.random.default_rng(seed)
    m = len(imgs)
    draws = []
    for _ in range(n):
        for _attempt in range(100):
            idx = rng.integers(0, m, size=m)
            if np.unique(idx).size >= min(min_views, m):
                break
        draws.append(idx)
    imgs = [np.asarray(c, dtype=np.float64) for c in imgs]
    chunk = 10
    tasks = [(obj, imgs, draws[i:i + chunk], image_size_px, K0, d0, flags) for i in range(0, n, chunk)]
    results: list = []
    bar = tqdm(total=n, desc="bootstrap", unit="fit", disable=not progress)
    try:
        if int(workers) <= 1 or len(tasks) == 1:
            for tk in tasks:
                results.extend(_boot_fit(tk))
                bar.update(len(tk[2]))
        else:
            with ProcessPoolExecutor(max_workers=int(workers), mp_context=mp_context()) as ex:
                for tk, res in zip(tasks, ex.map(_boot_fit, tasks), strict=True):
                    results.extend(res)
                    bar.update(len(tk[2]))
    finally:
        bar.close()
    ok = [v for v in results if v is not None]
    return BootstrapResult(np.array(ok).reshape(-1, 9), n, n - len(ok), int(seed))


def compare_sigmas(std_opencv, std_bootstrap) -> dict:
    """How the bootstrap standard deviations compare with OpenCV's (ratios and a verdict)."""
    a = np.asarray(std_opencv, dtype=np.float64)
    b = np.asarray(std_bootstrap, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = b / a
    ok = np.isfinite(ratio)
    med = float(np.median(ratio[ok])) if ok.any() else float("nan")
    if not np.isfinite(med):
        verdict = "no comparison (bootstrap not run or failed)"
    elif med > 1.5:
        verdict = ("bootstrap larger than OpenCV: the views disagree more than independent corner noise "
                   "explains (pose distribution, detection bias or lens-model misfit); the OpenCV "
                   "standard deviations are likely optimistic -- prefer the bootstrap (or 'max') for the budget")
    elif med < 1 / 1.5:
        verdict = ("bootstrap smaller than OpenCV: with few views the bootstrap under-samples the "
                   "variability, or OpenCV's residual-based noise estimate is inflated; check the per-view errors")
    else:
        verdict = "bootstrap and OpenCV agree within a factor 1.5 (median ratio)"
    return {"ratio_bootstrap_over_opencv": dict(zip(INTRINSIC_NAMES, (float(r) for r in ratio), strict=True)),
            "median_ratio": med, "verdict": verdict}


# ------------------------------------------------------------------------------------------ result
@dataclass
class FilterRound:
    """One round of the frame filter."""

    round: int
    n_views: int
    rms_px: float
    max_mean_error_px: float
    dropped: list[str]


@dataclass
class IntrinsicCalibration:
    """Result of an intrinsic calibration (see the module docstring).

    Attributes
    ----------
    board : Checkerboard
    image_size_px : (int, int)
    K : ndarray (3, 3)
    dist : ndarray (5,)
        k1, k2, p1, p2, k3.
    std_opencv : ndarray (9,)
        OpenCV's standard deviations, :data:`INTRINSIC_NAMES` order.
    cov_jacobian : ndarray (9, 9)
    corner_sigma_px : float
        Per-coordinate corner noise estimated from the residuals.
    rms_px : float
        OpenCV's overall RMS reprojection error of the final solve.
    labels : list of str
        Views used in the final solve.
    image_points_px : list of ndarray (N, 2)
    rvecs, tvecs : ndarray (n, 3)
        Board poses (board -> camera).
    residuals_px : list of ndarray (N, 2)
        ``detected - reprojected``, per used view.
    per_view_rms_px : ndarray (n,)
        OpenCV's per-view RMS error.
    detections : list of Detection
        Every input frame, found or not.
    rounds : list of FilterRound
    dropped : list of dict
        ``label, round, mean_error_px, reason`` per dropped frame.
    bootstrap : BootstrapResult or None
    opencv_version : str
    """

    board: Checkerboard
    image_size_px: tuple[int, int]
    K: np.ndarray
    dist: np.ndarray
    std_opencv: np.ndarray
    cov_jacobian: np.ndarray
    corner_sigma_px: float
    rms_px: float
    labels: list[str]
    image_points_px: list[np.ndarray]
    rvecs: np.ndarray
    tvecs: np.ndarray
    residuals_px: list[np.ndarray]
    per_view_rms_px: np.ndarray
    detections: list[Detection] = field(default_factory=list)
    rounds: list[FilterRound] = field(default_factory=list)
    dropped: list[dict] = field(default_factory=list)
    bootstrap: BootstrapResult | None = None
    max_mean_reproj_px: float | None = None
    flags: int = 0
    opencv_version: str = ""

    # -- values ---------------------------------------------------------------------
    @property
    def values(self) -> np.ndarray:
        """The nine intrinsics (fx, fy, cx, cy, k1, k2, p1, p2, k3)."""
        return np.array([self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], *self.dist[:5]])

    @property
    def per_view_mean_px(self) -> np.ndarray:
        """Mean reprojection error ``mean |detected - reprojected|`` per used view, px."""
        return np.array([np.linalg.norm(r, axis=-1).mean() for r in self.residuals_px])

    @property
    def std_jacobian(self) -> np.ndarray:
        return np.sqrt(np.diag(self.cov_jacobian))

    def std(self, source: str = "opencv") -> np.ndarray:
        """Standard deviations (9,) from ``"opencv"``, ``"jacobian"``, ``"bootstrap"`` or ``"max"`` (of the others)."""
        if source == "opencv":
            return self.std_opencv.copy()
        if source == "jacobian":
            return self.std_jacobian
        if source in ("bootstrap", "max"):
            if self.bootstrap is None or len(self.bootstrap.samples) < 2:
                raise InputError("sigma source", source, "a calibration run with bootstrap > 1 (e.g. --bootstrap 200)")
            if source == "bootstrap":
                return self.bootstrap.std
            return np.maximum.reduce([self.std_opencv, self.std_jacobian, self.bootstrap.std])
        raise InputError("sigma source", source, f"one of {SIGMA_SOURCES}")

    def paper_table(self) -> dict:
        """The paper's Table-2 row per available source: ``{source: {sigma_fx_px: ..., ...}}``."""
        out = {"opencv": paper_sigmas(self.std_opencv), "jacobian": paper_sigmas(self.std_jacobian)}
        if self.bootstrap is not None and len(self.bootstrap.samples) > 1:
            out["bootstrap"] = paper_sigmas(self.bootstrap.std)
            out["bootstrap_robust"] = paper_sigmas(self.bootstrap.robust_std)
        return out

    # -- conversions ----------------------------------------------------------------
    def budget_dict(self, source: str = "opencv", *, full_covariance: bool = False, name: str | None = None) -> dict:
        """The intrinsic part of a budget file (keys of :mod:`footprint_uq.uncertainty.budget`)."""
        s = self.std(source)
        d = {
            "name": name or f"calibrated-{source}",
            "description": (f"intrinsic error sizes from {len(self.labels)} views of a {self.board.label()} "
                            f"checkerboard, sigmas from {source} (OpenCV {self.opencv_version}); "
                            "focal_px = RSS(sigma_fx, sigma_fy) as in the paper"),
            "focal_px": float(math.hypot(s[0], s[1])),
            "principal_point_px": [float(s[2]), float(s[3])],
            "distortion": [float(v) for v in s[4:9]],
        }
        if full_covariance:
            if source == "bootstrap":
                cov = self.bootstrap.cov
            else:
                cov = self.cov_jacobian.copy()
                if source in ("opencv", "max"):  # rescale the correlations to the chosen sigmas
                    sj = np.sqrt(np.diag(cov))
                    cov = cov / np.outer(sj, sj) * np.outer(s, s)
            d["covariance"] = {"names": list(INTRINSIC_NAMES), "matrix": np.asarray(cov).tolist()}
        return d

    def to_budget(self, source: str = "opencv", *, full_covariance: bool = False, name: str | None = None):
        """An :class:`footprint_uq.uncertainty.budget.ErrorBudget` with the intrinsic error sizes (others zero)."""

        return ErrorBudget.from_dict(self.budget_dict(source, full_covariance=full_covariance, name=name))

    def intrinsics_dict(self) -> dict:
        """Our own camera-file keys for the intrinsics (general OpenCV model, no pose)."""
        return {"model": "opencv", "image_size_px": [int(v) for v in self.image_size_px],
                "K": self.K.tolist(), "dist": [float(v) for v in self.dist[:5]]}

    def camera(self, R, t, ground_z_m: float = 0.0):
        """An :class:`~footprint_uq.OpenCVCamera` with these intrinsics and a given pose (world -> camera)."""

        return OpenCVCamera(self.K, self.dist, R, t, self.image_size_px, ground_z_m)

    # -- maps -----------------------------------------------------------------------
    def board_outlines_px(self, hull: str = "corners") -> list[np.ndarray]:
        """Per used view, the points whose hull is the board in the image (``"corners"`` or ``"squares"``)."""
        if hull == "corners":
            return [np.asarray(c) for c in self.image_points_px]
        if hull == "squares":
            ol = self.board.outline()
            return [_project(ol, rv, tv, self.K, self.dist) for rv, tv in zip(self.rvecs, self.tvecs, strict=True)]
        raise InputError("hull", hull, "'corners' or 'squares'")

    def coverage(self, grid_px: float = 5.0, hull: str = "corners"):

        return coverage_map(self.board_outlines_px(hull), self.image_size_px, grid_px)

    def error_map(self, grid_px: float = 5.0):

        return reprojection_error_map(np.concatenate(self.image_points_px), np.concatenate(self.residuals_px),
                                      self.image_size_px, grid_px)

    def asymmetry(self, cell_px: float = 40.0, n_permutations: int = 200, seed: int = 0) -> dict:

        return error_asymmetry(np.concatenate(self.image_points_px), np.concatenate(self.residuals_px),
                               (self.K[0, 2], self.K[1, 2]), self.image_size_px, cell_px=cell_px,
                               n_permutations=n_permutations, seed=seed)

    # -- reporting ------------------------------------------------------------------
    def frames_table(self) -> list[dict]:
        """One row per input frame: label, path, frame_index, found, used, reason, errors."""
        used = {lab: i for i, lab in enumerate(self.labels)}
        dropped = {d["label"]: d for d in self.dropped}
        mean = self.per_view_mean_px
        rows = []
        for det in self.detections:
            lab = det.label
            row = {"label": lab, "path": det.source.path, "frame_index": det.source.frame_index,
                   "found": det.found, "method": det.method, "used": lab in used, "reason": det.reason,
                   "dropped_round": None, "mean_error_px": None, "rms_error_px": None}
            if lab in used:
                i = used[lab]
                row["mean_error_px"] = float(mean[i])
                row["rms_error_px"] = float(self.per_view_rms_px[i])
            elif lab in dropped:
                d = dropped[lab]
                row["dropped_round"] = d["round"]
                row["mean_error_px"] = d["mean_error_px"]
                row["reason"] = d["reason"]
            rows.append(row)
        return rows

    def summary(self, *, grid_px: float = 5.0, hull: str = "corners") -> dict:
        """JSON-ready summary: values, variability table per source, filter, maps, frames."""
        vals = self.values
        n_found = sum(d.found for d in self.detections) if self.detections else len(self.labels)
        out = {
            "opencv_version": self.opencv_version,
            "numpy_version": np.__version__,
            "board": {"inner_corners": [self.board.cols, self.board.rows], "square_m": self.board.square_m},
            "image_size_px": list(self.image_size_px),
            "frames": {"input": len(self.detections) or len(self.labels), "board_found": int(n_found),
                       "used": len(self.labels), "dropped_by_filter": len(self.dropped),
                       "not_found": [{"label": d.label, "reason": d.reason} for d in self.detections if not d.found]},
            "intrinsics": dict(zip(INTRINSIC_NAMES, (float(v) for v in vals), strict=True)),
            "K": self.K.tolist(), "dist": [float(v) for v in self.dist],
            "rms_reprojection_error_px": self.rms_px,
            "corner_sigma_px": self.corner_sigma_px,
            "std": {"opencv": dict(zip(INTRINSIC_NAMES, map(float, self.std_opencv), strict=True)),
                    "jacobian": dict(zip(INTRINSIC_NAMES, map(float, self.std_jacobian), strict=True))},
            "paper_table": self.paper_table(),
            "correlation_jacobian": _corr(self.cov_jacobian).tolist(),
            "filter": {"max_mean_reproj_px": self.max_mean_reproj_px,
                       "rounds": [r.__dict__ for r in self.rounds], "dropped": self.dropped,
                       "error_definition": "mean over the view's corners of |detected - reprojected| (px)"},
            "flags": int(self.flags),
        }
        if self.bootstrap is not None:
            b = self.bootstrap
            out["bootstrap"] = {"n_requested": b.n_requested, "n_ok": len(b.samples), "n_failed": b.n_failed,
                                "seed": b.seed, "resampling": "views with replacement, recalibrated"}
            if len(b.samples) > 1:
                out["std"]["bootstrap"] = dict(zip(INTRINSIC_NAMES, map(float, b.std), strict=True))
                out["std"]["bootstrap_robust"] = dict(zip(INTRINSIC_NAMES, map(float, b.robust_std), strict=True))
                out["comparison"] = compare_sigmas(self.std_opencv, b.std)
        cov = self.coverage(grid_px, hull)
        em = self.error_map(grid_px)
        asym = self.asymmetry()
        out["maps"] = {"coverage": {**cov.summary(), "hull": hull}, "reprojection_error": em.summary(),
                       "asymmetry": {k: v for k, v in asym.items() if not isinstance(v, np.ndarray)}}
        return out

    def save(self, out_dir, *, grid_px: float = 5.0, hull: str = "corners", budget_source: str = "opencv",
             full_covariance: bool = False, figures: bool = True) -> dict:
        """Write camera.yaml, intrinsics.yaml, budget.yaml, summary.json, report.md/.html, frames.csv, maps.npz, PNGs.

        Returns
        -------
        dict
            File name -> path of everything written.
        """
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        files: dict[str, str] = {}
        files["frames.csv"] = str(write_frames_csv(self.frames_table(), out / "frames.csv"))
        files["camera.yaml"] = str(self.write_opencv_yaml(out / "camera.yaml"))
        files["intrinsics.yaml"] = str(_write_yaml(out / "intrinsics.yaml", self.intrinsics_dict()))
        files["budget.yaml"] = str(_write_yaml(out / "budget.yaml",
                                               self.budget_dict(budget_source, full_covariance=full_covariance)))
        cov = self.coverage(grid_px, hull)
        em = self.error_map(grid_px)
        asym = self.asymmetry()
        with atomic_path(out / "maps.npz") as tmp:
            np.savez_compressed(tmp, coverage_count=cov.count, mean_error_px=em.mean_error_px,
                                corner_count=em.count, mean_residual_px=em.mean_residual_px,
                                reflection_map_px=asym["reflection_map_px"], grid_px=grid_px,
                                asymmetry_cell_px=asym["cell_px"], image_size_px=np.array(self.image_size_px),
                                principal_point_px=self.K[:2, 2])
        files["maps.npz"] = str(out / "maps.npz")
        summ = self.summary(grid_px=grid_px, hull=hull)
        summ["budget"] = {"source": budget_source, "full_covariance": bool(full_covariance),
                          "file": "budget.yaml"}
        if figures:

            files.update(save_calibration_figures(self, out, coverage=cov, error_map=em, asymmetry=asym))
        summ["files"] = sorted(files) + ["summary.json", "report.md"] + (["report.html"] if figures else [])
        atomic_write_text(out / "summary.json", json.dumps(_jsonable(summ), indent=2))
        files["summary.json"] = str(out / "summary.json")
        atomic_write_text(out / "report.md", render_report(summ))
        files["report.md"] = str(out / "report.md")
        if figures:

            files["report.html"] = str(write_calibration_html(summ, out))
        return files

    def write_opencv_yaml(self, path) -> Path:
        """OpenCV FileStorage YAML (``camera_matrix``, ``distortion_coefficients``) as OpenCV's sample writes."""


        path = Path(path)
        final, path = Path(path), temp_path(path)
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        try:
            fs.write("calibration_time", time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
            fs.write("nr_of_frames", len(self.labels))
            fs.write("image_width", int(self.image_size_px[0]))
            fs.write("image_height", int(self.image_size_px[1]))
            fs.write("board_width", int(self.board.cols))
            fs.write("board_height", int(self.board.rows))
            fs.write("square_size", float(self.board.square_m))
            fs.write("camera_matrix", self.K)
            fs.write("distortion_coefficients", self.dist.reshape(-1, 1))
            fs.write("avg_reprojection_error", float(self.rms_px))
            fs.write("opencv_version", self.opencv_version)
        except BaseException:
            fs.release()
            discard(path)
            raise
        fs.release()
        commit(path, final)
        return final


def _corr(cov):
    s = np.sqrt(np.diag(cov))
    with np.errstate(invalid="ignore", divide="ignore"):
        return cov / np.outer(s, s)


def _jsonable(o):
    if isinstance(o, dict):
        return {str(k): _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.ndarray):
        return _jsonable(o.tolist())
    if isinstance(o, (np.floating, float)):
        x = float(o)
        return x if math.isfinite(x) else None
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def _write_yaml(path, data) -> Path:

    path = Path(path)
    atomic_write_text(path, yaml.safe_dump(_jsonable(data), sort_keys=False, default_flow_style=None))
    return path


def write_frames_csv(rows: list[dict], path) -> Path:

    path = Path(path)
    cols = ["label", "path", "frame_index", "found", "method", "used", "dropped_round", "mean_error_px",
            "rms_error_px", "reason"]
    with atomic_path(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow({k: ("" if r.get(k) is None else r.get(k)) for k in cols})
    return path


def render_report(summ: dict) -> str:
    """A short Markdown report from :meth:`IntrinsicCalibration.summary`."""
    L = ["# Intrinsic calibration report", ""]
    fr = summ["frames"]
    L += [f"OpenCV {summ['opencv_version']}; board {summ['board']['inner_corners'][0]}x"
          f"{summ['board']['inner_corners'][1]} inner corners, square {summ['board']['square_m']} m; "
          f"image {summ['image_size_px'][0]}x{summ['image_size_px'][1]} px.", "",
          f"Frames: {fr['input']} input, {fr['board_found']} with the board, {fr['used']} used, "
          f"{fr['dropped_by_filter']} dropped by the reprojection-error filter.", ""]
    if fr["not_found"]:
        L += ["Frames without a board:", ""] + [f"- `{d['label']}`: {d['reason']}" for d in fr["not_found"]] + [""]
    f = summ["filter"]
    if f["max_mean_reproj_px"] is not None:
        L += [f"Filter threshold: mean reprojection error <= {f['max_mean_reproj_px']} px "
              f"({f['error_definition']})."]
        for r in f["rounds"]:
            L.append(f"- round {r['round']}: {r['n_views']} views, RMS {r['rms_px']:.4f} px, worst view mean "
                     f"{r['max_mean_error_px']:.4f} px, dropped {', '.join(r['dropped']) or 'none'}")
        L.append("")
    iv = summ["intrinsics"]
    L += [f"RMS reprojection error {summ['rms_reprojection_error_px']:.4f} px; corner noise estimate "
          f"{summ['corner_sigma_px']:.4f} px per coordinate.", "",
          "| parameter | value | sigma OpenCV | sigma Jacobian | sigma bootstrap |", "|---|---|---|---|---|"]
    st = summ["std"]
    for k in INTRINSIC_NAMES:
        b = st.get("bootstrap", {}).get(k)
        L.append(f"| {k} | {iv[k]:.6g} | {st['opencv'][k]:.4g} | {st['jacobian'][k]:.4g} | "
                 f"{'-' if b is None else f'{b:.4g}'} |")
    L += ["", "Paper's Table 2 (sigma f = RSS of sigma fx and sigma fy; c, r = principal point column, row):", "",
          "| source | " + " | ".join(PAPER_COLUMNS) + " |", "|---" * (len(PAPER_COLUMNS) + 1) + "|"]
    for src, row in summ["paper_table"].items():
        L.append(f"| {src} | " + " | ".join(f"{row[c]:.4g}" for c in PAPER_COLUMNS) + " |")
    if "comparison" in summ:
        c = summ["comparison"]
        L += ["", "## OpenCV vs bootstrap", "",
              f"Median ratio bootstrap / OpenCV: {c['median_ratio']:.3g}. {c['verdict']}.", "",
              "OpenCV's standard deviations are first-order and assume independent, identically distributed "
              "corner noise; the bootstrap over views also reflects how much the result depends on which "
              "board poses were captured."]
    m = summ["maps"]
    cv_, em, a = m["coverage"], m["reprojection_error"], m["asymmetry"]
    L += ["", "## Maps", "",
          f"Coverage ({cv_['cell_px']:g} px cells, hull of {cv_['hull']}): {100 * cv_['covered_fraction']:.1f} % "
          f"of the image seen by at least one board; image-corner patches: "
          f"{100 * cv_['image_corner_patches_covered_fraction']:.1f} %; up to {cv_['max_boards_per_cell']} boards "
          "per cell."]
    if "max_cell_mean_error_px" in em:
        L.append(f"Reprojection error: worst cell mean {em['max_cell_mean_error_px']:.3f} px at "
                 f"({em['max_cell_centre_px'][0]:.0f}, {em['max_cell_centre_px'][1]:.0f}) px, median cell "
                 f"{em['median_cell_mean_error_px']:.3f} px.")
    L.append(f"Asymmetry ({a['cell_px']:g} px cells): point-reflection index {a['reflection_index']:.3f} over "
             f"{a['reflection_pairs']} cell pairs" + (
                 f" (noise yardstick: permutation mean {a['reflection_index_null_mean']:.3f}, 95th percentile "
                 f"{a['reflection_index_null_p95']:.3f}, p = {a['reflection_p_value']:.3f})"
                 if a.get("reflection_index_null_p95") is not None else "")
             + f"; left/right imbalance {a['left_right']:+.3f}, top/bottom {a['top_bottom']:+.3f}; residual "
             f"coherence {a['residual_coherence']:.3f}.")
    L += ["", "Files: " + ", ".join(f"`{x}`" for x in summ.get("files", [])), ""]
    return "\n".join(L)


# ------------------------------------------------------------------------------------------ drivers
#: RMS reprojection error (px) above which a calibration is refused by default: a good chessboard
#: calibration is well below 1 px; several px mean wrong corners (e.g. a --board smaller than the
#: printed one: the detector then finds a different part of the board in every view)
MAX_RMS_PX = 2.0


def _view_points(image_points_px, board) -> list[np.ndarray]:
    """Each view's corners as ``(n_corners, 2)`` px, checked (count of the board, finite)."""
    imgs = []
    for i, c in enumerate(image_points_px):
        a = np.asarray(c, dtype=np.float64).reshape(-1, 2)
        if a.shape[0] != board.n_corners:
            raise InputError(f"image_points_px[{i}]", f"{a.shape[0]} corners", f"{board.n_corners} corners "
                             f"({board.label()} board)")
        if not np.all(np.isfinite(a)):
            raise InputError(f"image_points_px[{i}]", "non-finite corner", "finite pixel coordinates")
        imgs.append(a)
    return imgs


def _filter_views(obj, imgs: list, labels: list, size: tuple, flags: int, thr: float | None, mv: int,
                  max_rounds: int):
    """Calibrate, drop views whose mean reprojection error exceeds ``thr``, repeat until none is dropped.

    Returns ``(fit, active view indices, rounds, dropped views)``.
    """
    active = list(range(len(imgs)))
    rounds: list[FilterRound] = []
    dropped: list[dict] = []
    converged = thr is None
    for rnd in range(int(max_rounds)):
        fit = _calibrate(obj, [imgs[i] for i in active], size, flags)
        means = np.array([np.linalg.norm(imgs[i] - _project(obj, fit.rvecs[k], fit.tvecs[k], fit.K, fit.dist),
                                         axis=-1).mean() for k, i in enumerate(active)])
        bad = np.zeros(len(active), bool) if thr is None else means > thr
        rounds.append(FilterRound(rnd, len(active), fit.rms_px, float(means.max()),
                                  [labels[active[k]] for k in np.nonzero(bad)[0]]))
        if not bad.any():
            converged = True
            break
        keep = [i for k, i in enumerate(active) if not bad[k]]
        if len(keep) < mv:
            raise InputError("max_mean_reproj_px", thr,
                             f"a threshold that leaves at least {mv} views (round {rnd}: {len(keep)} of "
                             f"{len(active)} views at or below it; view mean errors range "
                             f"{means.min():.3f}..{means.max():.3f} px)")
        for k in np.nonzero(bad)[0]:
            dropped.append({"label": labels[active[k]], "round": rnd, "mean_error_px": float(means[k]),
                            "reason": f"mean reprojection error {means[k]:.4f} px > {thr:g} px (round {rnd})"})
        active = keep
    if not converged:  # the last round dropped frames: solve once more on the remaining ones
        warnings.warn(f"frame filter did not settle in {max_rounds} rounds; the result uses the {len(active)} "
                      "frames left after the last round", RuntimeWarning, stacklevel=3)
        fit = _calibrate(obj, [imgs[i] for i in active], size, flags)
    return fit, active, rounds, dropped


def calibrate_corners(image_points_px, board, image_size_px, *, labels=None, max_mean_reproj_px=None,
                      bootstrap: int = 0, seed: int = 0, min_views: int = 3, flags: int = 0, max_rounds: int = 50,
                      detections=None, workers: int = 1, progress: bool = False,
                      max_rms_px: float | None = MAX_RMS_PX) -> IntrinsicCalibration:
    """Calibrate from corner positions already detected.

    Parameters
    ----------
    image_points_px : sequence of array_like (N, 2)
        Per view, the board's inner corners in OpenCV order, px.
    board : Checkerboard or str
    image_size_px : (int, int)
    labels : sequence of str, optional
        View names (default ``view000``...).
    max_mean_reproj_px : float, optional
        Frame-filter threshold on the per-view mean reprojection error (px); None: no filter.
    bootstrap : int
        Bootstrap resamples (0: none).
    seed : int
        Bootstrap seed.
    min_views : int
        Fewest views accepted (>= 3; Zhang's method needs three views for all intrinsics).
    flags : int
        ``cv2.CALIB_*`` flags passed to OpenCV (default 0: fx, fy, cx, cy, k1, k2, p1, p2, k3 free, no skew).
    max_rounds : int
        Cap on filter rounds.
    max_rms_px : float or None
        Refuse (InputError naming the board) a fit whose RMS reprojection error exceeds it
        (default :data:`MAX_RMS_PX`; None: no limit).  A principal point outside the image is
        always refused: both are what a wrong board size gives.
    detections : list of Detection, optional
        All input frames (kept for the report).
    workers : int
        Processes for the bootstrap.
    progress : bool
        Progress bar for the bootstrap.

    Returns
    -------
    IntrinsicCalibration
    """

    board = parse_board(board)
    mv = int(min_views)
    if mv < 3:
        raise InputError("min_views", min_views, "an integer >= 3")
    try:
        w, h = (int(v) for v in image_size_px)
    except (TypeError, ValueError):
        raise InputError("image_size_px", image_size_px, "(width, height) in pixels") from None
    imgs = _view_points(image_points_px, board)
    labels = [f"view{i:03d}" for i in range(len(imgs))] if labels is None else [str(s) for s in labels]
    if len(labels) != len(imgs):
        raise InputError("labels", len(labels), f"{len(imgs)} labels (one per view)")
    if len(imgs) < mv:
        raise InputError("views", len(imgs), f"at least {mv} views with the whole {board.label()} board detected"
                         + _not_found_note(detections))
    thr = _reproj_threshold(max_mean_reproj_px)
    obj = board.object_points()
    fit, active, rounds, dropped = _filter_views(obj, imgs, labels, (w, h), flags, thr, mv, max_rounds)
    _check_fit(fit, board, (w, h), max_rms_px)
    used = [imgs[i] for i in active]
    residuals = [c - _project(obj, rv, tv, fit.K, fit.dist)
                 for c, rv, tv in zip(used, fit.rvecs, fit.tvecs, strict=True)]
    cov, sig, _dof = intrinsic_covariance(obj, used, fit.K, fit.dist, fit.rvecs, fit.tvecs)
    boot = None
    if bootstrap and int(bootstrap) > 0:
        boot = bootstrap_intrinsics(obj, used, (w, h), fit.K, fit.dist, int(bootstrap), seed=seed, min_views=mv,
                                    flags=flags, workers=workers, progress=progress)
    return IntrinsicCalibration(
        board=board, image_size_px=(w, h), K=fit.K, dist=fit.dist, std_opencv=fit.std9, cov_jacobian=cov,
        corner_sigma_px=sig, rms_px=fit.rms_px, labels=[labels[i] for i in active], image_points_px=used,
        rvecs=fit.rvecs, tvecs=fit.tvecs, residuals_px=residuals, per_view_rms_px=fit.per_view_rms_px,
        detections=list(detections) if detections is not None else
        [Detection(FrameSource(lab), True, c, (w, h), "", "given") for lab, c in zip(labels, imgs, strict=True)],
        rounds=rounds, dropped=dropped, bootstrap=boot, max_mean_reproj_px=thr, flags=int(flags),
        opencv_version=cv2.__version__)


def _reproj_threshold(max_mean_reproj_px) -> float | None:
    """The frame filter's threshold (px), checked: None (no filter) or a finite number > 0."""
    if max_mean_reproj_px is None:
        return None
    thr = float(max_mean_reproj_px)
    if not (np.isfinite(thr) and thr > 0):
        raise InputError("max_mean_reproj_px", max_mean_reproj_px, "a threshold > 0 px")
    return thr


def _check_fit(fit, board, size, max_rms_px) -> None:
    """Refuse a calibration whose principal point is outside the image or whose RMS is implausible."""
    w, h = size
    cx, cy = float(fit.K[0, 2]), float(fit.K[1, 2])
    hint = (f"is the board {board.label()} (inner corners, cols x rows) the one in the images? A smaller "
            "--board is found in a different part of a larger board in every view")
    if not (np.isfinite(cx) and np.isfinite(cy) and -0.5 <= cx <= w - 0.5 and -0.5 <= cy <= h - 0.5):
        raise InputError("board", board.label(), f"a calibration with its principal point inside the {w}x{h} image "
                         f"(got cx = {cx:.1f}, cy = {cy:.1f} px; RMS {fit.rms_px:.2f} px): {hint}")
    if max_rms_px is not None and not fit.rms_px <= float(max_rms_px):
        raise InputError("board", board.label(), f"a calibration with RMS reprojection error <= {float(max_rms_px):g}"
                         f" px (got {fit.rms_px:.2f} px; raise max_rms_px / --max-rms-px to accept it): {hint}")


def _not_found_note(detections) -> str:
    if not detections:
        return ""
    bad = [d for d in detections if not d.found]
    if not bad:
        return ""
    reasons: dict[str, int] = {}
    for d in bad:
        reasons[d.reason] = reasons.get(d.reason, 0) + 1
    return f" ({len(detections)} frames: " + "; ".join(f"{n} {r}" for r, n in reasons.items()) + ")"


def calibrate_detections(detections, board, **kw) -> IntrinsicCalibration:
    """Calibrate from :func:`detect_frames` output.

    Frames whose image size differs from the most common size are marked not
    found (reason given) and left out; see :func:`calibrate_corners` for ``kw``.
    """
    board = parse_board(board)
    dets = list(detections)
    sizes: dict[tuple, int] = {}
    for d in dets:
        if d.found:
            sizes[d.image_size_px] = sizes.get(d.image_size_px, 0) + 1
    if not sizes:
        raise InputError("views", 0, f"at least {kw.get('min_views', 3)} views with the whole {board.label()} "
                         "board detected" + _not_found_note(dets))
    size = max(sizes, key=lambda s: (sizes[s], s))
    for d in dets:
        if d.found and d.image_size_px != size:
            d.found = False
            d.reason = (f"image size {d.image_size_px[0]}x{d.image_size_px[1]} differs from the other frames "
                        f"({size[0]}x{size[1]})")
    other = [d for d in dets if (d.reason or "").startswith("image size ")]
    if other:
        warnings.warn(f"{len(other)} of {len(dets)} frames left out: their image size differs from the "
                      f"{size[0]}x{size[1]} px of the others (first: {other[0].label})", RuntimeWarning, stacklevel=2)
    good = [d for d in dets if d.found]
    return calibrate_corners([d.corners_px for d in good], board, size, labels=[d.label for d in good],
                             detections=dets, **kw)


def calibrate_intrinsics(images, board, square_m: float | None = None, *, video_step: int = 1,
                         workers: int | None = None, method: str = "auto", progress: bool = False,
                         **kw) -> IntrinsicCalibration:
    """Detect the board in ``images`` and calibrate (the whole pipeline).

    Parameters
    ----------
    images : path, glob, folder, video or a sequence of them
    board : Checkerboard or str
        E.g. ``"9x6"`` (inner corners).
    square_m : float, optional
        Square size (m) when ``board`` is a string (default 0.025).  The
        intrinsics do not depend on it; the board poses do.
    video_step, workers, method, progress
        See :func:`footprint_uq.calibration.detect.detect_frames`.
    **kw
        ``max_mean_reproj_px``, ``bootstrap``, ``seed``, ``min_views``, ``flags`` (see :func:`calibrate_corners`).

    Examples
    --------
    >>> cal = calibrate_intrinsics("calib/*.png", "9x6", 0.025, max_mean_reproj_px=0.5,
    ...                            bootstrap=200)  # doctest: +SKIP
    >>> cal.to_budget()            # doctest: +SKIP
    >>> cal.save("out/")           # doctest: +SKIP
    """
    if not isinstance(board, Checkerboard):
        board = parse_board(board, square_m if square_m is not None else 0.025)
    dets = detect_frames(images, board, video_step=video_step, workers=workers, method=method, progress=progress)
    n_workers = (os.cpu_count() or 1) if workers is None else int(workers)
    return calibrate_detections(dets, board, progress=progress, workers=n_workers, **kw)

