"""``footprint-uq validate`` on a large pairs table: wall time and peak memory at two sizes.

A synthetic probe-vehicle campaign (``footprint_uq.validation.synthetic``: 50 cameras, each with one
calibration draw, detections = bottom centres of 2-D boxes with pixel noise, truth on the true ground)
is written block by block to a Parquet pairs table with a camera registry.  The whole job
(:func:`footprint_uq.viz.validation_run.run_validation`: read in chunks -> contact function -> pairs ->
coverage accumulation -> per-object Parquet, summary JSON, HTML report) runs in a fresh subprocess per
size, which reports its wall time and its own peak resident memory (``VmHWM``).  Goal: 10^6 pairs in
under 60 s on the 2-core machine, peak memory flat in the number of pairs (the same at 10^5 and 10^6).

Run ``.venv/bin/python bench/bench_validate.py [--pairs 1000000] [--small 100000] [--cameras 50]
[--repeats 3] [--json out.json]``; :func:`measure` returns the figures.
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

import pyarrow.parquet as pq

from footprint_uq.io import save_camera
from footprint_uq.uncertainty.budget import ErrorBudget
from footprint_uq.validation.synthetic import campaign_table, random_cameras

BUDGET = ErrorBudget.preset("basler1@deg").replace(ground_height_m=0.05, ground_slope_deg=0.1, imaging_px=[1.0, 1.0])

_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
from footprint_uq.viz.validation_run import run_validation
from footprint_uq.uncertainty.budget import load_budget
t1 = time.perf_counter()
summary, files = run_validation(sys.argv[1], sys.argv[2], load_budget(sys.argv[3]), registry=sys.argv[4],
                                objects_format="parquet", chunk_rows=int(sys.argv[5]), fsync=False)
t2 = time.perf_counter()
hwm = [line for line in open("/proc/self/status") if line.startswith("VmHWM:")][0]
print(json.dumps({"pairs": summary["n_pairs"], "groups": summary["n_groups"], "verdict": summary["verdict"],
                  "coverage_95": summary["coverage"][2]["empirical"], "import_s": t1 - t0, "elapsed_s": t2 - t1,
                  "peak_rss_mb": int(hwm.split()[1]) / 1024.0}))
"""


def write_campaign(folder: Path, n_pairs: int, n_cameras: int, *, seed: int = 0) -> tuple[Path, Path]:
    """Pairs table (Parquet, written camera by camera) and camera registry of a synthetic campaign."""
    cams = random_cameras(n_cameras, seed=seed)
    per = n_pairs // n_cameras
    path = folder / f"pairs_{n_pairs}.parquet"
    writer = None
    for t in campaign_table(cams, BUDGET, per, seed=seed):
        writer = writer or pq.ParquetWriter(path, t.schema)
        writer.write_table(t)
    writer.close()
    for cid, cam in cams.items():
        save_camera(cam, folder / f"{cid}.yaml")
    reg = folder / "registry.json"
    reg.write_text(json.dumps([{"camera_id": cid, "camera": f"{cid}.yaml"} for cid in cams]))
    return path, reg


def run_child(pairs: Path, registry: Path, out: Path, budget_file: Path, chunk_rows: int) -> dict:
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    p = subprocess.run([sys.executable, "-c", _CHILD, str(pairs), str(out), str(budget_file), str(registry),
                        str(chunk_rows)], capture_output=True, text=True, env=env, timeout=3600)
    if p.returncode != 0:
        raise RuntimeError(p.stderr[-3000:])
    return json.loads(p.stdout.strip().splitlines()[-1])


def measure(*, pairs: int = 1_000_000, small: int = 100_000, cameras: int = 50, repeats: int = 3,
            chunk_rows: int = 131_072) -> dict:
    """Median wall time and peak RSS of the validation job at ``small`` and ``pairs`` pairs."""
    out: dict = {"cameras": cameras, "chunk_rows": chunk_rows, "repeats": repeats, "cpus": os.cpu_count(),
                 "sizes": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        budget_file = folder / "budget.json"
        budget_file.write_text(json.dumps(BUDGET.to_dict()))
        for n in (small, pairs):
            t0 = time.perf_counter()
            path, reg = write_campaign(folder, n, cameras)
            gen = time.perf_counter() - t0
            runs = [run_child(path, reg, folder / f"out_{n}", budget_file, chunk_rows) for _ in range(repeats)]
            out["sizes"][n] = {"generate_s": gen, "elapsed_s": [r["elapsed_s"] for r in runs],
                               "median_s": statistics.median(r["elapsed_s"] for r in runs),
                               "peak_rss_mb": max(r["peak_rss_mb"] for r in runs),
                               "us_per_pair": 1e6 * statistics.median(r["elapsed_s"] for r in runs) / runs[0]["pairs"],
                               "pairs": runs[0]["pairs"], "groups": runs[0]["groups"], "verdict": runs[0]["verdict"],
                               "coverage_95": runs[0]["coverage_95"]}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=1_000_000)
    ap.add_argument("--small", type=int, default=100_000)
    ap.add_argument("--cameras", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--chunk-rows", type=int, default=131_072)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    res = measure(pairs=a.pairs, small=a.small, cameras=a.cameras, repeats=a.repeats, chunk_rows=a.chunk_rows)
    for n, r in res["sizes"].items():
        print(f"{n:>9,} pairs, {res['cameras']} cameras: median {r['median_s']:.2f} s "
              f"({r['us_per_pair']:.1f} us/pair), peak RSS {r['peak_rss_mb']:.0f} MB, verdict {r['verdict']}, "
              f"95 % coverage {100 * r['coverage_95']:.1f} %")
    if a.json:
        a.json.write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
