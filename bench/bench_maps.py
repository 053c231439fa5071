"""Benchmark section "maps": full-HD covariance maps with the fused kernels.

For each camera model: the kernel (after a warm-up that compiles it) is timed
several times into preallocated output (page faults excluded), each run followed
by a plain ``np.copyto`` of the same number of bytes between two preallocated
buffers -- the memory-bandwidth reference measured under the same conditions.
``copy / ours`` >= 0.7 means the kernel runs within 70 % of that limit.  The
naive baseline is :func:`footprint_uq.uncertainty.propagation.propagate` (vectorised numpy,
full Jacobians) on the full grid (``--quick``: every 4th pixel; its rate is per
pixel either way).  ``cpu_ms`` is the process CPU time of one kernel run (all
threads): on a shared machine it shows the work done independently of waiting
for a core (with 2 idle cores the wall time approaches ``cpu_ms / 2``).

The linearity flag (``covariance_map(..., get_nonlinearity=True)``, computed in the same pass): the
map with and without it, runs interleaved (A B A B ...) into preallocated outputs, median of each;
``time / ours`` is with / without (target <= 1.5, the budget of issue 12).
"""

from __future__ import annotations

import time

import numpy as np

from footprint_uq import ErrorBudget, OpenCVCamera, PanTiltCamera, propagate
from footprint_uq.products.covariance import covariance_map

W, H = 1920, 1080
DIST = [-0.2, 0.05, 1e-3, -2e-3, 0.01]  # moderate barrel distortion (k1, k2, p1, p2, k3)


def cameras():
    pt = PanTiltCamera(1400, (W, H), 10.0, 30.0, 12.0, roll_deg=1.0, position_m=(5.0, -3.0))
    T = pt.T_cam_world
    oc = OpenCVCamera(pt.K, DIST, T[:3, :3], T[:3, 3], (W, H))
    return pt, oc


def _alloc():
    out = (np.empty((H, W, 2)), np.empty((H, W, 2, 2)), np.empty((H, W), dtype=np.bool_))
    for a in out:  # touch every page
        a.fill(0)
    nbytes = sum(a.nbytes for a in out)
    src = np.ones(nbytes, dtype=np.uint8)
    dst = np.zeros(nbytes, dtype=np.uint8)
    return out, src, dst, nbytes


def _time_kernel_and_copy(fn, src, dst, runs):
    fn()  # warm-up: JIT compile / load from cache
    np.copyto(dst, src)
    tk, tc, tcpu = [], [], []
    for _ in range(runs):
        c0 = time.process_time()
        t0 = time.perf_counter()
        fn()
        t1 = time.perf_counter()
        c1 = time.process_time()
        np.copyto(dst, src)
        t2 = time.perf_counter()
        tk.append(t1 - t0)
        tc.append(t2 - t1)
        tcpu.append(c1 - c0)
    return float(np.median(tk)), float(np.median(tc)), float(np.median(tcpu)), float(np.min(tk)), float(np.min(tc))


def _naive_rate(cam, budget, quick):
    step = 4 if quick else 1
    grid = cam.pixel_grid(step)
    n = grid.shape[0] * grid.shape[1]
    times = []
    for _ in range(2):
        t0 = time.perf_counter()
        propagate(cam, budget, grid)
        times.append(time.perf_counter() - t0)
    return n / float(np.median(times)) / 1e6, n


def flag_cost(cam, budget, out, runs: int):
    """Median seconds of the map without and with the linearity flag (interleaved runs) and CPU seconds."""
    nl = np.empty(out[2].shape)
    nl.fill(0)
    out4 = out + (nl,)
    covariance_map(cam, budget, out=out)  # warm-up (compile / load from cache)
    covariance_map(cam, budget, out=out4, get_nonlinearity=True)
    t0, t1, c0, c1 = [], [], [], []
    for _ in range(runs):
        for fn, t, c in ((lambda: covariance_map(cam, budget, out=out), t0, c0),
                         (lambda: covariance_map(cam, budget, out=out4, get_nonlinearity=True), t1, c1)):
            a, ca = time.perf_counter(), time.process_time()
            fn()
            t.append(time.perf_counter() - a)
            c.append(time.process_time() - ca)
    return (float(np.median(t0)), float(np.median(t1)), float(np.median(c0)), float(np.median(c1)),
            float(np.nanmax(nl)), float(np.mean(nl[out[2]] <= 0.05)))


def run(quick: bool = False) -> list[dict]:
    runs = 7 if quick else 21
    budget = ErrorBudget.preset("basler1").replace(roll_deg=0.05, ground_height_m=0.05, ground_slope_deg=0.5)
    pt, oc = cameras()
    out, src, dst, nbytes = _alloc()
    rows = []
    for label, cam, target in (("pan-tilt (closed form), all sources", pt, "<= 10 ms, copy/ours >= 0.7"),
                               ("OpenCV with distortion, all sources", oc, ">= 50 Mpx/s")):
        med, cp, cpu, best, best_cp = _time_kernel_and_copy(lambda cam=cam: covariance_map(cam, budget, out=out),
                                                            src, dst, runs)
        valid_frac = float(out[2].mean())
        print(f"  {label}: {med * 1e3:.2f} ms (CPU {cpu * 1e3:.2f} ms), copy {cp * 1e3:.2f} ms", flush=True)
        naive, n_naive = _naive_rate(cam, budget, quick)
        print(f"  numpy propagate: {naive:.3f} Mpx/s on {n_naive:,} px", flush=True)
        mpx = W * H / med / 1e6
        if cam is pt:
            met = (med <= 0.010, cp / med >= 0.7)
            met_txt = f"time {'yes' if met[0] else 'no'}, bandwidth {'yes' if met[1] else 'no'}"
        else:
            met_txt = "yes" if mpx >= 50 else "no"
        rows.append({
            "case": f"{label}, {W}x{H}", "pixels": W * H, "median_ms": med * 1e3, "cpu_ms": cpu * 1e3,
            "min_ms": best * 1e3, "copy_min_ms": best_cp * 1e3,
            "runs": runs, "mpx_per_s": mpx,
            "copy_ms": cp * 1e3, "copy_bytes": nbytes, "copy_ratio": cp / med, "naive_mpx_per_s": naive,
            "naive_pixels": n_naive, "speedup_vs_naive": mpx / naive, "target": target, "met": met_txt,
            "valid_fraction": valid_frac, "budget": "basler1 + roll 0.05 deg + ground 0.05 m / 0.5 deg",
            "notes": (f"{valid_frac:.0%} of pixels below the horizon; output {nbytes / 1e6:.1f} MB "
                      f"(xy + cov float64 + valid); numpy baseline on {n_naive:,} px"),
        })
    for label, cam in (("pan-tilt (closed form), all sources", pt), ("OpenCV with distortion, all sources", oc)):
        off, on, cpu_off, cpu_on, nl_max, ok_frac = flag_cost(cam, budget, out, runs)
        ratio = on / off
        print(f"  {label}: map with the linearity flag {on * 1e3:.2f} ms vs without {off * 1e3:.2f} ms: "
              f"ratio {ratio:.3f} (CPU {cpu_on / cpu_off:.3f})", flush=True)
        rows.append({
            "case": f"{label}, {W}x{H}: with the linearity flag", "pixels": W * H, "median_ms": on * 1e3,
            "cpu_ms": cpu_on * 1e3, "runs": runs, "mpx_per_s": W * H / on / 1e6, "time_vs_ours": ratio,
            "without_flag_ms": off * 1e3, "without_flag_cpu_ms": cpu_off * 1e3, "cpu_ratio": cpu_on / cpu_off,
            "target": "flag / no flag <= 1.5", "met": ratio <= 1.5,
            "notes": (f"time / ours = with / without the flag ({off * 1e3:.2f} ms, interleaved runs; CPU ratio "
                      f"{cpu_on / cpu_off:.2f}); linear_ok at {ok_frac:.1%} of the valid pixels, largest "
                      f"nonlinearity {nl_max:.3g}; output + {W * H * 8 / 1e6:.1f} MB"),
        })
    return rows
