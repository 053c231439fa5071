"""Velocity bias of a 2-D box's ground contact on a long vehicle (issue 36, part 4; docs/motion-fit.md, section 6).

With 2-D boxes the tracker follows the ground point of the box's bottom-edge centre.  On a long vehicle that point
is not a fixed point of the vehicle: it slides along the vehicle's near side as the line of sight turns, so its
velocity differs from the vehicle's.  A vehicle (a 3-D box: length, width, height) drives straight at 10 m/s past
:func:`~footprint_uq.tracking.synthetic.default_camera` (8 m high, looking north); every frame (30 Hz, 3 s) its 8
corners are projected by the camera, the 2-D box around them is the detection (noise-free: the bias alone), and the
velocity of its ground contact -- ``bottom-centre`` (:func:`footprint_uq.products.contact.bottom_centre`) and the
contact model's ``footprint-centre`` (:func:`footprint_uq.products.contact.footprint_centre`, size priors of the
class, the true yaw) -- by central differences is compared with the vehicle's: mean and largest error over the
pass.

Then the tracker (``--coverage``): seeded runs of the same passes, each with its own calibration draw
(``basler1@deg``) and 1.5 px of detector noise on every box edge, tracked by ``objects --tracks``' tracker (the
default IMM, and one mode at q = 0.5 m^2/s^3: a calm site's fitted model) on the bottom-centre contacts; per
vehicle and path, the share of the 95 % velocity regions (after the track's first 0.5 s) that hold the true
velocity, and the median velocity sigma (the larger semi-axis), before and with the slide term
(:class:`footprint_uq.tracking.contact_slide.ContactSlide`), and for the alternative, the velocity *corrected* by
the slide's mean with only its spread in the covariance (:func:`~footprint_uq.tracking.contact_slide.
slide_moments`); both with the class's size prior (``car`` 4.62 +- 0.43 m, ``truck`` 6.93 +- 1.39 m -- the
12 m truck is 3.6 sigma longer than its class's prior).
Writes JSON and Markdown; nothing is asserted.

    PYTHONPATH=src .venv/bin/python bench/contact_velocity_bias.py [--json ...] [--md ...] [--coverage RUNS]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from footprint_uq import params as P
from footprint_uq.cameras import general
from footprint_uq.products.contact import bottom_centre, class_size_priors, footprint_centre
from footprint_uq.products.frame_processor import FrameProcessor
from footprint_uq.tracking.contact_slide import ContactSlide, slide_moments, slide_moments_reference
from footprint_uq.tracking.synthetic import CHI2_95_2D, default_camera
from footprint_uq.tracking.table import SharedJacobianAt, TrackerConfig, TrackTable
from footprint_uq.uncertainty.budget import load_budget

#: (class, length, width, height) m
VEHICLES = (("car", 4.5, 1.8, 1.5), ("truck", 12.0, 2.5, 3.5))
#: paths: (name, start xy m, course rad counter-clockwise from east)
PATHS = (("crossing at 25 m", (-15.0, 25.0), 0.0), ("crossing at 45 m", (-15.0, 45.0), 0.0),
         ("receding at x = 6 m", (6.0, 20.0), np.pi / 2), ("diagonal", (-12.0, 20.0), np.pi / 4))
#: the trackers of the coverage runs: the default IMM, and one mode at a calm site's fitted density
TRACKERS = (("default IMM", TrackerConfig()), ("one mode q = 0.5", TrackerConfig(0.5, manoeuvre_accel_psd_m2ps3=None)))


def _boxes(camera, centre_xy, yaw, length, width, height, params=None):
    """2-D boxes ``(F, 4)`` around the projected corners of 3-D boxes at ``centre_xy (F, 2)`` with yaw, in the
    camera of ``params`` (default: the nominal one; the box stands on that camera's ground plane)."""
    p = camera.params if params is None else params
    c, s = np.cos(yaw), np.sin(yaw)
    dx = np.array([1, 1, -1, -1]) * length / 2
    dy = np.array([1, -1, -1, 1]) * width / 2
    ox, oy = c * dx - s * dy, s * dx + c * dy
    F = centre_xy.shape[0]
    pts = np.empty((F, 8, 3))
    zg = p[P.GDZ] + p[P.GSX] * (centre_xy[:, :1] - p[P.XM]) + p[P.GSY] * (centre_xy[:, 1:] - p[P.YM])
    for k, z in enumerate((0.0, height)):
        pts[:, 4 * k:4 * k + 4, 0] = centre_xy[:, :1] + ox
        pts[:, 4 * k:4 * k + 4, 1] = centre_xy[:, 1:] + oy
        pts[:, 4 * k:4 * k + 4, 2] = zg + z
    uv = general.project(p, pts.reshape(-1, 3), domain=camera.lens_domain).uv_px.reshape(F, 8, 2)
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


def _track_pass(camera, budget, cls, size, path, n_runs, rng, sigma_px, rate_hz, duration_s, speed_mps, config):
    """One vehicle on one path, ``n_runs`` seeded runs tracked side by side (one id each): per tracked update
    after 0.5 s, ``(d2 before, d2 after, sigma before, sigma after)`` of the true velocity (module doc)."""
    _, start, course = path
    t = np.arange(int(duration_s * rate_hz) + 1) / rate_hz
    v = speed_mps * np.array([np.cos(course), np.sin(course)])
    centre = np.asarray(start) + t[:, None] * v
    L = budget.param_factor().dense()
    boxes = np.empty((len(t), n_runs, 4))
    for r in range(n_runs):
        p_true = camera.params + L @ rng.standard_normal(L.shape[1])
        boxes[:, r] = _boxes(camera, centre, course, *size, params=p_true)
    boxes += sigma_px * rng.standard_normal(boxes.shape)
    proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, shared_jacobian=True,
                          v2x_policy="linear", allow_outside_image=True)
    at = SharedJacobianAt(camera, budget)
    table, slide = TrackTable(config, rank=at.rank, shared_at=at), ContactSlide(camera)
    det = np.broadcast_to(sigma_px ** 2 * np.eye(4), (n_runs, 4, 4))
    rows = []
    for k, tk in enumerate(t):
        est = proc.boxes2d(boxes[k], box_cov_px2=det)
        out = table.step(tk, list(range(n_runs)), est.centre_xy_world_m, est.centre_cov_frame_m2,
                         est.centre_shared_m)
        ok = np.isfinite(out.v_mps).all(1) & (out.age_s >= 0.5)
        if not ok.any():
            continue
        after = slide.apply(out, [cls] * n_runs)
        mean, sig = class_size_priors([cls] * int(ok.sum()), int(ok.sum()))
        u_mean, u_second = slide_moments(camera, out.xy_m[ok], out.v_mps[ok], mean, sig)
        dv = out.v_mps[ok] - v
        for d, cov in ((dv, out.cov_v_m2ps2[ok]), (dv, after.cov_v_m2ps2[ok]),  # before, the term, corrected:
                       (dv - u_mean, out.cov_v_m2ps2[ok] + u_second - np.einsum("ni,nj->nij", u_mean, u_mean))):
            rows.append((np.einsum("ni,nij,nj->n", d, np.linalg.inv(cov), d), np.sqrt(np.linalg.eigvalsh(cov)[:, 1])))
    return tuple(np.concatenate([r[j] for r in rows[m::3]]) for m in range(3) for j in (0, 1))


def coverage(n_runs: int = 40, seed: int = 0, sigma_px: float = 1.5, speed_mps: float = 10.0,
             duration_s: float = 3.0, rate_hz: float = 30.0) -> list[dict]:
    """The tracker's 95 % velocity coverage and median sigma, before and after the slide term (module doc)."""
    camera, budget = default_camera(), load_budget("basler1@deg")
    rows = []
    for tracker, config in TRACKERS:
        for cls, length, width, height in VEHICLES:
            for path in PATHS:
                rng = np.random.default_rng(seed)
                d2b, sb, d2a, sa, d2c, sc = _track_pass(camera, budget, cls, (length, width, height), path, n_runs,
                                                        rng, sigma_px, rate_hz, duration_s, speed_mps, config)
                row = {"tracker": tracker, "vehicle": cls, "length_m": length, "path": path[0],
                       "n_updates": int(d2b.size),
                       "coverage_before": float(np.mean(d2b <= CHI2_95_2D)),
                       "coverage_after": float(np.mean(d2a <= CHI2_95_2D)),
                       "median_sigma_before_mps": float(np.median(sb)), "median_sigma_after_mps": float(np.median(sa)),
                       "coverage_corrected": float(np.mean(d2c <= CHI2_95_2D)),
                       "median_sigma_corrected_mps": float(np.median(sc))}
                rows.append(row)
                print(json.dumps(row), flush=True)
    return rows


def timing(n_objects: int = 100, n_frames: int = 60, seed: int = 0) -> dict:
    """The term's cost per frame of ``n_objects`` tracked 2-D box contacts, against the tracker's own step in the
    same run (the reference), and the numpy form it replaced (the central difference along the path,
    ``slide_moments_reference(along_path=True)``, with the class lookup of the frame) on the same frames: medians
    over ``n_frames`` frames (after two warm-up frames)."""
    camera, budget = default_camera(), load_budget("basler1@deg")
    rng = np.random.default_rng(seed)
    at = SharedJacobianAt(camera, budget)
    table, slide = TrackTable(rank=at.rank, shared_at=at), ContactSlide(camera)
    proc = FrameProcessor(camera, budget, joint_cov=False, linearity=False, shared_jacobian=True,
                          v2x_policy="linear", allow_outside_image=True)
    xy = np.column_stack([rng.uniform(-12, 12, n_objects), rng.uniform(20, 50, n_objects)])
    v = rng.normal(0.0, 7.0, (n_objects, 2))
    classes = list(rng.choice(["car", "truck", "pedestrian"], n_objects))
    step_s, term_s, numpy_s = [], [], []
    for k in range(n_frames + 2):
        uv = camera.project_ground(xy + v * k / 30.0).uv_px + rng.normal(0.0, 1.5, (n_objects, 2))
        est = proc.corners(uv[:, None, :], pixel_cov_px2=np.broadcast_to(2.25 * np.eye(2), (n_objects, 2, 2)))
        t0 = time.perf_counter()
        out = table.step(k / 30.0, list(range(n_objects)), est.centre_xy_world_m, est.centre_cov_frame_m2,
                         est.centre_shared_m)
        t1 = time.perf_counter()
        slide.apply(out, classes)
        t2 = time.perf_counter()
        ok = np.isfinite(out.v_mps).all(1)
        mean, sig = class_size_priors([classes[i] for i in np.flatnonzero(ok)], int(ok.sum()))
        slide_moments_reference(camera, out.xy_m[ok], out.v_mps[ok], mean, sig, along_path=True)
        t3 = time.perf_counter()
        if k >= 2:
            step_s.append(t1 - t0)
            term_s.append(t2 - t1)
            numpy_s.append(t3 - t2)
    res = {"n_objects": n_objects, "tracker_step_ms": 1e3 * float(np.median(step_s)),
           "slide_term_ms": 1e3 * float(np.median(term_s)), "numpy_term_ms": 1e3 * float(np.median(numpy_s))}
    res["ratio"] = res["slide_term_ms"] / res["tracker_step_ms"]
    res["numpy_ratio"] = res["numpy_term_ms"] / res["tracker_step_ms"]
    print(json.dumps(res), flush=True)
    return res


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", default=None)
    ap.add_argument("--md", default=None)
    ap.add_argument("--timing", action="store_true", help="also time the term against the tracker's step")
    ap.add_argument("--coverage", type=int, default=0, metavar="RUNS",
                    help="also track RUNS seeded noisy runs per vehicle and path: coverage before/after the term")
    a = ap.parse_args(argv)
    rows = run()
    cov = coverage(a.coverage) if a.coverage > 0 else []
    tim = timing() if a.timing else None
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"bias": rows, "coverage": cov, "timing": tim}, f, indent=1)
    if a.md:
        lines = ["| vehicle | path | bottom-centre: mean / max velocity error (m/s) | footprint-centre: mean / max "
                 "(m/s) |", "|---|---|---|---|"]
        for r in rows:
            b, f_ = r["bottom-centre"], r["footprint-centre"]
            lines.append(f"| {r['vehicle']} ({r['length_m']:g} m) | {r['path']} | {b['mean_error_mps']:.2f} / "
                         f"{b['max_error_mps']:.2f} | {f_['mean_error_mps']:.2f} / {f_['max_error_mps']:.2f} |")
        if cov:
            lines += ["", f"Tracked: {a.coverage} seeded runs per row (a calibration draw of basler1@deg each, 1.5 px "
                      "per box edge, updates after 0.5 s); 95 % velocity region:", "",
                      "| tracker | vehicle | path | coverage before | with the slide term | corrected instead | "
                      "median sigma before / with the term / corrected (m/s) | updates |",
                      "|---|---|---|---|---|---|---|---|"]
            for r in cov:
                lines.append(f"| {r['tracker']} | {r['vehicle']} ({r['length_m']:g} m) | {r['path']} | "
                             f"{100 * r['coverage_before']:.1f} % | {100 * r['coverage_after']:.1f} % | "
                             f"{100 * r['coverage_corrected']:.1f} % | {r['median_sigma_before_mps']:.2f} / "
                             f"{r['median_sigma_after_mps']:.2f} / {r['median_sigma_corrected_mps']:.2f} | "
                             f"{r['n_updates']} |")
        if tim:
            lines += ["", f"Cost per frame of {tim['n_objects']} tracked objects (median of 60 frames): the tracker's "
                      f"step {tim['tracker_step_ms']:.3f} ms, the slide term {tim['slide_term_ms']:.3f} ms "
                      f"(x{tim['ratio']:.2f}; compiled), its former numpy form {tim['numpy_term_ms']:.2f} ms "
                      f"(x{tim['numpy_ratio']:.1f})."]
        with open(a.md, "w") as f:
            f.write("10 m/s, 3 s at 30 Hz, noise-free boxes (bench/contact_velocity_bias.py)\n\n" + "\n".join(lines)
                    + "\n")


if __name__ == "__main__":
    main()
