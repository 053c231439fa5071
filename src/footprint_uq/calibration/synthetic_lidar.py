"""Synthetic spinning-LiDAR scans of a checkerboard (and the ground), and the matching image corners.

For tests and for planning a calibration campaign.  The scanner is modelled like
the paper's Ouster OS1-128: ``n_beams`` beams spread evenly over a vertical field
of view (default 128 over 45 deg, +-22.5 deg), ``n_azimuth`` steps per turn (1024
or 2048), Gaussian range noise of ``range_noise_m`` along each ray (seeded).  The
scene is the ground plane ``z = 0`` of the world frame W, the board as a finite
rectangle (squares plus margins, see :class:`~.boards.Checkerboard`), optionally a
stand (a thin vertical strip from the ground to the board centre, just behind the
board) and optional walls (infinite planes).  Each ray returns its nearest hit;
rays that hit nothing return nothing (or NaN / (0, 0, 0), as real drivers do, with
``no_return=``).

Frames and poses
----------------
* ``T_world_lidar`` (4x4): LiDAR -> world W.
* ``T_world_board`` (4x4): board frame B (origin at the first inner corner, OpenCV
  object points, see :mod:`.boards`) -> world.
* the camera: a :class:`~footprint_uq.cameras.opencv.OpenCVCamera` (or any
  Camera) in W; :func:`image_corners` projects the true corners with the
  library's own camera model (distortion included) and adds seeded pixel noise,
  so these tests do not depend on an image renderer.

The default rig (:func:`default_rig`) is a camera and a LiDAR mounted side by side
on a vehicle roof, as in the paper; W is chosen so that it coincides with the ground
frame that :func:`~.lidar.ground_frame_from_plane` builds from the scans (origin
below the LiDAR, x along the LiDAR's x projected on the ground), so the poses
recovered by :mod:`.extrinsics` compare directly with the truth.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from ..cameras.opencv import OpenCVCamera
from ..cameras.rotation import R_W_C
from ..errors import InputError
from ..io import save_camera
from ..io.atomic import atomic_path, atomic_write_text
from .boards import PAPER_BOARD, Checkerboard
from .pointclouds import PointCloud, write_point_cloud

__all__ = ["SpinningLidar", "OS1_128", "default_rig", "simulate_scan", "image_corners", "board_corners_world",
           "sample_board_poses", "poses_from_camera", "LidarCampaign", "make_lidar_campaign", "rot_xyz"]


@dataclass(frozen=True)
class SpinningLidar:
    """A spinning multi-beam LiDAR.

    Parameters
    ----------
    n_beams : int
        Beams, evenly spaced in elevation over ``vfov_deg`` centred on the horizon.
    vfov_deg : float
        Vertical field of view, degrees.
    n_azimuth : int
        Azimuth steps per revolution.
    range_noise_m : float
        1-sigma Gaussian range noise along each ray, metres.
    min_range_m, max_range_m : float
    azimuth_window_deg : (float, float) or None
        Only simulate azimuths in this window (degrees, counter-clockwise from the
        LiDAR's +x), to save time; None: the full turn.
    """

    n_beams: int = 128
    vfov_deg: float = 45.0
    n_azimuth: int = 2048
    range_noise_m: float = 0.02
    min_range_m: float = 0.5
    max_range_m: float = 120.0
    azimuth_window_deg: tuple[float, float] | None = None

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Unit ray directions ``(n_beams * n_az, 3)`` in the LiDAR frame and their ring index."""
        el = np.deg2rad(np.linspace(self.vfov_deg / 2.0, -self.vfov_deg / 2.0, self.n_beams))
        az = np.arange(self.n_azimuth) * (2 * np.pi / self.n_azimuth)
        if self.azimuth_window_deg is not None:
            a0, a1 = np.deg2rad(self.azimuth_window_deg)
            rel = np.mod(az - a0, 2 * np.pi)
            az = az[rel <= np.mod(a1 - a0, 2 * np.pi)]
        E, A = np.meshgrid(el, az, indexing="ij")
        d = np.stack([np.cos(E) * np.cos(A), np.cos(E) * np.sin(A), np.sin(E)], -1).reshape(-1, 3)
        ring = np.repeat(np.arange(self.n_beams, dtype=np.uint16), len(az))
        return d, ring


#: the paper's LiDAR (Ouster OS1-128: 128 beams, 45 deg vertical field of view), 2048 azimuth steps, 2 cm noise
OS1_128 = SpinningLidar()


def rot_xyz(rx_deg=0.0, ry_deg=0.0, rz_deg=0.0) -> np.ndarray:
    """Rotation ``Rz @ Ry @ Rx`` (degrees) as a 3x3 matrix."""
    a, b, c = np.deg2rad([rx_deg, ry_deg, rz_deg])
    Rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    Ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    Rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def default_rig(*, lidar_height_m: float = 1.9, lidar_pitch_deg: float = 1.0, lidar_roll_deg: float = -0.5,
                camera_position_m=(0.15, -0.25), camera_height_m: float = 1.75, pan_deg: float = 91.0,
                tilt_deg: float = 4.0, roll_deg: float = 0.5, focal_px: float = 1400.0,
                image_size_px=(1920, 1200), dist=(-0.08, 0.05, 0.0005, -0.0003, 0.0), intrinsics=None):
    """A camera + LiDAR rig; returns ``(camera, T_world_lidar)``.

    ``intrinsics`` (anything with ``K``, ``dist`` and ``image_size_px``, e.g. a
    :class:`~footprint_uq.calibration.synthetic.SyntheticCamera`) replaces
    ``focal_px``/``image_size_px``/``dist``.

    The LiDAR sits at ``(0, 0, lidar_height_m)`` with zero yaw (its x axis projects
    onto the world +x, east) and small pitch/roll; the camera looks east-ish (pan
    ~90 deg).  W is then exactly the ground frame that the extrinsic pipeline
    derives from a ground-plane fit of the scans.
    """
    T = np.eye(4)
    T[:3, :3] = rot_xyz(lidar_roll_deg, lidar_pitch_deg, 0.0)
    T[:3, 3] = (0.0, 0.0, lidar_height_m)
    if intrinsics is not None:
        K = np.asarray(intrinsics.K, float)
        dist = np.asarray(intrinsics.dist, float).ravel()
        image_size_px = tuple(int(v) for v in intrinsics.image_size_px)
    else:
        w, h = image_size_px
        K = np.array([[focal_px, 0.0, (w - 1) / 2.0 + 3.0], [0.0, focal_px * 1.001, (h - 1) / 2.0 - 2.0], [0, 0, 1]])
    R_wc = R_W_C(np.deg2rad(pan_deg), np.deg2rad(tilt_deg), np.deg2rad(roll_deg))
    C = np.array([camera_position_m[0], camera_position_m[1], camera_height_m])
    cam = OpenCVCamera(K, np.asarray(dist, float), R_wc.T, -R_wc.T @ C, image_size_px)
    return cam, T


def poses_from_camera(camera, rvecs, tvecs) -> list:
    """Board poses ``T_world_board`` from board -> camera poses (OpenCV ``rvec``, ``tvec``; e.g. those of
    :func:`footprint_uq.calibration.synthetic.make_board_poses`) and the camera's pose in W, so that the
    LiDAR scans are taken at the same board poses as the synthetic images."""

    T_wc = camera.T_world_cam
    out = []
    for rv, tv in zip(np.asarray(rvecs, float).reshape(-1, 3), np.asarray(tvecs, float).reshape(-1, 3), strict=True):
        T_cb = np.eye(4)
        T_cb[:3, :3] = cv2.Rodrigues(rv)[0]
        T_cb[:3, 3] = tv
        out.append(T_wc @ T_cb)
    return out


def board_corners_world(board: Checkerboard, T_world_board) -> np.ndarray:
    """Inner corners ``(N, 3)`` of the board in the world, OpenCV order."""
    T = np.asarray(T_world_board, float)
    return board.object_points() @ T[:3, :3].T + T[:3, 3]


def _intersect_quad(o, d, centre, ax_u, ax_v, half_u, half_v):
    """Ray parameter of hits with a rectangle (centre, unit axes, half sizes); inf where missed."""
    n = np.cross(ax_u, ax_v)
    den = d @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((centre - o) @ n) / den
    p = o + t[:, None] * d - centre
    ok = (t > 0) & (np.abs(p @ ax_u) <= half_u) & (np.abs(p @ ax_v) <= half_v) & np.isfinite(t)
    return np.where(ok, t, np.inf)


def _stand_hits(o, d, centre, bx, by, ground_z_m) -> np.ndarray:
    """Ray distances ``(n_rays,)`` m to the board's stand (6 cm wide, 5 cm behind the board centre, down to
    the ground); inf where missed."""
    nb = np.cross(bx, by)
    nh = nb - nb[2] * np.array([0, 0, 1.0])
    if np.linalg.norm(nh) <= 1e-6:
        return np.full(d.shape[0], np.inf)
    nh /= np.linalg.norm(nh)
    if nh @ (centre - o) < 0:
        nh = -nh  # away from the LiDAR
    zt = centre[2]
    zb = 0.0 if ground_z_m is None else ground_z_m
    sc = centre + 0.05 * nh
    sc = np.array([sc[0], sc[1], (zt + zb) / 2.0])
    u = np.cross([0, 0, 1.0], nh)
    return _intersect_quad(o, d, sc, u / np.linalg.norm(u), np.array([0, 0, 1.0]), 0.03, max((zt - zb) / 2.0, 0.0))


def _plane_hits(o, d, p, n) -> np.ndarray:
    """Ray distances ``(n_rays,)`` m to the plane through ``p`` with normal ``n`` (inf: parallel or behind)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((p - o) @ n) / (d @ n)
    return np.where(t > 0, t, np.inf)


def _intensities(board: Checkerboard, TB, o, d, t, surf) -> np.ndarray:
    """Return intensity per ray: black squares 10, white 200, ground 60, stand 30, walls 90 (float32)."""
    s = board.square_m
    inten = np.zeros(surf.shape[0], np.float32)
    inten[surf == 2], inten[surf == 3], inten[surf == 4] = 60, 30, 90
    on_b = surf == 1
    if on_b.any():
        bx, by = TB[:3, 0], TB[:3, 1]
        pb = (o + t[on_b, None] * d[on_b]) - TB[:3, 3]
        xb, yb = pb @ bx, pb @ by
        i, j = np.floor(xb / s + 1.0), np.floor(yb / s + 1.0)
        in_sq = (i >= 0) & (i <= board.cols) & (j >= 0) & (j <= board.rows)
        black = in_sq & ((i + j) % 2 == 0)
        inten[on_b] = np.where(black, 10.0, 200.0)
    return inten


def simulate_scan(board: Checkerboard, T_world_board, T_world_lidar, *, scanner: SpinningLidar = OS1_128,
                  ground_z_m: float = 0.0, stand: bool = True, walls=(), seed=0, no_return: str = "drop",
                  with_board: bool = True) -> PointCloud:
    """One LiDAR scan of the scene, in the LiDAR frame.

    Parameters
    ----------
    board, T_world_board
        The target and its pose (board frame -> world).
    T_world_lidar : (4, 4)
    scanner : SpinningLidar
    ground_z_m : float or None
        Height of the ground plane in W (None: no ground).
    stand : bool
        Add a 6 cm wide vertical stand from the ground up to the board centre, 5 cm behind it.
    walls : sequence of (point_world (3,), normal_world (3,))
        Infinite planes (e.g. a building wall) to test the board search.
    seed : int or Generator
        Range-noise seed.
    no_return : {"drop", "nan", "zero"}
        What rays that hit nothing give: nothing, a NaN point or ``(0, 0, 0)``.
    with_board : bool
        False: the same scene without the board (a frame with no target).

    Returns
    -------
    PointCloud
        Fields ``ring`` (uint16), ``intensity`` (float32: black squares 10, white 200,
        ground 60, stand 30, walls 90) and ``surface`` (uint8: 0 none, 1 board,
        2 ground, 3 stand, 4 wall).
    """
    if no_return not in ("drop", "nan", "zero"):
        raise InputError("no_return", no_return, "drop, nan or zero")
    rng = np.random.default_rng(seed)
    TL = np.asarray(T_world_lidar, float)
    TB = np.asarray(T_world_board, float)
    dL, ring = scanner.rays()
    d = dL @ TL[:3, :3].T
    o = TL[:3, 3]
    n_r = d.shape[0]
    T_hit = np.full((5, n_r), np.inf)
    s, m = board.square_m, board.margin_m
    bx, by = TB[:3, 0], TB[:3, 1]
    x0, x1 = -(s + m), (board.cols - 1) * s + s + m
    y0, y1 = -(s + m), (board.rows - 1) * s + s + m
    centre = TB[:3, 3] + bx * (x0 + x1) / 2 + by * (y0 + y1) / 2
    if with_board:
        T_hit[1] = _intersect_quad(o, d, centre, bx, by, (x1 - x0) / 2, (y1 - y0) / 2)
    if ground_z_m is not None:
        T_hit[2] = _plane_hits(o, d, np.array([0.0, 0.0, ground_z_m]), np.array([0.0, 0.0, 1.0]))
    if stand and with_board:
        T_hit[3] = _stand_hits(o, d, centre, bx, by, ground_z_m)
    for pw, nw in walls:
        pw, nw = np.asarray(pw, float), np.asarray(nw, float) / np.linalg.norm(nw)
        T_hit[4] = np.minimum(T_hit[4], _plane_hits(o, d, pw, nw))
    surf = np.argmin(T_hit, axis=0)
    t = T_hit[surf, np.arange(n_r)]
    hit = np.isfinite(t) & (t >= scanner.min_range_m) & (t <= scanner.max_range_m)
    surf = np.where(hit, surf, 0).astype(np.uint8)
    r = np.where(hit, t, np.nan) + rng.normal(0.0, scanner.range_noise_m, n_r)
    xyz = dL * r[:, None]
    inten = _intensities(board, TB, o, d, t, surf)
    if no_return == "drop":
        keep = hit
        xyz, ring, inten, surf = xyz[keep], ring[keep], inten[keep], surf[keep]
    else:
        xyz[~hit] = np.nan if no_return == "nan" else 0.0
    return PointCloud.from_arrays(xyz, {"ring": ring, "intensity": inten, "surface": surf}, source="<synthetic>")


def image_corners(camera, board: Checkerboard, T_world_board, *, sigma_px: float = 0.0, seed=0):
    """Projected inner corners ``(N, 2)`` (px, with seeded Gaussian noise ``sigma_px`` per axis) and a flag
    telling whether every corner is in front of the camera and inside the image."""
    xyz = board_corners_world(board, T_world_board)
    pr = camera.project(xyz)
    uv = pr.uv_px + np.random.default_rng(seed).normal(0.0, sigma_px, pr.uv_px.shape)
    ok = bool(np.all(pr.valid) and np.all(camera.in_image(pr.uv_px)))
    return uv, ok


def sample_board_poses(camera, board: Checkerboard, n: int, *, T_world_lidar=None, scanner: SpinningLidar = OS1_128,
                       distance_m=(3.0, 8.0), max_yaw_deg: float = 35.0, max_pitch_deg: float = 25.0,
                       max_roll_deg: float = 15.0, min_board_points: int = 300, seed=0, max_tries: int = 5000):
    """``n`` board poses ``T_world_board`` (4x4) seen whole by the camera (and by the LiDAR, if given).

    Board centres are drawn along camera rays through the central 80 % of the image
    at distances in ``distance_m``; the board faces the camera (upright: its x along
    the image rows) turned by up to ``max_yaw_deg``/``max_pitch_deg``/``max_roll_deg``;
    the board's bottom stays >= 0.2 m above the ground.  With ``T_world_lidar`` a pose
    is kept only when a noise-free scan puts at least ``min_board_points`` on it.
    """
    rng = np.random.default_rng(seed)
    w, h = camera.image_size_px
    Kinv = np.linalg.inv(camera.K)
    R_wc = camera.R_world_cam
    C = camera.position_world_m
    out = []
    s = board.square_m
    c_b = np.array([(board.cols - 1) * s / 2, (board.rows - 1) * s / 2, 0.0])
    quiet = SpinningLidar(scanner.n_beams, scanner.vfov_deg, scanner.n_azimuth, 0.0, scanner.min_range_m,
                          scanner.max_range_m, scanner.azimuth_window_deg)
    for _ in range(max_tries):
        if len(out) == n:
            break
        uv = np.array([rng.uniform(0.1, 0.9) * w, rng.uniform(0.1, 0.9) * h, 1.0])
        ray = R_wc @ (Kinv @ uv)
        ray /= np.linalg.norm(ray)
        centre = C + rng.uniform(*distance_m) * ray
        R_cb = rot_xyz(rng.uniform(-max_pitch_deg, max_pitch_deg), rng.uniform(-max_yaw_deg, max_yaw_deg),
                       rng.uniform(-max_roll_deg, max_roll_deg))
        R_wb = R_wc @ R_cb
        T = np.eye(4)
        T[:3, :3] = R_wb
        T[:3, 3] = centre - R_wb @ c_b
        corners_outer = board.outline(include_margin=True, n_per_edge=2) @ R_wb.T + T[:3, 3]
        if corners_outer[:, 2].min() < 0.2:
            continue
        uvc, ok = image_corners(camera, board, T)
        if not ok:
            continue
        if T_world_lidar is not None:
            sc = simulate_scan(board, T, T_world_lidar, scanner=quiet, stand=False, ground_z_m=None)
            if int((sc.fields["surface"] == 1).sum()) < min_board_points:
                continue
        out.append(T)
    if len(out) < n:
        raise InputError("board poses", f"{len(out)} found in {max_tries} tries",
                         f"{n} poses seen whole by the camera (and the LiDAR); widen distance_m or the angles")
    return out


@dataclass
class LidarCampaign:
    """A synthetic extrinsic-calibration campaign (truth + data).

    ``clouds[k]`` is the scan (LiDAR frame) and ``corners_px[k]`` the noisy image
    corners (OpenCV order) of frame k; ``corners_lidar_true[k]`` the exact 3D
    corners in the LiDAR frame; ``T_ground_lidar`` the truth (= ``inv(T_world_lidar)``
    composed with nothing: W is the ground frame).
    """

    camera: OpenCVCamera
    T_world_lidar: np.ndarray
    board: Checkerboard
    scanner: SpinningLidar
    poses: list
    clouds: list
    corners_px: list
    corners_lidar_true: list
    sigma_px: float
    seed: int
    names: list = field(default_factory=list)

    @property
    def truth(self) -> dict:
        """The camera pose in the paper's terms: x_m, y_m, height_m, pan_deg, tilt_deg, roll_deg."""
        c = self.camera
        x, y = c.position_world_m[:2]
        return {"x_m": float(x), "y_m": float(y), "height_m": c.height_m, "pan_deg": c.pan_deg,
                "tilt_deg": c.tilt_deg, "roll_deg": c.roll_deg}

    def correspondences(self):
        """``(frames, X (M, 3) LiDAR frame, uv (M, 2))`` built from the TRUE 3D corners (no LiDAR fit error)."""
        fr = np.concatenate([np.full(len(u), k) for k, u in enumerate(self.corners_px)])
        return fr, np.concatenate(self.corners_lidar_true), np.concatenate(self.corners_px)

    def write(self, directory, *, cloud_format: str = ".pcd", **writer_kw) -> Path:
        """Write ``frame_XXX.<fmt>`` clouds and ``frame_XXX_corners.csv`` (u, v) files, plus
        ``camera_intrinsics.yaml`` (the true intrinsics; pose = truth) and ``truth.json``."""


        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        for k, (cl, uv) in enumerate(zip(self.clouds, self.corners_px, strict=True)):
            name = self.names[k] if self.names else f"frame_{k:03d}"
            write_point_cloud(d / f"{name}{cloud_format}", cl.xyz_m,
                              {"intensity": cl.fields["intensity"], "ring": cl.fields["ring"]}
                              if cloud_format in (".pcd", ".ply") else None, **writer_kw)
            with atomic_path(d / f"{name}_corners.csv") as tmp:
                np.savetxt(tmp, uv, delimiter=",", header="u,v", comments="", fmt="%.6f")
        save_camera(self.camera, d / "camera.yaml")
        atomic_write_text(d / "truth.json", json.dumps({"camera_pose": self.truth, "T_world_lidar":
                                                        self.T_world_lidar.tolist(), "sigma_px": self.sigma_px,
                                                        "range_noise_m": self.scanner.range_noise_m}, indent=2))
        return d


def make_lidar_campaign(n_frames: int = 12, *, camera=None, T_world_lidar=None, board: Checkerboard = PAPER_BOARD,
                        scanner: SpinningLidar | None = None, sigma_px: float = 0.3, seed: int = 0, poses=None,
                        stand: bool = True, walls=(), pose_seed: int | None = None, **pose_kw) -> LidarCampaign:
    """A synthetic campaign: board poses, LiDAR scans and noisy image corners, all seeded.

    ``poses`` (list of ``T_world_board``) reuses given board poses (e.g. those of the
    synthetic camera images); otherwise they are drawn by :func:`sample_board_poses`
    with ``pose_seed`` (default: ``seed``) so that repeated campaigns can keep the poses
    and redraw only the noise.
    """
    if camera is None or T_world_lidar is None:
        cam0, TL0 = default_rig()
        camera = cam0 if camera is None else camera
        T_world_lidar = TL0 if T_world_lidar is None else T_world_lidar
    if scanner is None:
        scanner = SpinningLidar(azimuth_window_deg=(-80.0, 80.0))
    if poses is None:
        poses = sample_board_poses(camera, board, n_frames, T_world_lidar=T_world_lidar, scanner=scanner,
                                   seed=seed if pose_seed is None else pose_seed, **pose_kw)
    rng = np.random.default_rng(seed)
    TL = np.asarray(T_world_lidar, float)
    T_lw = np.linalg.inv(TL)
    clouds, uvs, true3 = [], [], []
    for T in poses:
        clouds.append(simulate_scan(board, T, TL, scanner=scanner, stand=stand, walls=walls, seed=rng))
        uv, _ = image_corners(camera, board, T, sigma_px=sigma_px, seed=rng)
        uvs.append(uv)
        true3.append(board_corners_world(board, T) @ T_lw[:3, :3].T + T_lw[:3, 3])
    return LidarCampaign(camera, TL, board, scanner, list(poses), clouds, uvs, true3, float(sigma_px), int(seed))
