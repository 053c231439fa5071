"""Extrinsic calibration of a camera against a LiDAR ground truth (the paper's Table 3).

Inputs: per frame, the image corners of a checkerboard (``uv_px`` (N, 2), OpenCV
order) and the same corners in 3D in the LiDAR frame (from :mod:`.lidar`, or given
directly as a CSV of correspondences), plus the camera intrinsics.

Per frame: EPnP inside RANSAC (:func:`cv2.solvePnPRansac` with ``SOLVEPNP_EPNP``)
then Levenberg-Marquardt refinement on the inliers (:func:`cv2.solvePnPRefineLM`);
EPnP alone is unreliable for a planar target, so IPPE (the planar solver) is also
tried as a starting point and the refined pose with the smaller reprojection error
is kept.  When the 3D corners come from a LiDAR rectangle fit, the grid can sit on
the rectangle in 4 ways (8 for a square grid); every placement is solved, those
putting the camera behind the board are rejected, and the one consistent with the
other frames (the camera does not move) is kept (:func:`resolve_orientation`).

Each pose is expressed in the paper's terms relative to the ground frame
(``T_ground_lidar``: a ground-plane fit of the scans, or given): camera position
``x_m, y_m``, height ``height_m`` above the ground, ``pan_deg`` (compass heading,
clockwise from the ground frame's +y), ``tilt_deg`` (down positive), ``roll_deg``
(:func:`footprint_uq.cameras.rotation.pan_tilt_roll_from_R_W_C`).

Variability, three ways (all reported, compared in :meth:`ExtrinsicCalibration.summary`):

``per_frame``
    the spread (sample standard deviation) of the per-frame poses: what the paper's
    Table 3 tabulates; the uncertainty of a pose from ONE frame.
``bootstrap``
    a seeded bootstrap over frames: resample frames with replacement, re-solve the
    joint pose (LM from the joint estimate) on their correspondences; the
    uncertainty of the JOINT pose from all frames, including the LiDAR's per-frame
    board-fit errors.
``jacobian``
    first order: ``s^2 (J^T J)^-1`` with J the Jacobian of the reprojection of all
    corners with respect to (x, y, h, pan, tilt, roll) (the library's own
    :func:`footprint_uq.cameras.general.project`, ``duv_dp``) and ``s^2`` the
    residual variance; uncertainty of the joint pose if the residuals were
    independent per corner.  It does not see errors shared by all corners of a
    frame (a misplaced LiDAR rectangle), so it is optimistic when those dominate.

The budget file (extrinsic part) uses one of them (``budget_from``, default
``per_frame``, the paper's definition and the conservative choice); the full 6x6
covariance is written too, so the correlations (e.g. x with pan) reach the core.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
import yaml

from .. import params as P
from .._files import file_kind, read_input_text
from .._parse import load_yaml
from ..cameras import general
from ..cameras.opencv import OpenCVCamera
from ..cameras.rotation import R_W_C, pan_tilt_roll_from_R_W_C
from ..errors import InputError
from ..io import load_camera
from ..io.atomic import atomic_write_text
from ..uncertainty.budget import ErrorBudget
from .boards import Checkerboard, parse_board
from .detect import detect_corners
from .lidar import detect_board, fit_ground_plane, ground_frame_from_plane, parse_region, transform_points
from .pointclouds import PointCloud, read_point_cloud

__all__ = ["POSE_NAMES", "Intrinsics", "load_intrinsics", "FrameData", "FramePose", "ExtrinsicCalibration",
           "solve_frame", "resolve_orientation", "pose_in_ground", "calibrate_extrinsics", "frames_from_pairs",
           "pairs_from_directory", "read_correspondences_csv", "jacobian_covariance", "load_transform",
           "BUDGET_SOURCES"]

log = logging.getLogger(__name__)

#: the pose in the paper's terms, in this order
POSE_NAMES = ("x_m", "y_m", "height_m", "pan_deg", "tilt_deg", "roll_deg")
BUDGET_SOURCES = ("per_frame", "bootstrap", "jacobian")
_BUDGET_COV_NAMES = ["x_m", "y_m", "height_m", "pan_deg", "tilt_deg", "roll_deg"]


# ---------------------------------------------------------------------------------------------
# intrinsics
# ---------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Intrinsics:
    """``K`` (3, 3), OpenCV distortion ``dist`` (0/4/5/8,), ``image_size_px`` (width, height)."""

    K: np.ndarray
    dist: np.ndarray
    image_size_px: tuple[int, int]

    def params(self) -> np.ndarray:
        """The intrinsic part of the 22-parameter vector (pose entries zero)."""
        p = np.zeros(P.N_PARAMS)
        p[[P.FX, P.FY, P.CX, P.CY, P.SKEW]] = self.K[0, 0], self.K[1, 1], self.K[0, 2], self.K[1, 2], self.K[0, 1]
        d = np.zeros(8)
        d[:self.dist.size] = self.dist
        p[P.DIST_SLICE] = d
        return p


def load_intrinsics(spec) -> Intrinsics:
    """Intrinsics from an :class:`Intrinsics`, a Camera, an object with ``K``/``dist``/``image_size_px``
    (e.g. an intrinsic calibration result, or one with a ``camera`` attribute) or a camera file
    (any format :func:`footprint_uq.io.load_camera` reads; an intrinsics-only file is fine)."""
    if isinstance(spec, Intrinsics):
        return spec
    if isinstance(spec, (str, Path)):

        try:
            cam = load_camera(spec)
        except InputError as first:
            try:  # intrinsics-only file: any pose will do, only K and dist are used
                cam = load_camera(spec, pose={"height_m": 1.0, "pan_deg": 0.0, "tilt_deg": 0.0})
            except InputError:
                cam = _intrinsics_mapping(spec)
                if cam is None:
                    raise first from None
        spec = cam
    cam = getattr(spec, "camera", None)
    if cam is not None and not hasattr(spec, "K"):
        spec = cam
    try:
        K = np.asarray(spec.K, dtype=np.float64)
        dist = np.asarray(getattr(spec, "dist", np.zeros(5)), dtype=np.float64).ravel()
        size = tuple(int(v) for v in spec.image_size_px)
    except (AttributeError, TypeError, ValueError):
        raise InputError("intrinsics", type(spec).__name__,
                         "a camera file, a Camera, or an object with K, dist and image_size_px") from None
    if K.shape != (3, 3) or not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
        raise InputError("intrinsics K", K.tolist(), "a finite 3x3 camera matrix with fx, fy > 0")
    if dist.size > 8:
        raise InputError("intrinsics dist", dist.tolist(), "at most 8 coefficients (k1 k2 p1 p2 k3 k4 k5 k6)")
    if dist.size == 8 and not np.any(dist[5:]):
        dist = dist[:5]
    return Intrinsics(K, dist, size)


def _intrinsics_mapping(path):
    """Our camera-file keys without a pose (``model: opencv``, ``image_size_px``, ``K``[, ``dist``]), as
    the intrinsic calibration writes them; None if the file is not such a mapping."""

    try:
        d = load_yaml(read_input_text(path, "intrinsics"), str(path))
    except (OSError, yaml.YAMLError, UnicodeDecodeError, InputError):  # (ConfigError is an InputError)
        return None
    if not isinstance(d, dict) or "K" not in d or "image_size_px" not in d or any(k in d for k in ("R", "t", "P")):
        return None
    try:
        K = np.asarray(d["K"], dtype=np.float64).reshape(3, 3)
        dist = np.asarray(d.get("dist") or [], dtype=np.float64).ravel()
        size = tuple(int(v) for v in d["image_size_px"])
    except (TypeError, ValueError):
        raise InputError(f"{path}: K, dist, image_size_px", {k: d.get(k) for k in ("K", "dist", "image_size_px")},
                         "a 3x3 K, 0/4/5/8 distortion coefficients and [width, height]") from None
    if dist.size not in (0, 4, 5, 8) or len(size) != 2 or min(size) <= 0:
        raise InputError(f"{path}: dist, image_size_px", (dist.tolist(), size),
                         "0, 4, 5 or 8 distortion coefficients and [width, height] > 0")
    return Intrinsics(K, dist, size)


# ---------------------------------------------------------------------------------------------
# frames
# ---------------------------------------------------------------------------------------------
@dataclass
class FrameData:
    """Input of one frame.

    Attributes
    ----------
    name : str
    uv_px : ndarray (N, 2) or None
        Image corners (OpenCV order); None when not found.
    xyz_candidates : list of ndarray (N, 3)
        3D corners in the LiDAR frame, one array per possible grid placement
        (one for explicit correspondences).
    ok : bool
    reason : str
        Why the frame cannot be used (empty when ok).
    cloud_stats : dict
        Point-cloud read statistics (dropped NaN points...), when read from a file.
    detection : dict
        LiDAR board detection summary.
    """

    name: str
    uv_px: np.ndarray | None
    xyz_candidates: list
    ok: bool = True
    reason: str = ""
    cloud_stats: dict = field(default_factory=dict)
    detection: dict = field(default_factory=dict)
    board_xyz_m: np.ndarray | None = field(default=None, repr=False)


@dataclass
class FramePose:
    """Solved pose of one frame: OpenCV ``rvec``/``tvec`` (LiDAR -> camera), inliers, reprojection RMS."""

    name: str
    rvec: np.ndarray
    tvec: np.ndarray
    inliers: np.ndarray
    rms_px: float
    candidate: int
    method: str
    xyz_m: np.ndarray
    uv_px: np.ndarray

    @property
    def camera_centre_lidar_m(self) -> np.ndarray:

        R = cv2.Rodrigues(self.rvec)[0]
        return -R.T @ self.tvec.ravel()


def load_transform(spec) -> np.ndarray:
    """A 4x4 rigid transform from an array, or a file (.npy, .txt/.csv of 16 numbers, or YAML/JSON with
    a 4x4 matrix under ``T_ground_lidar`` / ``T`` / ``matrix``, or ``R`` + ``t``)."""
    if isinstance(spec, (str, Path)):
        p = Path(spec)
        if not p.exists():
            raise InputError("ground transform", str(p), "an existing file with a 4x4 matrix")
        if p.suffix.lower() == ".npy":
            T = np.load(p, allow_pickle=False)
        elif p.suffix.lower() in (".txt", ".csv"):
            T = np.array([float(v) for v in read_input_text(p, "ground transform").replace(",", " ").split()])
        else:

            d = load_yaml(read_input_text(p, "ground transform"), str(p))
            if isinstance(d, dict):
                for k in ("T_ground_lidar", "T", "matrix", "transform"):
                    if k in d:
                        d = d[k]
                        break
                else:
                    if "R" in d and "t" in d:
                        Tm = np.eye(4)
                        Tm[:3, :3] = np.asarray(d["R"], float)
                        Tm[:3, 3] = np.asarray(d["t"], float).ravel()
                        d = Tm
            T = d
        spec = T
    try:
        T = np.asarray(spec, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("ground transform", spec, "a 4x4 matrix") from None
    if T.size == 16:
        T = T.reshape(4, 4)
    elif T.shape == (3, 4):
        T = np.vstack([T, [0, 0, 0, 1]])
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise InputError("ground transform", getattr(T, "shape", T), "a finite 4x4 (or 3x4) rigid transform")
    R = T[:3, :3]
    if np.abs(R @ R.T - np.eye(3)).max() > 1e-4 or np.linalg.det(R) <= 0 or np.any(T[3] != [0, 0, 0, 1]):
        raise InputError("ground transform", T.tolist(), "a rigid transform (orthonormal R, det +1, last row 0 0 0 1)")
    return T


# ---------------------------------------------------------------------------------------------
# PnP
# ---------------------------------------------------------------------------------------------
def _reproj(rvec, tvec, xyz, uv, intr):

    pr = cv2.projectPoints(xyz.reshape(-1, 1, 3), rvec, tvec, intr.K, intr.dist)[0].reshape(-1, 2)
    return pr - uv


def solve_frame(xyz_m, uv_px, intr: Intrinsics, *, ransac_threshold_px: float = 4.0, seed: int = 0,
                name: str = "", candidate: int = 0):
    """Pose of one frame: EPnP in RANSAC, LM refinement on the inliers (IPPE tried as another start).

    Returns
    -------
    FramePose or None
        None when no pose with at least 6 inliers was found.
    """

    X = np.ascontiguousarray(xyz_m, dtype=np.float64).reshape(-1, 3)
    uv = np.ascontiguousarray(uv_px, dtype=np.float64).reshape(-1, 2)
    starts = []
    cv2.setRNGSeed(int(seed))
    try:
        ok, rvec, tvec, inl = cv2.solvePnPRansac(X, uv, intr.K, intr.dist, flags=cv2.SOLVEPNP_EPNP,
                                                 reprojectionError=float(ransac_threshold_px), iterationsCount=200,
                                                 confidence=0.999)
    except cv2.error:
        ok = False
    if ok and inl is not None and len(inl) >= 6:
        starts.append((rvec, tvec, inl.ravel(), "epnp-ransac+lm"))
    try:
        ok2, rv2, tv2 = cv2.solvePnP(X, uv, intr.K, intr.dist, flags=cv2.SOLVEPNP_IPPE)
        if ok2:
            starts.append((rv2, tv2, np.arange(len(X)), "ippe+lm"))
    except cv2.error:
        pass
    best = None
    for rv, tv, inl, method in starts:
        inl = np.asarray(inl, dtype=int)
        rv, tv = cv2.solvePnPRefineLM(X[inl], uv[inl], intr.K, intr.dist, rv.copy(), tv.copy(),
                                      (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12))
        res = np.linalg.norm(_reproj(rv, tv, X, uv, intr), axis=1)
        inl2 = np.nonzero(res < ransac_threshold_px)[0]
        if len(inl2) < 6:
            continue
        if len(inl2) != len(inl) or np.any(inl2 != inl):
            rv, tv = cv2.solvePnPRefineLM(X[inl2], uv[inl2], intr.K, intr.dist, rv, tv,
                                          (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-12))
            res = np.linalg.norm(_reproj(rv, tv, X, uv, intr), axis=1)
        Xc = X @ cv2.Rodrigues(rv)[0].T + tv.ravel()
        if np.any(Xc[inl2, 2] <= 0):
            continue
        rms = float(np.sqrt(np.mean(res[inl2] ** 2)))
        key = (-len(inl2), rms)
        if best is None or key < best[0]:
            best = (key, FramePose(name, rv.ravel().copy(), tv.ravel().copy(), inl2, rms, candidate, method, X, uv))
    return None if best is None else best[1]


def _camera_behind_board(pose: FramePose) -> bool:
    """True when the camera and the LiDAR (origin) are on opposite sides of the board plane."""
    X = pose.xyz_m
    c = X.mean(axis=0)
    _, _, vt = np.linalg.svd(X - c, full_matrices=False)
    n = vt[2]
    s_lidar = np.sign(n @ (-c))
    s_cam = np.sign(n @ (pose.camera_centre_lidar_m - c))
    return bool(s_lidar != 0 and s_cam != 0 and s_lidar != s_cam)


def _rot_angle_deg(ra, rb):

    Ra, Rb = cv2.Rodrigues(ra)[0], cv2.Rodrigues(rb)[0]
    c = (np.trace(Ra.T @ Rb) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def resolve_orientation(candidates: list[list[FramePose]], *, position_tol_m: float | None = None,
                        angle_tol_deg: float = 10.0):
    """Pick, for each frame, the grid placement consistent with one camera pose.

    ``candidates[f]`` lists the solved candidates of frame f.  Every candidate votes
    for the candidates of other frames whose camera pose (in the LiDAR frame) is
    within ``position_tol_m`` (default: max(0.5 m, 25 % of the median board
    distance)) and ``angle_tol_deg``; the best-supported one is the reference, and
    each frame keeps its candidate closest to it.  The wrong placements differ
    from the right one by a half turn of the board (camera poses metres and tens
    of degrees away), so the tolerances can be generous: noisy but right frames
    must not be thrown out, as that would shrink the per-frame spread.

    Returns
    -------
    chosen : list of (FramePose or None)
        None for frames with no candidate near the reference.
    ambiguous : bool
        True when the choice rests on one frame only.
    """
    flat = [(f, c) for f, cs in enumerate(candidates) for c in cs]
    if not flat:
        return [None] * len(candidates), True
    if position_tol_m is None:
        dist = [np.linalg.norm(c.tvec) for _, c in flat]
        position_tol_m = max(0.5, 0.25 * float(np.median(dist)))
    C = np.array([c.camera_centre_lidar_m for _, c in flat])
    support = np.zeros(len(flat))
    for i, (fi, ci) in enumerate(flat):
        near = set()
        for j, (fj, cj) in enumerate(flat):
            if fj == fi or fj in near:
                continue
            if np.linalg.norm(C[i] - C[j]) < position_tol_m and _rot_angle_deg(ci.rvec, cj.rvec) < angle_tol_deg:
                near.add(fj)
        support[i] = len(near) - 1e-3 * ci.rms_px / (1.0 + ci.rms_px)
    ref = flat[int(np.argmax(support))][1]
    c_ref = ref.camera_centre_lidar_m
    chosen = []
    for cs in candidates:
        best, best_d = None, np.inf
        for c in cs:
            d = np.linalg.norm(c.camera_centre_lidar_m - c_ref)
            if d < position_tol_m and _rot_angle_deg(c.rvec, ref.rvec) < angle_tol_deg and d < best_d:
                best, best_d = c, d
        chosen.append(best)
    return chosen, bool(np.max(support) < 1)


def pose_in_ground(rvec, tvec, T_ground_lidar) -> np.ndarray:
    """``(6,)`` pose in the paper's terms (:data:`POSE_NAMES`) from an OpenCV LiDAR -> camera pose."""

    R = cv2.Rodrigues(np.asarray(rvec, float))[0]
    t = np.asarray(tvec, float).ravel()
    T = np.asarray(T_ground_lidar, float)
    R_gc = T[:3, :3] @ R.T
    C_g = T[:3, :3] @ (-R.T @ t) + T[:3, 3]
    pan, tilt, roll = pan_tilt_roll_from_R_W_C(R_gc)
    return np.array([C_g[0], C_g[1], C_g[2], np.degrees(pan), np.degrees(tilt), np.degrees(roll)])


def _wrap_deg(a):
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def _params_from_pose(intr: Intrinsics, pose6) -> np.ndarray:
    p = intr.params()
    p[[P.XM, P.YM, P.HM]] = pose6[:3]
    p[[P.PAN, P.TILT, P.ROLL]] = np.deg2rad(pose6[3:])
    return p


def jacobian_covariance(pose6, xyz_ground_m, uv_px, intr: Intrinsics):
    """First-order covariance ``(6, 6)`` of the pose (:data:`POSE_NAMES` units: m and deg).

    ``s^2 (J^T J)^-1`` where J ``(2M, 6)`` is ``duv/d(x, y, h, pan, tilt, roll)`` from
    :func:`footprint_uq.cameras.general.project` at the pose, and ``s^2`` the residual
    variance ``sum r^2 / (2M - 6)``.  Returns ``(cov, sigma_px, residuals (M, 2))``.
    """
    p = _params_from_pose(intr, np.asarray(pose6, float))
    pr = general.project(p, np.asarray(xyz_ground_m, float), get_gradients=True)
    cols = [P.XM, P.YM, P.HM, P.PAN, P.TILT, P.ROLL]
    J = pr.duv_dp[..., cols].reshape(-1, 6)
    r = (np.asarray(uv_px, float) - pr.uv_px)
    dof = r.size - 6
    if dof <= 0:
        raise InputError("correspondences", r.shape[0], "at least 4 corners for a first-order covariance")
    s2 = float(np.sum(r**2) / dof)
    JtJ = J.T @ J
    cov = s2 * np.linalg.inv(JtJ)
    scale = np.array([1, 1, 1, 180 / np.pi, 180 / np.pi, 180 / np.pi])
    return cov * np.outer(scale, scale), float(np.sqrt(s2)), r


# ---------------------------------------------------------------------------------------------
# result
# ---------------------------------------------------------------------------------------------
@dataclass
class ExtrinsicCalibration:
    """Result of :func:`calibrate_extrinsics` (poses in the paper's terms, :data:`POSE_NAMES`)."""

    intrinsics: Intrinsics
    T_ground_lidar: np.ndarray
    ground_source: str
    frames: list  # FrameData (all frames, in input order)
    frame_poses: list  # FramePose or None per frame
    frame_status: list  # "ok" or the reason the frame was not used
    pose: np.ndarray  # joint estimate (6,)
    rvec: np.ndarray
    tvec: np.ndarray
    rms_px: float
    per_frame: np.ndarray  # (n_used, 6)
    cov_per_frame: np.ndarray
    cov_bootstrap: np.ndarray | None
    cov_jacobian: np.ndarray
    cov_jacobian_frames: np.ndarray  # (n_used, 6, 6) each frame's own first-order covariance
    sigma_px: float
    n_bootstrap: int
    seed: int
    ambiguous_orientation: bool = False
    ground_plane: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    estimator: str = "joint"
    pose_joint: np.ndarray | None = None
    pose_mean: np.ndarray | None = None

    @property
    def used(self) -> list[int]:
        return [i for i, s in enumerate(self.frame_status) if s == "ok"]

    def sigmas(self, source: str = "per_frame") -> np.ndarray:
        """Standard deviations ``(6,)`` from ``per_frame``, ``bootstrap`` or ``jacobian``."""
        return np.sqrt(np.diag(self._cov(source)))

    def _cov(self, source):
        if source not in BUDGET_SOURCES:
            raise InputError("budget_from", source, f"one of {BUDGET_SOURCES}")
        cov = {"per_frame": self.cov_per_frame, "bootstrap": self.cov_bootstrap, "jacobian": self.cov_jacobian}[source]
        if cov is None:
            raise InputError("budget_from", source, "a computed variability (run with bootstrap > 0)")
        return cov

    def camera(self) -> OpenCVCamera:
        """The camera with the joint pose, in the ground frame."""

        R = cv2.Rodrigues(self.rvec)[0]
        T = self.T_ground_lidar
        R_cg = R @ T[:3, :3].T
        C_g = T[:3, :3] @ (-R.T @ self.tvec) + T[:3, 3]
        return OpenCVCamera(self.intrinsics.K, self.intrinsics.dist, R_cg, -R_cg @ C_g, self.intrinsics.image_size_px)

    def budget(self, source: str = "per_frame", *, correlations: bool = True, name: str = "extrinsics-lidar"):
        """The extrinsic part of the error budget as an :class:`ErrorBudget`."""
        cov = self._cov(source)
        s = np.sqrt(np.maximum(np.diag(cov), 0.0))
        d = {"name": name,
             "description": (f"extrinsic calibration against LiDAR, {len(self.used)} frames, sigmas from {source}; "
                             f"ground frame: {self.ground_source}"),
             "position_m": [float(s[0]), float(s[1])], "height_m": float(s[2]), "pan_deg": float(s[3]),
             "tilt_deg": float(s[4]), "roll_deg": float(s[5])}
        if correlations:
            c = 0.5 * (cov + cov.T)
            d["covariance"] = {"names": list(_BUDGET_COV_NAMES), "matrix": c.tolist()}
        return ErrorBudget.from_dict(d)

    def summary(self) -> dict:
        """JSON-ready summary: pose, the three variabilities side by side, per-frame table, failures."""

        truthy = {}
        for src in BUDGET_SOURCES:
            try:
                truthy[src] = dict(zip(POSE_NAMES, map(float, self.sigmas(src)), strict=True))
            except InputError:
                truthy[src] = None
        mean_frame_jac = np.sqrt(np.mean([np.diag(c) for c in self.cov_jacobian_frames], axis=0))
        n = len(self.used)
        frames = []
        k = 0
        for i, f in enumerate(self.frames):
            row = {"name": f.name, "status": self.frame_status[i], "cloud": f.cloud_stats, "lidar_board": f.detection}
            fp = self.frame_poses[i]
            if self.frame_status[i] == "ok":
                row.update(pose=dict(zip(POSE_NAMES, map(float, self.per_frame[k]), strict=True)),
                           rms_px=fp.rms_px, n_inliers=int(len(fp.inliers)), n_corners=int(len(fp.uv_px)),
                           method=fp.method, grid_placement=fp.candidate)
                k += 1
            frames.append(row)
        return {
            "n_frames": len(self.frames), "n_used": n,
            "pose": dict(zip(POSE_NAMES, map(float, self.pose), strict=True)), "estimator": self.estimator,
            "pose_joint": None if self.pose_joint is None else dict(zip(POSE_NAMES, map(float, self.pose_joint),
                                                                        strict=True)),
            "pose_mean_of_frames": None if self.pose_mean is None else dict(zip(POSE_NAMES, map(float, self.pose_mean),
                                                                                strict=True)),
            "reprojection_rms_px": self.rms_px, "residual_sigma_px": self.sigma_px,
            "sigma": truthy,
            "sigma_per_frame_jacobian_mean": dict(zip(POSE_NAMES, map(float, mean_frame_jac), strict=True)),
            "notes": {
                "per_frame": "spread of the single-frame poses (the paper's Table 3): uncertainty of a one-frame pose",
                "bootstrap": f"{self.n_bootstrap} resamples of the frames, seed {self.seed}: uncertainty of the "
                             f"{self.estimator} pose, including per-frame LiDAR board-fit errors",
                "jacobian": f"first order ({self.estimator} pose): s^2 (J^T J)^-1, assumes independent corner errors, "
                            "blind to errors shared by a frame's corners",
                "expected": "bootstrap ~ jacobian when pixel noise dominates; jacobian < bootstrap when LiDAR "
                            "board-fit errors matter.  The joint pose is usually far better than "
                            "per_frame / sqrt(n_used): one planar board leaves translation and rotation "
                            "strongly correlated, boards at several places break that.",
                "per_frame_over_sqrt_n": dict(zip(POSE_NAMES, map(float, self.sigmas('per_frame') / np.sqrt(n)),
                                                  strict=True)),
            },
            "correlation_per_frame": _corr(self.cov_per_frame).tolist(),
            "T_ground_lidar": self.T_ground_lidar.tolist(), "ground_frame": self.ground_source,
            "ground_plane": self.ground_plane,
            "rvec_lidar_to_camera": self.rvec.tolist(), "tvec_lidar_to_camera_m": self.tvec.tolist(),
            "R_lidar_to_camera": cv2.Rodrigues(self.rvec)[0].tolist(),
            "ambiguous_grid_orientation": self.ambiguous_orientation,
            "frames": frames, "warnings": list(self.warnings),
            "opencv_version": cv2.__version__,
        }

    def table(self) -> str:
        """Plain-text table of the three variabilities (like the paper's Table 3, plus roll)."""
        head = f"{'source':<22}" + "".join(f"{n:>12}" for n in POSE_NAMES)
        lines = [head]
        for src in BUDGET_SOURCES:
            try:
                s = self.sigmas(src)
            except InputError:
                continue
            lines.append(f"{'sigma ' + src:<22}" + "".join(f"{v:>12.5g}" for v in s))
        lines.append(f"{'pose (' + self.estimator + ')':<22}" + "".join(f"{v:>12.5g}" for v in self.pose))
        return "\n".join(lines)


def _corr(c):
    s = np.sqrt(np.maximum(np.diag(c), 1e-300))
    return c / np.outer(s, s)


_LM_CRIT = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-14)


def _ground_frame(T_ground_lidar, ground_plane, ground: str, warn_list: list) -> tuple[np.ndarray, str, dict]:
    """The LiDAR -> ground transform ``(T_gl (4, 4), its source in words, ground-plane info)``."""
    if T_ground_lidar is not None:
        return load_transform(T_ground_lidar), "given T_ground_lidar", {}
    if ground_plane is not None:
        plane_info = {"normal_lidar": ground_plane.normal.tolist(), "offset_m": float(ground_plane.offset_m),
                      "n_inliers": ground_plane.n_inliers, "rms_m": ground_plane.rms_m,
                      "lidar_height_m": float(abs(ground_plane.offset_m))}
        return (ground_frame_from_plane(ground_plane),
                "ground-plane fit of the scans (z up, origin below the LiDAR, x = LiDAR x projected)", plane_info)
    if ground == "identity":
        warn_list.append("ground frame = LiDAR frame: height_m is measured from the LiDAR origin, not the ground")
        return np.eye(4), "LiDAR frame (identity)", {}
    raise InputError("ground", ground, "a T_ground_lidar, a fitted ground plane (clouds), or 'identity'")


def _solve_frames(frames, intr, ransac_threshold_px: float, seed: int) -> tuple[list, list]:
    """Per frame, its status (``ok`` or why not) and its candidate poses (one per LiDAR corner ordering)."""
    status = []
    cands: list[list[FramePose]] = []
    for k, f in enumerate(frames):
        if not f.ok:
            status.append(f.reason)
            cands.append([])
            continue
        if f.uv_px is None or len(f.uv_px) < 6:
            status.append("fewer than 6 image corners")
            cands.append([])
            continue
        cs = []
        for ci, X in enumerate(f.xyz_candidates):
            if X.shape[0] != f.uv_px.shape[0]:
                raise InputError(f"frame {f.name}", f"{X.shape[0]} 3D vs {f.uv_px.shape[0]} 2D corners",
                                 "as many 3D as 2D corners (same board size)")
            fp = solve_frame(X, f.uv_px, intr, ransac_threshold_px=ransac_threshold_px, seed=seed + k, name=f.name,
                             candidate=ci)
            if fp is None or (len(f.xyz_candidates) > 1 and _camera_behind_board(fp)):
                continue
            cs.append(fp)
        cands.append(cs)
        status.append("ok" if cs else "PnP failed (no pose with >= 6 inliers in front of the camera)")
    return status, cands


def _screen_chosen(chosen, status: list, max_frame_rms_px: float | None) -> None:
    """Mark in ``status`` the frames without a consistent pose, or above ``max_frame_rms_px``."""
    for k, c in enumerate(chosen):
        if status[k] == "ok" and c is None:
            status[k] = "pose inconsistent with the other frames (outlier, or board misdetected in the cloud)"
        elif status[k] == "ok" and max_frame_rms_px is not None and c.rms_px > max_frame_rms_px:
            status[k] = f"reprojection RMS {c.rms_px:.3g} px > max_frame_rms_px {max_frame_rms_px:g}"


def _joint_refine(chosen, used: list, X_all, U_all, intr) -> tuple[np.ndarray, np.ndarray]:
    """Joint LM solution ``(rvec, tvec)`` over all used frames' inliers, from the best-supported frame pose."""
    best = None
    for k in used:
        rv, tv = cv2.solvePnPRefineLM(X_all, U_all, intr.K, intr.dist, chosen[k].rvec.copy().reshape(3, 1),
                                      chosen[k].tvec.copy().reshape(3, 1), _LM_CRIT)
        cost = float(np.sum(_reproj(rv, tv, X_all, U_all, intr) ** 2))
        if best is None or cost < best[0] - 1e-9:
            best = (cost, rv.ravel(), tv.ravel())
        if len(used) > 5 and k == used[2]:
            break  # three starts are plenty: they all converge to the same minimum
    return best[1], best[2]


def _bootstrap_cov(Xs, Us, per_frame, pose, rvec, tvec, T_gl, intr, *, estimator: str, bootstrap: int,
                   seed: int) -> np.ndarray:
    """(6, 6) covariance of the pose over ``bootstrap`` resamples of the used frames."""
    rng = np.random.default_rng(seed)
    samples = np.empty((int(bootstrap), 6))
    n = len(Xs)
    for b in range(int(bootstrap)):
        pick = rng.integers(0, n, n)
        if estimator == "mean":
            samples[b] = per_frame[pick].mean(axis=0)
            continue
        Xb = np.concatenate([Xs[i] for i in pick])
        Ub = np.concatenate([Us[i] for i in pick])
        rv, tv = cv2.solvePnPRefineLM(Xb, Ub, intr.K, intr.dist, rvec.copy().reshape(3, 1),
                                      tvec.copy().reshape(3, 1), _LM_CRIT)
        samples[b] = pose_in_ground(rv, tv, T_gl)
    samples[:, 3] = pose[3] + _wrap_deg(samples[:, 3] - pose[3])
    return np.cov(samples, rowvar=False, ddof=1)


@dataclass
class _PoseFit:
    """The pose of the used frames: joint and mean estimates, the reported one, and their covariances."""

    Xs: list               # per used frame, (n_k, 3) inlier LiDAR corners (m)
    Us: list               # per used frame, (n_k, 2) inlier image corners (px)
    pose: np.ndarray       # (6,) reported pose (x, y, z m; angles deg)
    rvec: np.ndarray       # (3,) OpenCV LiDAR -> camera rotation of ``pose``
    tvec: np.ndarray       # (3,) and translation (m)
    rms_px: float          # reprojection RMS of ``pose`` over all inliers
    per_frame: np.ndarray  # (n_used, 6) single-frame poses
    cov_pf: np.ndarray     # (6, 6) spread of the single-frame poses
    cov_j: np.ndarray      # (6, 6) first-order covariance of ``pose``
    cov_jf: np.ndarray     # (n_used, 6, 6) first-order covariance of each single-frame pose
    sigma_px: float        # pixel noise estimated from the residuals
    pose_joint: np.ndarray  # (6,)
    pose_mean: np.ndarray   # (6,)


def _fit_pose(chosen, used: list, T_gl, intr, estimator: str) -> _PoseFit:
    """Joint and mean poses over the ``used`` frames; the reported one per ``estimator``, with covariances."""
    Xs = [chosen[k].xyz_m[chosen[k].inliers] for k in used]
    Us = [chosen[k].uv_px[chosen[k].inliers] for k in used]
    X_all, U_all = np.concatenate(Xs), np.concatenate(Us)
    rvec_j, tvec_j = _joint_refine(chosen, used, X_all, U_all, intr)
    pose_joint = pose_in_ground(rvec_j, tvec_j, T_gl)
    per_frame = np.array([pose_in_ground(chosen[k].rvec, chosen[k].tvec, T_gl) for k in used])
    per_frame[:, 3] = pose_joint[3] + _wrap_deg(per_frame[:, 3] - pose_joint[3])
    pose_mean = per_frame.mean(axis=0)
    cov_pf = np.cov(per_frame, rowvar=False, ddof=1)
    cov_jf = np.array([jacobian_covariance(per_frame[i], transform_points(T_gl, Xk), Uk, intr)[0]
                       for i, (Xk, Uk) in enumerate(zip(Xs, Us, strict=True))])
    Xg_all = transform_points(T_gl, X_all)
    if estimator == "joint":
        pose, rvec, tvec = pose_joint, rvec_j, tvec_j
        cov_j, sigma_px, _ = jacobian_covariance(pose, Xg_all, U_all, intr)
    else:  # mean of the single-frame poses; first order: frames independent
        pose = pose_mean
        rvec, tvec = _rt_from_pose(pose, T_gl)
        _, sigma_px, _ = jacobian_covariance(pose, Xg_all, U_all, intr)
        cov_j = cov_jf.sum(axis=0) / len(used) ** 2
    rms_px = float(np.sqrt(np.mean(np.sum(_reproj(rvec, tvec, X_all, U_all, intr) ** 2, axis=1))))
    return _PoseFit(Xs, Us, pose, rvec, tvec, rms_px, per_frame, cov_pf, cov_j, cov_jf, sigma_px, pose_joint,
                    pose_mean)


def _failures(frames, status: list) -> list[str]:
    """``name: reason`` of each frame that is not ok."""
    return [f"{f.name}: {s}" for f, s in zip(frames, status, strict=True) if s != "ok"]


# ---------------------------------------------------------------------------------------------
# the pipeline
# ---------------------------------------------------------------------------------------------
def calibrate_extrinsics(frames, intrinsics, *, T_ground_lidar=None, ground: str = "fit", ground_plane=None,
                         ransac_threshold_px: float = 4.0, bootstrap: int = 200, seed: int = 0, min_frames: int = 3,
                         position_tol_m: float | None = None, angle_tol_deg: float = 10.0,
                         estimator: str = "joint", max_frame_rms_px: float | None = None) -> ExtrinsicCalibration:
    """Solve the camera pose against the LiDAR from frames of corner correspondences.

    Parameters
    ----------
    frames : list of FrameData
        From :func:`frames_from_pairs` or :func:`read_correspondences_csv`.  Frames
        with ``ok=False`` are carried along and reported.
    intrinsics : Intrinsics, Camera, calibration result or camera file
    T_ground_lidar : (4, 4), optional
        LiDAR -> ground frame.  Default: from ``ground_plane`` (a :class:`PlaneFit`
        in the LiDAR frame, see :func:`frames_from_pairs`), else ``ground="identity"``
        uses the LiDAR frame itself as the ground frame (heights then from the LiDAR origin).
    ransac_threshold_px : float
        RANSAC / inlier reprojection threshold.
    bootstrap : int
        Bootstrap resamples over frames (0: skip).
    seed : int
        Seeds RANSAC and the bootstrap.
    min_frames : int
        Frames needed (>= 2; a spread from fewer than 3 frames is meaningless).
    estimator : {"joint", "mean"}
        The reported pose: ``joint`` minimises the reprojection error of all corners
        of all frames at once (best when pixel noise dominates and the boards are
        spread over several places); ``mean`` averages the single-frame poses
        (more robust when the LiDAR's per-frame board-fit errors dominate, e.g. a
        few boards close to the camera, where the joint fit compromises between
        frames whose 3D corners disagree).  Both are in the summary; the bootstrap
        and first-order covariances follow the chosen one.
    max_frame_rms_px : float, optional
        Drop frames whose own reprojection RMS (after PnP) exceeds this, as the
        paper filters frames by reprojection error; they are reported.

    Raises
    ------
    InputError
        Fewer than ``min_frames`` usable frames (the message lists why frames failed).
    """

    intr = load_intrinsics(intrinsics)
    if estimator not in ("joint", "mean"):
        raise InputError("estimator", estimator, "'joint' or 'mean'")
    if min_frames < 2:
        raise InputError("min_frames", min_frames, "an integer >= 2")
    warn_list = []
    T_gl, gsrc, plane_info = _ground_frame(T_ground_lidar, ground_plane, ground, warn_list)
    status, cands = _solve_frames(frames, intr, ransac_threshold_px, seed)
    if sum(s == "ok" for s in status) < min_frames:
        bad = _failures(frames, status)
        raise InputError("frames", f"{sum(s == 'ok' for s in status)} usable of {len(frames)}",
                         f"at least {min_frames} frames with the board in both image and cloud "
                         f"(failures: {'; '.join(bad[:6])}{' ...' if len(bad) > 6 else ''})")
    chosen, ambiguous = resolve_orientation(cands, position_tol_m=position_tol_m, angle_tol_deg=angle_tol_deg)
    _screen_chosen(chosen, status, max_frame_rms_px)
    used = [k for k, s in enumerate(status) if s == "ok"]
    if len(used) < min_frames:
        bad = _failures(frames, status)
        raise InputError("frames", f"{len(used)} consistent of {len(frames)}",
                         f"at least {min_frames} frames giving one camera pose (failures: {'; '.join(bad[:6])})")
    if ambiguous and any(len(f.xyz_candidates) > 1 for f in frames):
        warn_list.append("grid orientation on the LiDAR rectangle decided without support from other frames")
    fit = _fit_pose(chosen, used, T_gl, intr, estimator)
    cov_bs = None
    if bootstrap and bootstrap > 0:
        cov_bs = _bootstrap_cov(fit.Xs, fit.Us, fit.per_frame, fit.pose, fit.rvec, fit.tvec, T_gl, intr,
                                estimator=estimator, bootstrap=bootstrap, seed=seed)
    poses_all = [c if status[k] == "ok" else None for k, c in enumerate(chosen)]
    for w in warn_list:
        warnings.warn(w, stacklevel=2)
    return ExtrinsicCalibration(intr, T_gl, gsrc, list(frames), poses_all, status, fit.pose, fit.rvec, fit.tvec,
                                fit.rms_px, fit.per_frame, fit.cov_pf, cov_bs, fit.cov_j, fit.cov_jf, fit.sigma_px,
                                int(bootstrap or 0), int(seed), bool(ambiguous), plane_info, warn_list, estimator,
                                fit.pose_joint, fit.pose_mean)


def _rt_from_pose(pose6, T_ground_lidar):
    """OpenCV LiDAR -> camera ``(rvec, tvec)`` from a pose in the paper's terms (inverse of pose_in_ground)."""

    T = np.asarray(T_ground_lidar, float)
    R_gc = R_W_C(*np.deg2rad(pose6[3:]))
    C_g = np.asarray(pose6[:3], float)
    R_cg = R_gc.T
    R_cl = R_cg @ T[:3, :3]
    t_cl = R_cg @ (T[:3, 3] - C_g)
    return cv2.Rodrigues(R_cl)[0].ravel(), t_cl


# ---------------------------------------------------------------------------------------------
# inputs
# ---------------------------------------------------------------------------------------------
_IMG = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
_CLOUD = (".pcd", ".ply", ".npy", ".csv")


def pairs_from_directory(directory) -> list[tuple[str, Path | None, Path | None]]:
    """``[(name, image_or_corners, cloud)]`` matched by file stem in a folder.

    The image side is an image file ``<stem>.<png|jpg|...>`` or a corners file
    ``<stem>_corners.csv`` (columns u, v; OpenCV corner order); the cloud side is
    ``<stem>.<pcd|ply|npy|csv>``.  A stem with only one side is listed with None
    for the other (reported as a failed frame, not dropped).
    """
    d = Path(directory)
    if not d.is_dir():
        raise InputError("pairs", str(d), "a folder of image/corners + point-cloud files, or a correspondences CSV")
    img, cloud = {}, {}
    for p in sorted(d.iterdir()):
        suf = p.suffix.lower()
        if p.name.endswith("_corners.csv"):
            img[p.name[:-len("_corners.csv")]] = p
        elif suf in _IMG:
            img.setdefault(p.stem, p)
        elif suf in _CLOUD:
            cloud[p.stem] = p
    names = sorted(set(img) | set(cloud))
    if not names:
        raise InputError("pairs", str(d), "image (or <stem>_corners.csv) and point-cloud files with matching stems")
    return [(n, img.get(n), cloud.get(n)) for n in names]


def _read_corners_csv(path: Path) -> np.ndarray:
    rows = []
    for i, ln in enumerate(read_input_text(path, "corners").splitlines(), 1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        toks = [t for t in s.replace(";", ",").replace(",", " ").split()]
        try:
            rows.append([float(t) for t in toks])
        except ValueError:
            if rows or i > 1:
                raise InputError(f"{path}: row {i}", s[:50], "two numbers u, v (px)") from None
            continue  # header
        if len(toks) != 2:
            raise InputError(f"{path}: row {i}", s[:50], "two numbers u, v (px)")
    return np.array(rows, dtype=np.float64).reshape(-1, 2)


def _read_clouds(pairs) -> tuple[list, list[str]]:
    """Each pair's point cloud (None if missing or unreadable) and the reason it cannot be used ("" if usable)."""
    clouds: list[PointCloud | None] = []
    reasons: list[str] = []
    for name, _, c in pairs:
        if c is None:
            clouds.append(None)
            reasons.append("no point cloud for this frame")
            continue
        try:
            cl = c if isinstance(c, PointCloud) else (read_point_cloud(c) if isinstance(c, (str, Path))
                                                      else PointCloud.from_arrays(c, source=name))
            clouds.append(cl)
            reasons.append("" if len(cl) else f"empty point cloud ({cl.n_nonfinite_dropped} non-finite points)")
        except InputError as e:
            clouds.append(None)
            reasons.append(f"unreadable point cloud: {e}")
    return clouds, reasons


def _corners_from_image_file(p: Path, board, detect_method, image_size_px) -> tuple[np.ndarray | None, str]:
    """Image corners ``(n, 2)`` px from a corners CSV or an image file, or ``(None, why not)``."""
    if p.name.endswith("_corners.csv") or p.suffix.lower() == ".csv":
        return _read_corners_csv(p), ""
    if file_kind(p) not in (None, "regular file"):  # OpenCV would wait on a FIFO for its writer
        return None, f"image {p.name} is a {file_kind(p)}, not a regular file"
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        return None, f"unreadable image {p.name}"
    if image_size_px is not None and (img.shape[1], img.shape[0]) != tuple(image_size_px):
        return None, f"image size {img.shape[1]}x{img.shape[0]} differs from the intrinsics {image_size_px}"
    uv, _ = detect_corners(img, board, method=detect_method)
    return uv, "" if uv is not None else "no board found in the image"


def _image_corners(im, board, detect_method, image_size_px) -> tuple[np.ndarray | None, str]:
    """A frame's image corners ``(n_corners, 2)`` px (from an array, corners CSV or image), or ``(None, why)``."""
    uv, why = None, ""
    if im is None:
        why = "no image or corners file for this frame"
    elif isinstance(im, np.ndarray) and im.ndim == 2 and im.shape[1] == 2:
        uv = np.asarray(im, float)
    else:
        try:
            uv, why = _corners_from_image_file(Path(im), board, detect_method, image_size_px)
        except InputError as e:
            why = str(e)
    if uv is not None and len(uv) != board.n_corners:
        why, uv = f"{len(uv)} image corners, expected {board.n_corners} ({board.label()})", None
    if uv is not None and not np.all(np.isfinite(uv)):
        why, uv = "non-finite image corners", None
    return uv, why


def frames_from_pairs(pairs, board, *, region=None, ground="fit", plane_threshold_m: float = 0.05,
                      cluster_radius_m: float = 0.2, ground_up=(0.0, 0.0, 1.0), seed: int = 0, detect_method="auto",
                      image_size_px=None):
    """Read (image or corners, cloud) pairs and build :class:`FrameData` (+ the ground plane).

    Parameters
    ----------
    pairs : folder, or list of (name, image_or_corners_or_array, cloud_path_or_PointCloud_or_array)
    board : Checkerboard or "14x9" (then square size and margin must be set on a Checkerboard)
    region : Box, Sphere or str, optional
        Search region for the board in every cloud (LiDAR frame).
    ground : "fit" | "none"
        "fit": fit the ground plane in the pooled clouds (used for the ground frame
        and to ignore ground points in the board search).
    image_size_px : (w, h), optional
        Check that detected images have this size.

    Returns
    -------
    frames : list of FrameData
        One per pair, failures included with their reason.
    ground_plane : PlaneFit or None
    """


    board = parse_board(board) if not isinstance(board, Checkerboard) else board
    if isinstance(pairs, (str, Path)):
        pairs = pairs_from_directory(pairs)
    region = parse_region(region)
    clouds, reasons = _read_clouds(pairs)
    plane = None
    if ground == "fit":
        good = [c for c in clouds if c is not None and len(c)]
        if good:
            plane = fit_ground_plane(good, up_hint=ground_up, seed=seed)
    elif ground not in ("none", None):
        raise InputError("ground", ground, "'fit' or 'none'")
    frames = []
    for k, ((name, im, _), cl) in enumerate(zip(pairs, clouds, strict=True)):
        stats = cl.stats() if cl is not None else {}
        uv, why = _image_corners(im, board, detect_method, image_size_px)
        also = f"; also: {why}" if why else ""
        if reasons[k]:
            frames.append(FrameData(name, uv, [], False, reasons[k] + also, stats))
            continue
        det = detect_board(cl, board, region=region, ground=plane, plane_threshold_m=plane_threshold_m,
                           cluster_radius_m=cluster_radius_m, seed=seed + k)
        if not det.found:
            frames.append(FrameData(name, uv, [], False, f"no board in the cloud: {det.reason}{also}", stats,
                                    det.to_dict()))
            continue
        if why:
            frames.append(FrameData(name, uv, det.corner_candidates(), False, why, stats, det.to_dict(),
                                    det.board_xyz_m))
            continue
        frames.append(FrameData(name, uv, det.corner_candidates(), True, "", stats, det.to_dict(), det.board_xyz_m))
    return frames, plane


def read_correspondences_csv(path) -> list[FrameData]:
    """Frames from a CSV with columns ``frame, X, Y, Z, u, v`` (header required; X, Y, Z in the LiDAR
    frame, metres; u, v in px).  Rows with a bad number are reported with their row number and their
    frame is marked unusable; the other frames go on."""
    p = Path(path)
    if not p.exists():
        raise InputError("correspondences", str(p), "an existing CSV file (frame, X, Y, Z, u, v)")
    lines = read_input_text(p, "correspondences").splitlines()
    header = None
    data: dict = {}
    bad: dict = {}
    order = []
    for i, ln in enumerate(lines, 1):
        s = ln.strip()
        if not s or s.startswith("#"):
            continue
        toks = [t.strip() for t in s.split(",")]
        if header is None:
            header = [t.lower() for t in toks]
            need = ["frame", "x", "y", "z", "u", "v"]
            if not all(n in header for n in need):
                raise InputError(f"{p}: header", s[:60], "columns frame, X, Y, Z, u, v")
            idx = [header.index(n) for n in need]
            continue
        if len(toks) != len(header):
            raise InputError(f"{p}: row {i}", s[:60], f"{len(header)} comma-separated values")
        fr = toks[idx[0]]
        if fr not in data:
            data[fr] = []
            order.append(fr)
        try:
            vals = [float(toks[j]) for j in idx[1:]]
            if not np.all(np.isfinite(vals)):
                raise ValueError
            data[fr].append(vals)
        except ValueError:
            bad.setdefault(fr, []).append(i)
    if header is None:
        raise InputError(str(p), "empty file", "a header frame,X,Y,Z,u,v and rows")
    frames = []
    for fr in order:
        a = np.array(data[fr], float).reshape(-1, 5)
        if fr in bad:
            frames.append(FrameData(str(fr), a[:, 3:], [a[:, :3]], False,
                                    f"non-numeric or non-finite values in rows {bad[fr][:5]}"))
        elif len(a) < 6:
            frames.append(FrameData(str(fr), a[:, 3:], [a[:, :3]], False, f"only {len(a)} correspondences (need >= 6)"))
        else:
            frames.append(FrameData(str(fr), a[:, 3:], [a[:, :3]]))
    return frames


def write_correspondences_csv(path, frames: list[FrameData], which: int = 0) -> Path:
    """Write frames (their candidate ``which``) as a ``frame,X,Y,Z,u,v`` CSV."""
    rows = ["frame,X,Y,Z,u,v"]
    for f in frames:
        if f.uv_px is None or not f.xyz_candidates:
            continue
        for (x, y, z), (u, v) in zip(f.xyz_candidates[which], f.uv_px, strict=True):
            rows.append(",".join([str(f.name)] + [repr(float(q)) for q in (x, y, z, u, v)]))

    atomic_write_text(path, "\n".join(rows) + "\n")
    return Path(path)


__all__.append("write_correspondences_csv")
