"""Per-frame latency: one frame of 100 objects (3D boxes, four corners each) through the Python API.

From the boxes to the corner and centre covariances, largest-point values and the
CPM/J2735 fields (issue 3 target: <= 100 microseconds median).  Measured in one run:

* ``fast`` -- :meth:`footprint_uq.products.footprints.FrameProcessor.boxes3d` (fused numba kernel,
  joint corner covariance off, as a per-frame V2X producer would run it), and with the
  joint (N, 8, 8) covariance on;
* ``reference`` -- :func:`footprint_uq.products.footprints.footprints_from_boxes3d`, the vectorised
  numpy path, on the whole frame;
* ``naive`` -- a per-object Python loop over the numpy reference (one call per object).

Run ``.venv/bin/python bench/bench_footprints.py [--objects N] [--repeats R]``;
:func:`run` returns the figures as a dict (for ``bench/run.py``).  Timings are medians of
``repeats`` calls after a warm-up; nothing here is asserted.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import time

import numpy as np

from footprint_uq import OpenCVCamera, PanTiltCamera
from footprint_uq.io.atomic import atomic_write_text
from footprint_uq.products.footprints import FrameProcessor, footprints_from_boxes3d

TARGET_US = 100.0
CAMERA = dict(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
BUDGET = "basler1"


def make_frame(camera, n: int, seed: int = 0) -> np.ndarray:
    """n car-sized 3D boxes (N, 7) spread over the camera's view, 12..70 m away."""
    rng = np.random.default_rng(seed)
    C = camera.position_world_m
    d = rng.uniform(12.0, 70.0, n)
    a = np.deg2rad(camera.pan_deg + rng.uniform(-28.0, 28.0, n))
    return np.column_stack([C[0] + d * np.sin(a), C[1] + d * np.cos(a), np.full(n, 0.8), rng.uniform(3.5, 5.0, n),
                            rng.uniform(1.6, 2.0, n), rng.uniform(1.4, 1.8, n), rng.uniform(-np.pi, np.pi, n)])


def _median_us(fn, repeats: int) -> float:
    fn()  # warm-up
    ts = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return statistics.median(ts) * 1e6


def _touch(est):
    """What a V2X producer reads from a frame's result."""
    return est.centre_xy_world_m, est.centre_cov_m2, est.largest_semi_major_m, est.v2x_codes


def _measure(cam, n_objects: int, repeats: int, naive_repeats: int, seed: int) -> dict:
    boxes = make_frame(cam, n_objects, seed)
    proc = FrameProcessor(cam, BUDGET, joint_cov=False)
    proc_joint = FrameProcessor(cam, BUDGET, joint_cov=True)
    proc_noflag = FrameProcessor(cam, BUDGET, joint_cov=False, linearity=False)
    proc_joint_noflag = FrameProcessor(cam, BUDGET, joint_cov=True, linearity=False)
    fast = _median_us(lambda: _touch(proc.boxes3d(boxes)), repeats)
    fast_noflag = _median_us(lambda: _touch(proc_noflag.boxes3d(boxes)), repeats)
    fast_joint = _median_us(lambda: _touch(proc_joint.boxes3d(boxes)), repeats)
    fast_joint_noflag = _median_us(lambda: _touch(proc_joint_noflag.boxes3d(boxes)), repeats)
    ref = _median_us(lambda: _touch(footprints_from_boxes3d(cam, BUDGET, boxes)), max(repeats // 20, 5))
    ref_noflag = _median_us(lambda: _touch(footprints_from_boxes3d(cam, BUDGET, boxes, linearity=False)),
                            max(repeats // 20, 5))

    def naive(**kw):
        for i in range(n_objects):
            _touch(footprints_from_boxes3d(cam, BUDGET, boxes[i:i + 1], **kw))

    naive_us = _median_us(naive, naive_repeats)
    naive_noflag_us = _median_us(lambda: naive(linearity=False), naive_repeats)
    est = proc.boxes3d(boxes)
    return {
        "fast_median_us": fast, "fast_with_joint_cov_median_us": fast_joint,
        "fast_without_flag_median_us": fast_noflag, "fast_with_joint_cov_without_flag_median_us": fast_joint_noflag,
        "flagged_centres": int((est.centre_valid & ~est.centre_linear_ok).sum()),
        "numpy_reference_median_us": ref, "naive_loop_median_us": naive_us,
        "numpy_reference_without_flag_median_us": ref_noflag, "naive_loop_without_flag_median_us": naive_noflag_us,
        "naive_over_fast": naive_us / fast, "meets_target": fast <= TARGET_US,
        "objects_with_valid_centre": int(est.centre_valid.sum()),
    }


def run(n_objects: int = 100, repeats: int = 2000, naive_repeats: int = 20, seed: int = 0) -> dict:
    """Measure and return the figures (microseconds per frame of ``n_objects`` objects)."""
    pantilt = PanTiltCamera(**CAMERA)
    cameras = {"pan-tilt": pantilt}
    T = pantilt.T_cam_world
    cameras["opencv-distortion"] = OpenCVCamera(pantilt.K, [-0.12, 0.03, 1e-4, -2e-4, -0.004], T[:3, :3], T[:3, 3],
                                                CAMERA["image_size_px"])
    out: dict = {"objects": n_objects, "corners_per_object": 4, "repeats": repeats, "cpus": os.cpu_count(),
                 "target_us": TARGET_US}
    for name, cam in cameras.items():
        out[name] = _measure(cam, n_objects, repeats, naive_repeats, seed)
    return out


def report(res: dict) -> str:
    lines = [f"per-frame latency, {res['objects']} objects x 4 corners (3D boxes), median of {res['repeats']} calls "
             f"({res['cpus']} CPUs; target <= {res['target_us']:.0f} us)",
             "| camera | FrameProcessor | + joint cov | numpy reference | naive per-object loop | naive / fast |",
             "|---|---|---|---|---|---|"]
    for name in ("pan-tilt", "opencv-distortion"):
        if name in res:
            r = res[name]
            lines.append(f"| {name} | {r['fast_median_us']:.1f} us | {r['fast_with_joint_cov_median_us']:.1f} us | "
                         f"{r['numpy_reference_median_us']:.0f} us | {r['naive_loop_median_us'] / 1e3:.1f} ms | "
                         f"{r['naive_over_fast']:,.0f}x |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--repeats", type=int, default=2000)
    ap.add_argument("--naive-repeats", type=int, default=20)
    ap.add_argument("--json", default=None, help="also write the figures to this JSON file")
    a = ap.parse_args(argv)
    res = run(a.objects, a.repeats, a.naive_repeats)
    print(report(res))
    if a.json:
        atomic_write_text(a.json, json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
