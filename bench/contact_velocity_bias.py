"""Velocity bias of a 2-D box's ground contact on a long vehicle (issue 36, part 4; docs/motion-fit.md, section 6).

With 2-D boxes the tracker follows the ground point of the box's bottom-edge centre.  On a long vehicle that point
is not a fixed point of the vehicle: it slides along the vehicle's near side as the line of sight turns, so its
velocity differs from the vehicle's.  A vehicle (a 3-D box: length, width, height) drives straight at 10 m/s past
:func:`~footprint_uq.tracking.synthetic.default_camera` (8 m high, looking north); every frame (30 Hz, 3 s) its 8
corners are projected by the camera, the 2-D box around them is the detection (noise-free: the bias alone), and the
velocity of its ground contact -- ``bottom-centre`` (:func:`footprint_uq.products.contact.bottom_centre`) and the
contact model's ``footprint-centre`` (:func:`footprint_uq.products.contact.footprint_centre`, size priors of the
class, the true yaw) -- by central differences is compared with the vehicle's: mean and largest error over the
pass.  Writes JSON and Markdown; nothing is asserted.

    PYTHONPATH=src .venv/bin/python bench/contact_velocity_bias.py [--json ...] [--md ...]
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from footprint_uq.cameras import general
from footprint_uq.products.contact import bottom_centre, footprint_centre
from footprint_uq.tracking.synthetic import default_camera

#: (class, length, width, height) m
VEHICLES = (("car", 4.5, 1.8, 1.5), ("truck", 12.0, 2.5, 3.5))
#: paths: (name, start xy m, course rad counter-clockwise from east)
PATHS = (("crossing at 25 m", (-15.0, 25.0), 0.0), ("crossing at 45 m", (-15.0, 45.0), 0.0),
         ("receding at x = 6 m", (6.0, 20.0), np.pi / 2), ("diagonal", (-12.0, 20.0), np.pi / 4))


def _boxes(camera, centre_xy, yaw, length, width, height):
    """2-D boxes ``(F, 4)`` around the projected corners of 3-D boxes at ``centre_xy (F, 2)`` with yaw."""
    c, s = np.cos(yaw), np.sin(yaw)
    dx = np.array([1, 1, -1, -1]) * length / 2
    dy = np.array([1, -1, -1, 1]) * width / 2
    ox, oy = c * dx - s * dy, s * dx + c * dy
    F = centre_xy.shape[0]
    pts = np.empty((F, 8, 3))
    for k, z in enumerate((0.0, height)):
        pts[:, 4 * k:4 * k + 4, 0] = centre_xy[:, :1] + ox
        pts[:, 4 * k:4 * k + 4, 1] = centre_xy[:, 1:] + oy
        pts[:, 4 * k:4 * k + 4, 2] = z
    uv = general.project(camera.params, pts.reshape(-1, 3), domain=camera.lens_domain).uv_px.reshape(F, 8, 2)
    return np.column_stack([uv[..., 0].min(1), uv[..., 1].min(1), uv[..., 0].max(1), uv[..., 1].max(1)])


def run(speed_mps: float = 10.0, duration_s: float = 3.0, rate_hz: float = 30.0) -> list[dict]:
    camera = default_camera()
    t = np.arange(int(duration_s * rate_hz) + 1) / rate_hz
    rows = []
    for cls, length, width, height in VEHICLES:
        for name, start, course in PATHS:
            v = speed_mps * np.array([np.cos(course), np.sin(course)])
            centre = np.asarray(start) + t[:, None] * v
            boxes = _boxes(camera, centre, course, length, width, height)
            row = {"vehicle": cls, "length_m": length, "path": name}
            for model in ("bottom-centre", "footprint-centre"):
                if model == "bottom-centre":
                    xy = bottom_centre(camera, "basler1@deg", boxes).xy_world_m
                else:
                    xy = footprint_centre(camera, "basler1@deg", boxes, [cls] * len(t),
                                          yaw_rad=np.full(len(t), course)).xy_world_m
                vel = (xy[2:] - xy[:-2]) * rate_hz / 2.0
                err = np.linalg.norm(vel - v, axis=1)
                along = (vel - v) @ v / speed_mps
                row[model] = {"mean_error_mps": float(np.nanmean(err)), "max_error_mps": float(np.nanmax(err)),
                              "mean_along_track_mps": float(np.nanmean(along)),
                              "offset_from_centre_m": float(np.nanmean(np.linalg.norm(xy - centre, axis=1)))}
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--md", default=None)
    a = ap.parse_args(argv)
    rows = run()
    if a.json:
        with open(a.json, "w") as f:
            json.dump(rows, f, indent=1)
    if a.md:
        lines = ["| vehicle | path | bottom-centre: mean / max velocity error (m/s) | footprint-centre: mean / max "
                 "(m/s) |", "|---|---|---|---|"]
        for r in rows:
            b, f_ = r["bottom-centre"], r["footprint-centre"]
            lines.append(f"| {r['vehicle']} ({r['length_m']:g} m) | {r['path']} | {b['mean_error_mps']:.2f} / "
                         f"{b['max_error_mps']:.2f} | {f_['mean_error_mps']:.2f} / {f_['max_error_mps']:.2f} |")
        with open(a.md, "w") as f:
            f.write("10 m/s, 3 s at 30 Hz, noise-free boxes (bench/contact_velocity_bias.py)\n\n" + "\n".join(lines)
                    + "\n")


if __name__ == "__main__":
    main()
