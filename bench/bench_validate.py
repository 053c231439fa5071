"""``footprint-uq validate`` on a large pairs table: wall time and peak memory at two sizes.

A synthetic probe-vehicle campaign (``footprint_uq.validation.synthetic``: 50 cameras, each with one
calibration draw, detections = bottom centres of 2-D boxes with pixel noise, truth on the true ground)
is written block by block to a Parquet pairs table with a camera registry.  The whole job
(:func:`footprint_uq.viz.validation_run.run_validation`: read in chunks -> contact function -> pairs ->
coverage accumulation -> per-object Parquet, summary JSON, HTML report) runs in a fresh subprocess per
size, which reports its wall time and its own peak resident memory (``VmHWM``).  Goal: 10^6 pairs in
under 60 s on the 2-core machine, peak memory flat in the number of pairs (the same at 10^5 and 10^6; the
memory runs use small chunks so that 10^5 pairs span several chunks too).  The rows of the 50 cameras are
interleaved, so that every chunk holds every camera (the work per chunk is the same at both sizes).

Run ``.venv/bin/python bench/bench_validate.py [--pairs 1000000] [--small 100000] [--cameras 50]
[--repeats 3] [--chunk-rows 131072] [--memory-chunk-rows 16384] [--json out.json]``;
:func:`measure` returns the figures.
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

from footprint_uq.io import save_camera
from footprint_uq.io.atomic import atomic_write_text
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


def write_campaign(folder: Path, n_pairs: int, n_cameras: int, *, seed: int = 0, block: int = 100_000
                   ) -> tuple[Path, Path]:
    """Pairs table (Parquet) and camera registry of a synthetic campaign.  The rows of all cameras are
    interleaved (seeded shuffle, as detections sorted by time would be), so that every chunk holds every
    camera at both sizes: the work per chunk, hence the memory, is the same at 10^5 and 10^6 pairs."""
    cams = random_cameras(n_cameras, seed=seed)
    per = n_pairs // n_cameras
    path = folder / f"pairs_{n_pairs}.parquet"
    table = pa.concat_tables(campaign_table(cams, BUDGET, per, seed=seed))
    table = table.take(np.random.default_rng(seed).permutation(table.num_rows))
    with pq.ParquetWriter(path, table.schema) as writer:
        for start in range(0, table.num_rows, block):
            writer.write_table(table.slice(start, block))
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
            chunk_rows: int = 131_072, memory_chunk_rows: int = 16_384) -> dict:
    """Wall time (median of ``repeats`` fresh processes, ``chunk_rows``) at ``pairs`` pairs, and peak RSS at
    ``small`` and ``pairs`` pairs with ``memory_chunk_rows`` (so that the small input spans several chunks
    too: like for like)."""
    out: dict = {"cameras": cameras, "chunk_rows": chunk_rows, "memory_chunk_rows": memory_chunk_rows,
                 "repeats": repeats, "cpus": os.cpu_count(), "load_avg_start": os.getloadavg()[0], "sizes": {}}
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        budget_file = folder / "budget.json"
        budget_file.write_text(json.dumps(BUDGET.to_dict()))
        for n in (small, pairs):
            t0 = time.perf_counter()
            path, reg = write_campaign(folder, n, cameras)
            gen = time.perf_counter() - t0
            mem = run_child(path, reg, folder / f"mem_{n}", budget_file, memory_chunk_rows)
            row = {"generate_s": gen, "peak_rss_mb": mem["peak_rss_mb"], "memory_run_s": mem["elapsed_s"],
                   "pairs": mem["pairs"], "groups": mem["groups"], "verdict": mem["verdict"],
                   "coverage_95": mem["coverage_95"]}
            if n == pairs:
                runs = [run_child(path, reg, folder / f"out_{n}", budget_file, chunk_rows) for _ in range(repeats)]
                row.update(elapsed_s=[r["elapsed_s"] for r in runs], median_s=statistics.median(r["elapsed_s"]
                                                                                                 for r in runs),
                           peak_rss_mb_time_runs=max(r["peak_rss_mb"] for r in runs))
                row["us_per_pair"] = 1e6 * row["median_s"] / mem["pairs"]
            out["sizes"][n] = row
    out["load_avg_end"] = os.getloadavg()[0]
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=1_000_000)
    ap.add_argument("--small", type=int, default=100_000)
    ap.add_argument("--cameras", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--chunk-rows", type=int, default=131_072)
    ap.add_argument("--memory-chunk-rows", type=int, default=16_384)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    res = measure(pairs=a.pairs, small=a.small, cameras=a.cameras, repeats=a.repeats, chunk_rows=a.chunk_rows,
                  memory_chunk_rows=a.memory_chunk_rows)
    for n, r in res["sizes"].items():
        print(f"{n:>9,} pairs, {res['cameras']} cameras: peak RSS {r['peak_rss_mb']:.0f} MB "
              f"({res['memory_chunk_rows']}-row chunks), verdict {r['verdict']}, 95 % coverage "
              f"{100 * r['coverage_95']:.1f} %")
        if "median_s" in r:
            print(f"{n:>9,} pairs: wall time median {r['median_s']:.1f} s of {res['repeats']} "
                  f"({r['us_per_pair']:.1f} us/pair, {res['chunk_rows']}-row chunks; peak RSS "
                  f"{r['peak_rss_mb_time_runs']:.0f} MB); load average {res['load_avg_start']:.1f} -> "
                  f"{res['load_avg_end']:.1f} on {res['cpus']} CPUs")
    if a.json:
        atomic_write_text(a.json, json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
