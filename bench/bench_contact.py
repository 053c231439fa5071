"""Wall time of the contact model (``footprint_centre``, issue 20 item 3): compiled vs the numpy reference.

Usage::

    .venv/bin/python bench/bench_contact.py [--objects 1,10,100,1000] [--runs 7] [--out bench/results]

For each camera (the pan-tilt camera of the tests, and an OpenCV camera with distortion and a tilted ground
plane), each number of objects (cars rendered at 20-110 m, 2 px edge noise) and each yaw case (unknown: 36
yaw x 6 size nodes per object; known from a 3-D detector: 5 x 6) it times ``footprint_centre`` with the
compiled node solver and posterior (``footprint_uq.fast.contact_kernels``, the default) and with the numpy
reference (``contact._solve_nodes_reference`` / ``_posterior_reference``) in the same process, median of
``--runs`` runs (the reference: at most 3 runs, and skipped above 100 objects), after one warm-up call
(numba compilation not timed).  Also the largest difference between the two, relative to each output's
per-object scale.  Writes ``DIR/bench_contact.json`` and prints a table.
"""

from __future__ import annotations

import argparse
import functools
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "src"))

from footprint_uq import params as P  # noqa: E402
from footprint_uq.cameras import general  # noqa: E402
from footprint_uq.cameras.opencv import OpenCVCamera  # noqa: E402
from footprint_uq.cameras.pantilt import PanTiltCamera  # noqa: E402
from footprint_uq.io.atomic import atomic_write_text  # noqa: E402
from footprint_uq.products import contact as C  # noqa: E402


def cameras() -> dict:
    pt = PanTiltCamera(2000.0, (1920, 1080), 8.0, 30.0, 14.0, 0.5, (5.0, -3.0))
    T = PanTiltCamera(1800.0, (1920, 1080), 7.0, 0.0, 13.0).T_cam_world
    cv = OpenCVCamera(np.array([[1800.0, 0.5, 950.0], [0, 1790.0, 545.0], [0, 0, 1]]),
                      np.array([-0.05, 0.01, 1e-4, -2e-4, 0.0]), T[:3, :3], T[:3, 3], (1920, 1080), 0.0)
    cv.params[P.GSX], cv.params[P.GSY], cv.params[P.GDZ] = 0.01, -0.02, 0.05
    return {"pantilt": pt, "opencv-distorted": cv}


def boxes_of(cam, n: int, seed: int = 1):
    """``n`` noisy boxes of rendered cars whose centres are seen between rows 450 and 950."""
    rng = np.random.default_rng(seed)
    prior = C.load_size_priors()[0]["car"]
    uv = np.column_stack([rng.uniform(250, 1670, n), rng.uniform(450, 950, n)])
    centre = cam.backproject(uv).xy_world_m
    size = np.clip(prior.mean_m + prior.sigma_m * rng.standard_normal((n, 3)), 0.05, None)
    yaw = rng.uniform(0, 2 * np.pi, n)
    uvc = general.project(cam.params, C._corners(cam.params, centre, size, yaw)).uv_px
    b = np.column_stack([uvc[..., 0].min(1), uvc[..., 1].min(1), uvc[..., 0].max(1), uvc[..., 1].max(1)])
    return b + rng.normal(0, 2.0, b.shape), yaw


def _time(fn, runs: int):
    fn()  # warm-up (compilation, caches)
    ts = []
    for _ in range(runs):
        t0 = time.perf_counter()
        out = fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), out


def _reference(flag: bool):
    """Switch footprint_centre to the numpy reference (True) or back to the compiled path (False)."""
    C._solve_nodes, C._posterior = ((C._solve_nodes_reference, C._posterior_reference) if flag
                                    else (_FAST[0], _FAST[1]))


_FAST = (C._solve_nodes, C._posterior)


def _max_rel(a, b) -> float:
    worst = 0.0
    for f in ("xy_world_m", "cov_m2", "cov_object_m2", "dxy_dp"):
        x, y = getattr(a, f), getattr(b, f)
        scale = np.abs(np.nan_to_num(y)).reshape(len(y), -1).max(1).reshape((-1,) + (1,) * (y.ndim - 1))
        worst = max(worst, float(np.nanmax(np.abs(x - y) / np.where(scale > 0, scale, 1.0), initial=0.0)))
    return worst


def measure(objects=(1, 10, 100, 1000), runs: int = 7) -> list[dict]:
    rows = []
    for cname, cam in cameras().items():
        for n in objects:
            boxes, yaw = boxes_of(cam, n)
            for case, y in (("unknown yaw", None), ("known yaw", yaw)):
                call = functools.partial(C.footprint_centre, cam, {}, boxes, ["car"] * n, yaw_rad=y)
                _reference(False)
                t_fast, fast = _time(call, runs)
                row = {"camera": cname, "objects": n, "yaw": case, "compiled_ms": 1e3 * t_fast,
                       "compiled_us_per_object": 1e6 * t_fast / n, "runs": runs}
                if n <= 100:
                    _reference(True)
                    t_ref, ref = _time(call, min(runs, 3))
                    _reference(False)
                    row.update(reference_ms=1e3 * t_ref, speedup=t_ref / t_fast, max_rel_diff=_max_rel(fast, ref),
                               valid=int(fast.valid.sum()))
                rows.append(row)
                print(f"{cname:17s} {n:5d} objects, {case:11s}: compiled {row['compiled_ms']:8.2f} ms"
                      + (f", reference {row['reference_ms']:9.1f} ms, x{row['speedup']:6.0f}, "
                         f"max rel diff {row['max_rel_diff']:.1e}" if "reference_ms" in row else ""), flush=True)
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="1,10,100,1000")
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    a = ap.parse_args(argv)
    import numba

    load0 = os.getloadavg()[0]
    rows = measure(tuple(int(s) for s in a.objects.split(",")), a.runs)
    res = {"rows": rows, "numba_threads": numba.get_num_threads(), "load_avg": [load0, os.getloadavg()[0]]}
    atomic_write_text(a.out / "bench_contact.json", json.dumps(res, indent=2) + "\n", parents=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
