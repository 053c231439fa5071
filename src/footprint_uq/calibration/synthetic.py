"""Synthetic checkerboard campaigns with exact ground truth.

For tests, and for users planning a calibration campaign ("how many board poses,
where, for which error sizes?").

* :class:`SyntheticCamera` -- intrinsics and OpenCV distortion (k1, k2, p1, p2, k3);
  :data:`DEFAULT_CAMERA` resembles the paper's Basler ace 2 with a 3.5 mm
  low-distortion lens (1920x1200 px, f = 1015 px); ``.scaled(s)`` gives a
  smaller sensor with the same field of view for fast tests.
* :func:`make_board_poses` -- a campaign of board poses covering the image:
  target image positions stratified over a grid (corners of the image
  included), distances chosen so that the board fills a given fraction of the
  image width, tilts of 10..``max_tilt_deg`` degrees about a random in-plane
  axis (Zhang's method needs non-parallel views) and a small in-plane rotation;
  every pose keeps the whole printed pattern inside the image.
* :func:`project_corners` -- the exact image positions of the inner corners
  (``cv2.projectPoints``, the same lens model).
* :func:`render_board` -- a grey image of the board: every pixel is split into
  ``supersample x supersample`` sub-pixels, each sub-pixel centre is
  **inverse-mapped** through the lens (Newton undistortion to 1e-14) and the
  pinhole onto the board plane, and the square colour there is averaged.  The
  edges of the squares therefore pass exactly through the projected corners
  (up to the sub-pixel quantisation of the box filter), so the projected
  corners are the ground truth of the rendered image.  Optical blur (Gaussian,
  ``blur_sigma_px``) and sensor noise (Gaussian, ``noise_sigma_dn`` grey levels,
  then 8-bit quantisation) are added afterwards.
* :func:`noisy_corners` -- the fast path for statistics: exact corners plus
  independent Gaussian noise of a known size per coordinate.
* :func:`simulate_campaigns` -- a planning study: the error sizes (the paper's
  Table 2) that ``n_views`` boards with a given corner noise deliver, as the
  scatter over repeated campaigns next to OpenCV's and the bootstrap's estimates.

Board frame and corner order: see :mod:`footprint_uq.calibration.boards`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numba
import numpy as np

from .._checks import as_float
from ..errors import InputError
from ..io.atomic import atomic_path, atomic_write_text
from .boards import PAPER_BOARD, Checkerboard, parse_board
from .intrinsics import INTRINSIC_NAMES, calibrate_corners, paper_sigmas

__all__ = ["SyntheticCamera", "DEFAULT_CAMERA", "make_board_poses", "project_corners", "render_board",
           "noisy_corners", "render_campaign", "write_campaign", "simulate_campaigns"]


@dataclass(frozen=True)
class SyntheticCamera:
    """Intrinsics of a synthetic camera (pixels; distortion k1, k2, p1, p2, k3)."""

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    image_size_px: tuple[int, int]
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        for name in ("fx_px", "fy_px"):
            as_float(name, getattr(self, name), positive=True)
        for name in ("cx_px", "cy_px"):
            as_float(name, getattr(self, name))
        d = np.asarray(self.dist, dtype=np.float64).ravel()
        if d.size != 5 or not np.all(np.isfinite(d)):
            raise InputError("dist", self.dist, "5 finite coefficients (k1, k2, p1, p2, k3)")
        w, h = self.image_size_px
        if int(w) <= 0 or int(h) <= 0:
            raise InputError("image_size_px", self.image_size_px, "(width, height) > 0")

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, dtype=np.float64)

    @property
    def values(self) -> np.ndarray:
        """(fx, fy, cx, cy, k1, k2, p1, p2, k3), the order of :data:`INTRINSIC_NAMES`."""
        return np.array([self.fx_px, self.fy_px, self.cx_px, self.cy_px, *self.dist])

    def scaled(self, factor: float) -> SyntheticCamera:
        """Same field of view and lens on a sensor ``factor`` times the size (pixel centres kept consistent)."""
        s = as_float("factor", factor, positive=True)
        w, h = self.image_size_px
        return SyntheticCamera(self.fx_px * s, self.fy_px * s, (self.cx_px + 0.5) * s - 0.5,
                               (self.cy_px + 0.5) * s - 0.5, (int(round(w * s)), int(round(h * s))), self.dist)


#: resembles the paper's Basler ace 2 with a 3.5 mm low-distortion lens
DEFAULT_CAMERA = SyntheticCamera(1015.0, 1015.0, 962.3, 597.8, (1920, 1200), (-0.12, 0.05, 5e-4, -3e-4, -0.01))


def _rodrigues(R):

    return cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0].ravel()


def _rot(axis, angle):

    a = np.asarray(axis, dtype=np.float64)
    return cv2.Rodrigues(a / np.linalg.norm(a) * angle)[0]


def project_corners(camera: SyntheticCamera, board, rvec, tvec, points_m=None) -> np.ndarray:
    """Exact image positions (N, 2), px, of the board's inner corners (or of ``points_m`` (N, 3), board frame)."""

    board = parse_board(board)
    obj = board.object_points() if points_m is None else np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    pts = cv2.projectPoints(obj, np.asarray(rvec, dtype=np.float64).reshape(3),
                            np.asarray(tvec, dtype=np.float64).reshape(3), camera.K, camera.dist_array)[0]
    return pts.reshape(-1, 2)


def _render_margin(board: Checkerboard) -> float:
    return board.margin_m if board.margin_m > 0 else 0.5 * board.square_m


def _pose_ok(camera, board, rvec, tvec, margin_px, max_view_deg) -> bool:

    R = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))[0]
    e = board.square_m + _render_margin(board)
    s = board.square_m
    ol = Checkerboard(board.cols, board.rows, s, e - s).outline(include_margin=True, n_per_edge=12)
    Xc = ol @ R.T + tvec
    if np.any(Xc[:, 2] <= 0.05):
        return False
    centre = np.array([(board.cols - 1) * s / 2, (board.rows - 1) * s / 2, 0.0])
    c = R @ centre + tvec
    cosang = abs(R[:, 2] @ c) / np.linalg.norm(c)
    if np.degrees(np.arccos(min(1.0, cosang))) > max_view_deg:
        return False
    # the lens model is only trusted inside the image: check the undistorted footprint too
    uv = project_corners(camera, board, rvec, tvec, ol)
    w, h = camera.image_size_px
    return bool(np.all((uv[:, 0] >= margin_px) & (uv[:, 0] <= w - 1 - margin_px)
                       & (uv[:, 1] >= margin_px) & (uv[:, 1] <= h - 1 - margin_px)))


def _board_rotation(c_cam, roll_rad: float, tilt_rad: float, phi_rad: float) -> np.ndarray:
    """Board -> camera rotation (3, 3): facing the camera along the line of sight to ``c_cam``, rolled
    in-plane by ``roll_rad``, then tilted out of plane by ``tilt_rad`` about the in-plane axis at ``phi_rad``."""
    z = c_cam / np.linalg.norm(c_cam)
    x = np.cross([0.0, 1.0, 0.0], z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R0 = np.stack([x, y, z], axis=1)
    R = _rot(R0[:, 2], roll_rad) @ R0
    return _rot(np.cos(phi_rad) * R[:, 0] + np.sin(phi_rad) * R[:, 1], tilt_rad) @ R


def make_board_poses(camera: SyntheticCamera = DEFAULT_CAMERA, board=PAPER_BOARD, n: int = 20, *,
                     fill: tuple[float, float] = (0.3, 0.55), min_tilt_deg: float = 10.0, max_tilt_deg: float = 40.0,
                     max_roll_deg: float = 15.0, margin_px: float = 8.0, max_view_deg: float = 70.0,
                     seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A campaign of board poses covering the image.

    Parameters
    ----------
    camera : SyntheticCamera
    board : Checkerboard or str
    n : int
        Number of poses (>= 3).
    fill : (float, float)
        Range of the board's apparent width as a fraction of the image width
        (sets the distance).
    min_tilt_deg, max_tilt_deg : float
        Range of the board's tilt out of the fronto-parallel orientation.
    max_roll_deg : float
        Range of the in-plane rotation.
    margin_px : float
        Keep the whole printed pattern (squares and white margin) this far inside the image.
    max_view_deg : float
        Largest angle between the board normal and the line of sight.
    seed : int

    Returns
    -------
    rvecs, tvecs : ndarray (n, 3)
        Board -> camera poses (OpenCV: ``x_cam = R(rvec) x_board + tvec``), metres.

    Raises
    ------
    InputError
        When no valid pose is found for a target position (board too large for the image).
    """

    board = parse_board(board)
    n = int(n)
    if n < 3:
        raise InputError("n", n, "at least 3 poses")
    lo, hi = (float(v) for v in fill)
    if not (0 < lo <= hi < 1):
        raise InputError("fill", fill, "0 < min <= max < 1 (fraction of the image width)")
    rng = np.random.default_rng(seed)
    w, h = camera.image_size_px
    nu = max(2, int(round(np.sqrt(n * w / h))))
    nv = max(2, int(np.ceil(n / nu)))
    cells = [(i, j) for j in range(nv) for i in range(nu)]
    order = rng.permutation(len(cells))
    s = board.square_m
    width_m = (board.cols + 1) * s + 2 * _render_margin(board)
    centre_b = np.array([(board.cols - 1) * s / 2, (board.rows - 1) * s / 2, 0.0])
    rv, tv = [], []
    for k in range(n):
        ci, cj = cells[order[k % len(cells)]]
        for attempt in range(200):
            shrink = 1.0 - min(attempt, 150) / 200.0  # move the target towards the centre if it keeps failing
            u = w / 2 + ((ci + rng.uniform(0.1, 0.9)) / nu - 0.5) * w * shrink
            v = h / 2 + ((cj + rng.uniform(0.1, 0.9)) / nv - 0.5) * h * shrink
            frac = rng.uniform(lo, hi) * (1.0 if attempt < 100 else 0.7)
            depth = camera.fx_px * width_m / (frac * w)
            ray = cv2.undistortPoints(np.array([[[u, v]]], dtype=np.float64), camera.K, camera.dist_array).ravel()
            c_cam = np.array([ray[0], ray[1], 1.0]) * depth
            tilt = np.radians(rng.uniform(min_tilt_deg, max_tilt_deg))
            phi = rng.uniform(0, 2 * np.pi)
            roll = np.radians(rng.uniform(-max_roll_deg, max_roll_deg))
            R = _board_rotation(c_cam, roll, tilt, phi)
            t = c_cam - R @ centre_b
            r = _rodrigues(R)
            if _pose_ok(camera, board, r, t, margin_px, max_view_deg):
                rv.append(r)
                tv.append(t)
                break
        else:
            raise InputError("board", f"{board.label()} board, square {board.square_m} m",
                             f"a board that fits the {w}x{h} image at fill {fill} (no valid pose for pose {k})")
    return np.array(rv), np.array(tv)


# ------------------------------------------------------------------------------------------ rendering
@numba.njit(parallel=True, cache=True)
def _render_kernel(out, K, dist, R, t, s, cols, rows, margin, ss, shades):  # pragma: no cover - compiled
    h, w = out.shape
    fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    nx, ny, nz = R[0, 2], R[1, 2], R[2, 2]
    nt = nx * t[0] + ny * t[1] + nz * t[2]
    black, white, bg = shades[0], shades[1], shades[2]
    x_lo, x_hi = -s, cols * s
    y_lo, y_hi = -s, rows * s
    for row in numba.prange(h):
        for col in range(w):
            out[row, col] = 0.0
        for a in range(ss):
            vd = row - 0.5 + (a + 0.5) / ss
            yd = (vd - cy) / fy
            x, y = -cx / fx, yd  # warm start: the previous sub-pixel's solution along the sub-row
            for col in range(w):
                for b in range(ss):
                    ud = col - 0.5 + (b + 0.5) / ss
                    xd = (ud - cx) / fx
                    ok = False
                    for _ in range(50):
                        r2 = x * x + y * y
                        rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
                        drad = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2)
                        fxr = x * rad + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x) - xd
                        fyr = y * rad + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y - yd
                        j11 = rad + 2.0 * x * x * drad + 2.0 * p1 * y + 6.0 * p2 * x
                        j12 = 2.0 * x * y * drad + 2.0 * p1 * x + 2.0 * p2 * y
                        j22 = rad + 2.0 * y * y * drad + 6.0 * p1 * y + 2.0 * p2 * x
                        det = j11 * j22 - j12 * j12
                        if not det > 0.0:
                            break
                        sx = (j22 * fxr - j12 * fyr) / det
                        sy = (-j12 * fxr + j11 * fyr) / det
                        x -= sx
                        y -= sy
                        if abs(sx) < 1e-14 and abs(sy) < 1e-14:
                            ok = True
                            break
                    val = bg
                    if not ok:  # restart from the distorted point for the next sub-pixel
                        x, y = xd, yd
                    else:
                        den = nx * x + ny * y + nz
                        if den != 0.0:
                            lam = nt / den
                            if lam > 0.0:
                                px, py, pz = lam * x - t[0], lam * y - t[1], lam - t[2]
                                bx = R[0, 0] * px + R[1, 0] * py + R[2, 0] * pz
                                by = R[0, 1] * px + R[1, 1] * py + R[2, 1] * pz
                                if x_lo <= bx < x_hi and y_lo <= by < y_hi:
                                    i = int(np.floor(bx / s)) + 1
                                    j = int(np.floor(by / s)) + 1
                                    val = black if (i + j) % 2 == 0 else white
                                elif x_lo - margin <= bx < x_hi + margin and y_lo - margin <= by < y_hi + margin:
                                    val = white
                    out[row, col] += val / (ss * ss)



def render_board(camera: SyntheticCamera, board, rvec, tvec, *, supersample: int = 4, blur_sigma_px: float = 0.6,
                 noise_sigma_dn: float = 2.0, black_dn: float = 30.0, white_dn: float = 220.0,
                 background_dn: float = 110.0, seed=None) -> tuple[np.ndarray, np.ndarray]:
    """Render one 8-bit grey image of the board and return it with the exact corner positions.

    Parameters
    ----------
    camera : SyntheticCamera
    board : Checkerboard or str
        Rendered with its white margin (``margin_m``; half a square when 0, so that
        the detector sees a quiet zone around the squares).
    rvec, tvec : array_like (3,)
        Board -> camera pose.
    supersample : int
        Sub-pixels per pixel side (box filter).
    blur_sigma_px : float
        Gaussian optical blur, px (0: none).
    noise_sigma_dn : float
        Gaussian sensor noise, grey levels (0: none), before 8-bit quantisation.
    black_dn, white_dn, background_dn : float
        Grey levels of the black squares, white squares and margin, and the background.
    seed : int or numpy Generator, optional
        Noise seed.

    Returns
    -------
    image : ndarray (H, W) uint8
    corners_px : ndarray (N, 2)
        Exact corner positions (ground truth), px, in the board's corner order.
    """

    board = parse_board(board)
    ss = int(supersample)
    if ss < 1:
        raise InputError("supersample", supersample, "an integer >= 1")
    blur = as_float("blur_sigma_px", blur_sigma_px, nonnegative=True)
    noise = as_float("noise_sigma_dn", noise_sigma_dn, nonnegative=True)
    R = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3))[0]
    t = np.asarray(tvec, dtype=np.float64).reshape(3)
    w, h = camera.image_size_px
    img = np.empty((int(h), int(w)), dtype=np.float64)
    _render_kernel(img, camera.K, camera.dist_array, np.ascontiguousarray(R), t, float(board.square_m), int(board.cols),
              int(board.rows), float(_render_margin(board)), ss,
              np.array([black_dn, white_dn, background_dn], dtype=np.float64))
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur, borderType=cv2.BORDER_REPLICATE)
    if noise > 0:
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        img = img + rng.normal(0.0, noise, img.shape)
    img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return img, project_corners(camera, board, rvec, tvec)


def noisy_corners(camera: SyntheticCamera, board, rvecs, tvecs, corner_noise_px: float, *, seed=None) -> list:
    """Exact corners of every pose plus independent Gaussian noise (px, per coordinate)."""
    sig = as_float("corner_noise_px", corner_noise_px, nonnegative=True)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    out = []
    for rv, tv in zip(rvecs, tvecs, strict=True):
        c = project_corners(camera, board, rv, tv)
        out.append(c + rng.normal(0.0, sig, c.shape))
    return out


def render_campaign(camera: SyntheticCamera = DEFAULT_CAMERA, board=PAPER_BOARD, n: int = 20, *, seed: int = 0,
                    pose_kw: dict | None = None, progress=None,
                    **render_kw) -> tuple[list, list, np.ndarray, np.ndarray]:
    """Poses from :func:`make_board_poses` and one rendered image per pose (``progress(done, n)`` after each).

    Returns
    -------
    images : list of ndarray (H, W) uint8
    corners_px : list of ndarray (N, 2)
        Ground truth.
    rvecs, tvecs : ndarray (n, 3)
    """
    rvecs, tvecs = make_board_poses(camera, board, n, seed=seed, **(pose_kw or {}))
    rng = np.random.default_rng(seed + 1)
    images, corners = [], []
    for rv, tv in zip(rvecs, tvecs, strict=True):
        im, c = render_board(camera, board, rv, tv, seed=rng, **render_kw)
        images.append(im)
        corners.append(c)
        if progress is not None:
            progress(len(images), len(rvecs))
    return images, corners, rvecs, tvecs


def write_campaign(out_dir, camera: SyntheticCamera = DEFAULT_CAMERA, board=PAPER_BOARD, n: int = 20, *,
                   seed: int = 0, pose_kw: dict | None = None, progress=None, **render_kw) -> Path:
    """Render a campaign into ``out_dir`` (``board_000.png``...) with ``truth.json`` (camera, board, poses, corners);
    ``progress(done, n)`` after each image is rendered."""

    board = parse_board(board)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    images, corners, rvecs, tvecs = render_campaign(camera, board, n, seed=seed, pose_kw=pose_kw, progress=progress,
                                                    **render_kw)
    names = []
    for k, im in enumerate(images):
        name = f"board_{k:03d}.png"
        with atomic_path(out / name) as tmp:
            cv2.imwrite(str(tmp), im)
        names.append(name)
    truth = {"camera": {"K": camera.K.tolist(), "dist": list(camera.dist), "image_size_px": list(camera.image_size_px)},
             "board": {"inner_corners": [board.cols, board.rows], "square_m": board.square_m,
                       "margin_m": board.margin_m},
             "seed": seed, "render": {k: v for k, v in render_kw.items() if isinstance(v, (int, float))},
             "frames": [{"image": nm, "rvec": rv.tolist(), "tvec": tv.tolist(), "corners_px": c.tolist()}
                        for nm, rv, tv, c in zip(names, rvecs, tvecs, corners, strict=True)]}
    atomic_write_text(out / "truth.json", json.dumps(truth, indent=1))
    return out


def simulate_campaigns(camera: SyntheticCamera = DEFAULT_CAMERA, board=PAPER_BOARD, n_views: int = 20, *,
                       corner_noise_px: float = 0.1, n_campaigns: int = 50, bootstrap: int = 0, seed: int = 0,
                       pose_kw: dict | None = None, progress=None) -> dict:
    """Planning study: the intrinsic error sizes a campaign of ``n_views`` boards delivers (``progress(done,
    n_campaigns)`` after each campaign).

    One set of poses (:func:`make_board_poses`), ``n_campaigns`` repetitions of
    independent Gaussian corner noise (``corner_noise_px`` per coordinate, the fast
    path without rendering), one calibration each.

    Returns
    -------
    dict
        ``truth`` (9,), ``mean`` (9,) of the estimates, ``scatter`` (9,) their standard
        deviation over campaigns (the true error size), ``opencv`` (9,) the RMS of
        OpenCV's reported standard deviations, ``bootstrap`` (9,) the bootstrap
        standard deviation of the first campaign (when ``bootstrap`` > 1), and
        ``paper`` -- the paper's Table-2 row for each of ``scatter``, ``opencv``,
        ``bootstrap``.  Arrays follow :data:`~footprint_uq.calibration.INTRINSIC_NAMES`.
    """

    board = parse_board(board)
    m = int(n_campaigns)
    if m < 2:
        raise InputError("n_campaigns", n_campaigns, "an integer >= 2")
    rvecs, tvecs = make_board_poses(camera, board, n_views, seed=seed, **(pose_kw or {}))
    rng = np.random.default_rng(seed + 1)
    vals, stds, boot = [], [], None
    for k in range(m):
        cs = noisy_corners(camera, board, rvecs, tvecs, corner_noise_px, seed=rng)
        cal = calibrate_corners(cs, board, camera.image_size_px, bootstrap=bootstrap if k == 0 else 0, seed=seed)
        vals.append(cal.values)
        stds.append(cal.std_opencv)
        if k == 0 and cal.bootstrap is not None and len(cal.bootstrap.samples) > 1:
            boot = cal.bootstrap.std
        if progress is not None:
            progress(k + 1, m)
    vals, stds = np.array(vals), np.array(stds)
    out = {"names": list(INTRINSIC_NAMES), "truth": camera.values, "mean": vals.mean(0),
           "scatter": vals.std(0, ddof=1), "opencv": np.sqrt(np.mean(stds**2, 0)), "n_views": int(n_views),
           "n_campaigns": m, "corner_noise_px": float(corner_noise_px)}
    out["paper"] = {"scatter": paper_sigmas(out["scatter"]), "opencv": paper_sigmas(out["opencv"])}
    if boot is not None:
        out["bootstrap"] = boot
        out["paper"]["bootstrap"] = paper_sigmas(boot)
    return out
