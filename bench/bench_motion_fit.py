"""Cost of ``calibrate motion`` on a streamed recording (issue 36), extrapolated to one hour of 8 cameras x 30 Hz x
100 objects (86.4 M detections).

A seeded recording of one camera (``--objects`` road users at 30 Hz for ``--duration`` s, 2-D boxes whose bottom
centre is the true pixel; :func:`footprint_uq.tracking.motion_campaigns.campaign_frames`) is written as Parquet; then,
each in a fresh process (its peak resident memory from ``getrusage``), ``--repeats`` times interleaved:

* ``objects --tracks`` on it (the reference: footprints and the tracker alone);
* the fit with the one-mode grid (``--modes one``, 33 filters per track) and with the IMM members (``auto``, + 17
  two-mode filters).

Reports the median wall time per run, its ratio to the reference, detections per second and the extrapolation to
one hour (time x 86.4 M / n; memory: the chunk's plus 800 live tracks' bank states, which does not grow with the
recording's length).

    PYTHONPATH=src .venv/bin/python bench/bench_motion_fit.py [--objects 100] [--duration 10] [--repeats 3] \
        [--json bench/results/motion-fit-stream.json]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from footprint_uq.io.atomic import atomic_write_text

HOUR_DETECTIONS = 8 * 30 * 100 * 3600


def write_recording(path: Path, n_objects: int, duration_s: float, seed: int = 0) -> int:
    from footprint_uq.cameras import general
    from footprint_uq.tracking.motion_campaigns import campaign_frames
    from footprint_uq.tracking.synthetic import default_camera

    cam = default_camera()
    cols: dict = {k: [] for k in ("camera_id", "frame", "timestamp_s", "object_id", "class", "u_min_px", "v_min_px",
                                  "u_max_px", "v_max_px", "cov_uu_px2", "cov_uv_px2", "cov_vv_px2")}
    for k, (t, ids, _, xy, _, _, _) in enumerate(campaign_frames(2.5, 1, n_objects, duration_s=duration_s,
                                                                 rate_hz=30.0, seed=seed, camera=cam)):
        uv = general.project(cam.params, np.column_stack([xy, np.zeros(len(ids))]), domain=cam.lens_domain).uv_px
        ok = np.flatnonzero(np.isfinite(uv).all(1) & (uv[:, 1] < 1080) & (uv[:, 0] > 20) & (uv[:, 0] < 1900))
        cols["camera_id"] += ["c1"] * ok.size
        cols["frame"] += [k] * ok.size
        cols["timestamp_s"] += [t] * ok.size
        cols["object_id"] += [f"o{i}" for i in ok.tolist()]
        cols["class"] += ["car" if i % 3 else "truck" for i in ok.tolist()]
        cols["u_min_px"] += (uv[ok, 0] - 20).tolist()
        cols["v_min_px"] += (uv[ok, 1] - 40).tolist()
        cols["u_max_px"] += (uv[ok, 0] + 20).tolist()
        cols["v_max_px"] += uv[ok, 1].tolist()
        cols["cov_uu_px2"] += [2.25] * ok.size  # the detector's 1.5 px (campaign_frames' default)
        cols["cov_uv_px2"] += [0.0] * ok.size
        cols["cov_vv_px2"] += [2.25] * ok.size
    pq.write_table(pa.table(cols), path)
    return len(cols["frame"])


_CHILD = r"""
import resource, sys, time, json
from footprint_uq.io import save_camera
from footprint_uq.tracking.synthetic import default_camera
kind, rec, out = sys.argv[1], sys.argv[2], sys.argv[3]
cam = default_camera()
t0 = time.perf_counter()
if kind == "objects":
    from footprint_uq.batch.process import process_file
    process_file(cam, "basler1@deg", rec, out + "/o.parquet", tracks=True, linearity=False, v2x_policy="linear",
                 progress=False, fsync=False)
else:
    from footprint_uq.batch.motion_fit_run import run_motion_fit
    run_motion_fit(cam, "basler1@deg", rec, out, modes=kind, fsync=False)
dt = time.perf_counter() - t0
print(json.dumps({"s": dt, "maxrss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))
"""


def run_child(kind: str, rec: Path, out: Path) -> dict:
    env = dict(os.environ)
    r = subprocess.run([sys.executable, "-c", _CHILD, kind, str(rec), str(out)], capture_output=True, text=True,
                       env=env, check=True)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", type=int, default=100)
    ap.add_argument("--duration", type=float, default=10.0)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--json", default=None)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        rec = Path(tmp) / "rec.parquet"
        n = write_recording(rec, a.objects, a.duration)
        kinds = ("objects", "one", "auto")
        for k in kinds:  # warm numba's cache in this tree (not timed)
            run_child(k, rec, Path(tmp))
        runs: dict = {k: [] for k in kinds}
        for _ in range(a.repeats):
            for k in kinds:
                runs[k].append(run_child(k, rec, Path(tmp)))
    res = {"detections": n, "objects": a.objects, "duration_s": a.duration, "repeats": a.repeats,
           "date": time.strftime("%Y-%m-%d %H:%M"), "load_avg": os.getloadavg()[0], "kinds": {}}
    ref = statistics.median(r["s"] for r in runs["objects"])
    for k, rs in runs.items():
        s = statistics.median(r["s"] for r in rs)
        res["kinds"][k] = {"median_s": s, "ratio_to_objects_tracks": s / ref, "detections_per_s": n / s,
                           "peak_rss_mb": max(r["maxrss_mb"] for r in rs),
                           "one_hour_8x30hzx100_h": s * HOUR_DETECTIONS / n / 3600}
    print(json.dumps(res, indent=1))
    if a.json:
        atomic_write_text(a.json, json.dumps(res, indent=1) + "\n")


if __name__ == "__main__":
    main()
