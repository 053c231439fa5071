"""Road geometry of a four-way intersection, in the world frame W (x east, y north, z up).

Two straight roads cross at the origin: a north-south road along the y axis and an
east-west road along the x axis.  Each road has ``lanes_per_direction`` lanes in each
direction, ``lane_width_m`` wide, right-hand traffic (as in CARLA's towns and in the
US): a vehicle driving north uses the lanes east of the centre line.

Everything is plain geometry that the figures can draw and any camera can project:

* road surfaces: polygons ``(N, 2)`` (the cross-shaped paved area);
* markings: :class:`Marking` polylines ``(N, 2)`` -- road edges (solid white), the
  centre line (solid yellow), lane lines between lanes of one direction (dashed white)
  and stop lines across the incoming lanes of every arm (solid white);
* lane centres: :meth:`Intersection.lane_centre_line` gives a point and the travel
  direction of any lane, which :mod:`footprint_uq.scenario.trajectory` uses to build paths.

Arms are named after the compass direction they extend to from the centre:
``"north"`` (the road part with y > 0 on the north-south road), ``"south"``, ``"east"``,
``"west"``.  A vehicle "approaching from the south" drives north on the south arm.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from .._checks import as_float
from ..errors import ConfigError, InputError

__all__ = ["ARMS", "Marking", "RoadLayout", "Intersection", "arm_direction", "left_of", "right_of"]

#: unit vectors (x east, y north) from the centre along each arm
ARMS: dict[str, tuple[float, float]] = {
    "north": (0.0, 1.0), "south": (0.0, -1.0), "east": (1.0, 0.0), "west": (-1.0, 0.0),
}


def cfg_float(name: str, value, **kw) -> float:
    """:func:`footprint_uq._checks.as_float` for settings: raises :class:`ConfigError`."""
    try:
        return as_float(name, value, **kw)
    except ConfigError:
        raise
    except InputError as e:
        raise ConfigError(e.field, e.value, e.expected) from None


def arm_direction(arm: str) -> np.ndarray:
    """Unit vector ``(2,)`` from the intersection centre outwards along ``arm``."""
    try:
        return np.array(ARMS[str(arm).lower()])
    except KeyError:
        raise ConfigError("arm", arm, f"one of {list(ARMS)}") from None


def left_of(d) -> np.ndarray:
    """``d`` rotated 90 deg counter-clockwise (to the driver's left), shape ``(..., 2)``."""
    d = np.asarray(d, dtype=np.float64)
    return np.stack([-d[..., 1], d[..., 0]], -1)


def right_of(d) -> np.ndarray:
    """``d`` rotated 90 deg clockwise (to the driver's right), shape ``(..., 2)``."""
    d = np.asarray(d, dtype=np.float64)
    return np.stack([d[..., 1], -d[..., 0]], -1)


@dataclass(frozen=True)
class Marking:
    """A painted line on the road.

    Attributes
    ----------
    kind : str
        ``"edge"``, ``"centre"``, ``"lane"`` or ``"stop"``.
    xy_world_m : ndarray (N, 2)
        Polyline vertices in W, metres.
    dashed : bool
        Dashed (lane lines) or solid.
    width_m : float
        Painted width, metres (for drawing).
    """

    kind: str
    xy_world_m: np.ndarray
    dashed: bool = False
    width_m: float = 0.15

    def to_dict(self) -> dict:
        return {"kind": self.kind, "xy_world_m": np.asarray(self.xy_world_m).tolist(), "dashed": self.dashed,
                "width_m": self.width_m}

    @classmethod
    def from_dict(cls, d: dict) -> Marking:
        xy = np.asarray(d["xy_world_m"], dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2 or xy.shape[0] < 2:
            raise ConfigError("marking.xy_world_m", f"shape {xy.shape}", "a polyline of shape (N >= 2, 2)")
        return cls(str(d.get("kind", "lane")), xy, bool(d.get("dashed", False)), float(d.get("width_m", 0.15)))


@dataclass
class RoadLayout:
    """What the figures draw: paved polygons, painted markings and the lane width.

    Produced by :meth:`Intersection.layout` for the synthetic scene, or read from a
    recording (:mod:`footprint_uq.integrations.carla.bridge`) for a CARLA map.
    """

    road_polygons: list = field(default_factory=list)
    markings: list = field(default_factory=list)
    lane_width_m: float = 3.5
    #: optional: the intersection box (x_min, y_min, x_max, y_max), metres
    junction_box_m: tuple | None = None

    def bounds(self, margin_m: float = 0.0) -> tuple[float, float, float, float]:
        """``(x_min, y_min, x_max, y_max)`` of every polygon and marking, plus ``margin_m``."""
        pts = [np.asarray(p) for p in self.road_polygons] + [m.xy_world_m for m in self.markings]
        if not pts:
            return (-margin_m, -margin_m, margin_m, margin_m)
        a = np.concatenate(pts, 0)
        return (float(a[:, 0].min() - margin_m), float(a[:, 1].min() - margin_m),
                float(a[:, 0].max() + margin_m), float(a[:, 1].max() + margin_m))

    def to_dict(self) -> dict:
        return {"road_polygons": [np.asarray(p).tolist() for p in self.road_polygons],
                "markings": [m.to_dict() for m in self.markings], "lane_width_m": self.lane_width_m,
                "junction_box_m": None if self.junction_box_m is None else list(self.junction_box_m)}

    @classmethod
    def from_dict(cls, d: dict) -> RoadLayout:
        polys = []
        for i, p in enumerate(d.get("road_polygons", [])):
            a = np.asarray(p, dtype=np.float64)
            if a.ndim != 2 or a.shape[1] != 2 or a.shape[0] < 3:
                raise ConfigError(f"road_polygons[{i}]", f"shape {a.shape}", "a polygon of shape (N >= 3, 2)")
            polys.append(a)
        jb = d.get("junction_box_m")
        return cls(polys, [Marking.from_dict(m) for m in d.get("markings", [])],
                   cfg_float("lane_width_m", d.get("lane_width_m", 3.5), positive=True),
                   None if jb is None else tuple(float(v) for v in jb))


@dataclass(frozen=True)
class Intersection:
    """A four-way intersection of two straight roads (see the module docstring).

    Parameters
    ----------
    lanes_per_direction : int
        Lanes in each direction on both roads (>= 1).
    lane_width_m : float
        Lane width, metres (default 3.5).
    arm_length_m : float
        Length of each road arm beyond the intersection box, metres.
    stop_line_setback_m : float
        Distance of the stop lines before the intersection box, metres.
    curb_radius_m : float
        Radius of the rounded corners of the paved area (0: square corners).
    """

    lanes_per_direction: int = 2
    lane_width_m: float = 3.5
    arm_length_m: float = 45.0
    stop_line_setback_m: float = 1.5
    curb_radius_m: float = 4.0

    def __post_init__(self):
        n = self.lanes_per_direction
        if not isinstance(n, int | np.integer) or isinstance(n, bool) or n < 1:
            raise ConfigError("lanes_per_direction", n, "an integer >= 1")
        cfg_float("lane_width_m", self.lane_width_m, positive=True)
        cfg_float("arm_length_m", self.arm_length_m, positive=True)
        cfg_float("stop_line_setback_m", self.stop_line_setback_m, nonnegative=True)
        cfg_float("curb_radius_m", self.curb_radius_m, nonnegative=True)

    @classmethod
    def from_dict(cls, d: dict | None) -> Intersection:
        d = dict(d or {})
        allowed = {f for f in cls.__dataclass_fields__}
        unknown = sorted(set(d) - allowed)
        if unknown:
            raise ConfigError(f"intersection.{unknown[0]}", d[unknown[0]], f"one of {sorted(allowed)}")
        if "lanes_per_direction" in d:
            v = d["lanes_per_direction"]
            if isinstance(v, float) and v.is_integer():
                d["lanes_per_direction"] = int(v)
        return cls(**d)

    def to_dict(self) -> dict:
        return asdict(self)

    # -- dimensions ----------------------------------------------------------------------
    @property
    def half_width_m(self) -> float:
        """Half the paved width of each road (= half the side of the intersection box)."""
        return self.lanes_per_direction * self.lane_width_m

    @property
    def extent_m(self) -> float:
        """Distance from the centre to the end of each arm."""
        return self.half_width_m + self.arm_length_m

    @property
    def junction_box_m(self) -> tuple[float, float, float, float]:
        h = self.half_width_m
        return (-h, -h, h, h)

    # -- lanes -----------------------------------------------------------------------------
    def lane_centre_line(self, arm: str, lane: int, incoming: bool) -> tuple[np.ndarray, np.ndarray]:
        """A point on the centre line of a lane and its travel direction.

        Parameters
        ----------
        arm : str
            ``"north"``, ``"south"``, ``"east"`` or ``"west"``.
        lane : int
            0 is the lane next to the centre line, ``lanes_per_direction - 1`` the kerb lane.
        incoming : bool
            True: the lane that drives towards the intersection; False: away from it.

        Returns
        -------
        point_m, direction : ndarray (2,), ndarray (2,)
            ``point_m`` is where the lane centre line meets the edge of the intersection box.
        """
        if not isinstance(lane, int | np.integer) or not 0 <= lane < self.lanes_per_direction:
            raise ConfigError("lane", lane, f"an integer in [0, {self.lanes_per_direction - 1}]")
        a = arm_direction(arm)
        d = -a if incoming else a
        offset = (lane + 0.5) * self.lane_width_m
        point = self.half_width_m * a + offset * right_of(d)
        return point, d

    # -- drawing geometry ----------------------------------------------------------------------
    def road_polygon(self, n_arc: int = 8) -> np.ndarray:
        """The cross-shaped paved area ``(N, 2)``, counter-clockwise, with rounded kerb corners."""
        h, L, r = self.half_width_m, self.extent_m, self.curb_radius_m
        pts: list = []
        arm_ends = {(1, 1): [(L, -h), (L, h)], (-1, 1): [(h, L), (-h, L)],
                    (-1, -1): [(-L, h), (-L, -h)], (1, -1): [(-h, -L), (h, -L)]}
        for (sx, sy), reverse in (((1, 1), False), ((-1, 1), True), ((-1, -1), False), ((1, -1), True)):
            pts.extend(arm_ends[(sx, sy)])
            a = np.array([sx * (h + r), sy * h])
            b = np.array([sx * h, sy * (h + r)])
            p0, p1 = (b, a) if reverse else (a, b)
            if r == 0:
                pts.append(p0)
                continue
            c = np.array([sx * (h + r), sy * (h + r)])
            a0 = np.arctan2(p0[1] - c[1], p0[0] - c[0])
            a1 = np.arctan2(p1[1] - c[1], p1[0] - c[0])
            da = (a1 - a0 + np.pi) % (2 * np.pi) - np.pi
            ang = a0 + da * np.linspace(0.0, 1.0, n_arc + 1)
            pts.extend(c + r * np.stack([np.cos(ang), np.sin(ang)], -1))
        return np.array(pts, dtype=np.float64)

    def markings(self, dash_m: float = 3.0, gap_m: float = 6.0) -> list[Marking]:
        """Road edges, centre lines, dashed lane lines and stop lines (no markings inside the box)."""
        h, L, w, n = self.half_width_m, self.extent_m, self.lane_width_m, self.lanes_per_direction
        out: list[Marking] = []
        for arm in ARMS:
            a = arm_direction(arm)
            lat = left_of(a)  # across the arm
            p_in, p_out = h * a, L * a
            # centre line (yellow) and road edges
            out.append(Marking("centre", np.stack([p_in, p_out]), False, 0.3))
            for s in (-1.0, 1.0):
                off = s * h * lat
                out.append(Marking("edge", np.stack([p_in + off + self.curb_radius_m * a, p_out + off])))
            # dashed lane lines between lanes of one direction
            for k in range(1, n):
                for s in (-1.0, 1.0):
                    off = s * k * w * lat
                    out.append(Marking("lane", np.stack([p_in + off, p_out + off]), True, 0.15))
            # stop line across the incoming lanes (right of the incoming direction -a)
            d_in = -a
            q = (h + self.stop_line_setback_m) * a
            out.append(Marking("stop", np.stack([q, q + h * right_of(d_in)]), False, 0.4))
        return out

    def layout(self) -> RoadLayout:
        """The :class:`RoadLayout` (polygon, markings, lane width, junction box)."""
        return RoadLayout([self.road_polygon()], self.markings(), self.lane_width_m, self.junction_box_m)
