"""The worked example of the planner: the case study's four-way intersection as a site.

:func:`intersection_site_dict` turns a :class:`footprint_uq.scenario.intersection.Intersection` into
the mapping of a site file: the paved cross as the lane zone (95 % semi-major <= half a lane), the
junction box as the conflict zone of the left turn (tighter, weighted double), twelve candidate poles
(one at each kerb corner, two along each arm) and three camera types.  ``docs/planning.md``,
``examples/plan_intersection.py`` and ``bench/bench_plan.py`` use it; :func:`naive_layout` is the
reference a planner would draw by hand: one camera per arm, on the arm's nearer pole, looking at the
centre.
"""

from __future__ import annotations

import numpy as np

from ..scenario.intersection import ARMS, Intersection
from .coverage import CameraConfig

__all__ = ["intersection_site_dict", "naive_layout", "CAMERA_TYPES"]

#: three candidate camera types: a full-HD camera with two lenses, a full-HD telephoto, a 4K camera
CAMERA_TYPES = [
    {"name": "hd", "image_size_px": [1920, 1080], "budget": "basler1", "cost": 1.0,
     "lenses": [{"name": "wide", "focal_px": 1000.0, "dist": [-0.12, 0.02, 0.0, 0.0, 0.0]},
                {"name": "normal", "focal_px": 1400.0}]},
    {"name": "hd-tele", "image_size_px": [1920, 1080], "budget": "basler1", "cost": 1.2,
     "lenses": [{"name": "tele", "focal_px": 2600.0}]},
    {"name": "4k", "image_size_px": [3840, 2160], "budget": "basler2", "cost": 2.0,
     "lenses": [{"name": "normal", "focal_px": 2800.0}]},
]


def _poles(ix: Intersection) -> list[dict]:
    h = ix.half_width_m
    c = h + ix.curb_radius_m * 0.6 + 1.0
    out = []
    for sx, sy, name in ((1, 1, "ne"), (-1, 1, "nw"), (-1, -1, "sw"), (1, -1, "se")):
        out.append({"name": f"corner-{name}", "position_m": [sx * c, sy * c], "height_m": [6.0, 10.0],
                    "existing": True, "cost": 0.0})
    for arm, (ax, ay) in ARMS.items():
        d = np.array([ax, ay])
        side = np.array([ay, -ax])  # right of the outgoing direction
        for k, (dist, s) in enumerate(((0.45, 1.0), (0.8, -1.0))):
            p = (h + dist * ix.arm_length_m) * d + s * (h + 1.5) * side
            out.append({"name": f"{arm}-{k + 1}", "position_m": [float(p[0]), float(p[1])],
                        "height_m": [6.0, 12.0], "existing": False, "cost": 1.0})
    return out


def intersection_site_dict(ix: Intersection | None = None, *, resolution_m: float = 0.5, lane_m: float | None = None,
                           conflict_m: float = 1.0, max_cameras: int = 4) -> dict:
    """The site-file mapping of the worked example (see the module docstring).

    Parameters
    ----------
    ix : Intersection, optional
        Default: two lanes per direction, 3.5 m lanes, 43 m arms (100 m x 100 m end to end).
    resolution_m : float
        Ground sample spacing, metres.
    lane_m : float, optional
        Requirement of the lane zone (95 % semi-major, metres); default half a lane width.
    conflict_m : float
        Requirement of the junction box, metres.
    """
    ix = ix or Intersection(lanes_per_direction=2, lane_width_m=3.5, arm_length_m=43.0)
    x0, y0, x1, y1 = ix.junction_box_m
    lane = ix.lane_width_m / 2.0 if lane_m is None else float(lane_m)
    return {
        "name": "Four-way intersection (the case study's)",
        "resolution_m": float(resolution_m),
        "zones": [
            {"name": "lanes", "polygon_m": ix.road_polygon(4).tolist(), "max_semi_major_m": lane, "weight": 1.0},
            {"name": "conflict zone", "polygon_m": [[x0, y0], [x1, y0], [x1, y1], [x0, y1]],
             "max_semi_major_m": float(conflict_m), "weight": 2.0},
        ],
        "occluders": [{"name": "corner building", "polygon_m": [[22.0, 22.0], [40.0, 22.0], [40.0, 40.0], [22.0, 40.0]],
                       "height_m": 15.0}],
        "mounts": _poles(ix),
        "cameras": CAMERA_TYPES,
        "search": {"pan_step_deg": 30.0, "tilts_deg": [12.0, 20.0, 30.0], "heights_per_mount": 2,
                   "max_cameras": int(max_cameras)},
    }


def naive_layout(site) -> list[CameraConfig]:
    """One camera per arm (the ``ARM-1`` pole), the site's first camera type and lens, at the top of the
    pole's range, looking at the centre (0, 0) with the boresight on it."""
    ct = site.cameras[0]
    out = []
    for arm in ARMS:
        m = site.mount(f"{arm}-1")
        x, y = m.position_m
        h = m.height_range_m[1]
        pan = float(np.degrees(np.arctan2(-x, -y)) % 360.0)
        tilt = float(np.degrees(np.arctan2(h, np.hypot(x, y))))
        out.append(CameraConfig(m.name, ct.name, ct.lenses[-1].name, h, pan, tilt))
    return out
