"""ROS 2 MCAP recording of footprints: throughput and peak memory against the recording's length.

A 30 Hz camera with 100 objects per frame: footprint tables (the batch's output columns that the bag uses)
are generated chunk by chunk and written by :class:`footprint_uq.integrations.ros2.bag_writer.RosBagOut`
to one MCAP file (per frame a Detection3DArray and a MarkerArray; ``--foxglove``: also a Foxglove
SceneUpdate).  Each length (default 1k, 4k, 16k frames) runs in a fresh process that reports its wall time,
CPU time and peak resident memory (``VmHWM``); in the same process the same tables are also written to Parquet
(the batch's default output) as the reference.  Flat in the length means: frames per second and peak memory
about the same at every length.  The hour (108,000 frames) is extrapolated from the longest run's time per
frame, or run with ``--lengths 108000``.

Run ``.venv/bin/python bench/bench_mcap.py [--lengths 1000,4000,16000] [--foxglove] [--out FILE]``; writes
``bench/results/bench_mcap.json`` (with ``--foxglove``: ``bench_mcap_foxglove.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from footprint_uq.io.atomic import atomic_write_text

ROOT = Path(__file__).resolve().parents[1]
HZ, OBJECTS, HOUR_FRAMES = 30, 100, 108_000

_CHILD = r"""
import json, os, sys, time
import numpy as np, pyarrow as pa, pyarrow.parquet as pq
from footprint_uq.cameras.pantilt import PanTiltCamera
from footprint_uq.integrations.ros2.bag_writer import BagOptions, RosBagOut

frames, objects, hz = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3])
foxglove, folder = sys.argv[4] == "1", sys.argv[5]
cam = PanTiltCamera(focal_px=1400.0, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
rng = np.random.default_rng(0)
per_chunk = max(1, 131072 // objects)

def table(f0, nf):
    n = nf * objects
    fr = np.repeat(np.arange(f0, f0 + nf), objects)
    a = rng.normal(size=(n, 2, 2)) * 0.3
    cov = a @ a.transpose(0, 2, 1) + 0.01 * np.eye(2)
    return pa.table({"row": np.arange(f0 * objects, f0 * objects + n), "camera_id": pa.array(["cam1"] * n),
                     "frame": fr, "timestamp_s": 1714564800.0 + fr / hz,
                     "object_id": pa.array([str(i) for i in np.tile(np.arange(objects), nf)]),
                     "class": pa.array(["car"] * n), "score": np.full(n, 0.9),
                     "status": pa.array(["ok"] * n).dictionary_encode(),
                     "x_m": rng.uniform(-50, 50, n), "y_m": rng.uniform(5, 120, n),
                     "cov_xx_m2": cov[:, 0, 0], "cov_xy_m2": cov[:, 0, 1], "cov_yy_m2": cov[:, 1, 1]})

def run(make_writer, write, close):
    rng.bit_generator.state = np.random.default_rng(0).bit_generator.state
    w = make_writer()
    t0, c0, gen = time.perf_counter(), time.process_time(), 0.0
    for f0 in range(0, frames, per_chunk):
        g = time.perf_counter()
        t = table(f0, min(per_chunk, frames - f0))
        gen += time.perf_counter() - g
        write(w, t)
    close(w)
    return time.perf_counter() - t0 - gen, time.process_time() - c0

out = os.path.join(folder, "run.mcap")
schema = table(0, 1).schema
ref = os.path.join(folder, "run.parquet")
def mcap_writer():
    w = RosBagOut(out, schema, BagOptions(camera=cam, foxglove=foxglove))
    w.fsync = False
    return w
t_mcap, cpu_mcap = run(mcap_writer, lambda w, t: w.write(t), lambda w: w.close())
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0]
peak = int(hwm.split()[1]) / 1024.0
t_pq, cpu_pq = run(lambda: pq.ParquetWriter(ref, schema), lambda w, t: w.write_table(t), lambda w: w.close())
print(json.dumps({"frames": frames, "objects_per_frame": objects, "mcap_s": t_mcap, "mcap_cpu_s": cpu_mcap,
                  "parquet_s": t_pq, "parquet_cpu_s": cpu_pq, "peak_rss_mb": peak,
                  "mcap_bytes": os.path.getsize(out), "parquet_bytes": os.path.getsize(ref)}))
"""


def measure(frames: int, *, foxglove: bool = False, objects: int = OBJECTS) -> dict:
    """One length in a fresh process: the MCAP write's and the Parquet reference's times, peak RSS, sizes."""
    env = {**os.environ, "PYTHONPATH": str(ROOT / "src"), "PYTHONWARNINGS": "ignore"}
    with tempfile.TemporaryDirectory(prefix="bench-mcap-") as d:
        p = subprocess.run([sys.executable, "-c", _CHILD, str(frames), str(objects), str(HZ), str(int(foxglove)), d],
                           capture_output=True, text=True, env=env, check=False)
    if p.returncode != 0:
        raise RuntimeError(p.stderr.strip().splitlines()[-1] if p.stderr.strip() else f"exit {p.returncode}")
    r = json.loads(p.stdout.strip().splitlines()[-1])
    r["frames_per_s"] = frames / r["mcap_s"]
    r["frames_per_cpu_s"] = frames / r["mcap_cpu_s"]
    r["realtime_factor_cpu"] = r["frames_per_cpu_s"] / HZ
    r["ms_per_frame"] = 1e3 * r["mcap_s"] / frames
    r["cpu_ms_per_frame"] = 1e3 * r["mcap_cpu_s"] / frames
    r["mcap_over_parquet_cpu"] = r["mcap_cpu_s"] / r["parquet_cpu_s"]
    return r


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="1000,4000,16000", help="frames per run, comma-separated")
    ap.add_argument("--foxglove", action="store_true", help="also write the Foxglove SceneUpdates")
    ap.add_argument("--out", default=None, help="results JSON (default bench/results/bench_mcap[_foxglove].json)")
    a = ap.parse_args(argv)
    lengths = [int(x) for x in a.lengths.split(",")]
    load0 = os.getloadavg()
    runs = []
    for n in lengths:
        r = measure(n, foxglove=a.foxglove)
        runs.append(r)
        print(f"{n:>7} frames: CPU {r['cpu_ms_per_frame']:.2f} ms/frame = {r['frames_per_cpu_s']:.0f} frames per "
              f"CPU-s (x{r['realtime_factor_cpu']:.1f} real time; wall {r['ms_per_frame']:.2f} ms/frame at load "
              f"{os.getloadavg()[0]:.1f}), peak RSS {r['peak_rss_mb']:.0f} MB, {r['mcap_bytes'] / n / 1e3:.1f} "
              f"kB/frame, CPU x{r['mcap_over_parquet_cpu']:.0f} the Parquet reference", flush=True)
    last = runs[-1]
    hour = {"frames": HOUR_FRAMES, "estimated_cpu_s": last["mcap_cpu_s"] / last["frames"] * HOUR_FRAMES,
            "estimated_wall_s_at_this_load": last["mcap_s"] / last["frames"] * HOUR_FRAMES,
            "estimated_bytes": last["mcap_bytes"] / last["frames"] * HOUR_FRAMES,
            "peak_rss_mb_expected": max(r["peak_rss_mb"] for r in runs), "from_frames": last["frames"],
            "measured": last["frames"] >= HOUR_FRAMES}
    res = {"bench": "bench_mcap", "date_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
           "hz": HZ, "objects_per_frame": OBJECTS, "foxglove": a.foxglove, "runs": runs, "hour": hour,
           "flat": {"cpu_per_frame_max_over_min": max(r["cpu_ms_per_frame"] for r in runs) /
                    min(r["cpu_ms_per_frame"] for r in runs),
                    "peak_rss_mb_max_over_min": max(r["peak_rss_mb"] for r in runs) /
                    min(r["peak_rss_mb"] for r in runs)},
           "machine": {"cpus": os.cpu_count(), "python": platform.python_version(), "loadavg_start": load0,
                       "loadavg_end": os.getloadavg()}}
    print(f"hour ({HOUR_FRAMES} frames): {hour['estimated_cpu_s'] / 60:.1f} CPU-min estimated "
          f"(x{3600 / hour['estimated_cpu_s']:.1f} real time on one core), {hour['estimated_bytes'] / 1e9:.2f} GB, "
          f"peak RSS ~{hour['peak_rss_mb_expected']:.0f} MB; flat: CPU per frame max/min "
          f"{res['flat']['cpu_per_frame_max_over_min']:.2f}, RSS max/min {res['flat']['peak_rss_mb_max_over_min']:.2f}")
    out = Path(a.out) if a.out else ROOT / "bench" / "results" / (
        "bench_mcap_foxglove.json" if a.foxglove else "bench_mcap.json")
    atomic_write_text(out, json.dumps(res, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
