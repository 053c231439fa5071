"""Per-call latency of small calls: ``covariance_points`` for 2 / 100 / 10,000 points, with and without lens
distortion, on a quiet machine and with every other core busy (a spinning process per core but one, as next
to a detector), median and 90th percentile of many calls, wall clock and CPU time (issue 24: the distorted
path's p90 was 8 ms against a 0.39 ms median with the other core busy).  A wall p90 far above the CPU p90
is time spent waiting: for a thread or, on an oversubscribed machine (load average above the core count), for
the scheduler.  From 4096 points (``fast.map_kernels.SERIAL_BELOW``) the kernel runs threaded only when a second
core is idle at the moment of the call (``fast.cores.free_cores``); with the other core busy it stays serial.

Run ``.venv/bin/python bench/bench_small_calls.py [--calls N]``; prints one JSON line per case.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import time

import numpy as np

from footprint_uq import OpenCVCamera, PanTiltCamera
from footprint_uq.products.covariance import covariance_points

SIZES = (2, 100, 10_000)


def _spin(stop):  # a busy core
    x = 0
    while not stop.is_set():
        for _ in range(100_000):
            x += 1


def cameras() -> dict:
    pt = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    K = pt.K
    dist = np.array([-0.17, 0.12, -1.2e-4, -2.35e-3, -0.03])
    T = pt.T_cam_world
    return {"no distortion": pt, "distortion": OpenCVCamera(K, dist, T[:3, :3], T[:3, 3], (1920, 1080))}


def measure(calls: int = 200, busy: bool = False) -> list[dict]:
    stop, procs = mp.Event(), []
    if busy:
        for _ in range(max(1, (os.cpu_count() or 2) - 1)):
            p = mp.Process(target=_spin, args=(stop,), daemon=True)
            p.start()
            procs.append(p)
        time.sleep(0.5)
    rng = np.random.default_rng(0)
    out = []
    try:
        for name, cam in cameras().items():
            for n in SIZES:
                uv = np.c_[rng.uniform(0, 1919, n), rng.uniform(500, 1079, n)]
                covariance_points(cam, "basler1", uv)  # compiled and warm
                k = calls if n < 10_000 else max(20, calls // 10)
                t, c = np.empty(k), np.empty(k)
                for i in range(k):
                    t0, c0 = time.perf_counter(), time.process_time()
                    covariance_points(cam, "basler1", uv)
                    t[i], c[i] = time.perf_counter() - t0, time.process_time() - c0
                out.append({"camera": name, "points": n, "busy": busy, "calls": k,
                            "median_ms": round(1e3 * float(np.median(t)), 4),
                            "p90_ms": round(1e3 * float(np.percentile(t, 90)), 4),
                            "p99_ms": round(1e3 * float(np.percentile(t, 99)), 4),
                            "cpu_median_ms": round(1e3 * float(np.median(c)), 4),
                            "cpu_p90_ms": round(1e3 * float(np.percentile(c, 90)), 4),
                            "load_avg_1min": round(os.getloadavg()[0], 2)})
    finally:
        stop.set()
        for p in procs:
            p.join(5)
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--calls", type=int, default=200)
    a = ap.parse_args()
    for busy in (False, True):
        for row in measure(a.calls, busy):
            print(json.dumps(row))


if __name__ == "__main__":
    main()
