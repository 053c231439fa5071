"""First run and second run of each command in a fresh numba cache (issue 24: a newcomer's first impression).

Each command runs in its own process with ``NUMBA_CACHE_DIR`` pointing at an empty folder.  The first run
finds its kernel group cold: it starts the compile in a detached background process and runs on the numpy
reference path (``products.warmup.KernelGate``, the default ``FOOTPRINT_UQ_COMPILE=background``).  The bench
then waits for that compile to finish (its lock file in the cache folder gone: ``compile_s``, counted from
the first run's start) and runs the command again with the same folder (the second run loads the kernels).
``--mode foreground`` measures the old behaviour (the first run compiles before it answers).  Wall time of
the whole process, start-up included; the load average is recorded beside the figures, since the compile
is CPU-bound and the machine may be shared.

    .venv/bin/python bench/bench_first_run.py [--out bench/results/first-run.json]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from footprint_uq.io.atomic import atomic_write_text

EXE = str(Path(sys.executable).with_name("footprint-uq"))


def _inputs(d: Path) -> dict:
    """A camera file, 200 3-D boxes in view and one detector frame, written under ``d``."""
    from footprint_uq import PanTiltCamera, save_camera

    cam = PanTiltCamera(focal_px=1400, image_size_px=(1920, 1080), height_m=8.0, pan_deg=30.0, tilt_deg=20.0)
    save_camera(cam, d / "cam.yaml")
    rng = np.random.default_rng(0)
    r = rng.uniform(15.0, 60.0, 200)
    a = np.deg2rad(30.0 + rng.uniform(-20.0, 20.0, 200))  # compass bearings around the camera's pan
    lines = ["frame,object_id,x_m,y_m,z_m,length_m,width_m,height_m,yaw_rad"]
    lines += [f"0,{k},{r[k] * np.sin(a[k]):.3f},{r[k] * np.cos(a[k]):.3f},0.75,4.5,1.8,1.5,{rng.uniform(0, 3):.3f}"
              for k in range(200)]
    (d / "boxes.csv").write_text("\n".join(lines) + "\n")
    frame = {"camera_id": "cam1", "frame": 1, "timestamp_s": 1714564800.0,
             "detections": [{"object_id": 7, "class": "car", "u_min_px": 900, "v_min_px": 600, "u_max_px": 1000,
                             "v_max_px": 700}]}
    (d / "frame.jsonl").write_text(json.dumps(frame) + "\n")
    return {
        "locate": ([EXE, "locate", "--camera", str(d / "cam.yaml"), "--budget", "basler1", "--pixel", "959.5", "800"],
                   None),
        "objects": ([EXE, "objects", "--camera", str(d / "cam.yaml"), "--budget", "basler1", "--detections",
                     str(d / "boxes.csv"), "--out", str(d / "fp.parquet"), "--quiet"], None),
        "map": ([EXE, "map", "--camera", str(d / "cam.yaml"), "--budget", "basler1", "--out", str(d / "map"),
                 "--max-range-m", "120"], None),
        "serve": ([EXE, "serve", "--camera", str(d / "cam.yaml"), "--budget", "basler1", "--camera-id", "cam1",
                   "--input", "-"], d / "frame.jsonl"),
    }


def _run(cmd: list, stdin: Path | None, cache: Path, mode: str) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "FOOTPRINT_UQ_COMPILE": mode}
    t0 = time.perf_counter()
    with open(stdin) if stdin is not None else open(os.devnull) as f:
        p = subprocess.run(cmd, stdin=f, capture_output=True, text=True, env=env, timeout=1800)
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        raise RuntimeError(f"{cmd[1]}: exit {p.returncode}: {p.stderr[-500:]}")
    return dt


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=None, help="JSON file of the figures")
    ap.add_argument("--only", default=None, help="comma-separated commands (locate, objects, map, serve)")
    ap.add_argument("--mode", default="background", choices=("background", "foreground"),
                    help="FOOTPRINT_UQ_COMPILE of the runs (default: background, the commands' default)")
    args = ap.parse_args(argv)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        cmds = _inputs(d)
        names = args.only.split(",") if args.only else list(cmds)
        for name in names:
            cmd, stdin = cmds[name]
            cache = d / f"numba-{name}"
            cache.mkdir()
            load0 = os.getloadavg()[0]
            t0 = time.perf_counter()
            cold = _run(cmd, stdin, cache, args.mode)
            while list(cache.glob("*.lock")):  # the background compile the first run started
                time.sleep(0.2)
            compile_s = time.perf_counter() - t0
            warm = _run(cmd, stdin, cache, args.mode)
            rows[name] = {"first_s": round(cold, 2), "second_s": round(warm, 2), "compile_s": round(compile_s, 2),
                          "load_average": round(load0, 2)}
            print(f"{name:8s} first {cold:7.1f} s   second {warm:6.1f} s   background compile done after "
                  f"{compile_s:6.1f} s   (load average {load0:.1f})", flush=True)
    res = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "cpus": os.cpu_count(), "mode": args.mode,
           "rows": rows}
    if args.out:
        atomic_write_text(args.out, json.dumps(res, indent=2) + "\n")
    return res


if __name__ == "__main__":
    main()
