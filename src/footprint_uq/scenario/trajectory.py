"""A vehicle driving a left turn through an :class:`~footprint_uq.scenario.intersection.Intersection`.

The path of the vehicle's reference point (the centre of its 3-D box, projected on the
ground) is *straight entry lane -> circular arc -> straight exit lane*: continuous
position and heading (tangent to the path), piecewise-constant curvature.  The arc is
tangent to the centre lines of the entry and exit lanes; by default its radius is the
largest one that keeps the whole arc inside the intersection box, so the vehicle
leaves the entry lane at the box edge (just past the stop line) and joins the exit lane
at the opposite box edge.

Frames are sampled at a fixed rate ``frame_rate_hz``.  The paper's case study gives no
speed.  With ``turn_speed_mps`` the vehicle follows a **speed profile**: it approaches at
``speed_mps``, brakes at ``accel_mps2`` so as to enter the arc at ``turn_speed_mps``, keeps
that speed through the turn and accelerates back to ``speed_mps`` on the exit lane.  The
case study's default is 8 m/s (29 km/h) on the straights and 4.5 m/s through the turn at
2 m/s^2: 2.3 m/s^2 lateral on the default 8.75 m arc, a normal urban left turn.  Without
``turn_speed_mps`` the speed is constant.

Boxes follow the project's 3-D box layout ``(N, 7)``: centre x, y, z (W, metres),
length, width, height (metres), yaw (radians, counter-clockwise from +x east, i.e. the
direction the vehicle's nose points).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._checks import as_float
from ..errors import ConfigError, InputError
from .intersection import Intersection, arm_direction, cfg_float, left_of

__all__ = ["Vehicle", "LeftTurnPath", "Trajectory", "left_turn_path", "sample_trajectory", "speed_profile",
           "box_corners", "segment_labels", "SEGMENTS"]

#: segment codes: 0 entry straight, 1 turn, 2 exit straight
SEGMENTS = ("entry", "turn", "exit")


@dataclass(frozen=True)
class Vehicle:
    """A vehicle's 3-D box dimensions (metres); default: a mid-size car."""

    length_m: float = 4.8
    width_m: float = 1.9
    height_m: float = 1.5

    def __post_init__(self):
        for k in ("length_m", "width_m", "height_m"):
            cfg_float(f"vehicle.{k}", getattr(self, k), positive=True)

    @classmethod
    def from_dict(cls, d: dict | None) -> Vehicle:
        d = dict(d or {})
        unknown = sorted(set(d) - set(cls.__dataclass_fields__))
        if unknown:
            raise ConfigError(f"vehicle.{unknown[0]}", d[unknown[0]], f"one of {sorted(cls.__dataclass_fields__)}")
        return cls(**{k: float(v) for k, v in d.items()})

    def to_dict(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class LeftTurnPath:
    """Straight -> arc -> straight, parametrised by arc length ``s`` (metres).

    Attributes
    ----------
    start_m : (2,) first point of the entry straight
    entry_dir : (2,) unit travel direction on the entry lane
    exit_dir : (2,) unit travel direction on the exit lane (entry_dir turned 90 deg left)
    arc_centre_m : (2,) centre of the turning arc
    radius_m : float
    lead_in_m, lead_out_m : float  lengths of the straights
    """

    start_m: np.ndarray
    entry_dir: np.ndarray
    exit_dir: np.ndarray
    arc_centre_m: np.ndarray
    radius_m: float
    lead_in_m: float
    lead_out_m: float

    @property
    def arc_length_m(self) -> float:
        return 0.5 * np.pi * self.radius_m

    @property
    def length_m(self) -> float:
        return self.lead_in_m + self.arc_length_m + self.lead_out_m

    @property
    def breakpoints_m(self) -> tuple[float, float]:
        """Arc length where the turn starts and ends."""
        return self.lead_in_m, self.lead_in_m + self.arc_length_m

    def pose(self, s_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position ``(..., 2)``, yaw ``(...)`` (rad, ccw from +x) and segment code ``(...)`` at ``s_m``."""
        s = np.asarray(s_m, dtype=np.float64)
        if np.any(~np.isfinite(s)) or np.any(s < 0) or np.any(s > self.length_m + 1e-9):
            raise InputError("s_m", s_m, f"arc lengths in [0, {self.length_m:.3f}] m")
        s0, s1 = self.breakpoints_m
        d, b = self.entry_dir, self.exit_dir
        arc_start = self.start_m + s0 * d
        # entry straight
        p_entry = self.start_m + s[..., None] * d
        # arc: angle from the centre, ccw (left turn)
        phi0 = np.arctan2(arc_start[1] - self.arc_centre_m[1], arc_start[0] - self.arc_centre_m[0])
        phi = phi0 + np.clip(s - s0, 0.0, self.arc_length_m)[..., None] / self.radius_m
        p_arc = self.arc_centre_m + self.radius_m * np.concatenate([np.cos(phi), np.sin(phi)], -1)
        arc_end = self.arc_centre_m + self.radius_m * np.array([np.cos(phi0 + np.pi / 2), np.sin(phi0 + np.pi / 2)])
        p_exit = arc_end + np.clip(s - s1, 0.0, None)[..., None] * b
        seg = np.where(s < s0, 0, np.where(s <= s1, 1, 2)).astype(np.int8)
        xy = np.where((seg == 0)[..., None], p_entry, np.where((seg == 1)[..., None], p_arc, p_exit))
        yaw_in = np.arctan2(d[1], d[0])
        yaw = np.where(seg == 0, yaw_in, np.where(seg == 1, yaw_in + (s - s0) / self.radius_m, yaw_in + np.pi / 2))
        yaw = (yaw + np.pi) % (2 * np.pi) - np.pi
        return xy, yaw, seg

    def to_dict(self) -> dict:
        return {"start_m": self.start_m.tolist(), "entry_dir": self.entry_dir.tolist(),
                "exit_dir": self.exit_dir.tolist(), "arc_centre_m": self.arc_centre_m.tolist(),
                "radius_m": self.radius_m, "lead_in_m": self.lead_in_m, "lead_out_m": self.lead_out_m}


def left_turn_path(intersection: Intersection, *, approach: str = "south", entry_lane: int = 0,
                   exit_lane: int = 0, lead_in_m: float = 35.0, lead_out_m: float = 35.0,
                   turn_radius_m: float | None = None) -> LeftTurnPath:
    """The left turn from the ``approach`` arm into the arm on the driver's left.

    Parameters
    ----------
    intersection : Intersection
    approach : str
        Arm the vehicle comes from (``"south"``: it drives north, then turns west).
    entry_lane, exit_lane : int
        Lane index (0 = next to the centre line).
    lead_in_m, lead_out_m : float
        Length of the straight before and after the arc, metres.
    turn_radius_m : float, optional
        Arc radius; default: the largest that keeps the arc inside the intersection box.

    Returns
    -------
    LeftTurnPath
    """
    lead_in = as_float("lead_in_m", lead_in_m, nonnegative=True)
    lead_out = as_float("lead_out_m", lead_out_m, nonnegative=True)
    p_in, d = intersection.lane_centre_line(approach, entry_lane, incoming=True)
    exit_arm = _arm_name(left_of(d))
    p_out, b = intersection.lane_centre_line(exit_arm, exit_lane, incoming=False)
    # corner Q where the two lane centre lines cross: p_in + t d = p_out + u b
    A = np.stack([d, -b], 1)
    t, _ = np.linalg.solve(A, p_out - p_in)
    Q = p_in + t * d
    h = intersection.half_width_m
    r_max = min(float(Q @ d) + h, h - float(Q @ b))
    if turn_radius_m is None:
        R = r_max
    else:
        R = as_float("turn_radius_m", turn_radius_m, positive=True)
    if not R > 0:
        raise ConfigError("turn_radius_m", R, "a radius > 0 (check the lane indices)")
    arc_start = Q - R * d
    centre = arc_start + R * left_of(d)
    start = arc_start - lead_in * d
    return LeftTurnPath(start, d, b, centre, float(R), lead_in, lead_out)


def _arm_name(v) -> str:
    for name in ("north", "south", "east", "west"):
        if np.allclose(arm_direction(name), v):
            return name
    raise ConfigError("direction", v, "an axis-aligned direction")  # pragma: no cover


@dataclass
class Trajectory:
    """Sampled vehicle states.

    Attributes
    ----------
    t_s : (N,) timestamps, seconds
    s_m : (N,) arc length along the path, metres
    boxes_world : (N, 7) centre x, y, z, length, width, height, yaw (rad ccw from +x)
    segment : (N,) int8, 0 entry / 1 turn / 2 exit (:data:`SEGMENTS`)
    speed_mps : (N,) speed of each frame, m/s
    """

    t_s: np.ndarray
    s_m: np.ndarray
    boxes_world: np.ndarray
    segment: np.ndarray
    speed_mps: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.t_s.shape[0])


def speed_profile(path: LeftTurnPath, s_m, *, speed_mps: float, turn_speed_mps: float | None = None,
                  accel_mps2: float = 2.0) -> np.ndarray:
    """Speed ``(...)`` (m/s) at arc lengths ``s_m``: cruise, brake to the turn speed, turn, accelerate.

    ``v(s) = min(speed_mps, sqrt(turn_speed_mps^2 + 2 accel_mps2 dist))`` with ``dist`` the
    distance to the arc (before it) or from it (after it); ``turn_speed_mps`` on the arc.
    Constant ``speed_mps`` when ``turn_speed_mps`` is None.
    """
    v = as_float("speed_mps", speed_mps, positive=True)
    s = np.asarray(s_m, dtype=np.float64)
    if turn_speed_mps is None:
        return np.full(s.shape, v)
    vt = as_float("turn_speed_mps", turn_speed_mps, positive=True)
    a = as_float("accel_mps2", accel_mps2, positive=True)
    s0, s1 = path.breakpoints_m
    dist = np.where(s < s0, s0 - s, np.where(s > s1, s - s1, 0.0))
    return np.minimum(max(v, vt), np.sqrt(vt * vt + 2.0 * a * dist))


def sample_trajectory(path: LeftTurnPath, vehicle: Vehicle = Vehicle(), *, speed_mps: float = 8.0,
                      frame_rate_hz: float = 10.0, t0_s: float = 0.0, ground_z_m: float = 0.0,
                      turn_speed_mps: float | None = None, accel_mps2: float = 2.0) -> Trajectory:
    """Frames at ``frame_rate_hz`` of a vehicle driving ``path``.

    Parameters
    ----------
    speed_mps : float
        Speed on the straights (the whole path if ``turn_speed_mps`` is None), m/s.
    turn_speed_mps : float, optional
        Speed through the arc; the vehicle brakes before it and accelerates after it at
        ``accel_mps2`` (:func:`speed_profile`).
    accel_mps2 : float
        Braking and acceleration, m/s^2.

    The last frame is the last one whose arc length does not exceed the path length.
    """
    v = as_float("speed_mps", speed_mps, positive=True)
    fr = as_float("frame_rate_hz", frame_rate_hz, positive=True)
    if turn_speed_mps is None:
        n = int(np.floor(path.length_m / v * fr + 1e-9)) + 1
        if n > 100_000:
            raise ConfigError("frame_rate_hz", fr, f"a rate giving at most 100000 frames (got {n})")
        t = np.arange(n) / fr
        s = np.minimum(t * v, path.length_m)
        speed = np.full(n, v)
    else:
        # time along the path: t(s) = integral ds / v(s), on a 1 cm grid, then inverted
        grid = np.linspace(0.0, path.length_m, max(2, int(np.ceil(path.length_m / 0.01)) + 1))
        vg = speed_profile(path, grid, speed_mps=v, turn_speed_mps=turn_speed_mps, accel_mps2=accel_mps2)
        tg = np.concatenate([[0.0], np.cumsum(np.diff(grid) * 0.5 * (1.0 / vg[1:] + 1.0 / vg[:-1]))])
        n = int(np.floor(tg[-1] * fr + 1e-9)) + 1
        if n > 100_000:
            raise ConfigError("frame_rate_hz", fr, f"a rate giving at most 100000 frames (got {n})")
        t = np.arange(n) / fr
        s = np.minimum(np.interp(t, tg, grid), path.length_m)
        speed = speed_profile(path, s, speed_mps=v, turn_speed_mps=turn_speed_mps, accel_mps2=accel_mps2)
    xy, yaw, seg = path.pose(s)
    N = t.shape[0]
    boxes = np.column_stack([xy, np.full(N, ground_z_m + vehicle.height_m / 2), np.full(N, vehicle.length_m),
                             np.full(N, vehicle.width_m), np.full(N, vehicle.height_m), yaw])
    return Trajectory(t + t0_s, s, boxes, seg, speed)


def box_corners(boxes) -> np.ndarray:
    """The 8 corners ``(..., 8, 3)`` of 3-D boxes ``(..., 7)``.

    Order: the bottom face counter-clockwise seen from above starting rear-right --
    (-l/2, -w/2), (+l/2, -w/2), (+l/2, +w/2), (-l/2, +w/2) in the box frame (x forward, y
    left), the order of :func:`footprint_uq.products.footprints.box3d_bottom_corners` -- then the top
    face in the same order.  Corners 0-3 are the footprint.
    """
    b = np.asarray(boxes, dtype=np.float64)
    if b.ndim == 0 or b.shape[-1] != 7:
        raise InputError("boxes", getattr(b, "shape", b), "an array of shape (..., 7)")
    hl, hw, hh = b[..., 3] / 2, b[..., 4] / 2, b[..., 5] / 2
    lon = np.array([-1.0, 1.0, 1.0, -1.0])
    lat = np.array([-1.0, -1.0, 1.0, 1.0])
    c, s = np.cos(b[..., 6])[..., None], np.sin(b[..., 6])[..., None]
    dx = lon * hl[..., None]
    dy = lat * hw[..., None]
    x = b[..., 0:1] + c * dx - s * dy
    y = b[..., 1:2] + s * dx + c * dy
    zb = np.broadcast_to(b[..., 2:3] - hh[..., None], x.shape)
    zt = np.broadcast_to(b[..., 2:3] + hh[..., None], x.shape)
    bottom = np.stack([x, y, zb], -1)
    top = np.stack([x, y, zt], -1)
    return np.concatenate([bottom, top], -2)


def segment_labels(yaw_rad, tol_deg: float = 3.0) -> np.ndarray:
    """Entry / turn / exit codes ``(N,)`` from a heading sequence (for recordings without labels).

    Entry: heading within ``tol_deg`` of the first frame's heading; exit: within ``tol_deg``
    of the last frame's and after the last entry frame; turn: between.
    """
    y = np.unwrap(np.asarray(yaw_rad, dtype=np.float64))
    if y.ndim != 1 or y.size == 0:
        raise InputError("yaw_rad", getattr(y, "shape", y), "a non-empty 1-D array")
    tol = np.deg2rad(tol_deg)
    seg = np.ones(y.shape, dtype=np.int8)
    near_start = np.abs(y - y[0]) <= tol
    near_end = np.abs(y - y[-1]) <= tol
    # entry: the initial run near the start heading; exit: the final run near the end heading
    first_off = np.argmax(~near_start) if np.any(~near_start) else y.size
    seg[:first_off] = 0
    last_off = y.size - 1 - np.argmax(~near_end[::-1]) if np.any(~near_end) else -1
    seg[last_off + 1:] = 2
    return seg
